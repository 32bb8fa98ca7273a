"""CRSs as users give them: compound DEMs with layers in their horizontal CRS, tiles that differ
only in naming their heights, layers without a CRS, a --crs that replaces a file's own, and
what the messages for feet and for a projection far from true scale tell the user to do."""
import fiona
import numpy as np
import pytest
import rasterio
import shapely
from affine import Affine
from pyproj import CRS

from floodmesh.core.frontends.cli import main

from ..bad_inputs import (ORIGIN, las_vertical_feet_keys, plane_xyz, slope_dem, write_las,
                          write_tif)

RD = (155_000.0, 463_000.0)  # in the Netherlands, RD New (EPSG:28992)


def floodmesh(args, capsys):
    """(exit code, stderr lines) of the command ``args`` run in this process."""
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err.strip().splitlines()


def write_polygon(path, polygon, crs=None):
    """A polygon layer (GeoPackage or shapefile, by extension) in ``crs``, or without a CRS."""
    driver = "ESRI Shapefile" if path.suffix == ".shp" else "GPKG"
    options = {"crs_wkt": CRS.from_user_input(crs).to_wkt()} if crs else {}
    with fiona.open(path, "w", driver=driver, schema={"geometry": "Polygon", "properties": {}},
                    **options) as dst:
        dst.write({"geometry": shapely.geometry.mapping(polygon), "properties": {}})
    return path


def write_line(path, coords, crs):
    with fiona.open(path, "w", driver="GPKG", crs_wkt=CRS.from_user_input(crs).to_wkt(),
                    schema={"geometry": "LineString", "properties": {}}) as dst:
        dst.write({"geometry": {"type": "LineString", "coordinates": coords}, "properties": {}})
    return path


def rd_dem(path, crs="EPSG:7415"):
    """The bank DEM (60 x 60 m) in the Netherlands, by default in RD New + NAP height."""
    return write_tif(path, slope_dem(), crs=crs,
                     transform=Affine(1.0, 0.0, RD[0], 0.0, -1.0, RD[1] + 60))


@pytest.mark.parametrize("option", ["--boundary", "--lines"])
def test_compound_dem_takes_layers_in_its_horizontal_crs(tmp_path, capsys, option):
    """A LiDAR DEM in RD New + NAP height and a boundary or lines drawn in RD New: meshed."""
    dem = rd_dem(tmp_path / "dem.tif")
    layer = (write_polygon(tmp_path / "b.gpkg", shapely.box(RD[0] + 5, RD[1] + 5, RD[0] + 55,
                                                             RD[1] + 55), "EPSG:28992")
             if option == "--boundary" else
             write_line(tmp_path / "l.gpkg", [(RD[0] + 10, RD[1] + 10), (RD[0] + 50, RD[1] + 50)],
                        "EPSG:28992"))
    code, err = floodmesh(["mesh", dem, option, layer, "--out", tmp_path / "m.2dm"], capsys)
    assert code == 0, err
    assert (tmp_path / "m.2dm").exists()


def test_tiles_that_differ_only_in_naming_their_heights_grid_as_one(tmp_path, capsys):
    """Two tiles of one delivery, one tagged UTM 32N + DHHN92 height, one UTM 32N alone."""
    xyz = plane_xyz()
    west = xyz[:, 0] < xyz[:, 0].mean()
    write_las(tmp_path / "west.laz", xyz[west], crs="EPSG:25832+5783")
    write_las(tmp_path / "east.laz", xyz[~west], crs="EPSG:25832")
    code, err = floodmesh(["grid", tmp_path / "west.laz", tmp_path / "east.laz",
                           "--cell-size", 1, "--out", tmp_path / "dem.tif"], capsys)
    assert code == 0, err
    assert (tmp_path / "dem.tif").exists()


@pytest.mark.parametrize("name", ["b.gpkg", "b.shp"])
def test_boundary_without_crs_is_taken_in_the_dems_with_a_note(tmp_path, capsys, name):
    """A GeoPackage layer in an undefined SRS and a shapefile without .prj alike: meshed in the
    DEM's CRS, as QGIS draws them over it, and the user told so."""
    dem = rd_dem(tmp_path / "dem.tif", crs="EPSG:28992")
    boundary = write_polygon(tmp_path / name, shapely.box(RD[0] + 5, RD[1] + 5, RD[0] + 55,
                                                          RD[1] + 55))
    code, err = floodmesh(["mesh", dem, "--boundary", boundary, "--out", tmp_path / "m.2dm"],
                          capsys)
    assert code == 0, err
    assert any(f"{name} has no CRS: it is taken to be in the DEM's, Amersfoort / RD New" in line
               and "ogr2ogr -a_srs EPSG:XXXX" in line for line in err), err


