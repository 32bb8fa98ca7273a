"""Bad inputs of every kind FloodMesh checks, as real files written to a folder, each with the
command line that feeds it to ``floodmesh`` and, where a QGIS algorithm takes it, the algorithm
and parameters that feed it to QGIS. tests/core/test_bad_input.py runs them through the command
line, tests/qgis/test_bad_input.py through QGIS, and both compare the messages.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import laspy
import numpy as np
import rasterio
from affine import Affine
from pyproj import CRS

from floodmesh.core.chain.files import slope
from floodmesh.core.options import BREAKPOINT_METHODS

REAL_DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "real"
UTM = "EPSG:25832"
ORIGIN = (412_000.0, 5_652_000.0)


@dataclass
class BadInput:
    """``make(folder)`` writes the input and returns the arguments after ``floodmesh``;
    ``qgis(folder)`` returns (algorithm id, parameters) or None. ``words`` must be in the
    message: they name the problem. Memory messages end with the memory available, which
    changes from one call to the next; ``stable`` is the part to compare."""

    id: str
    words: str
    make: Callable[[Path], list]
    qgis: Callable[[Path], tuple] | None = None

    @staticmethod
    def stable(message: str) -> str:
        return message.split(" is available")[0].rsplit(" but ", 1)[0]


# ---------------------------------------------------------------------------------------------
# files
def plane_xyz(n=20_000, size=50.0, seed=0):
    """8 points/m² on a tilted plane: the default 0.1 % holdout gives exactly 20 check points."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, size, n), rng.uniform(0, size, n)
    return np.column_stack([x + ORIGIN[0], y + ORIGIN[1], 0.3 * x + 12.0])


def write_xyz(path, xyz):
    np.savetxt(path, xyz, fmt="%.3f")
    return path


def write_las(path, xyz, *, classes=2, crs: str | None = UTM):
    """A LAS/LAZ file written by laspy, with a WKT CRS (compound ones too) or none."""
    header = laspy.LasHeader(point_format=3, version="1.4")
    if len(xyz):
        header.offsets = np.floor(xyz.min(axis=0))
    header.scales = np.array([0.001, 0.001, 0.001])
    if crs is not None:
        header.add_crs(CRS.from_user_input(crs), keep_compatibility=False)
    las = laspy.LasData(header)
    if len(xyz):
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        las.classification = np.broadcast_to(np.asarray(classes, np.uint8), (len(xyz),)).copy()
    las.write(str(path))
    return path


def write_tif(path, values, *, transform=None, crs: str | None = UTM, nodata=-9999.0):
    """A GeoTIFF written with rasterio as given: any geotransform, CRS or none, NaN kept."""
    values = np.asarray(values, np.float32)
    if transform is None:
        transform = Affine(1.0, 0.0, ORIGIN[0], 0.0, -1.0, ORIGIN[1] + values.shape[0])
    with rasterio.open(path, "w", driver="GTiff", width=values.shape[1], height=values.shape[0],
                       count=1, dtype="float32", transform=transform, crs=crs,
                       nodata=nodata) as dst:
        dst.write(values, 1)
    return path


def slope_dem(rows=60, cols=60):
    """A tilted plane with a bank: z rises 0.3 m per m in x and steps 3 m across column 30."""
    yy, xx = np.mgrid[0:rows, 0:cols].astype(float)
    return 0.05 * xx + np.where(xx > 30, 3.0, 0.0) + 10.0


# ---------------------------------------------------------------------------------------------
# the cases
def _run(path, *extra, crs=None):
    return ["run", path, "--out", "{out}", *(["--crs", crs] if crs else []), *map(str, extra)]


def _lidar(path, crs=None, **params):
    def qgis(folder):
        p = {"INPUT": str(path(folder)), "OUTPUT_FOLDER": str(folder / "qgis-out")}
        if crs:
            p["CRS"] = crs
        p.update(params)
        return "floodmesh:lidartomesh", p
    return qgis


def _xyz(folder):
    return write_xyz(folder / "points.xyz", plane_xyz())


def _text_as(name):
    def make(folder):
        path = folder / name
        path.write_text("this is not what the extension says\n" * 40)
        return path
    return make


def _binary_xyz(folder):
    path = folder / "binary.xyz"
    path.write_bytes(bytes(range(256)) * 64)
    return path


def _empty_xyz(folder):
    path = folder / "empty.xyz"
    path.write_text("")
    return path


def _empty_las(folder):
    return write_las(folder / "empty.las", np.empty((0, 3)))


def _no_ground_las(folder):
    xyz = plane_xyz()
    return write_las(folder / "noground.laz", xyz, classes=np.where(np.arange(len(xyz)) % 2, 5, 6))


def _las_without_crs(folder):
    return write_las(folder / "nocrs.laz", plane_xyz(), crs=None)


def _las_vertical_feet(folder):
    xyz = plane_xyz() - [ORIGIN[0] - 500_000.0, ORIGIN[1] - 4_000_000.0, 0.0]
    return write_las(folder / "zfeet.laz", xyz, crs="EPSG:26910+6360")


def las_vertical_feet_keys(folder):
    """LAS 1.2 with GeoTIFF keys only, as US deliveries come: UTM 10N, NAVD88 height in US feet."""
    xyz = plane_xyz() - [ORIGIN[0] - 500_000.0, ORIGIN[1] - 4_000_000.0, 0.0]
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.offsets, header.scales = np.floor(xyz.min(axis=0)), np.full(3, 0.001)
    keys = laspy.vlrs.known.GeoKeyDirectoryVlr()
    keys.geo_keys_header.number_of_keys = 3
    keys.geo_keys = [laspy.vlrs.geotiff.GeoKeyEntryStruct(i, 0, 1, v)
                     for i, v in ((1024, 1), (3072, 26910), (4096, 6360))]
    header.vlrs.append(keys)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    las.classification = np.full(len(xyz), 2, np.uint8)
    path = folder / "zfeet_keys.las"
    las.write(str(path))
    return path


def _las_cut_short(folder):
    """A LAS whose copy stopped at a whole point: the header counts more points than it holds."""
    path = write_las(folder / "cut.las", plane_xyz())
    path.write_bytes(path.read_bytes()[:-34 * 5000])  # format 3: 34 bytes a point
    return path


