"""Without Triangle or numba (as in a stock QGIS) the plugin still loads, lists every algorithm,
and each says what to install instead of failing with an ImportError."""
import subprocess
import sys

from .conftest import REPO

SCRIPT = r"""
import sys
sys.modules["triangle"] = None   # as if not installed: importing it raises ImportError
sys.modules["numba"] = None
sys.path.append("/usr/share/qgis/python/plugins")
from qgis.core import QgsApplication, QgsProcessingContext, QgsProcessingFeedback
app = QgsApplication([], False); app.initQgis()
from processing.core.Processing import Processing
Processing.initialize()
import floodmesh
plugin = floodmesh.classFactory(None)
plugin.initProcessing()
provider = QgsApplication.processingRegistry().providerById("floodmesh")
print("ALGORITHMS", len(provider.algorithms()))
alg = QgsApplication.processingRegistry().createAlgorithmById("floodmesh:slope")
ok, message = alg.checkParameterValues({"INPUT": "x.tif", "OUTPUT": "y.tif"},
                                       QgsProcessingContext())
print("CHECK", ok, message)
import processing
try:
    processing.run("floodmesh:gridpoints", {"INPUT": "x.laz", "OUTPUT": "y.tif"})
except Exception as exc:
    print("RUN", type(exc).__name__, exc)
"""


def test_plugin_loads_and_explains_missing_dependencies():
    run = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         timeout=120, cwd=REPO, env={"QT_QPA_PLATFORM": "offscreen",
                                                     "PATH": "/usr/bin:/bin"})
    out = run.stdout
    assert "ALGORITHMS 12" in out, run.stdout + run.stderr
    check = next(line for line in out.splitlines() if line.startswith("CHECK"))
    assert check.startswith("CHECK False") and "numba" in check and "triangle" in check
    assert "pip install" in check
    ran = out[out.index("RUN"):]  # processing.run puts the algorithm's message on a new line
    assert "QgsProcessingException" in ran and "triangle" in ran and "pip install" in ran
    assert "ModuleNotFoundError" not in run.stdout + run.stderr
