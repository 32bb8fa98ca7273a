"""The steps of the method as file-level functions: paths in, paths out, options, and the
``progress`` (fraction 0–1), ``cancelled`` (polled) and ``note`` (what was assumed or repaired)
callables. The command line (``cli``), QGIS's worker (``worker``) and the library call these and
nothing else, so a step's glue is written once.

Each returns a dict of what it wrote and measured, keyed as the QGIS algorithms' outputs
(``OUTPUT``, ``NODES``, ``crs`` as WKT, …), with ``summary``: one or more lines saying what was
written, which the command line prints and QGIS logs.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .. import io
from ..engine.progress import part, report as stage
from ..errors import FloodMeshError
from ..io.outputs import check_output_folder, check_outputs, require_suffix
from ..options import (DEFAULT_MAX_TRIANGLES, check_cell_size, check_classes, check_flow_area,
                       check_holdout, check_max_area, check_max_gap, check_max_triangles,
                       check_min_angle, check_refinement, check_seed, is_point_source)
from ..points import PointCloud, at_places_of, split_holdout, step_points
from ..raster import (check_dem_size, check_scale, chosen_crs, corners_and_centre, parse_crs,
                      require_metric_crs, require_same_place)
from ..steps.breakpoints import breakpoints_file
from ..steps.slope import slope_raster_file

# the formats the steps write: the extensions an output's name may end in, and its name
GEOTIFF = ((".tif", ".tiff"), "a GeoTIFF")
GEOPACKAGE = ((".gpkg",), "a GeoPackage")
SMS_2DM = ((".2dm",), "an SMS 2DM mesh")


def _files(reads, writes, *, geotiff=(), gpkg=(), sms=()) -> None:
    """Before any work: no output may be (or replace) an input, each output's folder must be
    writable, and the names of the rasters, layers and meshes written (None: not written) end
    in their format's extension."""
    check_outputs([r for r in reads if r], [w for w in writes if w])
    for paths, (suffixes, what) in ((geotiff, GEOTIFF), (gpkg, GEOPACKAGE), (sms, SMS_2DM)):
        for path in (p for p in paths if p):
            require_suffix(path, suffixes, what)


def grid(input, output, *, cell_size: float, crs=None, classes=None, max_gap=None,
         holdout: float = 0.0, seed: int = 0, holdout_output=None, workers=None,
         scheduler=None, skip_unreadable: bool = False, progress=None, cancelled=None,
         note=None) -> dict:
    """Step 2: LiDAR points (a file, or tiles: gridded on Dask block by block, unreadable ones
    left out with ``skip_unreadable``) to a DEM GeoTIFF at ``cell_size`` m by linear (TIN)
    interpolation; ``holdout`` of the points held back and written to ``holdout_output``
    (GeoPackage)."""
    # lazy: PROJ loads only when this runs
    from .source import check_outputs_apart, open_source

    source = open_source(input, skip_unreadable=skip_unreadable)
    _files(source.paths, [output, holdout_output], geotiff=[output], gpkg=[holdout_output])
    check_outputs_apart(source, [output])
    check_cell_size(cell_size)
    check_max_gap(max_gap)
    check_holdout(holdout)
    seed = check_seed(seed)
    classes = check_classes(classes) if classes else None
    # lazy: PROJ loads only when this runs
    from ..engine.tiles import grid_point_tiles, read_point_tiles

    tiles = None
    if source.tiled and not scheduler:  # in memory where they fit
        tiles = read_point_tiles(source.paths, cell_size, crs=crs, classes=classes,
                                 holdout=holdout, seed=seed, workers=workers,
                                 cancelled=cancelled)
    if source.tiled and tiles is None:
        tiled = grid_point_tiles(source.paths, cell_size, max_gap=max_gap, crs=crs,
                                 classes=classes, holdout=holdout, seed=seed, out_path=output,
                                 keep=False, workers=workers, scheduler=scheduler,
                                 progress=progress, cancelled=cancelled)
        for message in tiled.notes if note else ():
            note(message)
        held, points_crs = tiled.holdout, tiled.crs
        written = f"DEM of {tiled.n_tiles} tiles ({tiled.n_points:,} points) written to {output}"
    else:
        # lazy: numba loads only when this runs
        from ..steps.grid import check_grid, grid_points_linear

        plan = None
        if tiles is None:
            points = io.read_points(source.path, crs=crs, classes=classes, note=note)
            gridding, kept_back = split_holdout(points, holdout, seed, note=note)
            held, points_crs, read = kept_back.xyz, points.crs, ""
            # the reader checked their spread: the plan spares the gridding that check
            plan = check_grid(gridding, cell_size, max_gap)
        else:
            for message in tiles.notes if note else ():
                note(message)
            gridding = PointCloud(tiles.gridding, tiles.crs)
            held, points_crs = tiles.holdout, tiles.crs
            read = f" from {tiles.n_tiles} tiles ({tiles.n_points:,} points)"
        dem = grid_points_linear(gridding, cell_size, max_gap=max_gap, progress=progress,
                                 cancelled=cancelled, plan=plan)
        io.write_raster(output, dem, quantity=io.ELEVATION)
        written = (f"DEM {dem.shape[1]} x {dem.shape[0]} cells of {dem.cell_size} m{read} "
                   f"written to {output}")
    result = {"OUTPUT": str(output), "crs": points_crs.to_wkt()}
    lines = []
    if holdout_output and len(held):
        io.write_points_gpkg(holdout_output, held, points_crs, layer="holdout")
        result["HOLDOUT_OUTPUT"] = str(holdout_output)
        lines.append(f"{len(held)} held-out points written to {holdout_output}")
    return {**result, "summary": "\n".join([*lines, written])}


