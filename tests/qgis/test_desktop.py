"""The desktop QGIS itself (``qgis.bin`` under a virtual display), as a modeller uses it: LiDAR to
mesh on Topography.laz with only the input and the output folder set, and what the user then
sees once Qt's events have run (queued layer removals happen there, so a tree read straight
after the run can show layers that are already on their way out): one group named after the
run, break lines above residuals above the mesh, all in the data's CRS, the map on them; the
mesh opened by hand in its CRS; the dialog's distances in metres and its help; the shipped model
valid as opened; none of FloodMesh's numerical packages in the QGIS process."""
import json
import os
import re
import shutil
import subprocess

import pytest

from .conftest import REPO, write_ept

SEARCHES = {  # what a modeller types into the toolbox's search, and what it should find
    "point cloud": ["assessaccuracy", "gridpoints", "lidartomesh", "refinemesh"],
    "levee": ["classifybreakpoints", "lidartomesh", "simplifybreaklines", "tracebreaklines"],
    "2dm": ["buildmesh", "exportmesh", "floodonmesh", "lidartomesh", "refinemesh"],
    "telemac": ["exportmesh", "lidartomesh"],
    "hec-ras": ["exportmesh", "lidartomesh"],
}
HELPERS = r"""
import json, os, sys, traceback
from qgis.utils import iface
from qgis.core import QgsApplication, QgsLayerTreeGroup, QgsProject
from qgis.PyQt.QtCore import QCoreApplication
from qgis.PyQt.QtTest import QTest
out = {}


def settle():
    # let Qt run what QGIS queued (the layer tree bridge removes layers in a queued call)
    for _ in range(5):
        QCoreApplication.processEvents()
        QTest.qWait(200)


def run_dialog(dialog):
    # the algorithm's dialog shown, Run pressed, waited for (it runs as a background task)
    dialog.show()
    settle()
    dialog.runAlgorithm()
    for _ in range(900):
        if dialog.results():
            break
        QTest.qWait(200)
    settle()


def kind(layer):
    from qgis.core import QgsMapLayerType, QgsWkbTypes
    if layer.type() == QgsMapLayerType.MeshLayer:
        return "mesh"
    return QgsWkbTypes.geometryDisplayString(layer.geometryType()).lower()


def tree(node):
    rows = []
    for child in node.children():
        if isinstance(child, QgsLayerTreeGroup):
            rows.append({"group": child.name(), "children": tree(child)})
        else:
            layer = child.layer()
            rows.append({"layer": child.name(), "valid": bool(layer and layer.isValid()),
                         "crs": layer.crs().authid() if layer else None})
    return rows
"""
def desktop_script(body: str) -> str:
    """A script for ``run_desktop``: ``body`` (indented one level) run after HELPERS, what it
    puts in ``out`` written to FM_RESULT as JSON, or the traceback of what it raised."""
    return HELPERS + "\ntry:\n" + body + """except Exception:
    out["error"] = traceback.format_exc()
open(os.environ["FM_RESULT"], "w").write(json.dumps(out))
os._exit(0)
"""


