"""Which of the Python packages FloodMesh needs are missing, and how to install them.

QGIS ships numpy and often GDAL's Python bindings, but not Triangle, laspy or numba. The QGIS
plugin never imports them: its worker (``core.worker``) checks them and says what to install.
"""
from __future__ import annotations

import importlib

# module → what pip installs it as
REQUIRED = {
    "numpy": "numpy", "scipy": "scipy", "shapely": "shapely>=2", "rasterio": "rasterio",
    "fiona": "fiona", "pyproj": "pyproj", "matplotlib": "matplotlib", "triangle": "triangle",
    "laspy": "laspy[lazrs]", "lazrs": "laspy[lazrs]", "numba": "numba",
}


def missing_dependencies() -> list[str]:
    """pip requirements of the packages that do not import (shapely 1.x counts as missing)."""
    missing = []
    for module, requirement in REQUIRED.items():
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
    import sys

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