def slope(input, output, *, method: str = "one-over-distance", sigma: float = 1.0,
          log_kernel: str = "pratt", crs=None, progress=None, cancelled=None,
          note=None) -> dict:
    """Step 3: slope in degrees by a 3x3 kernel, or the Laplacian-of-Gaussian response (m,
    ``method="log"``, σ ``sigma`` m), file to file block by block."""
    _files([input], [output], geotiff=[output])
    slope_raster_file(input, output, method, sigma=sigma, log_kernel=log_kernel, crs=crs,
                      note=note, progress=progress, cancelled=cancelled)
    written = (f"Laplacian-of-Gaussian response (sigma {sigma} m, m) written to {output}"
               if method == "log" else f"slope ({method}, degrees) written to {output}")
    return {"OUTPUT": str(output), "summary": written}


def breakpoints(input, output, *, s_crit: float = 10.0, sensitivity=None,
                zero_crossings: bool = False, crs=None, progress=None, cancelled=None,
                note=None) -> dict:
    """Step 4: thinned breakpoints where the slope reaches ``s_crit`` degrees (or a LoG response
    reaches ``sensitivity`` m), file to file block by block."""
    _files([input], [output], geotiff=[output])
    count = breakpoints_file(input, output, s_crit=s_crit, sensitivity=sensitivity,
                             zero_crossings=zero_crossings, crs=crs, progress=progress,
                             cancelled=cancelled)
    return {"OUTPUT": str(output), "summary": f"{count} breakpoints written to {output}"}


