"""Each pipeline step as its own Processing algorithm, chained through processing.run the way the
Graphical Modeler chains them; outputs open as QGIS layers with the expected sizes."""
import json
import subprocess

import numpy as np
import pytest
from numpy.testing import assert_allclose
from qgis.core import QgsMeshLayer, QgsRasterLayer, QgsVectorLayer

from floodmesh.core import io
from floodmesh.core.steps.slope import slope



def test_provider_lists_every_step(processing):
    from qgis.core import QgsApplication

    ids = {a.id() for a in QgsApplication.processingRegistry().providerById("floodmesh")
           .algorithms()}
    assert ids == {f"floodmesh:{n}" for n in (
        "gridpoints", "slope", "classifybreakpoints", "tracebreaklines", "simplifybreaklines",
        "buildmesh", "refinemesh", "assessaccuracy", "exportmesh", "lidartomesh", "floodonmesh",
        "LiDAR to mesh step by step")}


def test_steps_chain_through_processing_run(processing, demo_points_file, tmp_path):
    t = tmp_path
    grid = processing.run("floodmesh:gridpoints", {
        "INPUT": str(demo_points_file), "CELL_SIZE": 1.0, "HOLDOUT": 0.01, "SEED": 2,
        "OUTPUT": str(t / "dem.tif"), "HOLDOUT_OUTPUT": str(t / "holdout.gpkg")})
    dem_layer = QgsRasterLayer(grid["OUTPUT"], "dem")
    assert dem_layer.isValid() and (dem_layer.width(), dem_layer.height()) == (300, 240)
    assert dem_layer.crs().authid() == "EPSG:25832"

    slope_out = processing.run("floodmesh:slope", {"INPUT": grid["OUTPUT"], "METHOD": 2,
                                                   "OUTPUT": str(t / "slope.tif")})["OUTPUT"]
    # the algorithm writes exactly what the core computes (float32 on disk)
    expected = slope(io.read_raster(grid["OUTPUT"]), "sharpnack-akin").values
    assert_allclose(io.read_raster(slope_out).values, expected, rtol=1e-6, equal_nan=True)

    bp = processing.run("floodmesh:classifybreakpoints", {
        "INPUT": slope_out, "CRITICAL_SLOPE": 10.0, "OUTPUT": str(t / "bp.tif")})["OUTPUT"]
    bp_layer = QgsRasterLayer(bp, "bp")
    assert bp_layer.isValid() and bp_layer.width() == 300
    n_bp = int(np.nansum(io.read_raster(bp).values))
    assert n_bp > 1000

    lines = processing.run("floodmesh:tracebreaklines", {
        "BREAKPOINTS": bp, "SLOPE": slope_out, "DEM": grid["OUTPUT"], "CRITICAL_SLOPE": 10.0,
        "OUTPUT": str(t / "lines.gpkg")})["OUTPUT"]
    traced = QgsVectorLayer(lines, "lines", "ogr")
    assert traced.isValid() and traced.featureCount() >= 10

    simple = processing.run("floodmesh:simplifybreaklines", {
        "INPUT": lines, "METHOD": 1, "TOLERANCE": 0.9, "MIN_DISTANCE": 0.0,
        "OUTPUT": str(t / "simple.gpkg")})["OUTPUT"]
    assert QgsVectorLayer(simple, "simple", "ogr").featureCount() == traced.featureCount()

    mesh = processing.run("floodmesh:buildmesh", {
        "DEM": grid["OUTPUT"], "BREAKLINES": simple, "MIN_ANGLE": 25.0, "MAX_AREA": 100.0,
        "OUTPUT": str(t / "mesh.2dm"), "TRIANGLES": str(t / "triangles.gpkg")})
    mesh_layer = QgsMeshLayer(mesh["OUTPUT"], "mesh", "mdal")
    assert mesh_layer.isValid()
    assert mesh_layer.dataProvider().vertexCount() == mesh["NODES"]
    assert mesh_layer.dataProvider().faceCount() == mesh["TRIANGLE_COUNT"]
    assert QgsVectorLayer(mesh["TRIANGLES"], "tri", "ogr").featureCount() == mesh["TRIANGLE_COUNT"]

    assessed = processing.run("floodmesh:assessaccuracy", {
        "MESH": mesh["OUTPUT"], "POINTS": grid["HOLDOUT_OUTPUT"],
        "OUTPUT": str(t / "residuals.gpkg"), "REPORT": str(t / "stats.json")})
    stats = json.loads((t / "stats.json").read_text())
    assert stats["n_holdout"] == round(0.01 * 2 * 300 * 240)
    assert assessed["RMSE"] == pytest.approx(stats["rmse_m"]) and 0 < stats["rmse_m"] < 0.15
    assert QgsVectorLayer(assessed["OUTPUT"], "r", "ogr").featureCount() == stats["n_holdout"]


