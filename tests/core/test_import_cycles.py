"""No import cycles in the package, counting every import: at module level and inside functions
(a cycle through a function-level import still ties two modules into one). Read from the
source with ast, so that it sees imports that a run never reaches."""
import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("core", "algorithms", "provider")


def modules() -> dict:
    """Module name (``core.io``; ``core`` for its __init__) → source file."""
    found = {}
    for package in PACKAGES:
        for path in (REPO / package).rglob("*.py"):
            parts = path.relative_to(REPO).with_suffix("").parts
            found[".".join(parts[:-1] if path.stem == "__init__" else parts)] = path
    return found


def imported(module: str, path: Path, known: dict) -> set:
    """The package's modules that ``module`` imports anywhere in its source."""
    package = module if path.stem == "__init__" else module.rsplit(".", 1)[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + (
                    [node.module] if node.module else []))
            elif (node.module or "").startswith("floodmesh."):
                base = node.module[len("floodmesh."):]
            else:
                continue
            targets.add(base)
            targets.update(f"{base}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            targets.update(a.name[len("floodmesh."):] for a in node.names
                           if a.name.startswith("floodmesh."))
    return {t for t in targets if t in known and t != module}


def cycles(graph: dict) -> list:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_counting_imports_inside_functions():
    known = modules()
    assert "core.chain.pipeline" in known and "algorithms.base" in known
    assert "core.io" in known and "core.steps.mesh" in known
    graph = {m: imported(m, p, known) for m, p in known.items()}
    assert "core.steps.grid" in graph["core.engine.tiles"]  # function-level imports are seen
    assert cycles(graph) == []


def private_names_taken(module: str, path: Path, known: dict) -> list:
    """``_name``s that ``module`` takes from another of the package's modules: imported by name,
    or read as an attribute of a module it imported."""
    package = module if path.stem == "__init__" else module.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    taken, aliases = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            parts = package.split(".")
            base = ".".join(parts[:len(parts) - node.level + 1] + (
                [node.module] if node.module else []))
            for alias in node.names:
                if f"{base}.{alias.name}" in known:
                    aliases.add(alias.asname or alias.name)
                elif alias.name.startswith("_") and not alias.name.startswith("__"):
                    taken.append(f"{base}.{alias.name}")
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and node.attr.startswith("_")
                and not node.attr.startswith("__")):
            taken.append(f"{node.value.id}.{node.attr}")
    return taken


def test_the_private_name_finder_finds_one(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("from .raster import _slope\nfrom . import io\nio._write(1)\n")
    known = {"core.m": path, "core.raster": path, "core.io": path}
    assert private_names_taken("core.m", path, known) == ["core.raster._slope", "io._write"]


def test_no_private_name_crosses_a_module():
    known = modules()
    taken = {m: found for m, p in known.items() if (found := private_names_taken(m, p, known))}
    assert not taken, taken