def test_crs_given_for_a_raster_with_its_own_is_noted(tmp_path, capsys):
    """--crs replaces the file's CRS: said where it differs, not where it is the same."""
    dem = rd_dem(tmp_path / "dem.tif", crs="EPSG:25832")
    code, err = floodmesh(["mesh", dem, "--crs", "EPSG:25833", "--out", tmp_path / "m.2dm"],
                          capsys)
    assert code == 0, err
    assert ("floodmesh: note: raster dem.tif is in ETRS89 / UTM zone 32N, but the CRS given is "
            "used: ETRS89 / UTM zone 33N") in "\n".join(err)
    code, err = floodmesh(["mesh", dem, "--crs", "EPSG:25832", "--out", tmp_path / "m2.2dm"],
                          capsys)
    assert code == 0 and not any("CRS given" in line for line in err), err


def test_crs_given_for_point_tiles_with_their_own_is_noted_once(tmp_path, capsys):
    """One note for the tiles, not one a tile."""
    xyz = plane_xyz()
    west = xyz[:, 0] < xyz[:, 0].mean()
    for name, part in (("west.laz", xyz[west]), ("east.laz", xyz[~west])):
        write_las(tmp_path / name, part, crs="EPSG:25832")
    code, err = floodmesh(["grid", tmp_path / "west.laz", tmp_path / "east.laz", "--crs",
                           "EPSG:25833", "--cell-size", 1, "--out", tmp_path / "dem.tif"], capsys)
    assert code == 0, err
    noted = [line for line in err if "but the CRS given is used" in line]
    assert len(noted) == 1 and "(and that of 1 more tile)" in noted[0], err


@pytest.mark.parametrize("kind, crs, words", [
    ("raster", "EPSG:2229", 'gdal_calc.py -A IN --calc "A*0.3048006" --outfile OUT'),  # US ft
    ("points", "EPSG:2994", 'filters.assign --filters.assign.value="Z = Z * 0.3048"'),  # ft
])
def test_feet_message_says_how_to_bring_z_to_metres(tmp_path, capsys, kind, crs, words):
    """Reprojecting x, y (gdalwarp, pdal's reprojection) leaves z in feet: the message also
    names the scaling of z, by the CRS's foot."""
    if kind == "points":
        path = tmp_path / "points.xyz"
        np.savetxt(path, plane_xyz(), fmt="%.3f")
        args = ["run", path, "--crs", crs]
    else:
        args = ["run", write_tif(tmp_path / "dem.tif", slope_dem(), crs=crs)]
    code, err = floodmesh([*args, "--out", tmp_path / "out"], capsys)
    assert code == 2 and len(err) == 1 and words in err[0], err


@pytest.mark.parametrize("crs, transform", [
    ("EPSG:3857", Affine(1.0, 0.0, 1_001_875.0, 0.0, -1.0, 6_446_475.0)),  # 50° N
    ("EPSG:25832", Affine(1.0, 0.0, -2_500_000.0, 0.0, -1.0, 5_600_060.0)),  # 3000 km off
])
def test_slope_step_refuses_a_raster_far_from_true_scale(tmp_path, capsys, crs, transform):
    """``floodmesh slope`` passes the CRS through without PROJ where it can: not for a
    projection whose metre is not a metre on the ground there."""
    dem = write_tif(tmp_path / "dem.tif", slope_dem(), crs=crs, transform=transform)
    code, err = floodmesh(["slope", dem, "--out", tmp_path / "s.tif"], capsys)
    assert code == 2 and "on the ground at the data" in err[-1], err
    assert not (tmp_path / "s.tif").exists()


def test_point_tiles_far_from_true_scale_are_refused_from_their_headers(tmp_path, capsys):
    """Two LAZ tiles in Web Mercator at 50° N: refused before any tile is read whole."""
    xyz = plane_xyz() - [412_000.0 - 1_001_875.0, 5_652_000.0 - 6_446_275.0, 0.0]
    west = xyz[:, 0] < xyz[:, 0].mean()
    write_las(tmp_path / "west.laz", xyz[west], crs="EPSG:3857")
    write_las(tmp_path / "east.laz", xyz[~west], crs="EPSG:3857")
    code, err = floodmesh(["grid", tmp_path / "west.laz", tmp_path / "east.laz",
                           "--cell-size", 1, "--out", tmp_path / "dem.tif"], capsys)
    assert code == 2 and "whose metre is 0.64 m on the ground at the data" in err[-1], err
    assert not (tmp_path / "dem.tif").exists()


