"""Compile FloodMesh's numba kernels ahead of the first real run.

numba compiles each kernel on its first call (about 2 minutes for all of them on a 2-core
machine) and caches the machine code: in ``__pycache__`` beside the source when that folder is
writable (a QGIS profile's plugin folder, a git checkout), else in the user's cache folder
(``~/.cache/numba``-style, per user), or in ``NUMBA_CACHE_DIR`` when set. ``make setup``
runs ``python -m floodmesh.core.frontends.warmup``, which fills the cache on a tiny input. A run
that must compile (a fresh plugin install, another user) says so when numba really starts
compiling, not when it merely loads a kernel from the cache, and ends with the time it took
(``compiles.CompileWatch``).
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from .. import io
from .._kernels.aot import build
from ..engine.compiles import CompileWatch
from ..options import RunOptions
from ..steps.breakpoints import breakpoints_file
from ..steps.slope import slope_file


def compile_kernels(log=print) -> float:
    """Run the whole chain on a tiny synthetic floodplain (and the file-to-file raster steps),
    which compiles every kernel or loads it from the cache, saying so through ``log`` when
    numba really compiles (``compiles.CompileWatch``). Returns the seconds taken."""
    # lazy: GEOS, numba and PROJ load only when this runs
    from .demo import synthetic_floodplain
    from ..chain.pipeline import run_pipeline

    start, watch = time.perf_counter(), CompileWatch(log)
    points, _ = synthetic_floodplain(density=0.5, vegetation=0.0)
    with tempfile.TemporaryDirectory() as tmp, watch.watching():
        tmp = Path(tmp)
        io.write_points_las(tmp / "points.laz", points)
        run_pipeline(tmp / "points.laz", tmp / "out", RunOptions(cell_size=2.0, max_area=400.0))
        slope_file(tmp / "out" / "dem.tif", tmp / "slope.tif")
        breakpoints_file(tmp / "slope.tif", tmp / "bp.tif", s_crit=10.0)
    if watch.summary() and log:
        log(watch.summary())
    return time.perf_counter() - start


def main() -> int:
    seconds = compile_kernels(log=lambda message: print(f"floodmesh: {message}",
                                                        file=sys.stderr))
    print(f"floodmesh: kernels ready ({seconds:.0f} s)", file=sys.stderr)
    # after the numba kernels (which serve where the build cannot): the streaming raster
    # kernels ahead of time, so that `floodmesh slope` starts without numba

    start = time.perf_counter()
    if build(log=lambda message: print(f"floodmesh: {message}", file=sys.stderr)):
        print(f"floodmesh: raster kernels built ahead of time ({time.perf_counter() - start:.0f} s)",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
