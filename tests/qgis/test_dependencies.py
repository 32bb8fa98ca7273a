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
    assert "RUN" in run.stdout, run.stdout + run.stderr
    ran = run.stdout[run.stdout.index("RUN"):]
    assert "QgsProcessingException" in ran and "triangle" in ran and "numba" in ran
    assert "pip install" in ran and "FLOODMESH_PYTHON" in ran
    assert "ModuleNotFoundError" not in run.stdout + run.stderr
    assert not (tmp_path / "slope.tif").exists()


GEOS_SCRIPT = r"""
import shapely
from qgis.core import Qgis, QgsApplication, QgsGeometry
app = QgsApplication([], False); app.initQgis()
import numpy as np
from shapely.geometry import Polygon
# what crashed or went wrong with two GEOS libraries in one process: prepared predicates,
# representative points, coordinates back from GEOS
ring = Polygon([(0, 0), (10, 0), (10, 10), (0, 10)], [[(4, 4), (6, 4), (6, 6), (4, 6)]])
xy = np.random.default_rng(0).uniform(-1, 11, (100_000, 2))
inside = shapely.contains_xy(ring, xy[:, 0], xy[:, 1])
assert abs(inside.mean() - 96 / 144) < 0.01, inside.mean()
point = ring.representative_point()
assert len(point.coords[0]) == 2 and ring.contains(point)
assert QgsGeometry.fromWkt(ring.wkt).area() == ring.area == 96
print("SHAPELY", shapely.__file__, shapely.geos_version_string, Qgis.geosVersion())
"""


def _system_shapely_version():
    run = subprocess.run(["/usr/bin/python3", "-I", "-c", "import importlib.metadata as m; "
                          "print(m.version('shapely'))"], capture_output=True, text=True)
    return run.stdout.strip() if run.returncode == 0 else None


def test_a_pyqgis_script_in_the_project_env_has_one_geos_where_debian_has_shapely_2():
    """QGIS 3.40's qgis.core imports shapely itself: in the project's .venv that is Debian's
    shapely where Debian has shapely 2 (Debian 13), built against the GEOS QGIS links, not PyPI's
    wheel with a GEOS of its own (scripts/setup.sh); where Debian's is 1.x (Debian 12) the wheel,
    which QGIS 3.22 never imports itself. Either way shapely and QGIS work side by side."""
    run = subprocess.run([sys.executable, "-c", GEOS_SCRIPT], capture_output=True, text=True,
                         timeout=120, cwd=REPO, env={"QT_QPA_PLATFORM": "offscreen",
                                                     "PATH": "/usr/bin:/bin"})
    assert run.returncode == 0 and "SHAPELY" in run.stdout, run.stdout + run.stderr
    path, shapely_geos, qgis_geos = run.stdout.split("SHAPELY", 1)[1].split()
    system = _system_shapely_version()
    if system and int(system.split(".")[0]) >= 2:
        assert path.startswith("/usr/lib/python3/dist-packages/"), path
        assert shapely_geos.split("-")[0] == qgis_geos.split("-")[0]
    else:
        assert "/.venv/" in path, path