def _zone_prefixed(tmp_path, kind):
    """Points or a DEM whose eastings carry the UTM zone number before them (32 412 000 m) in
    EPSG:25832, as LAS, XYZ text, a GeoTIFF, LAS tiles or XYZ tiles; the command's arguments."""
    xyz = plane_xyz() + [32_000_000.0, 0.0, 0.0]
    west = xyz[:, 0] < xyz[:, 0].mean()
    if kind == "las":
        return [write_las(tmp_path / "prefixed.laz", xyz)]
    if kind == "xyz":
        np.savetxt(tmp_path / "prefixed.xyz", xyz, fmt="%.3f")
        return [tmp_path / "prefixed.xyz", "--crs", "EPSG:25832"]
    if kind == "dem":
        return [write_tif(tmp_path / "prefixed.tif", slope_dem(), transform=Affine(
            1.0, 0.0, 32_412_000.0, 0.0, -1.0, 5_652_060.0))]
    if kind == "las-tiles":
        return [write_las(tmp_path / "west.laz", xyz[west]),
                write_las(tmp_path / "east.laz", xyz[~west])]
    if kind == "classified-xyz-tiles":  # text with a class column, as some exports write it
        for name, part in (("west", xyz[west]), ("east", xyz[~west])):
            np.savetxt(tmp_path / f"{name}.xyz", np.column_stack([part, np.full(len(part), 2)]),
                       fmt=["%.3f", "%.3f", "%.3f", "%d"], header="x y z classification",
                       comments="")
        return [tmp_path / "west.xyz", tmp_path / "east.xyz", "--crs", "EPSG:25832"]
    np.savetxt(tmp_path / "west.xyz", xyz[west], fmt="%.3f")
    np.savetxt(tmp_path / "east.xyz", xyz[~west], fmt="%.3f")
    return [tmp_path / "west.xyz", tmp_path / "east.xyz", "--crs", "EPSG:25832"]


@pytest.mark.parametrize("kind", ["las", "xyz", "dem", "las-tiles", "xyz-tiles",
                                  "classified-xyz-tiles"])
def test_zone_prefixed_eastings_are_refused_naming_the_zone_prefixed_crs(tmp_path, capsys,
                                                                        kind):
    """Eastings of 32,412,000 m in ETRS89 / UTM zone 32N (the zone number before them, a German
    habit) gave a mesh 32,000 km east of the survey; every reader refuses them, naming the
    zone-prefixed CRS, under which the same file is gridded where it lies."""
    args = _zone_prefixed(tmp_path, kind)
    step = ["slope"] if kind == "dem" else ["grid", "--cell-size", 1]
    code, err = floodmesh([*step, *args, "--out", tmp_path / "out.tif"], capsys)
    assert code == 2 and len(err) == 1, err
    assert ("far outside the area where ETRS89 / UTM zone 32N is used (Europe between 6°E and "
            "12°E" in err[0]), err
    assert ("its eastings look like they carry the UTM zone number before them (32 before "
            "412,0") in err[0] and "--crs EPSG:4647" in err[0], err
    assert not (tmp_path / "out.tif").exists()
    args = [a for a in args if a not in ("--crs", "EPSG:25832")]
    code, err = floodmesh([*step, *args, "--crs", "EPSG:4647", "--out", tmp_path / "out.tif"],
                          capsys)
    assert code == 0, err
    with rasterio.open(tmp_path / "out.tif") as src:
        assert src.bounds.left > 32_411_000 and CRS(src.crs.to_wkt()).to_epsg() == 4647


def test_data_far_outside_a_national_grid_are_refused_naming_its_area(tmp_path, capsys):
    """A survey in UTM coordinates declared as RD New (EPSG:28992) lies 5,000 km north of the
    Netherlands: refused, naming the CRS, its area and the data's extent."""
    path = tmp_path / "points.xyz"
    np.savetxt(path, plane_xyz(), fmt="%.3f")  # y 5,652,000 m
    code, err = floodmesh(["grid", path, "--crs", "EPSG:28992", "--cell-size", 1, "--out",
                           tmp_path / "dem.tif"], capsys)
    assert code == 2 and len(err) == 1, err
    assert ("point file points.xyz lies at x 412,0" in err[0] and "far outside the area "
            "where Amersfoort / RD New is used (Netherlands - onshore" in err[0]), err
    assert "check its CRS and give the one its x, y are in (--crs EPSG:XXXX" in err[0], err