def _text(name, text):
    def make(folder):
        path = folder / name
        path.write_text(text, encoding="utf-16" if name.startswith("utf16") else "utf-8")
        return path
    return make


_ROWS = "".join(f"{x:.3f};{y:.3f};{z:.3f}\n" for x, y, z in plane_xyz(200))


def _tif(name, values_fn=slope_dem, **kwargs):
    def make(folder):
        return write_tif(folder / name, values_fn(), **kwargs)
    return make


def _tif_in(unit):
    """slope_dem() as a GeoTIFF whose band says its values are in ``unit`` (GDAL's unit type,
    as a NetCDF's units attribute or a USGS DEM sets it)."""
    def make(folder):
        path = write_tif(folder / f"dem_{unit.replace(' ', '_')}.tif", slope_dem())
        with rasterio.open(path, "r+") as dst:
            dst.set_band_unit(1, unit)
        return path
    return make


def _tiles_one_in(unit):
    """slope_dem() as two DEM tiles, the east one's band saying its values are in ``unit``."""
    def make(folder):
        tiles = folder / "tiles"
        tiles.mkdir(exist_ok=True)
        values = slope_dem()
        write_tif(tiles / "west.tif", values[:, :30])
        east = write_tif(tiles / "east.tif", values[:, 30:], transform=Affine(
            1.0, 0.0, ORIGIN[0] + 30, 0.0, -1.0, ORIGIN[1] + values.shape[0]))
        with rasterio.open(east, "r+") as dst:
            dst.set_band_unit(1, unit)
        return tiles
    return make


# Web Mercator at 50° N, where its metre is 0.64 m on the ground
WEB_MERCATOR_50N = Affine(1.0, 0.0, 1_001_875.0, 0.0, -1.0, 6_446_475.0)


# eastings with the UTM zone number before them (32 and 412,000 m), a German habit, under the
# zone's CRS, EPSG:25832: 32,000 km east of the zone
ZONE_PREFIXED = Affine(1.0, 0.0, 32_000_000.0 + ORIGIN[0], 0.0, -1.0, ORIGIN[1] + 60)


def _zone_prefixed_las(folder):
    return write_las(folder / "prefixed.laz", plane_xyz() + [32_000_000.0, 0.0, 0.0])


def _autzen(folder):
    return REAL_DATA / "autzen_trim.laz"


def _rotated(folder):
    return write_tif(folder / "rotated.tif", slope_dem(),
                     transform=Affine.translation(*ORIGIN) * Affine.rotation(20.0)
                     * Affine.scale(1.0, -1.0))


def _maker(fn, *extra, crs=None):
    return lambda folder: _run(fn(folder), *extra, crs=crs)


def _qgis(algorithm, **parameters):
    """QGIS's ``floodmesh:algorithm`` with ``parameters``: a callable value is an input made in
    the folder, a text holding {out} an output in the folder's qgis-out."""
    def qgis(folder):
        out = str(folder / "qgis-out")
        return f"floodmesh:{algorithm}", {
            name: str(value(folder)) if callable(value)
            else value.replace("{out}", out) if isinstance(value, str) else value
            for name, value in parameters.items()}
    return qgis


# LiDAR to mesh's parameters and the command-line options that set the same RunOptions field
OPTION_FLAGS = {"CELL_SIZE": "--cell-size", "CRITICAL_SLOPE": "--s-crit",
                "MIN_ANGLE": "--min-angle", "MAX_AREA": "--max-area",
                "MAX_TRIANGLES": "--max-triangles", "HOLDOUT": "--holdout", "SEED": "--seed"}


def _options_case(id_, words, **parameters):
    """Good points (with a CRS given) and bad options: floodmesh run, and LiDAR to mesh."""
    flags = [str(x) for name, value in parameters.items() for x in (OPTION_FLAGS[name], value)]
    return BadInput(id_, words, _maker(_xyz, *flags, crs=UTM),
                    _lidar(_xyz, crs=UTM, **parameters))


def _mesh_step(cli_options, qgis_parameters, size_field=None):
    """``floodmesh mesh`` and QGIS's Build mesh on the bank DEM with the given options (and
    the size field ``size_field(folder)`` writes)."""
    dem = _tif("dem.tif")

    def cli(f):
        size = ["--size-field", size_field(f)] if size_field else []
        return ["mesh", dem(f), *cli_options, *size, "--out", "{out}/mesh.2dm"]

    def qgis(f):
        size = {"SIZE_FIELD": str(size_field(f))} if size_field else {}
        return "floodmesh:buildmesh", {"DEM": str(dem(f)), **qgis_parameters, **size,
                                       "OUTPUT": str(f / "qgis-out" / "mesh.2dm")}

    return cli, qgis


def _mesh_layer_case(id_, words, option, parameter, write):
    """``floodmesh mesh`` and Build mesh on the bank DEM given, as ``option`` and ``parameter``,
    the layer ``write(path)`` writes (once) into the case's folder."""
    dem = _tif("dem.tif")

    def layer(folder):
        path = folder / f"{id_}.gpkg"
        if not path.exists():
            write(path)
        return path

    return BadInput(id_, words,
                    lambda f: ["mesh", dem(f), option, layer(f), "--out", "{out}/mesh.2dm"],
                    lambda f: ("floodmesh:buildmesh", {
                        "DEM": str(dem(f)), parameter: str(layer(f)),
                        "OUTPUT": str(f / "qgis-out" / "mesh.2dm")}))


def _boundary_case(id_, words, polygon, crs=UTM):
    """``floodmesh mesh --boundary`` and Build mesh's BOUNDARY with a polygon layer holding
    ``polygon`` (local coordinates from ORIGIN) on the bank DEM."""
    import fiona
    import shapely
    import shapely.affinity

    def write(path):
        with fiona.open(path, "w", driver="GPKG", crs_wkt=CRS.from_user_input(crs).to_wkt(),
                        schema={"geometry": "Polygon", "properties": {}}) as dst:
            moved = shapely.affinity.translate(polygon, *ORIGIN)
            dst.write({"geometry": shapely.geometry.mapping(moved), "properties": {}})

    return _mesh_layer_case(id_, words, "--boundary", "BOUNDARY", write)


