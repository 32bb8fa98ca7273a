"""Reading and writing at the pipeline's edges, by kind: point files (``points``), rasters
(``rasters``), vector layers and GeoPackages (``vectors``), meshes (``meshes``); where outputs
go, atomic writes and JSON (``outputs``); the report's pictures and page (``report``,
``report_html``) and the QGIS layer file (``layer_definition``).

Every writer writes to a temporary name beside the target and renames it when complete
(``atomic_output``), so an error, Ctrl-C or a cancel leaves the previous file (or none), never a
truncated one.

The readers and writers the rest of FloodMesh uses are re-exported here, so that
``from floodmesh.core import io; io.read_points(...)`` works whichever module holds them.
"""
from .meshes import (Mesh2DM, read_2dm, read_mesh_2dm, read_prj, write_mesh_2dm, write_mesh_gpkg,
                     write_prj)
from .outputs import atomic_output, jsonable, require_file, write_json
from .points import (GROUND_CLASS, classes_kept, file_format, las_classes, las_crs,
                     las_fields_read, las_xyz, point_file_name, read_las, read_point_file,
                     read_points, read_xyz, write_points_las)
from .rasters import (ELEVATION, INTEGER_COMPRESSION, RASTER_EXTENSIONS, TILE, band_scaling,
                      check_quantity, dem_file, describe_band, drop_implausible, held_quantity,
                      implausible_note, no_valid_cells, nodata_range, raster_crs, raster_crs_wkt,
                      raster_profile, read_band, read_dem, read_input, read_raster,
                      refuse_non_elevations, write_raster)
from .vectors import (read_boundary, read_breaklines, read_lines_gpkg, read_own_lines,
                      read_points_vector, read_regions, vector_crs, vector_path,
                      write_breaklines, write_gpkg, write_lines_gpkg, write_points_gpkg,
                      write_residuals)

__all__ = [
    # points
    "GROUND_CLASS", "classes_kept", "file_format", "las_classes", "las_crs", "las_fields_read",
    "las_xyz", "point_file_name", "read_las", "read_point_file", "read_points", "read_xyz",
    "write_points_las",
    # rasters
    "ELEVATION", "INTEGER_COMPRESSION", "RASTER_EXTENSIONS", "TILE", "band_scaling",
    "check_quantity",
    "dem_file", "describe_band", "drop_implausible", "held_quantity", "implausible_note",
    "no_valid_cells", "nodata_range", "raster_crs", "raster_crs_wkt", "raster_profile",
    "read_band", "read_input", "read_raster", "read_dem", "refuse_non_elevations", "write_raster",
    # vectors
    "read_boundary", "read_breaklines", "read_lines_gpkg", "read_own_lines",
    "read_points_vector", "read_regions",
    "vector_crs", "vector_path", "write_breaklines", "write_gpkg", "write_lines_gpkg",
    "write_points_gpkg", "write_residuals",
    # meshes
    "Mesh2DM", "read_2dm", "read_mesh_2dm", "read_prj", "write_mesh_2dm", "write_mesh_gpkg",
    "write_prj",
    # outputs: atomic writes, an input's existence check, JSON
    "atomic_output", "jsonable", "require_file", "write_json",
]