# Web Mercator at 50° N: x, y of a line across a floodplain there, its metre 0.64 m on the ground
MERCATOR_50N = (1_001_875.0, 6_446_275.0)


def test_simplify_refuses_break_lines_far_from_true_scale(tmp_path, capsys):
    """``floodmesh simplify`` of break lines in Web Mercator at 50° N: its tolerance (m) would be
    1.56 m on the ground; refused in one line, as such a DEM is, naming how to reproject."""
    x, y = MERCATOR_50N
    lines = write_line(tmp_path / "lines.gpkg",
                       [(x + 10 * i, y + (i % 3), 30.0) for i in range(20)], "EPSG:3857")
    code, err = floodmesh(["simplify", lines, "--tolerance", 0.5, "--out",
                           tmp_path / "simple.gpkg"], capsys)
    assert code == 2 and len(err) == 1, err
    assert "whose metre is 0.64 m on the ground at the data" in err[0], err
    assert "ogr2ogr -t_srs EPSG:32632" in err[0], err
    assert not (tmp_path / "simple.gpkg").exists()


def test_export_refuses_a_mesh_far_from_true_scale(tmp_path, capsys):
    """``floodmesh export`` of a mesh in Web Mercator (its open boundaries snapped within metres
    that are not metres there) is refused in one line; nothing is written."""
    from floodmesh.core import io

    x, y = MERCATOR_50N
    nodes = np.array([[x, y, 1.0], [x + 100, y, 1.0], [x + 100, y + 100, 1.0], [x, y + 100, 1.0]])
    io.write_mesh_2dm(tmp_path / "mesh.2dm", nodes, np.array([[0, 1, 2], [0, 2, 3]]),
                      crs="EPSG:3857")
    sections = write_line(tmp_path / "open.gpkg", [(x, y), (x, y + 100)], "EPSG:3857")
    code, err = floodmesh(["export", tmp_path / "mesh.2dm", tmp_path / "out.2dm",
                           "--open-boundaries", sections], capsys)
    assert code == 2 and len(err) == 1, err
    assert "whose metre is 0.64 m on the ground at the data" in err[0], err
    assert not (tmp_path / "out.2dm").exists()


def test_an_xyz_tile_in_degrees_among_utm_tiles_is_refused_by_name(tmp_path, capsys):
    """A folder of XYZ tiles in UTM 32N with one in longitude and latitude (9.5° E, 51.4° N),
    all given --crs EPSG:25832: refused in one line naming that tile, its extent and the
    reprojection from degrees, not a point-spacing error about the whole set."""
    folder = tmp_path / "xt"
    folder.mkdir()
    xyz = plane_xyz()
    np.savetxt(folder / "a.xyz", xyz, fmt="%.3f")
    degrees = (xyz - [xyz[:, 0].min(), xyz[:, 1].min(), 0.0]) * [1e-5, 1e-5, 1.0] + [9.5, 51.4, 0]
    np.savetxt(folder / "b.xyz", degrees, fmt="%.7f")
    code, err = floodmesh(["grid", folder, "--crs", "EPSG:25832", "--cell-size", 1, "--out",
                           tmp_path / "dem.tif"], capsys)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("floodmesh: error: tile b.xyz lies at x 9.5 to 9.5005, y 51.4 "), err
    assert "in degrees" in err[0] and "in_srs=EPSG:4326" in err[0], err
    assert not (tmp_path / "dem.tif").exists()


