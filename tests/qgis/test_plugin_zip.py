"""The installable plugin zip: built from the tracked files, unpacked into a fresh QGIS profile
(as the plugin manager does), enabled, and run headless from there."""
import configparser
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
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


def test_zip_install_says_how_to_make_anugas_environment_then_floods(tmp_path):
    """After Install from ZIP the plugin has no Makefile and the worker's Python no ANUGA:
    Flood on mesh says, in one line, the command that makes ANUGA's environment beside the
    profile (not `make setup`); once that environment is there, the flood runs."""
    exe, env, profile = _install(tmp_path, FLOODMESH_PYTHON=str(REPO / ".venv" / "bin" / "python"))
    env.pop("FLOODMESH_FLOOD_PYTHON", None)
    from floodmesh.core import io

    x0, y0 = 382_000.0, 6_354_000.0  # a 40 x 12 m slope of 4 m squares, halved
    x, y = np.meshgrid(np.arange(0, 41, 4.0), np.arange(0, 13, 4.0))
    corner, width = np.arange(x.size).reshape(x.shape)[:-1, :-1].ravel(), x.shape[1]
    io.write_mesh_2dm(tmp_path / "m.2dm",
                      np.column_stack([x.ravel() + x0, y.ravel() + y0, 0.02 * (40 - x.ravel())]),
                      np.vstack([np.column_stack([corner, corner + 1, corner + width + 1]),
                                 np.column_stack([corner, corner + width + 1, corner + width])]))
    (tmp_path / "scenario.json").write_text(json.dumps({
        "duration_s": 20, "output_interval_s": 10, "manning": 0.03,
        "inflows": [{"line": [[x0 + 2, y0 + 1], [x0 + 2, y0 + 11]], "discharge_m3s": 1.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}]}))

    def flood(out):
        return subprocess.run([exe, "run", "floodmesh:floodonmesh", "--json", "--",
                               f"MESH={tmp_path / 'm.2dm'}", "CRS=EPSG:32756",
                               f"SCENARIO={tmp_path / 'scenario.json'}",
                               f"OUTPUT_FOLDER={tmp_path / out}"],
                              env=env, capture_output=True, text=True, timeout=600)

    refused = flood("none")
    said = refused.stdout + refused.stderr
    own = profile / "floodmesh" / "venv-flood"
    assert refused.returncode != 0
    assert f"/usr/bin/python3 -m venv {own} && {own}/bin/pip install anuga==4.2.0" in said, said
    assert "make setup" not in said and "Traceback" not in said
    assert not (tmp_path / "none").exists() or not any((tmp_path / "none").iterdir())

    from floodmesh.core.flood.model import flood_python

    anuga = flood_python()
    if anuga is None:
        pytest.skip("ANUGA is not installed here (make setup): its environment's place is "
                    "checked, not a flood in it")
    own.parent.mkdir(parents=True, exist_ok=True)
    own.symlink_to(Path(anuga).parent.parent, target_is_directory=True)
    run = flood("flood")
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    results = json.loads(run.stdout[run.stdout.index("{"):])["results"]
    assert QgsRasterLayer(results["MAX_DEPTH"], "depth").isValid()


def _install_and_run(tmp_path, real_data, **worker_env):
    exe, env, _ = _install(tmp_path, **worker_env)
    out = tmp_path / "slope.tif"
    run = subprocess.run([exe, "run", "floodmesh:slope", "--json", "--",
                          f"INPUT={real_data / 'merewether_topography1.asc'}", f"OUTPUT={out}"],
                         env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert json.loads(run.stdout[run.stdout.index("{"):])["results"]["OUTPUT"] == str(out)
    assert QgsRasterLayer(str(out), "slope").isValid()
    return run


def _install(tmp_path, **worker_env):
    """(qgis_process, its environment, the profile's folder) after the plugin ZIP is built,
    unpacked into a fresh profile as the plugin manager does and enabled."""
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
    return exe, env, plugins.parent.parent
