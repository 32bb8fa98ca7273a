"""Which of the Python packages FloodMesh needs are missing, and how to install them.

QGIS ships numpy and often GDAL's Python bindings, but not Triangle, laspy or numba. The QGIS
plugin never imports them: its worker (``core.frontends.worker``) checks them and says what to
install.
"""
from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

REQUIREMENTS = Path(__file__).parents[1] / "requirements.txt"  # the one list (pyproject reads it)
# modules a requirement's extras bring, beside its own
EXTRA_MODULES = {"laspy[lazrs]": ("lazrs",)}


def requirements() -> list[str]:
    """FloodMesh's pip requirements (``requirements.txt``)."""
    lines = REQUIREMENTS.read_text(encoding="utf-8").splitlines()
    return [line.split("#")[0].strip() for line in lines if line.split("#")[0].strip()]


def required_modules() -> dict:
    """Module → the requirement that installs it."""
    modules = {}
    for requirement in requirements():
        name = re.split(r"[\[<>=!~; ]", requirement, maxsplit=1)[0]
        for module in (name, *EXTRA_MODULES.get(requirement, ())):
            modules[module] = requirement
    return modules


def missing_dependencies() -> list[str]:
    """pip requirements of the packages that do not import (shapely 1.x counts as missing)."""
    missing = []
    for module, requirement in required_modules().items():
        try:
            imported = importlib.import_module(module)
        except Exception:
            missing.append(requirement)
            continue
        if module == "shapely" and not str(getattr(imported, "__version__", "2")).startswith("2"):
            missing.append(requirement)
    return sorted(set(missing))


def install_hint(missing: list[str]) -> str:
    """One message naming the missing packages and the command that installs them into this
    Python (the worker's: QGIS itself never imports them), numpy kept at its version."""
    quoted = " ".join(f'"{r}"' if "[" in r or ">" in r else r for r in missing)
    try:
        import numpy
        pin = f" numpy=={numpy.__version__}"
    except ImportError:
        pin = ""
    return (f"FloodMesh's Python ({sys.executable}) lacks {', '.join(missing)}: install them "
            f"there with `{sys.executable} -m pip install {quoted}{pin}`"
            + ("" if sys.prefix != sys.base_prefix else
               " (in a virtual environment: Debian's own Python refuses pip; with "
               "FLOODMESH_PYTHON unset the plugin sets one up itself)")
            + f", or set "
            f"FLOODMESH_PYTHON to a Python that has them (a checkout's .venv after `make "
            f"setup`; see docs/qgis.md, Which Python the worker uses), then run again.")
