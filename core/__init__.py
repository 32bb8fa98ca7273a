"""FloodMesh core: LiDAR points to break lines, quality meshes and their error, without QGIS.

The pipeline, one module per step: ``io`` (reading points and rasters, writing outputs) →
``grid`` → ``slope`` → ``breakpoints`` → ``breaklines`` → ``simplify`` → ``mesh`` →
``accuracy``; ``pipeline`` chains them and ``cli`` is the command line.
"""

import os as _os


def _numba_cache() -> None:
    """Numba caches compiled kernels beside their source or in the user's cache folder; where
    neither can be written (a read-only install and home) every ``cache=True`` kernel would
    fail with 'no locator available'. Point it at a writable folder before numba is imported,
    or else turn caching off (kernels are then compiled afresh in each process)."""
    import tempfile

    def writable(folder) -> bool:
        try:
            _os.makedirs(folder, exist_ok=True)
            with tempfile.TemporaryFile(dir=folder):
                return True
        except OSError:
            return False

    if _os.environ.get("NUMBA_CACHE_DIR") or writable(_os.path.join(
            _os.path.dirname(__file__), "__pycache__")):
        return
    home_cache = _os.environ.get("XDG_CACHE_HOME") or _os.path.expanduser("~/.cache")
    try:
        temporary = _os.path.join(tempfile.gettempdir(), f"floodmesh-numba-{_os.getuid()}")
    except FileNotFoundError:  # no usable temporary folder
        temporary = None
    for folder in (_os.path.join(home_cache, "floodmesh", "numba"), temporary):
        if folder is None:
            continue
        if writable(folder):
            _os.environ["NUMBA_CACHE_DIR"] = folder
            return
    import numba.core.dispatcher

    numba.core.dispatcher.Dispatcher.enable_caching = lambda self: None


_numba_cache()
