"""QGIS never loads FloodMesh's numerical packages: the plugin loads, lists every algorithm and
runs them with none of shapely, Triangle, numba or laspy imported into the QGIS process (their
GEOS and their crashes stay in the worker); a worker Python that lacks them says what to
install, once, as a Processing error."""
import subprocess
import sys

from .conftest import REPO

SCRIPT = r"""
import sys
sys.path.append("/usr/share/qgis/python/plugins")
from qgis.core import QgsApplication
app = QgsApplication([], False); app.initQgis()
from processing.core.Processing import Processing
Processing.initialize()
HEAVY = ("shapely", "triangle", "numba", "laspy", "lazrs", "rasterio", "fiona")
# QGIS 3.40's qgis.core imports shapely itself when it can (its geometry conversions): what
# counts is what FloodMesh adds
before = {m for m in HEAVY if m in sys.modules}
import floodmesh
plugin = floodmesh.classFactory(None)
plugin.initProcessing()
provider = QgsApplication.processingRegistry().providerById("floodmesh")
print("ALGORITHMS", len(provider.algorithms()))
import processing
try:
    processing.run("floodmesh:slope", {"INPUT": sys.argv[1], "OUTPUT": sys.argv[2]})
    print("RAN")
except Exception as exc:
    print("RUN", type(exc).__name__, exc)
heavy = sorted(m for m in HEAVY if m in sys.modules and m not in before)
print("IMPORTED", heavy)
"""


def _run(args, **env):
    return subprocess.run([sys.executable, "-c", SCRIPT, *map(str, args)], capture_output=True,
                          text=True, timeout=300, cwd=REPO,
                          env={"QT_QPA_PLATFORM": "offscreen", "PATH": "/usr/bin:/bin", **env})


def test_qgis_imports_none_of_the_numerical_packages(real_data, tmp_path):
    out = tmp_path / "slope.tif"
    run = _run([real_data / "merewether_topography1.asc", out])
    assert "ALGORITHMS 12" in run.stdout, run.stdout + run.stderr
    assert "RAN" in run.stdout and out.exists(), run.stdout + run.stderr
    assert "IMPORTED []" in run.stdout, run.stdout


def test_a_worker_python_without_the_packages_says_what_to_install(real_data, tmp_path):
    """Debian's own Python has neither Triangle nor numba: the message names them and the
    command, not a ModuleNotFoundError."""
    run = _run([real_data / "merewether_topography1.asc", tmp_path / "slope.tif"],
               FLOODMESH_PYTHON="/usr/bin/python3")
    ran = run.stdout[run.stdout.index("RUN"):]
    assert "QgsProcessingException" in ran and "triangle" in ran and "numba" in ran
    assert "pip install" in ran and "FLOODMESH_PYTHON" in ran
    assert "ModuleNotFoundError" not in run.stdout + run.stderr
    assert not (tmp_path / "slope.tif").exists()
