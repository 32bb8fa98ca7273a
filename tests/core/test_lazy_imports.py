"""Imports inside functions only where they keep a heavy or optional package out of a module's
start, each saying why: a ``# lazy:`` comment above its run of imports, or an optional
dependency tried under ``except ImportError``. What the laziness buys is checked too: the
command line starts without numba, GDAL, PROJ or GEOS, and the modules QGIS's own Python
imports (options, errors, the flood summary) need nothing beyond the standard library."""
import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[2] / "core"
HEAVY = ("numba", "scipy", "pyproj", "shapely", "rasterio", "laspy", "fiona", "matplotlib",
         "dask", "distributed", "triangle")


def unexplained_imports(source: str) -> list:
    """Line numbers of function-level imports with neither a ``# lazy:`` comment above their
    run of imports nor an ``except ImportError`` around them."""
    tree = ast.parse(source)
    lines = source.split("\n")
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Import, ast.ImportFrom)):
            continue
        owner, optional = parents.get(node), False
        while owner is not None and not isinstance(owner, (ast.FunctionDef,
                                                           ast.AsyncFunctionDef)):
            if isinstance(owner, ast.Try) and any(
                    isinstance(h.type, ast.Name) and h.type.id in ("ImportError",
                                                                    "ModuleNotFoundError")
                    for h in owner.handlers):
                optional = True
            owner = parents.get(owner)
        if owner is None or optional:
            continue
        first = node  # the first of the run of imports this one belongs to
        siblings = next(block for field in ("body", "orelse", "finalbody")
                        if node in (block := getattr(parents[node], field, None) or []))
        for earlier in reversed(siblings[:siblings.index(node)]):
            if not isinstance(earlier, (ast.Import, ast.ImportFrom)):
                break
            first = earlier
        if not lines[first.lineno - 2].lstrip().startswith("# lazy:"):
            found.append(node.lineno)
    return found


def test_the_rule_sees_an_unexplained_import():
    source = ("def f():\n    import shapely\n\n    return shapely\n\n\n"
              "def g():\n    # lazy: GEOS loads only when this runs\n    import shapely\n"
              "    from shapely import box\n\n    return box\n\n\n"
              "def h():\n    try:\n        import anuga\n    except ImportError:\n"
              "        anuga = None\n    return anuga\n")
    assert unexplained_imports(source) == [2]


def test_every_import_inside_a_function_says_why():
    found = {str(path.relative_to(CORE)): lines for path in sorted(CORE.rglob("*.py"))
             if (lines := unexplained_imports(path.read_text(encoding="utf-8")))}
    assert not found, f"imports inside functions without a '# lazy:' reason: {found}"


def loaded_after(module: str) -> set:
    """Top-level packages in sys.modules after importing ``module`` in a fresh Python."""
    code = (f"import sys, json; import {module}; "
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    return set(json.loads(result.stdout))


def test_the_command_line_starts_without_the_heavy_packages():
    loaded = loaded_after("floodmesh.core.frontends.cli")
    assert not loaded & set(HEAVY), sorted(loaded & set(HEAVY))


@pytest.mark.parametrize("module", ["floodmesh.core.options", "floodmesh.core.errors",
                                    "floodmesh.core.flood.summary"])
def test_what_qgis_imports_needs_only_the_standard_library(module):
    # what the interpreter loads by itself (site's .pth hooks) is not the module's doing
    outside = (loaded_after(module) - loaded_after("sys") - set(sys.stdlib_module_names)
               - {"floodmesh"})
    assert not outside, sorted(outside)