def trace(breakpoints, slope, dem, output, *, s_crit: float = 10.0, mode: str = "auto",
          min_points: int = 3, min_length: float = 0.0, join: bool = True, seed: int = 0,
          crs=None, progress=None, cancelled=None, note=None) -> dict:
    """Step 5: break lines through the breakpoints (GeoPackage of LineStringZ)."""
    # lazy: numba loads only when this runs
    from ..steps.breaklines import check_tracing, trace_breaklines

    _files([breakpoints, slope, dem], [output], gpkg=[output])
    check_tracing(s_crit, mode, min_points, min_length, seed)
    fix = "give the slope's breakpoints (floodmesh breakpoints SLOPE; Classify breakpoints in QGIS)"
    points = io.read_raster(breakpoints, crs=crs, elevations=False, holds=("breakpoints", fix))
    slope_grid = io.read_raster(slope, crs=crs, elevations=False, holds=(
        "slope", "the tracer follows the slope, also where the breakpoints come from the LoG "
        "response: give the DEM's slope (floodmesh slope DEM, without --method log)"))
    # an untagged raster (another program's, or a DEM given in its place) is judged by its values
    other = points.values[(points.values != 0) & (points.values != 1) & ~np.isnan(points.values)]
    if other.size:
        raise FloodMeshError(f"raster {Path(breakpoints).name} holds values other than 0 and 1 "
                             f"(such as {other[0]:g}): it is no breakpoints raster: {fix}")
    points = points.with_values((points.values == 1).astype("uint8"))
    terrain = io.read_dem(dem, crs=crs, note=note)
    stage(progress, cancelled, 0.1)
    lines = trace_breaklines(points, slope_grid, terrain, s_crit, mode=mode,
                             min_points=min_points, min_length=min_length, join=join, seed=seed,
                             progress=part(progress, 0.1, 0.9), cancelled=cancelled)
    io.write_breaklines(output, lines, terrain.crs)
    stage(progress, None, 1.0)
    return {"OUTPUT": str(output), "crs": terrain.crs.to_wkt(),
            "summary": f"{len(lines)} break lines written to {output}"}


def simplify(input, output, *, method: str, amount: float, min_distance: float = 0.0,
             crs=None, progress=None, cancelled=None, note=None) -> dict:
    """Step 6: break lines simplified by ``method`` (every ``amount``-th point, or within
    ``amount`` m by Douglas–Peucker or a spline), crossings repaired, slivers merged."""
    # lazy: numba and GEOS load only when this runs
    from ..steps.simplify import simplify_breaklines

    _files([input], [output], gpkg=[output])
    name = io.vector_path(input).name
    crs = require_metric_crs(chosen_crs(crs, io.vector_crs(input), name, note), name, "vector")
    lines = io.read_breaklines(input)
    if lines:  # tolerances and distances are metres on the ground: a CRS true to scale there
        xy = np.concatenate([line.coords[:, :2] for line in lines])
        check_scale(crs, *corners_and_centre(*xy.min(axis=0), *xy.max(axis=0)), name, "vector")
    stage(progress, cancelled, 0.1)
    simple = simplify_breaklines(lines, method, amount, min_distance=min_distance,
                                 progress=part(progress, 0.1, 0.9), cancelled=cancelled)
    io.write_breaklines(output, simple, crs)
    stage(progress, None, 1.0)
    before, after = sum(len(x.coords) for x in lines), sum(len(x.coords) for x in simple)
    return {"OUTPUT": str(output), "crs": crs.to_wkt(),
            "summary": f"{len(simple)} break lines, {before} → {after} points, written to "
                       f"{output}"}


def _mesh_inputs(dem, breaklines, boundary, user_lines, crs=None, note=None):
    """(DEM, break lines, the user's own lines, domain) of a meshing step."""
    # lazy: numba, PROJ and GEOS load only when this runs
    from .pipeline import layer_crs, mesh_constraints

    terrain = io.read_dem(dem, crs=crs, note=note)
    check_dem_size(terrain.values, terrain.cell_size, f"raster {Path(dem).name}")
    if breaklines:
        layer_crs(breaklines, "break line", terrain.crs, note=note)
    lines = io.read_lines_gpkg(breaklines) if breaklines else []
    domain, own = mesh_constraints(terrain, boundary, user_lines, note=note)
    return terrain, lines, own, domain


