"""numba's first-run compile as the user sees it: said when numba really compiles, with the time
it took, never when the kernels only load from the cache; a bad input is answered by its error
alone, whatever the state of the cache (the compile note came first, before validation)."""
import os
import subprocess
import sys

import numba

from floodmesh.core.compiles import CompileWatch, is_compile_message


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
    run = subprocess.run([sys.executable, "-m", "floodmesh.core.cli", "run",
                          str(tmp_path / "missing.laz"), "--out", str(tmp_path / "out")],
                         env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode != 0
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "missing.laz" in lines[0], run.stderr
    assert "compil" not in run.stderr and not (tmp_path / "out").exists()
