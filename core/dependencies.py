"""Which of the Python packages FloodMesh needs are missing, and how to install them.

QGIS ships numpy and often GDAL's Python bindings, but not Triangle, laspy or numba; the QGIS
plugin loads without them and its algorithms say what to install.
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
    """One message naming the missing packages and the command that installs them."""
    quoted = " ".join(f'"{r}"' if "[" in r or ">" in r else r for r in missing)
    return (f"FloodMesh needs Python packages that this QGIS does not have: {', '.join(missing)}. "
            f"Install them into the Python that QGIS runs (keeping its numpy), e.g. "
            f"`python3 -m pip install --user {quoted}` (on Debian/Ubuntu add "
            f"--break-system-packages, or use the project's `make setup` and put "
            f".venv/lib/python3.*/site-packages on PYTHONPATH), then restart QGIS.")