def mesh(dem, output, *, breaklines=None, boundary=None, user_lines=None, size_field=None,
         min_area=None, flow_area: float | None = None, conforming: bool = False,
         min_angle: float = 25.0, max_area: float = 100.0,
         max_triangles: int = DEFAULT_MAX_TRIANGLES, triangles=None, crs=None, progress=None,
         cancelled=None, note=None) -> dict:
    """Step 7: a Triangle mesh (SMS 2DM, and the triangles as a GeoPackage to ``triangles``) of
    the DEM's valid area or ``boundary``, honouring the break lines and the user's own lines,
    no angle below ``min_angle`` degrees and no triangle above ``max_area`` m² (smaller where
    ``size_field`` or the flow zone, ``flow_area`` m², None: the default, 0: off, asks)."""
    # lazy: numba, PROJ and GEOS load only when this runs
    from ..steps.drainage import flow_area_for, flow_refined, flow_size
    from ..steps.mesh import build_mesh, mesh_quality
    from .pipeline import size_field as size_from

    _files([dem, breaklines, boundary, user_lines, size_field if size_field != "slope" else None],
           [output, triangles], sms=[output], gpkg=[triangles])
    check_min_angle(min_angle)
    check_max_area(max_area)
    check_max_triangles(max_triangles)
    check_flow_area(flow_area)
    terrain, lines, own, domain = _mesh_inputs(dem, breaklines, boundary, user_lines, crs, note)
    stage(progress, cancelled, 0.05)
    size = size_from(size_field, terrain, max_area=max_area, min_area=min_area)
    flow_area = flow_area_for(flow_area, terrain.cell_size)
    # smaller triangles where water flows and the terrain needs them (see drainage)
    flow = None if flow_area is None else flow_size(terrain, flow_area=flow_area)
    stage(progress, cancelled, 0.1)
    # the first mesh, then (where the flow zone asks) the one refined there
    result_mesh, _, _ = flow_refined(lambda size, _, told, **progress_cancelled: build_mesh(
        terrain, lines, own_lines=own, min_angle=min_angle, max_area=max_area,
        conforming=conforming, domain=domain, size_field=size, max_triangles=max_triangles,
        note=told, **progress_cancelled),
        size, flow, None, terrain, lines=lines + own, note=note,
        progress=part(progress, 0.1, 0.85), cancelled=cancelled)
    io.write_mesh_2dm(output, result_mesh.nodes, result_mesh.triangles, crs=terrain.crs)
    result = {"OUTPUT": str(output), "crs": terrain.crs.to_wkt()}
    stage(progress, None, 0.9)  # written: no more stopping
    if triangles:
        io.write_mesh_gpkg(triangles, result_mesh.nodes, result_mesh.triangles, terrain.crs)
        result["TRIANGLES"] = str(triangles)
    q = mesh_quality(result_mesh, min_angle=min_angle, max_area=max_area)
    stage(progress, None, 1.0)
    return {**result, "NODES": q["nodes"], "TRIANGLE_COUNT": q["triangles"],
            "summary": f"{q['nodes']} nodes, {q['triangles']} triangles (min angle "
                       f"{q['min_angle_deg']:.2f}°, max area {q['max_area_m2']:.1f} m²) written "
                       f"to {output}"}


def measured_points(path, crs=None, fallback=None, note=None, *, what="point", of="mesh"):
    """(xyz, CRS) of measured points: a LiDAR point file (LAS/LAZ ground, XYZ/CSV; ``crs``
    overrides its own) or a point layer (GeoPackage, Shapefile, GeoJSON; ``crs``, which
    ``note`` hears replace its own, else its own, else ``fallback``, the ``of``'s, mesh's or
    DEM's); refused where their CRS is not ``fallback`` (the ``what`` file, by name). Either way
    ``note`` hears of the points left out (``points.drop_unusable``)."""
    name = io.vector_path(path).name
    if is_point_source(path):
        cloud = io.read_points(path, crs=crs, note=note)
        xyz, points_crs = cloud.xyz, cloud.crs
    else:
        # the point readers' rule: points without a finite x, y, z or with a z no ground has
        # (-9999) are left out, ``note`` told; none left is refused
        xyz = step_points(io.read_points_vector(path), f"point layer {name}", note, least=1)
        points_crs = require_metric_crs(
            chosen_crs(crs, io.vector_crs(path), name, note) or fallback, name)
    if fallback is not None and points_crs is not None:
        require_same_place(parse_crs(points_crs, name), parse_crs(fallback, name),
                           f"{what} file {name}", of)
    return xyz, points_crs