def _own_lines_case(id_, words, lines):
    """``floodmesh mesh --lines`` and Build mesh's USER_LINES with a layer of 3-D lines
    ``lines`` ((x, y, z) vertices, x and y local from ORIGIN) on the bank DEM."""
    import fiona

    def write(path):
        with fiona.open(path, "w", driver="GPKG", crs_wkt=CRS.from_user_input(UTM).to_wkt(),
                        schema={"geometry": "3D LineString", "properties": {}}) as dst:
            for line in lines:
                dst.write({"geometry": {"type": "LineString", "coordinates": [
                    (x + ORIGIN[0], y + ORIGIN[1], z) for x, y, z in line]}, "properties": {}})

    return _mesh_layer_case(id_, words, "--lines", "USER_LINES", write)


# a road's line on the bank DEM's ground (z = 10 + 0.05 x) and a bridge deck's 7 m above it
_ROAD = [(5, 30, 10.25), (25, 30, 11.25)]
_DECK = [(20, 10, 18.0), (20, 50, 18.0)]


def _bowtie():
    import shapely
    return shapely.Polygon([(5, 5), (50, 50), (50, 5), (5, 50)])


def _touching_holes(*holes):
    """A 45 m square holding ``holes`` (local coordinates): valid to GEOS."""
    import shapely
    return shapely.Polygon(shapely.box(5, 5, 50, 50).exterior.coords, holes)


def layered_boundary(folder):
    """A GeoPackage of two polygon layers: ``buildings`` (one 5 m house) first, ``domain``."""
    import fiona
    import shapely
    import shapely.affinity

    path = folder / "layers.gpkg"
    for layer, polygon in (("buildings", _box(20, 20, 25, 25)), ("domain", _box(5, 5, 50, 50))):
        with fiona.open(path, "w", driver="GPKG", layer=layer, crs_wkt=CRS(UTM).to_wkt(),
                        schema={"geometry": "Polygon", "properties": {}}) as dst:
            moved = shapely.affinity.translate(polygon, *ORIGIN)
            dst.write({"geometry": shapely.geometry.mapping(moved), "properties": {}})
    return path


def _box(x0, y0, x1, y1):
    import shapely
    return shapely.box(x0, y0, x1, y1)


def _collinear_xyz(folder):
    """Points along one tilted line (x and y both vary): no area to grid."""
    t = np.linspace(0, 100, 20_000)
    return write_xyz(folder / "line.xyz", np.column_stack([ORIGIN[0] + 0.8 * t,
                                                         ORIGIN[1] + 0.6 * t, 10 + 0.01 * t]))


def _one_place_xyz(folder):
    xyz = np.tile([ORIGIN[0], ORIGIN[1], 10.0], (50, 1))
    xyz[:, 2] += np.linspace(0, 1, 50)
    return write_xyz(folder / "oneplace.xyz", xyz)


def _degrees_xyz(folder):
    """A 200 x 200 m survey written as longitude and latitude (degrees): given a CRS in metres,
    a few millimetres, thinner than the line check's 5 mm."""
    rng = np.random.default_rng(0)
    lon, lat = 9.0 + rng.uniform(0, 0.0028, 5000), 50.0 + rng.uniform(0, 0.0018, 5000)
    return write_xyz(folder / "lonlat.xyz", np.column_stack([lon, lat, rng.uniform(10, 12,
                                                                                  5000)]))


def _one_place_degrees_xyz(folder):
    xyz = np.tile([9.0, 50.0, 10.0], (50, 1))
    xyz[:, 2] += np.linspace(0, 1, 50)
    return write_xyz(folder / "oneplace_lonlat.xyz", xyz)


def _line_layer(folder):
    """A line layer where a polygon layer belongs (a domain boundary)."""
    import fiona

    path = folder / "domain_line.gpkg"
    if not path.exists():
        with fiona.open(path, "w", driver="GPKG", crs_wkt=CRS.from_user_input(UTM).to_wkt(),
                        schema={"geometry": "LineString", "properties": {}}) as dst:
            dst.write({"geometry": {"type": "LineString", "coordinates": [
                (ORIGIN[0] + 5, ORIGIN[1] + 5), (ORIGIN[0] + 50, ORIGIN[1] + 50)]},
                "properties": {}})
    return path


def _vertices(kind, name):
    """A layer of 3-D ``kind`` (Point or LineString) at three places on _mesh_2dm's square,
    written as ``name``: lines where check points belong, points where break lines do."""
    def write(folder):
        import fiona

        path = folder / name
        corners = [(ORIGIN[0] + x, ORIGIN[1] + y, 1.0) for x, y in ((1, 1), (5, 6), (9, 2))]
        with fiona.open(path, "w", driver="GPKG", crs_wkt=CRS.from_user_input(UTM).to_wkt(),
                        schema={"geometry": f"3D {kind}", "properties": {}}) as dst:
            for geometry in ([{"type": "Point", "coordinates": c} for c in corners]
                             if kind == "Point" else [{"type": kind, "coordinates": corners}]):
                dst.write({"geometry": geometry, "properties": {}})
        return path
    return write


_check_lines = _vertices("LineString", "check_lines.gpkg")


def _mesh_2dm(folder):
    """A small valid mesh (two triangles of a 10 m square)."""
    path = folder / "mesh.2dm"
    x, y = ORIGIN
    path.write_text(f"MESH2D\nE3T 1 1 2 3 1\nE3T 2 1 3 4 1\nND 1 {x} {y} 1\n"
                    f"ND 2 {x + 10} {y} 1\nND 3 {x + 10} {y + 10} 1\nND 4 {x} {y + 10} 1\n")
    return path


def _export_case(id_, words, crs):
    return BadInput(id_, words,
                    lambda f: ["export", _mesh_2dm(f), "{out}/mesh.nc", "--crs", crs],
                    lambda f: ("floodmesh:exportmesh", {
                        "INPUT": str(_mesh_2dm(f)), "FORMAT": 4, "CRS": crs,
                        "OUTPUT": str(f / "qgis-out" / "mesh.nc")}))