def test_log_through_the_slope_and_breakpoint_algorithms(processing, tmp_path, real_data):
    dem = str(real_data / "merewether_topography1.asc")
    response = processing.run("floodmesh:slope", {
        "INPUT": dem, "METHOD": 6, "SIGMA": 1.0, "OUTPUT": str(tmp_path / "log.tif")})["OUTPUT"]
    bp = processing.run("floodmesh:classifybreakpoints", {
        "INPUT": response, "LOG_SENSITIVITY": 0.05, "OUTPUT": str(tmp_path / "bp.tif")})["OUTPUT"]
    layer = QgsRasterLayer(bp, "bp")
    assert layer.isValid() and (layer.width(), layer.height()) == (321, 416)
    assert np.nansum(io.read_raster(bp).values) > 1000


def test_slope_headless_through_qgis_process(qgis_process, real_data, tmp_path):
    exe, env = qgis_process
    out = tmp_path / "slope.tif"
    run = subprocess.run(
        [exe, "run", "floodmesh:slope", "--json", "--",
         f"INPUT={real_data / 'merewether_topography1.asc'}", "METHOD=4", f"OUTPUT={out}"],
        env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert json.loads(run.stdout[run.stdout.index("{"):])["results"]["OUTPUT"] == str(out)
    layer = QgsRasterLayer(str(out), "slope")
    assert layer.isValid() and (layer.width(), layer.height()) == (321, 416)
    values = io.read_raster(out).values
    assert 0 <= np.nanmin(values) and np.nanmax(values) < 90


def test_grid_and_breakpoints_headless_with_las_classes(qgis_process, demo_points_file,
                                                        tmp_path):
    """Grid only the vegetation class (1) headless, then its slope and breakpoints headless."""
    exe, env = qgis_process

    def run(algorithm, *args):
        result = subprocess.run([exe, "run", algorithm, "--json", "--", *args], env=env,
                                capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
        return json.loads(result.stdout[result.stdout.index("{"):])["results"]

    dem = run("floodmesh:gridpoints", f"INPUT={demo_points_file}", "CLASSES=1", "CELL_SIZE=2",
              f"OUTPUT={tmp_path / 'veg.tif'}")["OUTPUT"]
    layer = QgsRasterLayer(dem, "veg")
    assert layer.isValid() and (layer.width(), layer.height()) == (150, 120)
    # vegetation sits 0.5-12 m above the ground: its surface is far above the ground DEM's
    ground = mean_ground_z(demo_points_file)
    assert np.nanmean(io.read_raster(dem).values) > ground + 2
    slope = run("floodmesh:slope", f"INPUT={dem}", f"OUTPUT={tmp_path / 'slope.tif'}")["OUTPUT"]
    bp = run("floodmesh:classifybreakpoints", f"INPUT={slope}", "CRITICAL_SLOPE=30",
             f"OUTPUT={tmp_path / 'bp.tif'}")["OUTPUT"]
    assert QgsRasterLayer(bp, "bp").isValid() and np.nansum(io.read_raster(bp).values) > 100


def mean_ground_z(path):
    return float(io.read_points(path).xyz[:, 2].mean())


@pytest.fixture(scope="module")
def demo_rasters(tmp_path_factory):
    """DEM, slope and breakpoints of the noise-free demo terrain (1 m), written by the core."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.frontends import demo
    from floodmesh.core.steps.breakpoints import classify_breakpoints
    from floodmesh.core.raster import Grid

    t = tmp_path_factory.mktemp("demo_rasters")
    x, y = np.meshgrid(np.arange(300) + 0.5, 240 - (np.arange(240) + 0.5))
    origin = demo.DEMO_ORIGIN
    dem = Grid(demo.ground_elevation(x, y), Affine(1, 0, origin[0], 0, -1, origin[1] + 240),
               CRS.from_epsg(25832))
    s = slope(dem, "one-over-distance")
    paths = {name: str(t / f"{name}.tif") for name in ("dem", "slope", "bp")}
    io.write_raster(paths["dem"], dem)
    io.write_raster(paths["slope"], s)
    io.write_raster(paths["bp"], classify_breakpoints(s, 10.0))
    return paths


def _loaded(name):
    from qgis.core import QgsProject

    layers = QgsProject.instance().mapLayersByName(name)
    assert len(layers) == 1, f"{name} was not loaded"
    return layers[0]


def test_trace_and_simplify_load_in_one_readable_style(processing, demo_rasters, tmp_path):
    """Run as from the toolbox (results loaded into the project): the break lines come in with
    one legend entry (a line on a halo), not one per connected system; spline simplification
    with a minimum length and a minimum distance keeps that style and the component ids."""
    from qgis.core import QgsProject, QgsSingleSymbolRenderer

    QgsProject.instance().clear()
    traced = processing.runAndLoadResults("floodmesh:tracebreaklines", {
        "BREAKPOINTS": demo_rasters["bp"], "SLOPE": demo_rasters["slope"],
        "DEM": demo_rasters["dem"], "CRITICAL_SLOPE": 10.0, "MIN_LENGTH": 5.0,
        "OUTPUT": str(tmp_path / "lines.gpkg")})
    layer = _loaded("Break lines")
    assert isinstance(layer.renderer(), QgsSingleSymbolRenderer)
    assert layer.renderer().symbol().symbolLayerCount() == 2
    components = {f["component_id"] for f in layer.getFeatures()}
    assert len(components) >= 3
    assert min(f["length_m"] for f in layer.getFeatures()) >= 5.0

    processing.runAndLoadResults("floodmesh:simplifybreaklines", {
        "INPUT": traced["OUTPUT"], "METHOD": 2, "TOLERANCE": 0.9, "MIN_DISTANCE": 0.5,
        "OUTPUT": str(tmp_path / "simple.gpkg")})
    simple = _loaded("Simplified break lines")
    assert isinstance(simple.renderer(), QgsSingleSymbolRenderer)
    assert {f["component_id"] for f in simple.getFeatures()} <= components
    assert sum(f["n_points"] for f in simple.getFeatures()) < \
        0.5 * sum(f["n_points"] for f in layer.getFeatures())
    QgsProject.instance().clear()


def test_simplify_by_default_gives_the_command_line_s_lines(processing, demo_rasters,
                                                            tmp_path):
    """Simplify break lines and floodmesh simplify take one default (minimum distance 0: off),
    so the documented step chain gives the same lines in QGIS and on the command line; here a
    minimum distance changes the lines (merges parts beside longer lines, whose segments get
    back the vertices they skipped: not always fewer vertices), so a default of 0.5 m would
    show."""
    import sys
    from pathlib import Path

    lines = processing.run("floodmesh:tracebreaklines", {
        "BREAKPOINTS": demo_rasters["bp"], "SLOPE": demo_rasters["slope"],
        "DEM": demo_rasters["dem"], "OUTPUT": str(tmp_path / "lines.gpkg")})["OUTPUT"]
    qgis = processing.run("floodmesh:simplifybreaklines", {
        "INPUT": lines, "OUTPUT": str(tmp_path / "qgis.gpkg")})["OUTPUT"]
    cli = subprocess.run([str(Path(sys.executable).parent / "floodmesh"), "simplify", lines,
                          "--out", str(tmp_path / "cli.gpkg")], capture_output=True, text=True,
                         timeout=300)
    assert cli.returncode == 0, cli.stderr
    by_qgis, by_cli = io.read_lines_gpkg(qgis), io.read_lines_gpkg(tmp_path / "cli.gpkg")
    assert len(by_qgis) == len(by_cli) > 10
    for a, b in zip(by_qgis, by_cli):
        np.testing.assert_array_equal(a, b)
    merged = processing.run("floodmesh:simplifybreaklines", {
        "INPUT": lines, "MIN_DISTANCE": 0.5, "OUTPUT": str(tmp_path / "merged.gpkg")})["OUTPUT"]
    by_merging = io.read_lines_gpkg(merged)
    assert len(by_merging) != len(by_cli) or any(
        not np.array_equal(a, b) for a, b in zip(by_merging, by_cli))


def test_refine_mesh_algorithm(processing, demo_rasters, tmp_path):
    """Refine mesh from the toolbox: measured points and check points as layers; the refined
    mesh has more nodes than the unrefined one, meets the RMSE target on its points, loads as a
    mesh layer shaded by elevation, and the rounds are written as JSON."""
    from qgis.core import QgsProject

    from floodmesh.core.frontends import demo

    rng = np.random.default_rng(0)
    xy = rng.uniform([1, 1], [299, 239], (6000, 2))
    z = demo.ground_elevation(xy[:, 0], xy[:, 1])
    origin = np.array(demo.DEMO_ORIGIN)
    dem = io.read_raster(demo_rasters["dem"])
    io.write_points_gpkg(tmp_path / "points.gpkg", np.column_stack([xy + origin, z])[:5000],
                         dem.crs)
    io.write_points_gpkg(tmp_path / "check.gpkg", np.column_stack([xy + origin, z])[5000:],
                         dem.crs)
    QgsProject.instance().clear()
    result = processing.runAndLoadResults("floodmesh:refinemesh", {
        "DEM": demo_rasters["dem"], "POINTS": str(tmp_path / "points.gpkg"),
        "CHECK": str(tmp_path / "check.gpkg"), "MAX_AREA": 100.0, "LOWER": 0.05, "UPPER": 0.15,
        "TARGET_RMSE": 0.05, "OUTPUT": str(tmp_path / "refined.2dm"),
        "REPORT": str(tmp_path / "rounds.json")})
    rounds = json.loads((tmp_path / "rounds.json").read_text())["rounds"]
    assert len(rounds) >= 2 and rounds[-1]["nodes"] > rounds[0]["nodes"]
    assert rounds[-1]["rmse_m"] <= 0.05 < rounds[0]["rmse_m"]
    assert result["NODES"] == rounds[-1]["nodes"]
    layer = _loaded("Refined mesh")
    assert isinstance(layer, QgsMeshLayer) and layer.dataProvider().vertexCount() == result["NODES"]
    assert layer.rendererSettings().activeScalarDatasetGroup() == 0
    QgsProject.instance().clear()


def test_build_mesh_with_a_domain_polygon_and_own_lines(processing, demo_rasters, tmp_path):
    """Build mesh with a model domain polygon holding a hole (a building) and a 2-D line of
    one's own: the mesh covers the polygon minus the hole, and a bow-tie polygon is refused
    with a message naming the problem and the fix."""
    import fiona
    import shapely
    from qgis.core import QgsProcessingException

    from floodmesh.core.frontends import demo
    from floodmesh.core.steps.mesh import triangle_areas

    x0, y0 = demo.DEMO_ORIGIN
    hole = shapely.box(x0 + 100, y0 + 60, x0 + 112, y0 + 72)
    domain = shapely.Polygon(shapely.box(x0 + 20, y0 + 20, x0 + 200, y0 + 100).exterior.coords,
                             [hole.exterior.coords])
    bowtie = shapely.Polygon([(x0, y0), (x0 + 50, y0 + 50), (x0 + 50, y0), (x0, y0 + 50)])
    for name, polygon in (("domain", domain), ("bowtie", bowtie)):
        with fiona.open(tmp_path / f"{name}.gpkg", "w", driver="GPKG", crs="EPSG:25832",
                        schema={"geometry": "Polygon", "properties": {}}) as dst:
            dst.write({"geometry": shapely.geometry.mapping(polygon), "properties": {}})
    io.write_lines_gpkg(tmp_path / "own.gpkg", [np.array([[x0 + 30, y0 + 30],
                                                         [x0 + 190, y0 + 90]])],
                        io.read_raster(demo_rasters["dem"]).crs, layer="own")
    dem = io.read_raster(demo_rasters["dem"])
    io.write_raster(tmp_path / "size.tif", dem.with_values(np.full(dem.shape, 12.0)))
    result = processing.run("floodmesh:buildmesh", {
        "DEM": demo_rasters["dem"], "BOUNDARY": str(tmp_path / "domain.gpkg"),
        "USER_LINES": str(tmp_path / "own.gpkg"), "MAX_AREA": 50.0,
        "SIZE_FIELD": str(tmp_path / "size.tif"), "OUTPUT": str(tmp_path / "mesh.2dm")})
    nodes, triangles = io.read_mesh_2dm(result["OUTPUT"])
    assert triangle_areas(nodes, triangles).sum() == pytest.approx(domain.area, rel=1e-6)
    assert triangle_areas(nodes, triangles).max() <= 12 * (1 + 1e-9)
    assert QgsMeshLayer(result["OUTPUT"], "m", "mdal").dataProvider().faceCount() == \
        len(triangles)
    with pytest.raises(QgsProcessingException, match="not a valid polygon.*Fix geometries"):
        processing.run("floodmesh:buildmesh", {
            "DEM": demo_rasters["dem"], "BOUNDARY": str(tmp_path / "bowtie.gpkg"),
            "OUTPUT": str(tmp_path / "bad.2dm")})
    assert not (tmp_path / "bad.2dm").exists()


def test_build_mesh_and_assess_accuracy_load_styled(processing, demo_rasters, tmp_path):
    """From the toolbox, Build mesh loads its mesh as a mesh layer shaded by elevation, and
    Assess accuracy loads the residual points with the three classes (and outside-the-mesh) as
    categories of the class field."""
    from qgis.core import QgsCategorizedSymbolRenderer, QgsProject

    from floodmesh.core.frontends import demo

    QgsProject.instance().clear()
    mesh = processing.runAndLoadResults("floodmesh:buildmesh", {
        "DEM": demo_rasters["dem"], "MAX_AREA": 400.0, "OUTPUT": str(tmp_path / "coarse.2dm")})
    loaded = _loaded("Mesh")  # Build mesh loads its mesh, shaded by elevation
    assert isinstance(loaded, QgsMeshLayer) and loaded.dataProvider().vertexCount() == \
        mesh["NODES"]
    assert loaded.rendererSettings().activeScalarDatasetGroup() == 0
    rng = np.random.default_rng(1)
    xy = rng.uniform([1, 1], [299, 239], (500, 2))
    xyz = np.column_stack([xy + np.array(demo.DEMO_ORIGIN), demo.ground_elevation(*xy.T)])
    io.write_points_gpkg(tmp_path / "check.gpkg", xyz, io.read_raster(demo_rasters["dem"]).crs)
    QgsProject.instance().clear()
    processing.runAndLoadResults("floodmesh:assessaccuracy", {
        "MESH": mesh["OUTPUT"], "POINTS": str(tmp_path / "check.gpkg"),
        "OUTPUT": str(tmp_path / "residuals.gpkg")})
    layer = _loaded("Residuals")
    renderer = layer.renderer()
    assert isinstance(renderer, QgsCategorizedSymbolRenderer) and renderer.classAttribute() == "class"
    assert {c.value() for c in renderer.categories()} == {0, 1, 2, -1}
    classes = {f["class"] for f in layer.getFeatures()}
    assert {0, 2} <= classes  # a 400 m² mesh misses the banks: some residuals over 25 cm
    QgsProject.instance().clear()


def test_long_steps_move_the_progress_bar_before_they_end(processing, demo_rasters, tmp_path):
    """Trace, Simplify, Build mesh, Assess accuracy and Export mesh move the dialog's bar while
    they work, not only to 100 % when done (the worker passes a step's first report at once,
    later ones at most every 0.1 s: at least one lies between)."""
    from qgis.core import QgsProcessingContext, QgsProcessingFeedback

    from floodmesh.core.frontends import demo

    rng = np.random.default_rng(3)
    xy = rng.uniform([1, 1], [299, 239], (500, 2))
    xyz = np.column_stack([xy + np.array(demo.DEMO_ORIGIN), demo.ground_elevation(*xy.T)])
    io.write_points_gpkg(tmp_path / "check.gpkg", xyz, io.read_raster(demo_rasters["dem"]).crs)
    t, d = tmp_path, demo_rasters
    steps = [
        ("tracebreaklines", {"BREAKPOINTS": d["bp"], "SLOPE": d["slope"], "DEM": d["dem"],
                             "OUTPUT": str(t / "lines.gpkg")}),
        ("simplifybreaklines", {"INPUT": str(t / "lines.gpkg"), "OUTPUT": str(t / "s.gpkg")}),
        ("buildmesh", {"DEM": d["dem"], "BREAKLINES": str(t / "s.gpkg"), "MAX_AREA": 100.0,
                       "OUTPUT": str(t / "mesh.2dm")}),
        ("assessaccuracy", {"MESH": str(t / "mesh.2dm"), "POINTS": str(t / "check.gpkg"),
                            "OUTPUT": str(t / "residuals.gpkg")}),
        ("exportmesh", {"INPUT": str(t / "mesh.2dm"), "FORMAT": 1, "CRS": "EPSG:25832",
                        "OUTPUT": str(t / "geo.slf")}),
    ]
    seen = {}
    for name, params in steps:
        feedback = QgsProcessingFeedback()
        feedback.progressChanged.connect(seen.setdefault(name, []).append)
        processing.run(f"floodmesh:{name}", params, context=QgsProcessingContext(),
                       feedback=feedback)
    moved = {name: any(0 < p < 100 for p in values) and values == sorted(values)
             and values[-1] == pytest.approx(100) for name, values in seen.items()}
    assert moved == dict.fromkeys(seen, True), seen