def refine(dem, points, output, *, breaklines=None, boundary=None, user_lines=None, check=None,
           min_angle: float = 25.0, max_area: float = 100.0, lower: float = 0.10,
           upper: float = 0.25, target_rmse=None, target_max=None, max_nodes: int = 1_000_000,
           max_rounds: int = 8, noise=None, report=None, crs=None, progress=None,
           cancelled=None, note=None) -> dict:
    """Step 9: refine the mesh with the measured ``points`` until no triangle's points misfit by
    more than ``lower`` m RMS beyond their ``noise`` (m; None: estimated from them) and none by
    more than ``upper`` m (or the targets are met); ``check`` points are only measured, each
    round."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import mesh_quality
    from ..steps.refine import refine_mesh

    _files([dem, points, check, breaklines, boundary, user_lines], [output, report],
           sms=[output])
    check_min_angle(min_angle)
    check_max_area(max_area)
    check_refinement(lower, upper, target_rmse=target_rmse, target_max=target_max, noise=noise,
                     max_rounds=max_rounds, max_nodes=max_nodes)
    terrain, lines, own, domain = _mesh_inputs(dem, breaklines, boundary, user_lines, crs, note)
    measured = measured_points(points, crs, terrain.crs, note, what="measured point",
                               of="DEM")[0]
    check_xyz = (measured_points(check, crs, terrain.crs, note, what="check point", of="DEM")[0]
                 if check else None)
    if check_xyz is not None:
        measured = _without_check_points(measured, check_xyz, points, check, note)
    refined, rounds = refine_mesh(terrain, lines, measured, check=check_xyz, domain=domain,
                                  min_angle=min_angle, max_area=max_area, lower=lower,
                                  upper=upper, target_rmse=target_rmse, target_max=target_max,
                                  max_nodes=max_nodes, max_rounds=max_rounds, noise=noise,
                                  mesh_options=dict(own_lines=own), progress=progress,
                                  cancelled=cancelled, note=note)
    io.write_mesh_2dm(output, refined.nodes, refined.triangles, crs=terrain.crs)
    result = {"OUTPUT": str(output), "NODES": len(refined.nodes), "RMSE": rounds[-1].rmse_m,
              "crs": terrain.crs.to_wkt()}
    if report:
        io.write_json(report, {"rounds": [asdict(r) for r in rounds],
                               **mesh_quality(refined, min_angle=min_angle, max_area=max_area)})
        result["REPORT"] = str(report)
    table = [f"{'round':>5}{'nodes':>9}{'RMSE cm':>9}{'max cm':>8}{'check RMSE':>12}"
             f"{'inserted':>10}{'refined':>9}"]
    table += [f"{k:>5}{r.nodes:>9}{100 * r.rmse_m:>9.1f}{100 * r.max_abs_m:>8.1f}"
              f"{100 * r.check_rmse_m:>12.1f}{r.inserted:>10}{r.refined:>9}"
              for k, r in enumerate(rounds, 1)]
    return {**result, "summary": "\n".join([*table, f"{len(refined.nodes)} nodes written to "
                                                    f"{output}"])}


def _without_check_points(measured, check, points_path, check_path, note):
    """The ``measured`` points (n, 3) less those at a check point's x, y (to 0.1 mm): a survey
    given whole beside its held-out points (``grid --holdout``) would refine the mesh at the
    check points and flatter their error."""
    shared = at_places_of(measured, check)
    if shared.all():
        raise FloodMeshError(f"every measured point of {Path(points_path).name} is a check point "
                             f"of {Path(check_path).name}: give the refinement the survey's "
                             "points and the held-out ones as check points")
    if shared.any() and note:
        note(f"{int(shared.sum()):,} of the {len(measured):,} measured points of "
             f"{Path(points_path).name} lie at check points of {Path(check_path).name} and were "
             "left out of the refinement: check points are only measured, never inserted")
    return measured[~shared] if shared.any() else measured


def assess(mesh, points, output, *, report=None, png=None, crs=None, progress=None,
           cancelled=None, note=None) -> dict:
    """Step 8: residuals of check points against the mesh's TIN (GeoPackage), their statistics
    (RMSE, NSSDA test, classes) to ``report`` (JSON) and the residual map and histogram into the
    folder ``png``."""
    # lazy: PROJ and GEOS load only when this runs
    from ..io.report import HISTOGRAM_PNG, MAP_PNG, write_report_pngs
    from ..steps.accuracy import assess as assess_mesh
    from ..steps.mesh import Mesh

    _files([mesh, points], [output, report], gpkg=[output])
    if png:  # a folder, made if missing
        check_output_folder(png, [mesh, points], [HISTOGRAM_PNG, MAP_PNG])
    read = io.read_2dm(mesh)
    stage(progress, cancelled, 0.1)
    xyz, points_crs = measured_points(points, crs, read.crs, note, what="check point")
    stage(progress, cancelled, 0.2)
    # the library's step, with its notes (too few check points for the NSSDA test)
    res, stats = assess_mesh(Mesh(read.nodes, read.triangles, points_crs), xyz, note=note,
                             progress=part(progress, 0.2, 0.7), cancelled=cancelled)
    io.write_residuals(output, xyz, res, points_crs)
    stage(progress, None, 0.8)  # written: no more stopping
    result = {"OUTPUT": str(output), "RMSE": stats["rmse_m"], "statistics": stats}
    if report:
        io.write_json(report, stats)
        result["REPORT"] = str(report)
    if png:
        Path(png).mkdir(parents=True, exist_ok=True)
        stage(progress, None, 0.85)
        result["figures"] = [str(p) for p in write_report_pngs(png, read.nodes, read.triangles,
                                                               xyz, res)]
    stage(progress, None, 1.0)
    return {**result, "summary": json.dumps(stats, indent=2)}


def export(mesh, output, *, fmt=None, crs=None, open_boundaries=None, snap: float = 1.0,
           regions=None, material_field=None, datum_offset: float = 0.0,
           element_elevations: bool = False, breaklines=None, progress=None, cancelled=None,
           note=None) -> dict:
    """A mesh (SMS 2DM) for a solver: TELEMAC (SLF + CLI), ADCIRC, SCHISM, UGRID, … by ``fmt``
    or ``output``'s extension, with open boundaries, material regions and a datum offset."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.export import export_mesh, format_of, layers_crs

    fmt = format_of(output, fmt)
    _files([mesh, open_boundaries, regions, breaklines],
           [output, Path(output).with_suffix(".cli") if fmt == "slf" else None])
    read = io.read_2dm(mesh)
    stage(progress, cancelled, 0.2)
    crs = layers_crs(chosen_crs(crs, read.crs, f"mesh {Path(mesh).name}", note),
                     {"open boundary": open_boundaries, "region": regions,
                      "break line": breaklines})
    open_lines = io.read_lines_gpkg(open_boundaries) if open_boundaries else ()
    regions = io.read_regions(regions, field=material_field) if regions else ()
    breaklines = io.read_lines_gpkg(breaklines) if breaklines else ()
    stage(progress, cancelled, 0.3)
    written = export_mesh(
        output, read.nodes, read.triangles, fmt=fmt, crs=crs, open_lines=open_lines, snap=snap,
        regions=regions, materials=read.materials, datum_offset=datum_offset,
        element_elevations=element_elevations, breaklines=breaklines,
        progress=part(progress, 0.3, 1.0), cancelled=cancelled)
    result = {"OUTPUT": str(output), "files": [str(p) for p in written],
              "crs": crs.to_wkt() if crs is not None else None}
    if fmt == "slf":
        result["CLI"] = str(written[1])
    return {**result, "summary": f"{len(read.nodes)} nodes, {len(read.triangles)} triangles "
                                 f"written as {fmt} to {', '.join(str(p) for p in written)}"}