def test_a_dem_tile_in_degrees_among_utm_tiles_is_named_as_in_degrees(tmp_path, capsys):
    """A folder of two GeoTIFF DEM tiles in UTM 32N and one in EPSG:4326 given to run, with and
    without --crs, or one without a CRS placed by --crs: refused in one line naming that tile as
    in degrees and the reprojection to the others' CRS, not as cells of 1e-05 m off the grid."""
    folder = tmp_path / "dem"
    folder.mkdir()
    dem = slope_dem(40, 40)
    write_tif(folder / "a.tif", dem)
    write_tif(folder / "b.tif", dem, transform=Affine(1.0, 0, ORIGIN[0] + 40, 0, -1.0,
                                                      ORIGIN[1] + 40))
    write_tif(folder / "c.tif", dem, transform=Affine(1e-5, 0, 9.5, 0, -1e-5, 51.4),
              crs="EPSG:4326")
    for given in ([], ["--crs", "EPSG:25832"]):
        code, err = floodmesh(["run", folder, "--out", tmp_path / "out", *given], capsys)
        assert code == 2 and len(err) == 1, err
        assert err[0].startswith("floodmesh: error: tile c.tif is in degrees"), err
        assert "gdalwarp -t_srs EPSG:25832 IN OUT" in err[0], err
        assert not (tmp_path / "out").exists()
    # without a CRS of its own, placed by --crs: named by where it lies, in degrees
    write_tif(folder / "c.tif", dem, transform=Affine(1e-5, 0, 9.5, 0, -1e-5, 51.4), crs=None)
    code, err = floodmesh(["run", folder, "--out", tmp_path / "out", "--crs", "EPSG:25832"],
                          capsys)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("floodmesh: error: tile c.tif lies at x 9.5 to 9.5004"), err
    assert "in degrees" in err[0] and "-s_srs EPSG:4326 -t_srs EPSG:25832" in err[0], err


def test_a_point_tile_in_degrees_among_utm_tiles_is_named_as_in_degrees(tmp_path, capsys):
    """Two LAZ tiles in UTM 32N and one in EPSG:4326 (longitude, latitude) given to grid, with
    and without --crs: refused in one line naming that tile as in degrees and the reprojection
    to the others' CRS (EPSG:25832), not a reprojection to EPSG:XXXX or cells of metres."""
    xyz = plane_xyz()
    write_las(tmp_path / "a.laz", xyz)
    write_las(tmp_path / "b.laz", xyz + [40.0, 0.0, 0.0])
    lonlat = (xyz - xyz.min(axis=0)) * [1e-5, 1e-5, 1.0] + [9.5, 51.4, 0.0]
    write_las(tmp_path / "c.laz", lonlat, crs="EPSG:4326")
    for given in ([], ["--crs", "EPSG:25832"]):
        code, err = floodmesh(["grid", *(tmp_path / f"{t}.laz" for t in "abc"), "--cell-size",
                               1, "--out", tmp_path / "dem.tif", *given], capsys)
        assert code == 2 and len(err) == 1, err
        assert err[0].startswith("floodmesh: error: tile c.laz is in degrees"), err
        assert "out_srs=EPSG:25832" in err[0], err
        assert not (tmp_path / "dem.tif").exists()


def test_a_point_tile_in_feet_among_tiles_in_metres_is_refused_for_its_feet(tmp_path, capsys):
    """A LAS tile whose GeoTIFF keys give NAVD88 heights in US feet, listed with a UTM tile:
    the one-line refusal of its feet, not a traceback from the check for tiles in degrees."""
    xyz = plane_xyz() - [ORIGIN[0] - 500_000.0, ORIGIN[1] - 4_000_000.0, 0.0]
    write_las(tmp_path / "a.laz", xyz + [40.0, 0.0, 0.0], crs="EPSG:26910")
    feet = las_vertical_feet_keys(tmp_path)
    code, err = floodmesh(["grid", tmp_path / "a.laz", feet, "--cell-size", 1, "--out",
                           tmp_path / "dem.tif"], capsys)
    assert code == 2 and len(err) == 1, err
    assert "zfeet_keys.las" in err[0] and "elevations in" in err[0], err
    assert not (tmp_path / "dem.tif").exists()


def test_a_tile_set_far_from_true_scale_names_the_tile_at_fault(tmp_path, capsys):
    """Two LAZ tiles 8 km apart far east of UTM 32N's meridian, where its scale passes 1.02
    between them: the message names the eastern tile, not the first of the set."""
    xyz = plane_xyz() - [ORIGIN[0], ORIGIN[1], 0.0] + [0.0, 5_700_000.0, 0.0]
    write_las(tmp_path / "a.laz", xyz + [1_782_000.0, 0.0, 0.0])
    write_las(tmp_path / "b.laz", xyz + [1_790_000.0, 0.0, 0.0])
    code, err = floodmesh(["grid", tmp_path / "a.laz", tmp_path / "b.laz", "--cell-size", 1,
                           "--out", tmp_path / "dem.tif"], capsys)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("floodmesh: error: tile b.laz is in ETRS89 / UTM zone 32N, whose "
                             "metre is 0.98 m"), err
