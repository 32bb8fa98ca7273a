"""The core runs without QGIS: every module of floodmesh.core imports with qgis, PyQt5 and
processing blocked (``sys.modules[name] = None`` makes any import of them fail)."""
import pkgutil
import subprocess
import sys

import floodmesh.core

BLOCK = ("import sys, importlib\n"
         "sys.modules['qgis'] = None\n"
         "sys.modules['PyQt5'] = None\n"
         "sys.modules['processing'] = None\n")


def core_modules():
    return sorted(m.name for m in pkgutil.walk_packages(floodmesh.core.__path__,
                                                         "floodmesh.core."))


def run_blocked(extra=""):
    code = BLOCK + extra + "".join(f"importlib.import_module({m!r})\n" for m in core_modules())
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)


def test_discovers_the_core_modules():
    names = set(core_modules())
    for step in ("io", "steps.grid", "steps.slope", "steps.breakpoints", "steps.breaklines",
                 "steps.mesh", "steps.accuracy", "chain.pipeline", "frontends.cli",
                 "_kernels.raster", "engine.tiles", "flood.model"):
        assert f"floodmesh.core.{step}" in names


def test_every_core_module_imports_without_qgis():
    result = run_blocked()
    assert result.returncode == 0, result.stderr


def test_a_qgis_import_would_be_caught():
    """Control: the same subprocess with an import of qgis.core fails."""
    result = run_blocked("import qgis.core\n")
    assert result.returncode != 0
    assert "ModuleNotFoundError" in result.stderr and "qgis" in result.stderr
