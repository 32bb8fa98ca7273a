"""The desktop QGIS itself (``qgis.bin`` under a virtual display): LiDAR to mesh on
Topography.laz (where shapely's second GEOS crashed the desktop with the user's project), the
results stacked lines above the mesh, the mesh in the run's CRS, the map zoomed to it, and none
of FloodMesh's numerical packages in the QGIS process."""
import json
import os
import shutil
import subprocess

import pytest

from .conftest import REPO, write_ept

SCRIPT = r"""
import json, os, sys, traceback
from qgis.utils import iface
from qgis.core import QgsProject
out = {}
try:
    import processing
    processing.runAndLoadResults("floodmesh:lidartomesh", {
        "INPUT": os.environ["FM_INPUT"], "CLASSES": "2,9", "CELL_SIZE": 2.0, "HOLDOUT": 0.003,
        "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]})
    project = QgsProject.instance()
    out["order"] = [n.layer().name() for n in project.layerTreeRoot().findLayers()]
    mesh = project.mapLayersByName("Mesh")[0]
    out["mesh_crs"] = mesh.crs().authid()
    out["edges"] = mesh.rendererSettings().nativeMeshSettings().isEnabled()
    out["scale"] = iface.mapCanvas().scale()
    # what the dialog shows: the cell size's unit (the CRS parameter is empty: metres)
    from qgis.PyQt.QtWidgets import QComboBox, QLabel
    from qgis.core import QgsPointCloudLayer
    dialog = processing.createAlgorithmDialog("floodmesh:lidartomesh", {})
    widget = dialog.mainWidget().wrappers["CELL_SIZE"].wrappedWidget()
    out["cell_size_unit"] = ([l.text() for l in widget.findChildren(QLabel)]
                             + [c.currentText() for c in widget.findChildren(QComboBox)])
    # a point-cloud layer of the project as the LiDAR input
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


@pytest.mark.skipif(not shutil.which("xvfb-run"), reason="xvfb-run (package xvfb) is missing")
def test_the_desktop_runs_lidar_to_mesh_and_shows_the_result(real_data, tmp_path):
    profile = tmp_path / "data" / "QGIS" / "QGIS3" / "profiles" / "default" / "QGIS"
    profile.mkdir(parents=True)
    (profile / "QGIS3.ini").write_text("[PythonPlugins]\nfloodmesh=true\nprocessing=true\n")
    (tmp_path / "run.py").write_text(SCRIPT)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "QT_QPA_PLATFORM")}
    result = tmp_path / "result.json"
    env.update(HOME=str(tmp_path), XDG_DATA_HOME=str(tmp_path / "data"),
               QGIS_PLUGINPATH=str(REPO / "build" / "plugins"),
               FM_INPUT=str(real_data / "Topography.laz"), FM_OUTPUT=str(tmp_path / "run"),
               FM_RESULT=str(result),
               FM_EPT=str(write_ept(real_data / "Topography.laz", tmp_path / "ept")))  # the script's arguments (qgis.bin would open more)
    run = subprocess.run(["xvfb-run", "-a", "qgis.bin", "--noversioncheck", "--nologo",
                          "--code", str(tmp_path / "run.py")],
                         env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and result.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    seen = json.loads(result.read_text())
    assert "error" not in seen, seen.get("error")
    assert seen["order"] == ["Break lines", "Residuals", "Mesh"]
    assert seen["mesh_crs"] == "EPSG:2949" and seen["edges"]
    assert seen["scale"] < 100_000  # zoomed to the 286 m tile, not the whole world
    assert any("meter" in text.lower() for text in seen["cell_size_unit"]), seen
    assert seen["grid"] == str(tmp_path / "run.tif") and (tmp_path / "run.tif").exists()
    # QGIS 3.40's qgis.core imports shapely itself when Debian's is installed (Debian 13, where
    # make setup installs it: built against QGIS's own GEOS); nothing else, and never a wheel
    shapely = seen["imported"].pop("shapely", "/usr/lib/python3/dist-packages/")
    assert seen["imported"] == {} and shapely.startswith("/usr/lib/python3/dist-packages/")
