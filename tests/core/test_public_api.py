"""The library's public API, ``floodmesh.core``: every name in ``__all__`` resolves, the steps
chain (what one returns, the next takes), and importing the package loads none of the heavy
dependencies until a step is used."""
import subprocess
import sys

import numpy as np

from floodmesh import core

STEPS = ("grid_points", "terrain_slope", "classify_breakpoints", "trace_breaklines",
         "simplify_breaklines", "build_mesh", "assess", "refine_mesh", "export_mesh",
         "run_pipeline")


def test_every_public_name_resolves_to_no_submodule():
    import importlib
    import pkgutil

    assert set(STEPS) <= set(core.__all__)
    submodules = {m.name for m in pkgutil.iter_modules(core.__path__)}
    assert not set(core.__all__) & submodules
    for name in submodules:
        importlib.import_module(f"floodmesh.core.{name}")
    for name in core.__all__:
        assert not isinstance(getattr(core, name), type(core)), name


def test_importing_the_package_is_light():
    code = ("import sys, floodmesh.core; "
            "print(sorted(m for m in ('numba', 'rasterio', 'triangle', 'shapely', 'laspy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_the_steps_chain_from_points_to_assessment():
    from floodmesh.core.frontends.demo import synthetic_floodplain

    points, _ = synthetic_floodplain(density=1.0, seed=3)
    held = core.PointCloud(points.xyz[::200], points.crs)
    dem = core.grid_points(points, 2.0)
    slope = core.terrain_slope(dem, "one-over-distance")
    breakpoints = core.classify_breakpoints(slope, 10.0)
    lines = core.trace_breaklines(breakpoints, slope, dem, 10.0)
    lines = core.simplify_breaklines(lines, "keep-every", 4)
    assert lines and isinstance(lines[0], core.BreakLine)
    mesh = core.build_mesh(dem, lines, min_angle=25, max_area=400)
    assert isinstance(mesh, core.Mesh) and len(mesh.triangles) > 100
    residuals, stats = core.assess(mesh, held.xyz)
    assert residuals.shape == (len(held),) and np.isfinite(stats["rmse_m"])
