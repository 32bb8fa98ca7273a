"""FloodMesh core: LiDAR points to break lines, quality meshes and their error, without QGIS.

The library, one function per step of the method, each taking what the one before returns::

    from floodmesh import core

    points = core.read_points("reach.laz")                  # PointCloud (ground class)
    dem = core.grid_points(points, 1.0)                     # Grid, linear (TIN), d = 1 m
    slope = core.terrain_slope(dem, "one-over-distance")    # Grid, degrees
    breakpoints = core.classify_breakpoints(slope, 10.0)    # Grid, S_crit = 10°
    lines = core.trace_breaklines(breakpoints, slope, dem, 10.0)          # [BreakLine]
    lines = core.simplify_breaklines(lines, "keep-every", 4)              # [BreakLine]
    mesh = core.build_mesh(dem, lines, min_angle=25, max_area=100)        # Mesh
    residuals, stats = core.assess(mesh, held_out.xyz)      # m; RMSE, NSSDA, classes

or the whole chain with the command line's defaults: ``core.run_pipeline(path, out,
core.RunOptions())``. Names are imported on first use, so ``import floodmesh.core`` stays
light (no numba, rasterio or Triangle until a step needs them).
"""

import importlib as _importlib
import os as _os
import tempfile as _tempfile

# public name → the module that defines it (or (module, its name there)); never a submodule's
# name, which the import system sets on the package once that submodule is imported
_API = {
    "read_points": "io", "read_raster": "io", "read_input": "io", "write_raster": "io",
    "write_breaklines": "io", "write_mesh_2dm": "io", "open_source": "chain.source",
    "Source": "chain.source",
    "grid_points": ("steps.grid", "grid_points_linear"), "terrain_slope": ("steps.slope", "slope"),
    "laplacian_of_gaussian": "steps.slope", "classify_breakpoints": "steps.breakpoints",
    "log_breakpoints": "steps.breakpoints", "trace_breaklines": "steps.breaklines",
    "simplify_breaklines": "steps.simplify", "localise_traced": "steps.localise",
    "build_mesh": "steps.mesh", "assess": "steps.accuracy", "refine_mesh": "steps.refine",
    "export_mesh": "steps.export", "run_pipeline": "chain.pipeline",
    "run_series": "chain.series", "RunOptions": "options", "Grid": "raster",
    "PointCloud": "points", "BreakLine": "steps.breaklines", "Mesh": "steps.mesh",
    "FloodMeshError": "errors", "Cancelled": "errors",
}
__all__ = sorted(_API)


def __getattr__(name):
    if name not in _API:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module, attribute = (_API[name] if isinstance(_API[name], tuple) else (_API[name], name))
    value = getattr(_importlib.import_module(f"{__name__}.{module}"), attribute)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


def _numba_cache() -> None:
    """Numba caches compiled kernels beside their source or in the user's cache folder; where
    neither can be written (a read-only install and home) every ``cache=True`` kernel would
    fail with 'no locator available'. Point it at a writable folder before numba is imported,
    or else turn caching off (kernels are then compiled afresh in each process)."""
    def writable(folder) -> bool:
        try:
            _os.makedirs(folder, exist_ok=True)
            with _tempfile.TemporaryFile(dir=folder):
                return True
        except OSError:
            return False

    if _os.environ.get("NUMBA_CACHE_DIR") or writable(_os.path.join(
            _os.path.dirname(__file__), "__pycache__")):
        return
    home_cache = _os.environ.get("XDG_CACHE_HOME") or _os.path.expanduser("~/.cache")
    try:
        temporary = _os.path.join(_tempfile.gettempdir(), f"floodmesh-numba-{_os.getuid()}")
    except FileNotFoundError:  # no usable temporary folder
        temporary = None
    for folder in (_os.path.join(home_cache, "floodmesh", "numba"), temporary):
        if folder is None:
            continue
        if writable(folder):
            _os.environ["NUMBA_CACHE_DIR"] = folder
            return
    # lazy: numba loads only when this runs
    import numba.core.dispatcher

    numba.core.dispatcher.Dispatcher.enable_caching = lambda self: None


_numba_cache()
