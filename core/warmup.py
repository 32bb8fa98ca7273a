"""Compile FloodMesh's numba kernels ahead of the first real run, and say so when a run must.

numba compiles each kernel on its first call (about 2 minutes for all of them on a 2-core
machine) and caches the machine code: in ``__pycache__`` beside the source when that folder is
writable (a QGIS profile's plugin folder, a git checkout), else in the user's cache folder
(``~/.cache/numba``-style, per user), or in ``NUMBA_CACHE_DIR`` when set. ``make setup`` runs
``python -m floodmesh.core.warmup``, which fills the cache on a tiny input. A run that must
compile (a fresh plugin install, another user) says so when numba really starts compiling, not
when it merely loads a kernel from the cache, and ends with the time it took
(``compiles.CompileWatch``).
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from .compiles import COMPILE_NOTE


# Kernels called from Python (the others compile into them and keep no cache of their own).
ENTRY_KERNELS = (("grid", "_bucket_sort"), ("grid", "_rasterise_tin"), ("delaunay", "_sweep"),
                 ("raster_kernels", "_slope_block"), ("raster_kernels", "_missing_to_nan"),
                 ("raster_kernels", "_nan_to_value"), ("breaklines", "_trace"),
                 ("breaklines", "_join_fragments"), ("nearest", "_cell_sort"),
                 ("nearest", "_ball_csr"), ("point_kernels", "spread"),
                 ("point_kernels", "position_keys"))


def _dispatchers():
    """The cached numba entry kernels of ``core``."""
    import importlib

    for module, name in ENTRY_KERNELS:
        value = getattr(importlib.import_module(f"{__package__}.{module}"), name)
        cache = getattr(value, "_cache", None)
        if cache is not None and type(cache).__name__ == "FunctionCache":
            yield value


def cache_folder() -> str:
    """Where numba keeps FloodMesh's compiled kernels."""
    for dispatcher in _dispatchers():
        return str(dispatcher._cache._cache_path)
    return "numba's cache"


def kernels_cached() -> bool:
    """True when every kernel has machine code in numba's cache (numba's own index files)."""
    try:
        return all(Path(d._cache._cache_file._index_path).exists() for d in _dispatchers())
    except AttributeError:  # another numba's internals: do not claim a compile that may not come
        return True


def compile_note() -> str | None:
    """The message to show before a run that will compile, or None when the cache is full."""
    return None if kernels_cached() else COMPILE_NOTE.format(where=cache_folder())


def compile_kernels(log=print) -> float:
    """Run the whole chain on a tiny synthetic floodplain (and the file-to-file raster steps),
    which compiles every kernel or loads it from the cache. Returns the seconds taken."""
    from . import io
    from .breakpoints import breakpoints_file
    from .demo import synthetic_floodplain
    from .options import RunOptions
    from .pipeline import run_pipeline
    from .slope import slope_file

    start = time.perf_counter()
    note = compile_note()
    if note and log:
        log(note)
    points, _ = synthetic_floodplain(density=0.5, vegetation=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        io.write_points_las(tmp / "points.laz", points)
        run_pipeline(tmp / "points.laz", tmp / "out", RunOptions(cell_size=2.0, max_area=400.0))
        slope_file(tmp / "out" / "dem.tif", tmp / "slope.tif")
        breakpoints_file(tmp / "slope.tif", tmp / "bp.tif", s_crit=10.0)
    return time.perf_counter() - start


def main() -> int:
    seconds = compile_kernels(log=lambda message: print(f"floodmesh: {message}",
                                                        file=sys.stderr))
    print(f"floodmesh: kernels ready in {cache_folder()} ({seconds:.0f} s)", file=sys.stderr)
    # after the numba kernels (which serve where the build cannot): the streaming raster
    # kernels ahead of time, so that `floodmesh slope` starts without numba
    from .compiled import build

    start = time.perf_counter()
    if build(log=lambda message: print(f"floodmesh: {message}", file=sys.stderr)):
        print(f"floodmesh: raster kernels built ahead of time ({time.perf_counter() - start:.0f} s)",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