SCRIPT = f"SEARCHES = {SEARCHES!r}\n" + HELPERS + r"""

try:
    import processing
    project = QgsProject.instance()
    processing.runAndLoadResults("floodmesh:lidartomesh", {
        "INPUT": os.environ["FM_INPUT"], "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]})
    settle()
    out["tree"] = tree(project.layerTreeRoot())
    out["project_layers"] = sorted(l.name() for l in project.mapLayers().values())
    mesh = project.mapLayersByName("Mesh")
    out["edges"] = bool(mesh) and mesh[0].rendererSettings().nativeMeshSettings().isEnabled()
    canvas = iface.mapCanvas()
    out["scale"] = canvas.scale()
    out["canvas_crs"] = canvas.mapSettings().destinationCrs().authid()
    # the same from the algorithm's dialog, Run pressed: the layers, and the report in the
    # Results Viewer
    from processing.core.ProcessingResults import resultsList
    dialog = processing.createAlgorithmDialog("floodmesh:lidartomesh", {
        "INPUT": os.environ["FM_INPUT"], "OUTPUT_FOLDER": os.environ["FM_OUTPUT"] + " dialog"})
    run_dialog(dialog)
    out["dialog_results"] = sorted(dialog.results() or {})
    out["results_viewer"] = [r.filename for r in resultsList.getResults()]
    out["tree_after_dialog"] = tree(project.layerTreeRoot())
    # the shipped model, run with only its input as its dialog does: every output left at its
    # default, a temporary file
    before = set(project.mapLayers())
    model = QgsApplication.processingRegistry().algorithmById(
        "floodmesh:LiDAR to mesh step by step")
    processing.runAndLoadResults(model, {"points": os.environ["FM_INPUT"], **{
        d.name(): d.defaultValue() for d in model.destinationParameterDefinitions()}})
    settle()
    added = [n for n in project.layerTreeRoot().findLayers() if n.layerId() not in before]
    out["model_layers"] = [[kind(n.layer()), n.layer().isValid(), n.layer().crs().authid()]
                           for n in added]
    # the mesh opened by hand (Add Mesh Layer; the browser does the same)
    by_hand = iface.addMeshLayer(os.path.join(os.environ["FM_OUTPUT"], "mesh.2dm"), "by hand",
                                 "mdal")
    settle()
    out["by_hand_crs"] = by_hand.crs().authid() if by_hand else None
    # what the dialog shows: the distances' units (no CRS chosen) and its Help button
    from qgis.PyQt.QtWidgets import QComboBox, QDialogButtonBox, QLabel
    dialog = processing.createAlgorithmDialog("floodmesh:lidartomesh", {})
    dialog.show()
    settle()
    units = {}
    for name in ("CELL_SIZE", "MAX_GAP", "TOLERANCE"):
        widget = dialog.mainWidget().wrappers[name].wrappedWidget()
        units[name] = ([l.text() for l in widget.findChildren(QLabel) if l.isVisible()]
                       + [c.currentText() for c in widget.findChildren(QComboBox)
                          if c.isVisible()])
    out["units"] = units
    help_button = dialog.findChild(QDialogButtonBox).button(QDialogButtonBox.Help)
    out["help_button"] = help_button is not None and help_button.isVisible()
    dialog.close()
    registry = QgsApplication.processingRegistry()
    algorithms = [a for a in registry.algorithms() if a.provider().id() == "floodmesh"]
    out["help_urls"] = {a.id(): a.helpUrl() for a in algorithms}
    out["help_texts"] = {a.id(): len(a.shortHelpString() or "") for a in algorithms}
    # the toolbox's own search (QGIS's proxy model): what each word finds
    from qgis.gui import QgsProcessingToolboxProxyModel
    from qgis.PyQt.QtCore import QModelIndex
    proxy = QgsProcessingToolboxProxyModel(None, registry)

    def found(text):
        proxy.setFilterString(text)
        names = []

        def walk(parent):
            for row in range(proxy.rowCount(parent)):
                index = proxy.index(row, 0, parent)
                algorithm = proxy.toolboxModel().algorithmForIndex(proxy.mapToSource(index))
                if algorithm is not None and algorithm.provider().id() == "floodmesh":
                    names.append(algorithm.name())
                walk(index)
        walk(QModelIndex())
        return sorted(set(names))
    out["search"] = {text: found(text) for text in SEARCHES}
    out["all"] = sorted(a.name() for a in algorithms)
    # the shipped model as the Modeler opens it
    model = registry.algorithmById("floodmesh:LiDAR to mesh step by step")
    ok, issues = model.validate()
    out["model_valid"], out["model_issues"] = ok, list(issues)
    # a point-cloud layer of the project as the LiDAR input
    from qgis.core import QgsPointCloudLayer
    cloud = QgsPointCloudLayer(os.environ["FM_EPT"], "Topography", "ept")
    project.addMapLayer(cloud)
    grid = processing.run("floodmesh:gridpoints", {"POINT_CLOUD": cloud.id(), "CELL_SIZE": 2.0,
                                                   "OUTPUT": os.environ["FM_OUTPUT"] + ".tif"})
    out["grid"] = grid["OUTPUT"]
    out["imported"] = {m: getattr(sys.modules[m], "__file__", "")
                       for m in ("shapely", "triangle", "numba", "laspy") if m in sys.modules}
except Exception:
    out["error"] = traceback.format_exc()
open(os.environ["FM_RESULT"], "w").write(json.dumps(out))
os._exit(0)
"""