def _refine(folder, *extra):
    """``floodmesh refine`` of the bank DEM with the plane's points and ``extra`` options."""
    return ["refine", _tif("dem.tif")(folder), "--points", _xyz(folder), "--crs", UTM,
            *extra, "--out", "{out}/refined.2dm"]


def _qgis_refine(**parameters):
    """QGIS's Refine mesh as ``_refine``."""
    return _qgis("refinemesh", DEM=_tif("dem.tif"), POINTS_FILE=_xyz, **parameters,
                 OUTPUT="{out}/refined.2dm")


# the bank DEM as breakpoints, slope and DEM: ``floodmesh breaklines`` and Trace break lines
_TRACED = {"BREAKPOINTS": _tif("bp.tif"), "SLOPE": _tif("slope.tif"), "DEM": _tif("dem.tif")}


def _slope_step(name, **options):
    """The bank DEM through FloodMesh's own slope step: a slope (degrees) or, with
    ``method="log"``, a LoG response (m), each tagged with what it holds."""
    def make(folder):
        slope(_tif("dem.tif")(folder), folder / name, **options)
        return folder / name
    return make


_SLOPE, _LOG = _slope_step("slope-step.tif"), _slope_step("log-step.tif", method="log")


def _trace(folder, *extra):
    return ["breaklines", _TRACED["BREAKPOINTS"](folder), "--slope", _TRACED["SLOPE"](folder),
            "--dem", _TRACED["DEM"](folder), *extra]


def _existing_file(folder):
    path = folder / "results"
    path.write_text("a file where the output folder should be\n")
    return path


def _check_points_xyz(folder):
    """30 check points on _mesh_2dm's square."""
    xyz = plane_xyz(n=30, size=10.0)
    xyz[:, 2] = 1.0
    return write_xyz(folder / "check.xyz", xyz)


def _assess_pictures_into(png):
    """``floodmesh assess`` with residuals and statistics into {out} and the pictures into
    ``png(folder)``."""
    return lambda f: ["assess", _mesh_2dm(f), "--points", _check_points_xyz(f), "--crs", UTM,
                      "--out", "{out}/res.gpkg", "--report", "{out}/stats.json", "--png", png(f)]


def _flood_case(id_, words, scenario: dict, files: dict | None = None):
    """``floodmesh flood`` and Flood on mesh with ``_mesh_2dm`` and the scenario (its ``files``,
    name: text, beside it); the scenario is refused before ANUGA is looked for."""
    def scenario_file(folder):
        for name, text in (files or {}).items():
            (folder / name).write_text(text)
        path = folder / "scenario.json"
        path.write_text(json.dumps(scenario))
        return path
    return BadInput(id_, words,
                    lambda f: ["flood", _mesh_2dm(f), "--scenario", scenario_file(f), "--out",
                               "{out}", "--crs", UTM],
                    _qgis("floodonmesh", MESH=_mesh_2dm, SCENARIO=scenario_file, CRS=UTM,
                          OUTPUT_FOLDER="{out}"))


_CIRCLE = {"circle": {"centre": [ORIGIN[0] + 5, ORIGIN[1] + 5], "radius": 3}}
_FLOOD = {"duration_s": 20, "output_interval_s": 10}
_SQUARE = [[ORIGIN[0], ORIGIN[1]], [ORIGIN[0] + 5, ORIGIN[1]], [ORIGIN[0] + 5, ORIGIN[1] + 5]]

