"""The installable plugin zip: built from the tracked files, unpacked into a fresh QGIS profile
(as the plugin manager does), enabled, and run headless from there."""
import configparser
import json
import os
import subprocess
import sys
import zipfile

from qgis.core import QgsRasterLayer

from .conftest import REPO


def test_zip_installs_into_a_fresh_profile_and_runs(tmp_path, real_data):
    _install_and_run(tmp_path, real_data, FLOODMESH_PYTHON=str(REPO / ".venv" / "bin" / "python"))


def test_zip_on_a_stock_qgis_sets_up_its_python_on_the_first_run(tmp_path, real_data):
    """Without FLOODMESH_PYTHON and without a checkout's .venv, as after Install from ZIP on a
    stock Debian QGIS: the first run creates <profile>/floodmesh/venv from /usr/bin/python3
    (system site-packages, numpy pinned) with pip, says so, and runs in it."""
    run = _install_and_run(tmp_path, real_data)
    assert "sets up its Python packages" in run.stdout + run.stderr
    venv = (tmp_path / "home" / "data" / "QGIS" / "QGIS3" / "profiles" / "default" / "floodmesh"
            / "venv")
    assert (venv / "bin" / "python").exists() and (venv / ".floodmesh-ready").exists()
    check = subprocess.run([str(venv / "bin" / "python"), "-c",
                            "import numpy, triangle, numba, laspy, lazrs, shapely; "
                            "print(numpy.__version__)"], capture_output=True, text=True)
    system = subprocess.run(["/usr/bin/python3", "-c", "import numpy; print(numpy.__version__)"],
                            capture_output=True, text=True)
    assert check.returncode == 0 and check.stdout == system.stdout, check.stderr


def _install_and_run(tmp_path, real_data, **worker_env):
    built = subprocess.run([sys.executable, str(REPO / "scripts" / "build_plugin_zip.py"),
                            str(tmp_path / "dist")], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    archive = next((tmp_path / "dist").glob("floodmesh-*.zip"))
    with zipfile.ZipFile(archive) as z:
        names = z.namelist()
        assert all(n.startswith("floodmesh/") for n in names)
        assert {"floodmesh/metadata.txt", "floodmesh/__init__.py", "floodmesh/icons/floodmesh.svg",
                "floodmesh/models/lidar_to_mesh_steps.model3"} <= set(names)
        assert not any("/tests/" in n or "__pycache__" in n for n in names)
        meta = configparser.ConfigParser()
        meta.read_string(z.read("floodmesh/metadata.txt").decode())
        plugins = tmp_path / "home" / "data" / "QGIS" / "QGIS3" / "profiles" / "default" / \
            "python" / "plugins"
        z.extractall(plugins)
    general = meta["general"]
    for key in ("name", "description", "about", "version", "qgisMinimumVersion", "author",
                "email", "homepage", "tracker", "repository", "tags", "icon", "experimental",
                "license"):
        assert general.get(key), f"metadata.txt lacks {key}"
    assert general["hasProcessingProvider"] == "yes"

    from qgis.core import Qgis
    assert Qgis.QGIS_VERSION_INT >= int("".join(
        f"{int(p):02d}" for p in general["qgisMinimumVersion"].split("."))) * 100

    import shutil
    exe = shutil.which("qgis_process.bin") or shutil.which("qgis_process")
    env = {k: v for k, v in os.environ.items() if k != "QGIS_PLUGINPATH"}
    env.update(QT_QPA_PLATFORM="offscreen", HOME=str(tmp_path / "home"),
               XDG_DATA_HOME=str(tmp_path / "home" / "data"), **worker_env)
    env.pop("PYTHONPATH", None)  # QGIS itself needs none of FloodMesh's packages
    if not worker_env:
        env.pop("FLOODMESH_PYTHON", None)
    enable = subprocess.run([exe, "plugins", "enable", "floodmesh"], env=env,
                            capture_output=True, text=True, timeout=120)
    assert enable.returncode == 0, enable.stdout + enable.stderr
    out = tmp_path / "slope.tif"
    run = subprocess.run([exe, "run", "floodmesh:slope", "--json", "--",
                          f"INPUT={real_data / 'merewether_topography1.asc'}", f"OUTPUT={out}"],
                         env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert json.loads(run.stdout[run.stdout.index("{"):])["results"]["OUTPUT"] == str(out)
    assert QgsRasterLayer(str(out), "slope").isValid()
    return run