def run_desktop(script: str, tmp_path, **variables) -> dict:
    """Run ``script`` in the desktop QGIS (qgis.bin, a fresh profile with the plugin enabled)
    under a virtual display; returns what it wrote to ``FM_RESULT`` as JSON."""
    profile = tmp_path / "data" / "QGIS" / "QGIS3" / "profiles" / "default" / "QGIS"
    profile.mkdir(parents=True)
    (profile / "QGIS3.ini").write_text("[PythonPlugins]\nfloodmesh=true\nprocessing=true\n")
    (tmp_path / "run.py").write_text(script)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "QT_QPA_PLATFORM")}
    result = tmp_path / "result.json"
    env.update(HOME=str(tmp_path), XDG_DATA_HOME=str(tmp_path / "data"),
               QGIS_PLUGINPATH=str(REPO / "build" / "plugins"), FM_RESULT=str(result),
               **{k: str(v) for k, v in variables.items()})
    run = subprocess.run(["xvfb-run", "-a", "qgis.bin", "--noversioncheck", "--nologo",
                          "--code", str(tmp_path / "run.py")],
                         env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and result.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    seen = json.loads(result.read_text())
    assert "error" not in seen, seen.get("error")
    return seen


def run_on_real_data(script: str, tmp_path) -> dict:
    """``run_desktop`` with FM_INPUT Topography.laz, FM_DEM Merewether's DEM and FM_OUTPUT a
    path in ``tmp_path``; skipped where xvfb-run or ../shared/data/real is missing."""
    real = REPO.parent / "shared" / "data" / "real"
    if not shutil.which("xvfb-run") or not (real / "Topography.laz").exists():
        pytest.skip("xvfb-run or ../shared/data/real is missing")
    return run_desktop(script, tmp_path, FM_INPUT=real / "Topography.laz",
                       FM_DEM=real / "merewether_topography1.asc", FM_OUTPUT=tmp_path / "run")


@pytest.fixture(scope="module")
def desktop(tmp_path_factory):
    if not shutil.which("xvfb-run"):
        pytest.skip("xvfb-run (package xvfb) is missing")
    real = REPO.parent / "shared" / "data" / "real"
    if not (real / "Topography.laz").exists():
        pytest.skip("../shared/data/real is not beside the checkout")
    tmp_path = tmp_path_factory.mktemp("desktop")
    return run_desktop(SCRIPT, tmp_path, FM_INPUT=real / "Topography.laz",
                       FM_OUTPUT=tmp_path / "Topography run",
                       FM_EPT=write_ept(real / "Topography.laz", tmp_path / "ept"))


def test_lidar_to_mesh_results_stay_in_one_group_in_order(desktop):
    """Defaults only (the holdout sized from the data): the run's layers are in the project
    after Qt's events, in one group named after the run, lines above residuals above mesh."""
    groups = [row for row in desktop["tree"] if "group" in row]
    assert len(groups) == 1, desktop["tree"]
    group = groups[0]
    assert "Topography run" in group["group"]
    assert [row["layer"] for row in group["children"]] == ["Break lines", "Residuals", "Mesh"]
    assert all(row["valid"] and row["crs"] == "EPSG:2949" for row in group["children"]), group
    assert {"Break lines", "Residuals", "Mesh"} <= set(desktop["project_layers"])
    assert desktop["edges"]


def test_the_dialog_loads_its_run_and_shows_the_report_in_the_results_viewer(desktop):
    groups = {row["group"]: row["children"] for row in desktop["tree_after_dialog"]
              if "group" in row}
    assert set(groups) == {"Topography run", "Topography run dialog"}, desktop["tree_after_dialog"]
    assert [row["layer"] for row in groups["Topography run dialog"]] == [
        "Break lines", "Residuals", "Mesh"]
    assert [path for path in desktop["results_viewer"]
            if path.endswith("Topography run dialog/report.html")], desktop["results_viewer"]


def test_the_model_loads_its_results_in_order(desktop):
    """The model's three outputs, lines above residuals above the mesh, in the data's CRS."""
    kinds = [kind for kind, valid, crs in desktop["model_layers"]]
    assert all(valid and crs == "EPSG:2949" for _, valid, crs in desktop["model_layers"]), (
        desktop["model_layers"])
    assert kinds == ["line", "point", "mesh"], desktop["model_layers"]


def test_the_map_shows_the_run(desktop):
    assert desktop["scale"] < 100_000  # zoomed to the 286 m tile, not the whole world
    assert desktop["canvas_crs"] == "EPSG:2949"


def test_mesh_opened_by_hand_has_the_data_crs(desktop):
    assert desktop["by_hand_crs"] == "EPSG:2949"


def test_distances_say_metres_with_no_crs_chosen(desktop):
    for name, texts in desktop["units"].items():
        assert texts and all("meter" in t.lower() for t in texts), (name, texts)


def test_help_is_no_file_url_and_is_there(desktop):
    for algorithm, url in desktop["help_urls"].items():
        assert not url.lower().startswith("file:"), (algorithm, url)
        assert desktop["help_texts"][algorithm] > 200, algorithm
    assert not desktop["help_button"]  # no button that opens nothing


def test_toolbox_search_narrows_to_the_right_algorithms(desktop):
    assert len(desktop["all"]) >= 11
    for text, expected in SEARCHES.items():
        assert desktop["search"][text] == expected, (text, desktop["search"][text])


def test_shipped_model_is_valid_as_opened(desktop):
    assert desktop["model_valid"], desktop["model_issues"]


def test_a_point_cloud_layer_is_an_input(desktop):
    assert desktop["grid"].endswith("Topography run.tif")


def test_no_numerical_package_in_the_qgis_process(desktop):
    # QGIS 3.40's qgis.core imports shapely itself when Debian's is installed (Debian 13, where
    # make setup installs it: built against QGIS's own GEOS); nothing else, and never a wheel
    imported = dict(desktop["imported"])
    shapely = imported.pop("shapely", "/usr/lib/python3/dist-packages/")
    assert imported == {} and shapely.startswith("/usr/lib/python3/dist-packages/")


FLOOD_SCRIPT = desktop_script(r"""
    import processing
    processing.runAndLoadResults("floodmesh:floodonmesh", {
        "MESH": os.environ["FM_MESH"], "SCENARIO": os.environ["FM_SCENARIO"],
        "CRS": "EPSG:32756", "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]})
    settle()
    out["tree"] = tree(QgsProject.instance().layerTreeRoot())
""")


def test_a_flood_shows_where_its_time_step_was_set(tmp_path):
    """Flood on mesh run as from the toolbox: once Qt's events have run, the run's group holds
    the points where the solver's time step was set, valid and in the mesh's CRS, above the
    four rasters."""
    import numpy as np

    from floodmesh.core import io
    from floodmesh.core.flood.model import flood_python
    from floodmesh.core.steps.mesh import PSLG, triangulate_pslg

    if not shutil.which("xvfb-run") or flood_python() is None:
        pytest.skip("xvfb-run or ANUGA (make setup) is missing")
    x0, y0 = 382_000.0, 6_354_000.0
    corners = np.array([[0, 0], [100, 0], [100, 20], [0, 20]], float) + (x0, y0)
    xy, tri = triangulate_pslg(PSLG(corners, np.array([[0, 1], [1, 2], [2, 3], [3, 0]]),
                                    np.empty((0, 2))), min_angle=25.0, max_area=2.0)
    io.write_mesh_2dm(tmp_path / "channel.2dm",
                      np.column_stack([xy, 0.02 * (100 - (xy[:, 0] - x0))]), tri)
    (tmp_path / "scenario.json").write_text(json.dumps({
        "duration_s": 60, "output_interval_s": 10, "manning": 0.03,
        "inflows": [{"line": [[x0 + 2, y0 + 1], [x0 + 2, y0 + 19]], "discharge_m3s": 2.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}]}))
    seen = run_desktop(FLOOD_SCRIPT, tmp_path, FM_MESH=tmp_path / "channel.2dm",
                       FM_SCENARIO=tmp_path / "scenario.json", FM_OUTPUT=tmp_path / "flood")
    groups = [row for row in seen["tree"] if "group" in row]
    assert len(groups) == 1, seen["tree"]
    layers = groups[0]["children"]
    assert layers[0]["layer"] == "Where the time step was set", layers
    assert layers[0]["valid"] and layers[0]["crs"] == "EPSG:32756", layers
    assert len(layers) == 5, layers


RERUN_SCRIPT = desktop_script(r"""
    import processing
    from qgis.core import QgsMeshLayer, QgsRasterLayer
    project = QgsProject.instance()
    dem, mesh = os.environ["FM_OUTPUT"] + ".tif", os.environ["FM_OUTPUT"] + ".2dm"
    for cell in (2.0, 4.0):  # the same GeoTIFF, loaded, rewritten at another cell size
        processing.runAndLoadResults("floodmesh:gridpoints", {
            "INPUT": os.environ["FM_INPUT"], "CELL_SIZE": cell, "OUTPUT": dem})
        settle()
    for area in (100, 400):  # the same mesh, loaded, rewritten with larger triangles
        processing.runAndLoadResults("floodmesh:buildmesh", {
            "DEM": os.environ["FM_DEM"], "MAX_AREA": area, "OUTPUT": mesh})
        settle()
    for area in (100, 200):  # LiDAR to mesh twice into one folder
        processing.runAndLoadResults("floodmesh:lidartomesh", {
            "INPUT": os.environ["FM_INPUT"], "CELL_SIZE": 2.0, "MAX_AREA": area,
            "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]})
        settle()
    out["groups"] = [row["group"] for row in tree(project.layerTreeRoot()) if "group" in row]
    on = {path: [l for l in project.mapLayers().values() if l.source() == path]
          for path in (dem, mesh)}
    out["dem"] = [[l.width(), l.height()] for l in on[dem]]
    on_disk = QgsRasterLayer(dem, "file"), QgsMeshLayer(mesh, "file", "mdal")
    out["dem_file"] = [on_disk[0].width(), on_disk[0].height()]
    out["mesh"] = [l.dataProvider().faceCount() for l in on[mesh]]
    out["mesh_file"] = on_disk[1].dataProvider().faceCount()
""")


def test_a_rerun_into_a_loaded_file_shows_the_new_file_once(tmp_path):
    """Grid LiDAR points run twice into one GeoTIFF, Build mesh twice into one 2DM, LiDAR to
    mesh twice into one folder: once Qt's events have run, each file is in the project once,
    showing what is on disk now, and the folder's run has one group."""
    seen = run_on_real_data(RERUN_SCRIPT, tmp_path)
    assert seen["dem"] == [seen["dem_file"]], seen
    assert seen["mesh"] == [seen["mesh_file"]], seen
    assert seen["groups"] == ["run"], seen


ONE_TILE_SCRIPT = desktop_script(r"""
    import processing


    def outcome(algorithm, parameters):
        try:
            return sorted(processing.run(algorithm, parameters))
        except Exception as exc:
            return str(exc)

    laz, dem, folder = os.environ["FM_INPUT"], os.environ["FM_DEM"], os.environ["FM_OUTPUT"]
    out["one_laz"] = outcome("floodmesh:gridpoints", {
        "TILES": [laz], "CELL_SIZE": 2.0, "OUTPUT": folder + ".tif"})
    out["one_dem"] = outcome("floodmesh:lidartomesh", {
        "TILES": [dem], "MAX_AREA": 400, "OUTPUT_FOLDER": folder})
    out["mixed"] = outcome("floodmesh:gridpoints", {
        "TILES": [laz, dem], "CELL_SIZE": 2.0, "OUTPUT": folder + " mixed.tif"})
""")


def test_one_tile_runs_as_its_file_and_a_mixed_list_is_named(tmp_path):
    """Tiles given as a list of one LAZ (Grid LiDAR points) or one DEM (LiDAR to mesh) run as
    that file would; a list mixing a LAZ and a DEM is refused naming the files, not a folder."""
    seen = run_on_real_data(ONE_TILE_SCRIPT, tmp_path)
    assert seen["one_laz"] == ["OUTPUT"], seen
    assert "MESH" in seen["one_dem"], seen
    assert seen["mixed"].endswith(
        "as many of each: 1 point file (Topography.laz) and 1 DEM raster "
        "(merewether_topography1.asc): give one kind: list the point files or the DEM rasters, "
        "not both"), seen


AFTER_RUN_SCRIPT = desktop_script(r"""
    import processing
    processing.runAndLoadResults("floodmesh:lidartomesh", {
        "INPUT": os.environ["FM_INPUT"], "CELL_SIZE": 2.0,
        "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]})
    settle()
    processing.runAndLoadResults("floodmesh:slope", {
        "INPUT": os.environ["FM_DEM"], "OUTPUT": os.environ["FM_OUTPUT"] + " slope.tif"})
    settle()
    out["tree"] = tree(QgsProject.instance().layerTreeRoot())
""")


def test_a_later_result_loads_outside_the_run_group(tmp_path):
    """After LiDAR to mesh, the next algorithm's result loads beside the run's group, above
    it, as it would without the run, not into the group."""
    seen = run_on_real_data(AFTER_RUN_SCRIPT, tmp_path)
    assert [row.get("layer", row.get("group")) for row in seen["tree"]] == [
        "Slope (degrees)", "run"], seen
    assert len(seen["tree"][1]["children"]) == 3, seen


EXPORT_SCRIPT = desktop_script(r"""
    import processing
    from qgis.core import QgsMeshLayer
    mesh = os.environ["FM_OUTPUT"] + ".2dm"
    processing.run("floodmesh:buildmesh", {"DEM": os.environ["FM_DEM"], "MAX_AREA": 400,
                                           "OUTPUT": mesh})
    for fmt, ext in ((0, ".2dm"), (4, ".nc"), (5, ".gpkg")):
        processing.runAndLoadResults("floodmesh:exportmesh", {
            "INPUT": mesh, "CRS": "EPSG:32756", "FORMAT": fmt,
            "OUTPUT": os.environ["FM_OUTPUT"] + " export" + ext})
        settle()
    out["tree"] = tree(QgsProject.instance().layerTreeRoot())
    out["faces"] = sorted(l.dataProvider().faceCount() for l in
                          QgsProject.instance().mapLayers().values()
                          if isinstance(l, QgsMeshLayer))
""")


def test_export_mesh_loads_what_qgis_opens(tmp_path):
    """Export mesh as 2DM, UGRID netCDF and GeoPackage: the two meshes load as mesh layers
    in the mesh's CRS, the GeoPackage's layers in one group named after it."""
    seen = run_on_real_data(EXPORT_SCRIPT, tmp_path)
    tree = seen["tree"]
    assert [row.get("layer", row.get("group")) for row in tree] == [
        "run export.gpkg", "Exported mesh", "Exported mesh"], seen
    assert all(row["valid"] and row["crs"] == "EPSG:32756" for row in tree[1:]), seen
    assert len(set(seen["faces"])) == 1, seen
    assert sorted(row["layer"] for row in tree[0]["children"]) == [
        "boundary", "nodes", "triangles"], seen


RESTRETCH_SCRIPT = desktop_script(r"""
    import processing
    slope = os.environ["FM_OUTPUT"] + " slope.tif"
    for method in (1, 6):  # slope in degrees, then the LoG response (m) into the same file
        processing.runAndLoadResults("floodmesh:slope", {
            "INPUT": os.environ["FM_DEM"], "METHOD": method, "OUTPUT": slope})
        settle()
    layers = [l for l in QgsProject.instance().mapLayers().values() if l.source() == slope]
    out["stretch"] = [[l.renderer().contrastEnhancement().minimumValue(),
                       l.renderer().contrastEnhancement().maximumValue()] for l in layers]
    out["slope"] = slope
    names = {}
    for method in (1, 6):  # the same two, each into a file of its own
        processing.runAndLoadResults("floodmesh:slope", {
            "INPUT": os.environ["FM_DEM"], "METHOD": method, "OUTPUT": f"{slope}{method}.tif"})
        settle()
        names[method] = [l.name() for l in QgsProject.instance().mapLayers().values()
                         if l.source() == f"{slope}{method}.tif"]
    out["names"] = names
""")


def test_a_rerun_into_a_loaded_raster_stretches_it_for_its_new_values(tmp_path):
    """Slope for break lines run in degrees, then as the LoG response (m) into the same GeoTIFF:
    the layer, reloaded in place, is stretched over the new values, as a fresh load of the file
    would be, not over the first run's degrees (which leave the LoG's metres one grey)."""
    import rasterio

    seen = run_on_real_data(RESTRETCH_SCRIPT, tmp_path)
    with rasterio.open(seen["slope"]) as src:
        values = src.read(1, masked=True)
    low, high = float(values.min()), float(values.max())
    assert len(seen["stretch"]) == 1, seen
    shown = seen["stretch"][0]
    assert abs(shown[0] - low) < 0.05 * (high - low), (shown, low, high)
    assert abs(shown[1] - high) < 0.05 * (high - low), (shown, low, high)


def rerun_script(setup: str, algorithm: str, removed: str) -> str:
    """A desktop script: ``setup`` (lines indented once, setting ``parameters``), then
    ``algorithm`` run as from the toolbox, the layer ``removed`` taken out of the project, the
    same run again; the tree that then shows is ``out["tree"]``."""
    return desktop_script(setup + f"""
    processing.runAndLoadResults("floodmesh:{algorithm}", parameters)
    settle()
    project.removeMapLayers([l.id() for l in project.mapLayersByName("{removed}")])
    settle()
    processing.runAndLoadResults("floodmesh:{algorithm}", parameters)  # the same output again
    settle()
    out["tree"] = tree(project.layerTreeRoot())
""")


REGROUP_SCRIPT = rerun_script(r"""
    import processing
    project = QgsProject.instance()
    parameters = {"INPUT": os.environ["FM_INPUT"], "CELL_SIZE": 2.0, "MAX_AREA": 200,
                  "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]}
""", "lidartomesh", "Residuals")


def test_a_rerun_loads_what_is_missing_into_the_run_group(tmp_path):
    """LiDAR to mesh run, its residuals removed from the project, run again into the same
    folder: the residuals come back into the folder's one group, in their place, beside the
    reloaded break lines and mesh, not into a second group of the same name."""
    seen = run_on_real_data(REGROUP_SCRIPT, tmp_path)
    assert [row.get("group") for row in seen["tree"]] == ["run"], seen
    assert [row["layer"] for row in seen["tree"][0]["children"]] == [
        "Break lines", "Residuals", "Mesh"], seen


WRONG_GEOMETRY_SCRIPT = desktop_script(r"""
    import processing
    from qgis.core import (QgsCoordinateTransformContext, QgsFeature, QgsGeometry,
                           QgsVectorFileWriter, QgsVectorLayer)
    base = os.environ["FM_OUTPUT"]
    processing.run("floodmesh:buildmesh", {"DEM": os.environ["FM_DEM"], "MAX_AREA": 400,
                                           "OUTPUT": base + ".2dm"})
    for kind, wkt in (("lines", "LineStringZ (382300 6354300 10, 382400 6354400 12, "
                                "382450 6354380 11)"),
                      ("points", "PointZ (382300 6354300 10)")):
        layer = QgsVectorLayer(wkt.split()[0] + "?crs=EPSG:32756", kind, "memory")
        feature = QgsFeature()
        feature.setGeometry(QgsGeometry.fromWkt(wkt))
        layer.dataProvider().addFeatures([feature])
        options = QgsVectorFileWriter.SaveVectorOptions()
        options.driverName = "GPKG"
        QgsVectorFileWriter.writeAsVectorFormatV2(layer, f"{base} {kind}.gpkg",
                                                  QgsCoordinateTransformContext(), options)
        iface.addVectorLayer(f"{base} {kind}.gpkg", kind, "ogr")
    try:  # the break lines given as check points (the dialog's … button, a script)
        processing.run("floodmesh:assessaccuracy", {
            "MESH": base + ".2dm", "POINTS": base + " lines.gpkg",
            "OUTPUT": base + " residuals.gpkg"})
        out["said"] = None
    except Exception as exc:
        out["said"] = str(exc)
    out["written"] = os.path.exists(base + " residuals.gpkg")
    # what the dialog offers as check points among the project's layers
    from qgis.PyQt.QtWidgets import QComboBox
    dialog = processing.createAlgorithmDialog("floodmesh:assessaccuracy", {})
    dialog.show()
    settle()
    combo = dialog.mainWidget().wrappers["POINTS"].wrappedWidget().findChild(QComboBox)
    out["offered"] = [combo.itemText(i) for i in range(combo.count())]
    dialog.close()
""")


def test_assess_accuracy_given_lines_says_points_are_needed(tmp_path):
    """A line layer given as Assess accuracy's check points is refused in one line that says it
    has lines and points are needed (not numpy's words), before any output is written; the
    dialog offers only the project's point layers there."""
    seen = run_on_real_data(WRONG_GEOMETRY_SCRIPT, tmp_path)
    said = seen["said"] or ""
    last = said.strip().splitlines()[-1] if said.strip() else ""
    assert "lines" in last and "points are needed" in last, said
    assert "array" not in said and "sequence" not in said and "Traceback" not in said, said
    assert not seen["written"], seen
    assert [text.split(" [")[0] for text in seen["offered"]] == ["points"], seen


STACK_SCRIPT = desktop_script(r"""
    import processing
    from qgis.core import (QgsCoordinateTransformContext, QgsFeature, QgsGeometry,
                           QgsVectorFileWriter, QgsVectorLayer)
    base = os.environ["FM_OUTPUT"]
    lines = QgsVectorLayer("LineStringZ?crs=EPSG:32756", "lines", "memory")
    feature = QgsFeature()
    feature.setGeometry(QgsGeometry.fromWkt("LineStringZ (" + ", ".join(
        f"{382300 + 10 * k} {6354400 + 3 * k} {20 + 0.1 * k}" for k in range(12)) + ")"))
    lines.dataProvider().addFeatures([feature])
    options = QgsVectorFileWriter.SaveVectorOptions()
    options.driverName = "GPKG"
    QgsVectorFileWriter.writeAsVectorFormatV2(lines, base + " lines.gpkg",
                                              QgsCoordinateTransformContext(), options)
    # a modeller's steps, one after another: lines, a slope, then the mesh
    processing.runAndLoadResults("floodmesh:simplifybreaklines", {
        "INPUT": base + " lines.gpkg", "OUTPUT": base + " simple.gpkg"})
    settle()
    processing.runAndLoadResults("floodmesh:slope", {
        "INPUT": os.environ["FM_DEM"], "OUTPUT": base + " slope.tif"})
    settle()
    processing.runAndLoadResults("floodmesh:buildmesh", {
        "DEM": os.environ["FM_DEM"], "MAX_AREA": 400, "OUTPUT": base + ".2dm"})
    settle()
    out["tree"] = tree(QgsProject.instance().layerTreeRoot())
""")


def test_steps_run_one_after_another_stack_lines_above_rasters_above_the_mesh(tmp_path):
    """Simplify break lines, Slope and Build mesh run one after another: the mesh, loaded last,
    goes below the slope and the lines, as it does among a model's outputs, instead of on top
    of them where its shaded faces hide them."""
    seen = run_on_real_data(STACK_SCRIPT, tmp_path)
    assert [row["layer"] for row in seen["tree"]] == [
        "Simplified break lines", "Slope (degrees)", "Mesh"], seen


ASSESS_LOG_SCRIPT = desktop_script(r"""
    import processing
    from qgis.core import QgsProcessingFeedback

    class Log(QgsProcessingFeedback):  # what the dialog's log shows
        def __init__(self):
            super().__init__()
            self.lines = []

        def pushInfo(self, text):  # noqa: N802
            self.lines.append(text)

    base = os.environ["FM_OUTPUT"]
    processing.run("floodmesh:gridpoints", {
        "INPUT": os.environ["FM_INPUT"], "CELL_SIZE": 2.0, "HOLDOUT": 0.01,
        "OUTPUT": base + " dem.tif", "HOLDOUT_OUTPUT": base + " holdout.gpkg"})
    processing.run("floodmesh:buildmesh", {"DEM": base + " dem.tif", "MAX_AREA": 100,
                                           "OUTPUT": base + ".2dm"})
    log = Log()
    processing.runAndLoadResults("floodmesh:assessaccuracy", {
        "MESH": base + ".2dm", "POINTS": base + " holdout.gpkg",
        "OUTPUT": base + " residuals.gpkg"}, feedback=log)
    out["log"] = log.lines
""")


def test_assess_accuracy_says_its_figures_in_words_and_centimetres(tmp_path):
    """Assess accuracy's log gives the RMSE, the classes and the FEMA/NSSDA test's outcome as
    a modeller reads them (cm, %, passed or failed), not core's JSON with keys and 16 digits."""
    seen = run_on_real_data(ASSESS_LOG_SCRIPT, tmp_path)
    text = "\n".join(line for line in seen["log"] if not line.startswith("Results: "))  # QGIS's
    assert "{" not in text and "rmse_m" not in text, text
    assert re.search(r"RMSE \d+\.\d cm on \d+ of \d+ check points", text), text
    assert re.search(r"FEMA/NSSDA test (passed|failed)", text), text
    assert re.search(r"\d+ % under 10 cm", text), text


TRIANGLES_SCRIPT = desktop_script(r"""
    import processing
    from qgis.core import QgsProject
    from qgis.PyQt.QtCore import Qt
    base = os.environ["FM_OUTPUT"]
    processing.runAndLoadResults("floodmesh:buildmesh", {
        "DEM": os.environ["FM_DEM"], "MAX_AREA": 400, "OUTPUT": base + ".2dm",
        "TRIANGLES": base + " triangles.gpkg"})
    settle()
    processing.runAndLoadResults("floodmesh:exportmesh", {
        "INPUT": base + ".2dm", "CRS": "EPSG:32756", "FORMAT": 5,
        "OUTPUT": base + " export.gpkg"})
    settle()
    out["fills"] = {}
    for layer in QgsProject.instance().mapLayers().values():
        if layer.name() in ("Triangles", "triangles"):
            symbol = layer.renderer().symbol()
            out["fills"][layer.source()] = [
                symbol.symbolLayer(0).brushStyle() == Qt.NoBrush, symbol.color().alpha()]
""")


def test_triangles_load_as_outlines_over_what_lies_below(tmp_path):
    """Build mesh's Triangles and Export mesh's GeoPackage triangles load as the mesh's edges,
    unfilled, not as polygons filled with a random colour that hide the layers below."""
    seen = run_on_real_data(TRIANGLES_SCRIPT, tmp_path)
    assert len(seen["fills"]) == 2, seen
    assert all(unfilled for unfilled, _ in seen["fills"].values()), seen


DEM_AS_SLOPE_SCRIPT = desktop_script(r"""
    import processing
    base = os.environ["FM_OUTPUT"]
    processing.runAndLoadResults("floodmesh:gridpoints", {
        "INPUT": os.environ["FM_INPUT"], "CELL_SIZE": 2.0, "OUTPUT": base + " dem.tif"})
    settle()
    try:  # the DEM picked where the slope belongs: every raster of the project is offered
        processing.run("floodmesh:classifybreakpoints", {
            "INPUT": base + " dem.tif", "OUTPUT": base + " breakpoints.tif"})
        out["said"] = None
    except Exception as exc:
        out["said"] = str(exc)
    out["written"] = os.path.exists(base + " breakpoints.tif")
    processing.run("floodmesh:slope", {"INPUT": base + " dem.tif", "OUTPUT": base + " slope.tif"})
    try:  # the slope picked where the breakpoints belong
        processing.run("floodmesh:tracebreaklines", {
            "BREAKPOINTS": base + " slope.tif", "SLOPE": base + " slope.tif",
            "DEM": base + " dem.tif", "OUTPUT": base + " lines.gpkg"})
        out["traced"] = None
    except Exception as exc:
        out["traced"] = str(exc)
""")


def test_a_raster_picked_for_another_is_refused_naming_the_right_step(tmp_path):
    """Grid LiDAR points' DEM picked as Classify breakpoints' slope, and a slope as Trace break
    lines' breakpoints: refused in one line that says what the raster holds and names the step
    that makes the right one, instead of breakpoints wherever the ground is above S_crit metres
    and lines through the cells whose slope is exactly 1 degree."""
    seen = run_on_real_data(DEM_AS_SLOPE_SCRIPT, tmp_path)
    last = (seen["said"] or "").strip().splitlines()[-1:]
    assert last and "holds elevations" in last[0] and "not a slope in degrees" in last[0], seen
    assert "Slope for break lines" in last[0], seen
    assert not seen["written"], seen
    assert seen["traced"] and seen["traced"].splitlines()[-1].endswith(
        "holds a slope in degrees, as FloodMesh's slope step wrote it, not breakpoints (1) and "
        "other cells (0): give the slope's breakpoints (floodmesh breakpoints SLOPE; Classify "
        "breakpoints in QGIS)"), seen


REEXPORT_SCRIPT = rerun_script(r"""
    import processing
    project = QgsProject.instance()
    base = os.environ["FM_OUTPUT"]
    processing.run("floodmesh:buildmesh", {"DEM": os.environ["FM_DEM"], "MAX_AREA": 400,
                                           "OUTPUT": base + ".2dm"})
    parameters = {"INPUT": base + ".2dm", "CRS": "EPSG:32756", "FORMAT": 5,
                  "OUTPUT": base + " export.gpkg"}
""", "exportmesh", "nodes")


def test_a_reexport_loads_what_is_missing_into_the_geopackage_group(tmp_path):
    """Export mesh to a GeoPackage, one of its layers removed, exported again to the same
    file: the layer comes back into the file's one group, not into a second one."""
    seen = run_on_real_data(REEXPORT_SCRIPT, tmp_path)
    assert [row.get("group") for row in seen["tree"]] == ["run export.gpkg"], seen
    assert sorted(row["layer"] for row in seen["tree"][0]["children"]) == [
        "boundary", "nodes", "triangles"], seen


def test_a_slope_layer_is_named_after_what_it_holds(tmp_path):
    """Slope for break lines in degrees and as the LoG response load as "Slope (degrees)" and
    "LoG response (m)", not both as "Slope (degrees) or LoG response (m)"."""
    seen = run_on_real_data(RESTRETCH_SCRIPT, tmp_path)
    assert seen["names"] == {"1": ["Slope (degrees)"], "6": ["LoG response (m)"]}, seen


BATCH_SCRIPT = desktop_script(r"""
    import processing
    from processing.gui.BatchAlgorithmDialog import BatchAlgorithmDialog
    project = QgsProject.instance()
    base = os.environ["FM_OUTPUT"]

    def algorithm():
        return QgsApplication.processingRegistry().createAlgorithmById("floodmesh:buildmesh")

    def batch(name, load):
        # the Batch Processing dialog: two rows, DEM and mesh file set in each, the "Load layers
        # on completion" box as the user left it, Run pressed
        dialog = BatchAlgorithmDialog(algorithm(), iface.mainWindow())
        dialog.show()
        panel = dialog.mainWidget()
        panel.addRow()
        context = processing.tools.dataobjects.createContext()
        for row in range(2):
            panel.wrappers[row][panel.parameter_to_column["DEM"]].setParameterValue(
                os.environ["FM_DEM"], context)
            panel.wrappers[row][panel.parameter_to_column["MAX_AREA"]].setParameterValue(
                400, context)
            panel.tblParameters.cellWidget(row + 1, panel.parameter_to_column["OUTPUT"]).setValue(
                f"{base} {name} {row}.2dm")
        panel.checkLoadLayersOnCompletion.setChecked(load)
        dialog.runAlgorithm()  # QGIS 3.22 runs the rows in turn; later, one task a row
        written = [f"{base} {name} {row}.2dm" for row in range(2)]
        for _ in range(900):
            if (all(os.path.exists(path) for path in written)
                    and not QgsApplication.taskManager().countActiveTasks()):
                break
            QTest.qWait(200)
        settle()
        out[name] = sorted(l.name() for l in project.mapLayers().values())
        out[name + " written"] = [os.path.exists(path) for path in written]
        dialog.close()
        project.removeAllMapLayers()
        settle()

    batch("unticked", False)
    batch("ticked", True)
    # the algorithm's own dialog, as it opens: the mesh loads
    dialog = processing.createAlgorithmDialog("floodmesh:buildmesh", {
        "DEM": os.environ["FM_DEM"], "MAX_AREA": 400, "OUTPUT": base + " dialog.2dm"})
    run_dialog(dialog)
    out["dialog"] = sorted(l.name() for l in project.mapLayers().values())
""")


def test_batch_loads_meshes_only_with_its_load_box_ticked(tmp_path):
    """Build mesh in Batch Processing, "Load layers on completion" unticked: the meshes are
    written and nothing is added to the project (as QGIS's own algorithms do), not one layer
    "Mesh" per row; ticked, each row's mesh loads; the algorithm's own dialog still loads it."""
    seen = run_on_real_data(BATCH_SCRIPT, tmp_path)
    assert seen["unticked written"] == [True, True], seen
    assert seen["unticked"] == [], seen
    assert seen["ticked"] == ["Mesh", "Mesh"], seen
    assert seen["dialog"] == ["Mesh"], seen
