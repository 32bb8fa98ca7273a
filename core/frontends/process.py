"""How FloodMesh's command-line and worker processes allocate their memory and end."""
from __future__ import annotations

import atexit
import os
import sys

# glibc's mallopt parameters, and the values a run keeps its freed memory under
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
HEAP_BLOCK_LIMIT = 64 << 20  # bytes: larger arrays still get pages of their own
HEAP_KEPT = 512 << 20  # bytes of freed memory the heap keeps for the next arrays


def keep_freed_memory() -> bool:
    """Have glibc's malloc serve arrays of up to 64 MiB from its heap and keep up to 512 MiB
    freed there for the next ones; returns whether it could (False off glibc).

    By default a block of over 128 KiB (its bound moving up to 32 MiB) has pages of its own,
    handed back to the kernel when freed, and the next array of that size faults them in
    again: the gridding's tiles alone made 160,000-270,000 such faults on 9 M points. Kept,
    a whole run spent 1.27 s of system time instead of 1.53 and 0.96x the wall time (five
    alternating pairs), at 100 MB more peak memory. For a process of FloodMesh's own (the
    command line, the QGIS worker), never a library's host."""
    # lazy: ctypes loads only in a front end's process
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):  # not glibc (macOS, Windows, musl's stub)
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, HEAP_BLOCK_LIMIT)
                and mallopt(M_TRIM_THRESHOLD, HEAP_KEPT))


def end_process(code: int) -> None:
    """End the process with ``code`` as soon as its work is on disk: the exit handlers run
    (temporary folders, Dask's and multiprocessing's children, logging) and the streams are
    flushed, as in a normal exit, but the interpreter's teardown of every module is skipped.
    After a run that teardown (collecting and freeing the objects of numba, GEOS, matplotlib and
    the arrays) took 0.5-1.2 s that the user waited for with the results already written."""
    atexit._run_exitfuncs()  # CPython's own first step of a normal exit
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (BrokenPipeError, ValueError):  # a closed stream: nothing more can reach it
            code = code or 1
    os._exit(code)