CASES = [
    _flood_case("flood-scenario-misspelt-keys",
                "'initial_stage' at its top level (did you mean 'initial_stage_m'? it takes "
                "duration_s, output_interval_s",
                {**_FLOOD, "initial_stage": 30.0, "inflows": [{**_CIRCLE, "discharge_m3s": 1}],
                 "boundaries": [{"kind": "outflow", "sides": ["east"], "snap": 50}]}),
    _flood_case("flood-scenario-rain", "'rain_mm_h' at its top level: rain is not supported: "
                "give it as an inflow", {**_FLOOD, "rain_mm_h": 50}),
    _flood_case("flood-inflow-discharge-misspelt",
                "'discharge' in inflow 1 (did you mean 'discharge_m3s'?",
                {**_FLOOD, "inflows": [{**_CIRCLE, "discharge": 5}]}),
    _flood_case("flood-inflow-without-discharge",
                "inflow 1 has no discharge: give it a discharge_m3s (m³/s) or a hydrograph",
                {**_FLOOD, "inflows": [_CIRCLE]}),
    _flood_case("flood-roughness-n-for-manning",
                "'n' in roughness zone 1 (did you mean 'manning'? it takes polygons, file, "
                "manning)", {**_FLOOD, "roughness": [{"polygons": [_SQUARE], "n": 0.02}]}),
    _flood_case("flood-hydrograph-missing", "inflow 1's hydrograph names nope.csv, which does "
                "not exist in", {**_FLOOD, "inflows": [{**_CIRCLE, "hydrograph": "nope.csv"}]}),
    _flood_case("flood-hydrograph-not-numbers", "inflow 1's hydrograph, q.csv, has 'ten,2' on "
                "line 3", {**_FLOOD, "inflows": [{**_CIRCLE, "hydrograph": "q.csv"}]},
                {"q.csv": "t,q\n0,1\nten,2\n"}),
    _flood_case("flood-hydrograph-semicolons", "inflow 1's hydrograph, q.csv, has '10;2' on "
                "line 2: each line must be time s, m³/s, 2 comma-separated numbers",
                {**_FLOOD, "inflows": [{**_CIRCLE, "hydrograph": "q.csv"}]},
                {"q.csv": "0;1\n10;2\n"}),
    _flood_case("flood-levels-times-not-increasing", "the times in boundary 1's levels, h.csv, "
                "must increase from row to row: row 3 (5 s) follows row 2 (10 s)",
                {**_FLOOD, "boundaries": [{"kind": "level", "sides": ["east"],
                                           "levels": "h.csv"}]}, {"h.csv": "0,1\n10,2\n5,3\n"}),
    _boundary_case("boundary-self-intersecting", "is not a valid polygon (Self-intersection",
                   _bowtie()),
    _boundary_case("boundary-off-the-data", "does not overlap the DEM's data",
                   _box(5000, 5000, 5100, 5100)),
    _boundary_case("boundary-hole-at-the-outer-ring", "the domain touches itself at one point",
                   _touching_holes([(5, 20), (20, 15), (20, 25)])),
    _boundary_case("boundary-holes-meeting-at-a-corner", "the domain touches itself at one point",
                   _touching_holes([(10, 10), (20, 10), (20, 20), (10, 20)],
                                   [(20, 20), (30, 20), (30, 30), (20, 30)])),
    _boundary_case("boundary-in-another-crs", "reproject it to the DEM's CRS",
                   _box(5, 5, 50, 50), crs="EPSG:32633"),
    _boundary_case("boundary-smaller-than-four-cells",
                   "is too small to mesh: it covers 2.25 m² of the DEM's data (2.25 m² in all), "
                   "and a part needs more than 4 cells, 4 m² at the cell size of 1 m",
                   _box(20, 20, 21.5, 21.5)),
    _own_lines_case("own-lines-crossing-at-two-heights",
                    "features 1 and 2 cross at (412020.00, 5652030.00) at heights 11.00 and "
                    "18.00 m, 7.00 m apart", [_ROAD, _DECK]),
    _own_lines_case("own-line-z-not-a-number",
                    "feature 2, vertex 2 of 3 at (412020.00, 5652030.00), has a z of nan, not a "
                    "number", [_DECK, [(5, 30, 10.25), (20, 30, np.nan), (25, 30, 11.25)]]),
    _own_lines_case("own-line-x-not-a-number",
                    "feature 1, vertex 2 of 3, has an x of nan, not a number",
                    [[(5, 30, 10.25), (np.nan, 30, 11.0), (25, 30, 11.25)]]),
    BadInput("missing-file", "does not exist",
             lambda f: _run(f / "missing.laz"), _lidar(lambda f: f / "missing.laz")),
    BadInput("laz-holding-text", "not a readable LAS/LAZ",
             _maker(_text_as("text.laz")), _lidar(_text_as("text.laz"))),
    BadInput("tif-holding-text", "not a readable raster",
             _maker(_text_as("text.tif")), _lidar(_text_as("text.tif"))),
    BadInput("xyz-holding-binary", "not an XYZ text file",
             _maker(_binary_xyz, crs=UTM), _lidar(_binary_xyz, crs=UTM)),
    BadInput("xyz-header-without-x-y-z", "its header line names the columns Elev, Punkt",
             _maker(_text("named.csv", "Elev;Punkt;Wert\n" + _ROWS), crs=UTM),
             _lidar(_text("named.csv", "Elev;Punkt;Wert\n" + _ROWS), crs=UTM)),
    BadInput("xyz-header-elevation-in-feet", "named.csv has elevations in 'ft NAVD88' (its "
             "header's Elevation (ft NAVD88)); FloodMesh works in metres: convert them first, "
             'e.g. `pdal translate IN OUT -f filters.assign --filters.assign.value="Z = Z * '
             '0.3048"`',
             _maker(_text("named.csv", "Easting (m),Northing (m),Elevation (ft NAVD88)\n"
                          + _ROWS.replace(";", ",")), crs=UTM),
             _lidar(_text("named.csv", "Easting (m),Northing (m),Elevation (ft NAVD88)\n"
                          + _ROWS.replace(";", ",")), crs=UTM)),
    BadInput("xyz-header-x-y-in-us-feet", "has x, y in 'US-FT' (its header's X [US-FT])",
             _maker(_text("named.csv", "X [US-FT];Y [US-FT];Z [m]\n"
                          + _ROWS), crs=UTM),
             _lidar(_text("named.csv", "X [US-FT];Y [US-FT];Z [m]\n"
                          + _ROWS), crs=UTM)),
    BadInput("xyz-decimal-comma", "decimal comma",
             _maker(_text("comma.csv", _ROWS.replace(".", ",")), crs=UTM),
             _lidar(_text("comma.csv", _ROWS.replace(".", ",")), crs=UTM)),
    BadInput("xyz-utf16", "is UTF-16 text", _maker(_text("utf16.xyz", _ROWS), crs=UTM),
             _lidar(_text("utf16.xyz", _ROWS), crs=UTM)),
    BadInput("las-cut-short", "its header counts 20,000 points, the file holds 15,000",
             _maker(_las_cut_short), _lidar(_las_cut_short)),
    BadInput("vertical-feet-geotiff-keys", "has elevations in US survey foot",
             _maker(las_vertical_feet_keys), _lidar(las_vertical_feet_keys)),
    BadInput("empty-xyz", "is empty", _maker(_empty_xyz, crs=UTM), _lidar(_empty_xyz, crs=UTM)),
    BadInput("empty-las", "holds no points", _maker(_empty_las), _lidar(_empty_las)),
    BadInput("no-ground-points", "no ground points", _maker(_no_ground_las),
             _lidar(_no_ground_las)),
    BadInput("all-nodata-raster", "no valid cells",
             _maker(_tif("nodata.tif", lambda: np.full((40, 40), -9999.0))),
             _lidar(_tif("nodata.tif", lambda: np.full((40, 40), -9999.0)))),
    BadInput("all-nan-raster", "no valid cells",
             _maker(_tif("nan.tif", lambda: np.full((40, 40), np.nan), nodata=None)),
             _lidar(_tif("nan.tif", lambda: np.full((40, 40), np.nan), nodata=None))),
    BadInput("geographic-points", "geographic", _maker(_xyz, crs="EPSG:4326"),
             _lidar(_xyz, crs="EPSG:4326")),
    BadInput("geographic-raster", "geographic",
             _maker(_tif("degrees.tif", transform=Affine(1e-5, 0, 7.0, 0, -1e-5, 51.0),
                         crs="EPSG:4326")),
             _lidar(_tif("degrees.tif", transform=Affine(1e-5, 0, 7.0, 0, -1e-5, 51.0),
                         crs="EPSG:4326"))),
    # a DEM in degrees given a CRS in metres: a few millimetres of data; then one of 3 x 3 cells
    BadInput("raster-cells-in-degrees-under-metres", "cells of 1e-05 m, far smaller than a LiDAR",
             _maker(_tif("degrees.tif", transform=Affine(1e-5, 0, 7.0, 0, -1e-5, 51.0),
                         crs="EPSG:4326"), crs=UTM),
             _lidar(_tif("degrees.tif", transform=Affine(1e-5, 0, 7.0, 0, -1e-5, 51.0),
                         crs="EPSG:4326"), crs=UTM)),
    BadInput("raster-of-3-by-3-cells", "covers only 3 x 3 m, fewer than 4 cells of 1 m",
             _maker(_tif("tiny.tif", lambda: slope_dem(3, 3))),
             _lidar(_tif("tiny.tif", lambda: slope_dem(3, 3)))),
    BadInput("mesh-of-3-by-3-cells", "covers only 3 x 3 m, fewer than 4 cells of 1 m",
             lambda f: ["mesh", _tif("tiny.tif", lambda: slope_dem(3, 3))(f),
                        "--out", "{out}/mesh.2dm"],
             lambda f: ("floodmesh:buildmesh", {
                 "DEM": str(_tif("tiny.tif", lambda: slope_dem(3, 3))(f)),
                 "OUTPUT": str(f / "qgis-out" / "mesh.2dm")})),
    BadInput("feet-points", "horizontal units of 'foot'", _maker(_xyz, crs="EPSG:2994"),
             _lidar(_xyz, crs="EPSG:2994")),
    BadInput("feet-raster", "horizontal units of 'US survey foot'",
             _maker(_tif("feet.tif", crs="EPSG:2229")),
             _lidar(_tif("feet.tif", crs="EPSG:2229"))),
    BadInput("feet-real-autzen", "horizontal units of 'foot'", _maker(_autzen), _lidar(_autzen)),
    BadInput("dem-band-in-feet", "has elevations in 'ft' (its band's unit); FloodMesh works in "
             'metres: convert them first, e.g. `gdal_calc.py -A IN --calc "A*0.3048" --outfile '
             'OUT`', _maker(_tif_in("ft")), _lidar(_tif_in("ft"))),
    BadInput("dem-tile-band-in-feet", "tile east.tif has elevations in 'US survey foot'",
             _maker(_tiles_one_in("US survey foot")),
             _qgis("lidartomesh", TILE_FOLDER=_tiles_one_in("US survey foot"),
                   OUTPUT_FOLDER="{out}")),
    BadInput("dem-band-in-centimetres", "has elevations in 'cm' (its band's unit)",
             lambda f: ["slope", _tif_in("cm")(f), "--out", "{out}/slope.tif"],
             _qgis("slope", INPUT=_tif_in("cm"), OUTPUT="{out}/slope.tif")),
    BadInput("vertical-feet", "elevations in 'US survey foot'", _maker(_las_vertical_feet),
             _lidar(_las_vertical_feet)),
    BadInput("geocentric-crs", "a geocentric CRS, not a projected one",
             _maker(_xyz, crs="EPSG:4978"), _lidar(_xyz, crs="EPSG:4978")),
    BadInput("vertical-only-crs", "a vertical CRS, not a projected one",
             _maker(_xyz, crs="EPSG:5783")),
    BadInput("crs-given-as-a-name", "give it as EPSG:XXXX", _maker(_xyz, crs="foo")),
    BadInput("web-mercator-raster", "whose metre is 0.64 m on the ground at the data",
             _maker(_tif("webmerc.tif", transform=WEB_MERCATOR_50N, crs="EPSG:3857")),
             _lidar(_tif("webmerc.tif", transform=WEB_MERCATOR_50N, crs="EPSG:3857"))),
    BadInput("web-mercator-points", "Reproject it to the UTM zone first",
             _maker(_xyz, crs="EPSG:3857"), _lidar(_xyz, crs="EPSG:3857")),
    BadInput("zone-prefixed-las", "carry the UTM zone number before them (32 before 412,025 m)"
             ": give the zone-prefixed CRS, --crs EPSG:4647",
             _maker(_zone_prefixed_las), _lidar(_zone_prefixed_las)),
    BadInput("zone-prefixed-raster", "far outside the area where ETRS89 / UTM zone 32N is "
             "used", _maker(_tif("prefixed.tif", transform=ZONE_PREFIXED)),
             _lidar(_tif("prefixed.tif", transform=ZONE_PREFIXED))),
    BadInput("no-crs-text", "no coordinate reference system", _maker(_xyz), _lidar(_xyz)),
    BadInput("no-crs-las", "no coordinate reference system", _maker(_las_without_crs),
             _lidar(_las_without_crs)),
    BadInput("no-crs-raster", "no coordinate reference system",
             _maker(_tif("nocrs.tif", crs=None)), _lidar(_tif("nocrs.tif", crs=None))),
    BadInput("rotated-raster", "is rotated", _maker(_rotated), _lidar(_rotated)),
    BadInput("non-square-cells", "not square",
             _maker(_tif("rect.tif", transform=Affine(1.0, 0, ORIGIN[0], 0, -2.0, ORIGIN[1]))),
             _lidar(_tif("rect.tif", transform=Affine(1.0, 0, ORIGIN[0], 0, -2.0, ORIGIN[1])))),
    BadInput("south-up-raster", "not north-up",
             _maker(_tif("southup.tif", transform=Affine(1.0, 0, ORIGIN[0], 0, 1.0, ORIGIN[1]))),
             _lidar(_tif("southup.tif", transform=Affine(1.0, 0, ORIGIN[0], 0, 1.0, ORIGIN[1])))),
    _options_case("cell-size-larger-than-data", "fewer than 4 cells", CELL_SIZE=30.0),
    # 50 m of points at 20 m cells: a grid of 3 x 3 cells, which a DEM of its own would not mesh
    _options_case("cell-size-of-3-cells-across", "the data covers only 50 x 50 m, fewer "
                  "than 4 cells of 20 m each way (3 x 3): too little to mesh; choose a smaller "
                  "cell size", CELL_SIZE=20.0),
    _options_case("cell-size-below-point-spacing", "would leave most grid cells empty",
                  CELL_SIZE=0.02),
    _options_case("cell-size-zero", "cell size must be a positive", CELL_SIZE=0.0),
    _options_case("s-crit-zero", "S_crit must be above 0 and below 90", CRITICAL_SLOPE=0.0),
    _options_case("s-crit-90", "S_crit must be above 0 and below 90", CRITICAL_SLOPE=90.0),
    _options_case("min-angle-above-34", "at most 34 degrees", MIN_ANGLE=34.5),
    _options_case("min-angle-zero", "minimum angle must be above 0", MIN_ANGLE=0.0),
    _options_case("max-area-zero", "maximum triangle area must be a positive", MAX_AREA=0.0),
    _options_case("max-area-negative", "maximum triangle area must be a positive",
                  MAX_AREA=-5.0),
    _options_case("too-many-triangles", "more than the limit of 10,000", MAX_AREA=0.1,
                  MAX_TRIANGLES=10_000),
    BadInput("mesh-step-too-many-triangles", "more than the limit of 1,000",
             *_mesh_step(["--max-area", 0.5, "--max-triangles", 1000],
                         {"MAX_AREA": 0.5, "MAX_TRIANGLES": 1000})),
    BadInput("size-field-in-another-crs", "reproject it to the DEM's CRS",
             *_mesh_step([], {}, size_field=_tif("size.tif", lambda: np.full((60, 60), 20.0),
                                                 crs="EPSG:25833"))),
    BadInput("mesh-step-min-angle", "at most 34 degrees",
             *_mesh_step(["--min-angle", 35], {"MIN_ANGLE": 35.0})),
    BadInput("mesh-step-flow-area-negative", "the flow area must be 0 (off) or more",
             *_mesh_step(["--flow-area", -5], {"FLOW_AREA": -5.0})),
    _options_case("max-triangles-zero", "maximum number of triangles must be a whole number",
                  MAX_TRIANGLES=0),
    _options_case("holdout-one", "holdout fraction must be at least 0 and below 1",
                  HOLDOUT=1.0),
    BadInput("output-is-the-input", "FloodMesh never overwrites an input",
             lambda f: ["slope", _tif("dem.tif")(f), "--out", f / "dem.tif"],
             lambda f: ("floodmesh:slope", {"INPUT": str(_tif("dem.tif")(f)),
                                            "OUTPUT": str(f / "dem.tif")})),
    BadInput("grid-output-named-laz", "this writes a GeoTIFF",
             lambda f: ["grid", _xyz(f), "--crs", UTM, "--cell-size", 1, "--out",
                        "{out}/dem.laz"]),
    BadInput("mesh-output-named-slf", "this writes an SMS 2DM mesh",
             lambda f: ["mesh", _tif("dem.tif")(f), "--out", "{out}/mesh.slf"],
             _qgis("buildmesh", DEM=_tif("dem.tif"), OUTPUT="{out}/mesh.slf")),
    BadInput("mesh-triangles-named-shp", "this writes a GeoPackage",
             lambda f: ["mesh", _tif("dem.tif")(f), "--out", "{out}/mesh.2dm", "--gpkg",
                        "{out}/triangles.shp"],
             _qgis("buildmesh", DEM=_tif("dem.tif"), OUTPUT="{out}/mesh.2dm",
                   TRIANGLES="{out}/triangles.shp")),
    BadInput("simplify-output-named-tif", "this writes a GeoPackage",
             lambda f: ["simplify", _line_layer(f), "--out", "{out}/simple.tif"],
             _qgis("simplifybreaklines", INPUT=_line_layer, OUTPUT="{out}/simple.tif")),
    BadInput("breaklines-output-named-shp", "this writes a GeoPackage",
             lambda f: _trace(f, "--out", "{out}/lines.shp"),
             _qgis("tracebreaklines", **_TRACED, OUTPUT="{out}/lines.shp")),
    BadInput("run-output-folder-holds-the-input", "FloodMesh never overwrites an input",
             lambda f: ["run", _tif("dem.tif")(f), "--out", f],
             lambda f: ("floodmesh:lidartomesh", {"INPUT": str(_tif("dem.tif")(f)),
                                                  "OUTPUT_FOLDER": str(f)})),
    BadInput("run-output-folder-is-a-file", "is a file, not a folder",
             lambda f: ["run", _xyz(f), "--crs", UTM, "--out", _existing_file(f)],
             lambda f: ("floodmesh:lidartomesh", {"INPUT": str(_xyz(f)), "CRS": UTM,
                                                  "OUTPUT_FOLDER": str(_existing_file(f))})),
    BadInput("assess-pictures-folder-is-a-file", "is a file, not a folder",
             _assess_pictures_into(_existing_file)),
    BadInput("assess-pictures-folder-not-writable", "cannot write to the output folder",
             _assess_pictures_into(lambda f: "/proc/floodmesh-pictures")),
    BadInput("output-folder-not-writable", "cannot write to the output folder",
             lambda f: ["run", _xyz(f), "--crs", UTM, "--out", "/proc/floodmesh-out"],
             _lidar(_xyz, crs=UTM, OUTPUT_FOLDER="/proc/floodmesh-out")),
    _options_case("seed-negative", "random seed must be a whole number of at least 0",
                  SEED=-1),
    BadInput("log-sigma-beyond-the-data", "no cell would get a response",
             _maker(_xyz, "--slope-method", "log", "--sigma", 1000, crs=UTM)),
    BadInput("log-sensitivity-zero", "LoG sensitivity must be a positive number",
             _maker(_xyz, "--slope-method", "log", "--sensitivity", 0, crs=UTM),
             _lidar(_xyz, crs=UTM, SLOPE_METHOD=BREAKPOINT_METHODS.index("log"),
                    SENSITIVITY=0.0)),
    BadInput("breakpoints-sensitivity-zero", "LoG sensitivity must be a positive number",
             lambda f: ["breakpoints", _tif("log.tif")(f), "--sensitivity", 0, "--out",
                        "{out}/bp.tif"],
             _qgis("classifybreakpoints", INPUT=_tif("log.tif"), LOG_SENSITIVITY=0.0,
                   OUTPUT="{out}/bp.tif")),
    BadInput("breakpoints-of-a-log-response-without-sensitivity",
             "holds a Laplacian-of-Gaussian response in metres, as FloodMesh's slope step wrote "
             "it, not a slope in degrees: give its LoG sensitivity",
             lambda f: ["breakpoints", _LOG(f), "--out", "{out}/bp.tif"],
             _qgis("classifybreakpoints", INPUT=_LOG, OUTPUT="{out}/bp.tif")),
    BadInput("breakpoints-of-a-slope-with-sensitivity",
             "holds a slope in degrees, as FloodMesh's slope step wrote it, not a "
             "Laplacian-of-Gaussian response in metres: leave out the LoG sensitivity",
             lambda f: ["breakpoints", _SLOPE(f), "--sensitivity", 0.02, "--out", "{out}/bp.tif"],
             _qgis("classifybreakpoints", INPUT=_SLOPE, LOG_SENSITIVITY=0.02,
                   OUTPUT="{out}/bp.tif")),
    BadInput("breaklines-following-a-log-response", "the tracer follows the slope",
             lambda f: ["breaklines", _TRACED["BREAKPOINTS"](f), "--slope", _LOG(f), "--dem",
                        _TRACED["DEM"](f), "--out", "{out}/lines.gpkg"],
             _qgis("tracebreaklines", **{**_TRACED, "SLOPE": _LOG}, OUTPUT="{out}/lines.gpkg")),
    BadInput("refine-negative-noise", "noise of the points must be zero or a positive number",
             lambda f: _refine(f, "--noise", -1), _qgis_refine(NOISE=-1.0)),
    BadInput("refine-negative-target", "target RMSE must be a positive number",
             lambda f: _refine(f, "--target-rmse", -1), _qgis_refine(TARGET_RMSE=-1.0)),
    BadInput("refine-no-rounds", "number of refinement rounds must be a whole number of at "
             "least 1", lambda f: _refine(f, "--max-rounds", 0), _qgis_refine(MAX_ROUNDS=0)),
    BadInput("breaklines-negative-seed", "random seed must be a whole number of at least 0",
             lambda f: _trace(f, "--seed", -1, "--out", "{out}/lines.gpkg"),
             _qgis("tracebreaklines", **_TRACED, SEED=-1, OUTPUT="{out}/lines.gpkg")),
    BadInput("series-area-twice", "maximum area 100 is given more than once",
             lambda f: ["series", _xyz(f), "--crs", UTM, "--max-areas", "100,100", "--out",
                        "{out}"]),
    BadInput("points-on-one-tilted-line", "all points lie on one straight line",
             _maker(_collinear_xyz, crs=UTM), _lidar(_collinear_xyz, crs=UTM)),
    BadInput("points-at-one-place", "all points lie at one place",
             _maker(_one_place_xyz, crs=UTM), _lidar(_one_place_xyz, crs=UTM)),
    BadInput("points-in-degrees-with-a-crs-in-metres",
             "m across); a terrain model needs points spread over an area; the coordinates "
             "look like degrees (longitude/latitude): reproject the points to a projected CRS "
             "in metres",
             _maker(_degrees_xyz, crs=UTM), _lidar(_degrees_xyz, crs=UTM)),
    BadInput("points-at-one-place-in-degrees",
             "all points lie at one place (9.000, 50.000); a terrain model needs points spread "
             "over an area; the coordinates look like degrees (longitude/latitude)",
             _maker(_one_place_degrees_xyz, crs=UTM), _lidar(_one_place_degrees_xyz, crs=UTM)),
    BadInput("boundary-of-several-layers", "holds the layers buildings, domain; choose one",
             lambda f: ["mesh", _tif("dem.tif")(f), "--boundary", layered_boundary(f), "--out",
                        "{out}/mesh.2dm"]),
    BadInput("boundary-layer-not-there", "but none named 'roads'",
             lambda f: ["mesh", _tif("dem.tif")(f), "--boundary",
                        f"{layered_boundary(f)}|layername=roads", "--out", "{out}/mesh.2dm"]),
    BadInput("boundary-given-lines", "domain_line.gpkg has lines; polygons are needed",
             lambda f: ["mesh", _tif("dem.tif")(f), "--boundary", _line_layer(f), "--out",
                        "{out}/mesh.2dm"],
             _qgis("buildmesh", DEM=_tif("dem.tif"), BOUNDARY=_line_layer,
                   OUTPUT="{out}/mesh.2dm")),
    BadInput("simplify-given-points", "points.gpkg has points; lines are needed here: give a "
             "layer of lines (QGIS: Points to path makes one of points)",
             lambda f: ["simplify", _vertices("Point", "points.gpkg")(f), "--out",
                        "{out}/simple.gpkg"],
             _qgis("simplifybreaklines", INPUT=_vertices("Point", "points.gpkg"),
                   OUTPUT="{out}/simple.gpkg")),
    BadInput("assess-given-lines", "check_lines.gpkg has lines; points are needed",
             lambda f: ["assess", _mesh_2dm(f), "--points", _check_lines(f), "--crs", UTM,
                        "--out", "{out}/res.gpkg"],
             _qgis("assessaccuracy", MESH=_mesh_2dm, POINTS=_check_lines,
                   OUTPUT="{out}/res.gpkg")),
    _export_case("export-geographic-crs", "is not a projected CRS in metres", "EPSG:4326"),
    _export_case("export-feet-crs", "is not a projected CRS in metres", "EPSG:2229"),
    BadInput("grid-too-large-for-memory", "of memory",
             lambda f: ["grid", _xyz(f), "--crs", UTM, "--cell-size", 0.001, "--max-gap", 5,
                        "--out", "{out}/dem.tif"],
             lambda f: ("floodmesh:gridpoints", {
                 "INPUT": str(_xyz(f)), "CRS": UTM, "CELL_SIZE": 0.001, "MAX_GAP": 5.0,
                 "OUTPUT": str(f / "qgis-out" / "dem.tif")})),
]
