"""numba's first-run compile as the user sees it: said when numba really compiles, with the time
it took, never when the kernels only load from the cache; a bad input is answered by its error
alone, whatever the state of the cache (the compile note came first, before validation)."""
import os
import subprocess
import sys

import numba

from floodmesh.core.engine.compiles import CompileWatch, is_compile_message


def test_a_real_compile_is_said_once_with_its_duration(tmp_path):
    said = []
    watch = CompileWatch(said.append)

    @numba.njit
    def inner(x):
        return x + 1

    @numba.njit
    def kernel(x):  # compiles inner inside it: one compile as the user sees it
        return inner(x) * 2

    with watch.watching():
        assert kernel(1) == 4
    with watch.watching():
        assert kernel(2) == 6  # compiled already: nothing more to say
        assert kernel(2.5) == 7.0  # a new signature compiles again, said no second time
    assert len(said) == 1 and said[0].startswith("compiling FloodMesh's numba kernels")
    assert watch.seconds > 0
    summary = watch.summary()
    assert summary.startswith("compiled FloodMesh's numba kernels in ")
    assert is_compile_message(said[0]) and is_compile_message(summary)


def test_nothing_compiled_nothing_said():
    said = []
    watch = CompileWatch(said.append)
    with watch.watching():
        sum(range(10))
    assert said == [] and watch.summary() is None


def test_bad_input_with_an_empty_cache_is_answered_by_the_error_alone(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "empty-cache"))
    run = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run",
                          str(tmp_path / "missing.laz"), "--out", str(tmp_path / "out")],
                         env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode != 0
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "missing.laz" in lines[0], run.stderr
    assert "compil" not in run.stderr and not (tmp_path / "out").exists()


def test_a_worker_step_on_a_warm_cache_says_nothing_of_compiling(tmp_path):
    """QGIS's worker said 'First run ... numba compiles' on every run where numba's cache was
    not core/__pycache__ (a plugin installed from its ZIP): it now says only what happens."""
    import io as stdio
    import json

    import numpy as np
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core import io
    from floodmesh.core.raster import Grid
    from floodmesh.core.frontends.worker import Channel, run_job

    dem = Grid(np.add.outer(np.arange(40.0), np.arange(50.0)) * 0.2,
               Affine(1.0, 0, 500000.0, 0, -1.0, 6000040.0), CRS.from_epsg(25832))
    io.write_raster(tmp_path / "dem.tif", dem)
    job = {"step": "slope", "args": {"input": str(tmp_path / "dem.tif"),
                                     "output": str(tmp_path / "slope.tif"),
                                     "method": "one-over-distance"}}
    for _ in range(2):  # the first may compile where the cache is cold; the second never
        stream = stdio.StringIO()
        assert run_job(job, Channel(stream)) == 0
    messages = [json.loads(line) for line in stream.getvalue().splitlines()]
    assert "result" in messages[-1]
    assert not [m for m in messages if "compil" in json.dumps(m).lower()], messages
