"""Nothing lost: a run interrupted at random points (Ctrl-C at random moments, QGIS-style
Cancel after a random number of polls, the process killed outright) leaves the output folder
as a whole either as it was before the run or complete, never a mix of the two runs and never
a truncated file; what a killed run leaves beside it is removed by the next run; and the same
inputs and seed give byte-identical outputs, so 'complete' can be checked byte for byte."""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.errors import Cancelled
from floodmesh.core.chain.pipeline import OUTPUT_FILES, RunOptions, run_pipeline
from floodmesh.core.points import PointCloud

from ..conftest import child_processes, plane_points

FLOODMESH = str(Path(sys.executable).parent / "floodmesh")
BEFORE = RunOptions(holdout=0.05, cell_size=2.0, max_area=80.0)  # the previous run's outputs
AFTER = RunOptions(holdout=0.05, cell_size=1.0, max_area=30.0)   # the interrupted run's
RNG = np.random.default_rng(20261123)


def _contents(folder: Path) -> dict:
    """Every file in the folder: name → bytes (report.json without its timings, report.html
    without its lines of the clock, the run's date and duration, run.qlr without its group's
    name, the folder's)."""
    out = {}
    for path in sorted(folder.iterdir()):
        data = path.read_bytes()
        if path.name == "report.html":
            data = re.sub(rb'(?m)^.*class="[^"]*\brun-time\b[^"]*".*\n', b"", data)
        if path.name == "run.qlr":
            data = re.sub(rb'(<layer-tree-group name=")[^"]+"', rb'\1RUN"', data)
        if path.name == "report.json":
            report = json.loads(data)
            report.pop("seconds")
            report.pop("cpu_seconds")
            report.pop("input")
            data = json.dumps(report, sort_keys=True).encode()
        out[path.name] = data
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The input (a 60 m plane with a bank, 3 points/m²) and the complete outputs of the
    previous and of the new options."""
    root = tmp_path_factory.mktemp("interrupt")
    xyz = plane_points(size=60.0, density=3.0, seed=4)
    xyz[:, 2] += np.where(xyz[:, 0] - xyz[:, 0].min() > 30, 2.0, 0.0)  # a 2 m bank
    source = root / "points.laz"
    io.write_points_las(source, PointCloud(xyz, CRS.from_epsg(25832)))
    done = {}
    for name, options in (("before", BEFORE), ("after", AFTER)):
        run_pipeline(source, root / name, options)
        done[name] = _contents(root / name)
    assert set(done["before"]) == set(done["after"]) == set(OUTPUT_FILES)
    # every file differs but the CRS sidecar (the same CRS)
    assert all(done["before"][n] != done["after"][n] for n in OUTPUT_FILES if n != "mesh.prj")
    return source, root, done


def _start_from_previous(root, target):
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(root / "before", target)


def _assert_each_file_old_or_new(target, done):
    """Each output is the previous run's or the new run's, byte for byte; no temporary file is
    left (``allow_partial``: a killed process cannot remove its temporary files, which are
    hidden names beside the outputs and never replace one)."""
    now = _contents(target)
    assert set(now) == set(OUTPUT_FILES), sorted(set(now) ^ set(OUTPUT_FILES))
    states = {}
    for name in OUTPUT_FILES:
        if done["before"][name] == done["after"][name]:  # the CRS sidecar: either run's
            assert now[name] == done["after"][name], f"{name} is neither old nor new"
            continue
        if now[name] == done["before"][name]:
            states[name] = "old"
        else:
            assert now[name] == done["after"][name], f"{name} is neither old nor new"
            states[name] = "new"
    assert len(set(states.values())) == 1, f"the folder mixes two runs: {states}"
    return states


def _leftovers(folder: Path) -> list:
    """Hidden temporaries of FloodMesh in ``folder`` and beside it."""
    inside = [p.name for p in folder.iterdir() if ".partial" in p.name or ".floodmesh-" in p.name]
    beside = [p.name for p in folder.parent.iterdir() if p.name.startswith(f".{folder.name}.")]
    return inside + beside


def test_same_inputs_and_seed_give_byte_identical_outputs(runs, tmp_path):
    """Every output file, GeoPackages and GeoTIFFs included, and every figure of the report but
    the timings, are the same bytes on a second run."""
    source, _, done = runs
    run_pipeline(source, tmp_path / "again", AFTER)
    assert _contents(tmp_path / "again") == done["after"]


# An interrupt inside a GeoPackage write makes fiona's session complain, as it is collected,
# that its (already removed) temporary file is gone: harmless, and not ours to silence.
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_ctrl_c_at_random_moments_leaves_old_or_complete_files(runs, tmp_path):
    """SIGINT (KeyboardInterrupt) at 11 random moments of an in-process run over the previous
    outputs, from the first millisecond to its length when run alone, and one past its end."""
    source, root, done = runs
    start = time.perf_counter()
    run_pipeline(source, tmp_path / "timed", AFTER)
    duration = time.perf_counter() - start
    seen = set()

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        # the folder changes in one step at the end: the last moment is surely past it
        for delay in [*np.sort(RNG.uniform(0.001, duration, 11)), 10 * duration]:
            target = tmp_path / "out"
            _start_from_previous(root, target)
            # the timer set and cleared inside the handled block (as test_arrays does): an alarm
            # that went off just before the run or while the timer was being cleared escaped the
            # test on a loaded machine
            try:
                try:
                    signal.setitimer(signal.ITIMER_REAL, delay)
                    run_pipeline(source, target, AFTER)
                finally:
                    signal.setitimer(signal.ITIMER_REAL, 0)
            except KeyboardInterrupt:
                pass
            seen.add(tuple(sorted(_assert_each_file_old_or_new(target, done).items())))
    finally:
        signal.signal(signal.SIGALRM, previous)
    assert len(seen) >= 2, "every interrupt hit the same state: the moments are not spread"


def test_cancel_after_random_polls_leaves_old_files(runs, tmp_path):
    """Cancel (as QGIS's button: cancelled() turns true) after k polls, for random k from the
    first poll to the last, leaves every previous output untouched."""
    source, root, done = runs
    polls = []
    run_pipeline(source, tmp_path / "count", AFTER, cancelled=lambda: polls.append(1) and False)
    assert len(polls) > 5
    for k in sorted(set(RNG.integers(0, len(polls), 8).tolist()) | {0, len(polls) - 1}):
        target = tmp_path / "out"
        _start_from_previous(root, target)
        calls = []
        with pytest.raises(Cancelled):
            run_pipeline(source, target, AFTER,
                         cancelled=lambda: calls.append(1) or len(calls) > k)
        assert set(_assert_each_file_old_or_new(target, done).values()) == {"old"}


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "SIGHUP", "SIGKILL"])
def test_command_interrupted_at_random_moments(runs, tmp_path, how):
    """The floodmesh command, given Ctrl-C, SIGTERM or SIGHUP (taken as Ctrl-C) or killed at 4
    random moments: exit code 130 (128 + the signal; or 0 when it had finished) and no
    truncated file. A killed process may leave its hidden temporary files; they are never an
    output's name."""
    source, root, done = runs
    killed = []
    # from 1 s on: a Ctrl-C while the interpreter itself starts, before floodmesh runs any
    # code, ends Python with its own traceback
    for delay in np.sort(RNG.uniform(1.0, 4.5, 4)):
        target = tmp_path / "out"
        _start_from_previous(root, target)
        proc = subprocess.Popen([FLOODMESH, "run", str(source), "--out", str(target),
                                 "--holdout", "0.05", "--cell-size", "1", "--max-area", "30"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        proc.send_signal(getattr(signal, how))
        _, stderr = proc.communicate(timeout=120)
        if how != "SIGKILL":
            assert proc.returncode in (0, 128 + getattr(signal, how)), stderr
            assert how == "SIGINT" or proc.returncode == 0 or f"stopped by {how}" in stderr
            # a Ctrl-C inside a C extension's import (Cython) is reported by Python as
            # "Exception ignored" and lost: the run goes on and ends normally
            assert "Traceback" not in stderr or ("Exception ignored" in stderr
                                                 and proc.returncode == 0), stderr
        # the folder being written lies beside the target: nothing partial is inside it
        assert [p.name for p in target.iterdir() if ".partial" in p.name] == []
        assert how == "SIGKILL" or _leftovers(target) == []
        killed += _leftovers(target)
        _assert_each_file_old_or_new(target, done)
    # the next run removes what the killed ones left
    subprocess.run([FLOODMESH, "run", str(source), "--out", str(target), "--holdout", "0.05",
                    "--cell-size", "1", "--max-area", "30"], check=True, capture_output=True)
    assert _leftovers(target) == [], killed
    assert set(_assert_each_file_old_or_new(target, done).values()) == {"new"}


def test_temporaries_of_a_killed_earlier_version_are_removed(runs, tmp_path):
    """Hidden partial files (and SQLite journals) an older FloodMesh left when killed go with
    the next run; a hidden file of the user's stays."""
    source, root, done = runs
    target = tmp_path / "out"
    _start_from_previous(root, target)
    stale = [".breaklines.0123abcd.partial.gpkg", ".breaklines.0123abcd.partial.gpkg-journal",
             ".dem.99999999-89abcdef.partial.tif"]
    for name in stale + [".mine"]:
        (target / name).write_bytes(b"x")
    run_pipeline(source, target, AFTER)
    assert sorted(p.name for p in target.iterdir() if p.name.startswith(".")) == [".mine"]


def test_inputs_are_opened_read_only(runs, tmp_path):
    """A read-only input in a read-only folder runs through and is unchanged afterwards."""
    source, _, _ = runs
    folder = tmp_path / "ro"
    folder.mkdir()
    copy = folder / source.name
    shutil.copy2(source, copy)
    before = (copy.read_bytes(), os.stat(copy).st_mtime_ns)
    copy.chmod(0o444)
    folder.chmod(0o555)
    try:
        run_pipeline(copy, tmp_path / "out", AFTER)
    finally:
        folder.chmod(0o755)
        copy.chmod(0o644)
    assert (copy.read_bytes(), os.stat(copy).st_mtime_ns) == before
    assert sorted(p.name for p in folder.iterdir()) == [source.name]


def test_ctrl_c_inside_a_compiled_call_is_an_interrupt():
    """Ctrl-C while numba runs reaches Python as a SystemError caused by the KeyboardInterrupt,
    at times through a second SystemError (the point index's query, seen in the full suite):
    a step of the chain turns either back into KeyboardInterrupt; other SystemErrors pass."""
    from floodmesh.core.chain.pipeline import _Steps

    steps = _Steps({"query": 1}, None, None, None)

    def compiled_call(wrappings):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            error = exc
            for _ in range(wrappings):  # what numba's dispatcher raises, one or two deep
                try:
                    raise SystemError("returned a result with an exception set") from error
                except SystemError as wrapped:
                    error = wrapped
            raise error

    for wrappings in (1, 2):
        with pytest.raises(KeyboardInterrupt):
            steps.run("query", compiled_call, wrappings)

    def fails():
        raise SystemError("not an interrupt")

    with pytest.raises(SystemError, match="not an interrupt"):
        steps.run("query", fails)


class _CtrlCInsideKernel:
    """Ctrl-C arriving while a parallel numba kernel runs, where the random moments of
    ``test_ctrl_c_at_random_moments_leaves_old_or_complete_files`` meet it now and then: such
    a kernel calls back into Python (numba's ``_numba_unpickle``) on every call, and a
    KeyboardInterrupt raised there leaves the kernel as a SystemError. Raised there, through a
    trace function, the first time a call from ``caller`` (a function's name) makes it."""

    def __init__(self, caller: str):
        self.caller, self.fired = caller, False

    def __enter__(self):
        self.previous = sys.gettrace()
        sys.settrace(self.trace)
        return self

    def __exit__(self, *exc):
        sys.settrace(self.previous)

    def trace(self, frame, event, arg):
        if (event == "call" and not self.fired and frame.f_code.co_name == "_numba_unpickle"
                and frame.f_back is not None and frame.f_back.f_code.co_name == self.caller):
            self.fired = True
            raise KeyboardInterrupt


def test_ctrl_c_inside_the_holdout_split_leaves_old_files(runs, tmp_path):
    """Ctrl-C inside the holdout split's compiled (parallel) kernel, between reading and
    gridding: run_pipeline raises KeyboardInterrupt, not numba's SystemError, and the
    previous outputs stay as they were."""
    source, root, done = runs
    target = tmp_path / "out"
    _start_from_previous(root, target)
    with _CtrlCInsideKernel("split_holdout") as ctrl_c, pytest.raises(KeyboardInterrupt):
        run_pipeline(source, target, AFTER)
    assert ctrl_c.fired
    assert set(_assert_each_file_old_or_new(target, done).values()) == {"old"}
    assert not _leftovers(target)


def test_grid_command_given_ctrl_c_inside_a_compiled_kernel_says_interrupted(runs, tmp_path,
                                                                             capsys):
    """`floodmesh grid` given Ctrl-C inside a parallel kernel (the holdout split's): exit code
    130 and its one line, no traceback, no DEM."""
    from floodmesh.core.frontends.cli import main

    source, _, _ = runs
    dem = tmp_path / "dem.tif"
    with _CtrlCInsideKernel("split_holdout") as ctrl_c:
        code = main(["grid", str(source), "--cell-size", "1", "--holdout", "0.05",
                     "--out", str(dem)])
    assert ctrl_c.fired
    assert code == 130
    assert "floodmesh: interrupted" in capsys.readouterr().err
    assert not dem.exists()


@pytest.mark.parametrize("lock", ["numba's compiler lock", "llvmlite's lock on LLVM"])
def test_ctrl_c_as_a_compiler_lock_is_taken_leaves_the_lock_free(lock):
    """Ctrl-C (or SIGTERM) whose handler raises just after numba takes its compiler lock, or
    llvmlite its lock on LLVM's C API (some 10,000 times a run), leaves the lock's
    ``__enter__`` before it returns, so nothing gives the lock back: another thread compiling
    a kernel then waits forever (a run's background thread did, and the run joining it hung).
    Unwound through ``interrupts_unwrapped`` the lock is free again."""
    import threading

    import llvmlite.binding
    import numba

    from floodmesh.core.errors import compiler_locks_freed, interrupts_unwrapped

    @numba.njit
    def first(x):
        return x + 1

    @numba.njit
    def second(x):
        return x * 2

    where, taking = {"numba's compiler lock": (("acquire", "_CompilerLock"), lambda: first(1)),
                     "llvmlite's lock on LLVM": (("__enter__", "_LLVMLock"),
                                                 llvmlite.binding.get_process_triple)}[lock]

    def in_enter(frame, event, arg):  # the interrupt as the lock is taken
        if event == "return":
            raise KeyboardInterrupt
        return in_enter

    def trace(frame, event, arg):
        if (event == "call" and frame.f_code.co_name == where[0]
                and type(frame.f_locals.get("self")).__name__ == where[1]):
            return in_enter
        return None

    previous = sys.gettrace()
    sys.settrace(trace)
    try:
        with pytest.raises(KeyboardInterrupt), interrupts_unwrapped():
            taking()
    finally:
        sys.settrace(previous)
    compiled = []
    other = threading.Thread(target=lambda: compiled.append(second(3)), daemon=True)
    try:
        other.start()
        other.join(timeout=60)
        assert compiled == [6], f"another thread could not take {lock}"
    finally:  # the suite goes on either way
        compiler_locks_freed()


# A process of the front ends' signal handling: stop signals sent to its main thread one at a
# time, at random moments, while a parallel kernel of the run (the holdout split) runs over and
# over; it prints what each signal became.
_SIGNALLED_KERNEL = """
import json, random, signal, threading, time
import numba, numpy as np
from floodmesh.core._kernels.points import split_rows
from floodmesh.core.errors import stop_signals_as_interrupts

rows = np.random.default_rng(1).random((200_000, 3))
taken = np.random.default_rng(2).random(len(rows)) < 0.05
expected = split_rows(rows, taken, numba.get_num_threads())
stop_signals_as_interrupts()
main, armed, handled, seen = threading.main_thread().ident, [], [], {"whole": 0, "broken": 0}

def send():  # signal i once the main thread is in its loop of kernel calls for the i-th time
    rng = random.Random(3)
    for i in range(160):
        while len(armed) <= i:
            time.sleep(0.0005)
        time.sleep(rng.uniform(0.0, 0.004))
        signal.pthread_kill(main, (signal.SIGTERM, signal.SIGINT)[i % 2])

sender = threading.Thread(target=send, daemon=True)
sender.start()
while len(handled) < 160:
    try:
        armed.append(True)
        while True:  # until the signal comes: wherever it is raised, it is raised in here
            got = split_rows(rows, taken, numba.get_num_threads())
            ok = all(np.array_equal(a, b) for a, b in zip(got, expected))
            seen["whole" if ok else "broken"] += 1
    except KeyboardInterrupt as exc:  # Terminated too: the modules of the frames it went through
        tb, modules = exc.__traceback__, set()
        while tb is not None:
            modules.add(tb.tb_frame.f_globals["__name__"].partition(".")[0])
            tb = tb.tb_next
        handled.append([type(exc).__name__, sorted(modules)])
    except Exception as exc:
        handled.append([type(exc).__name__, repr(exc)])
print(json.dumps({"handled": handled, **seen}))
"""


def test_a_stop_signal_waits_until_a_compiled_kernel_has_returned():
    """SIGTERM and Ctrl-C (alternately), sent to the main thread 160 times at random moments
    while a parallel kernel runs over and over, come out of the front ends' handler
    (``stop_signals_as_interrupts``) as ``Terminated`` and ``KeyboardInterrupt`` raised after a
    kernel has returned, its results whole. Raised where they arrive, most land in the kernel's
    call back into numba's Python code: the kernel returns a SystemError, and at times goes on
    with what it did not get, and the process ends in a segmentation fault (the QGIS worker
    did, on 5 of 150 SIGTERMs at random moments, and failed this suite's worker test)."""
    done = subprocess.run([sys.executable, "-c", _SIGNALLED_KERNEL], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    seen = json.loads(done.stdout)
    assert len(seen["handled"]) == 160
    assert sorted({kind for kind, _ in seen["handled"]}) == ["KeyboardInterrupt", "Terminated"], \
        seen["handled"]
    through = {module for _, modules in seen["handled"] for module in modules}
    assert not through & {"numba", "llvmlite"}, seen["handled"]
    assert seen["broken"] == 0 and seen["whole"] > 0


def test_worker_given_sigterm_unwinds_and_says_so(runs, tmp_path):
    """QGIS's worker (core.frontends.worker) ended with SIGTERM mid-run: one error
    line on its protocol, exit code 143, the previous folder intact, nothing left beside it."""
    import json
    import sys

    source, root, done = runs
    target = tmp_path / "out"
    _start_from_previous(root, target)
    job = {"step": "run", "args": {"input": str(source), "output_folder": str(target),
                                   "options": {"holdout": 0.05, "cell_size": 1.0,
                                               "max_area": 30.0}}}
    proc = subprocess.Popen([sys.executable, "-m", "floodmesh.core.frontends.worker"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    proc.stdin.write(json.dumps(job))
    proc.stdin.close()
    lines = [proc.stdout.readline()]  # the run has started (its first message), then SIGTERM
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=120)
    stdout, stderr = "".join(lines) + proc.stdout.read(), proc.stderr.read()
    last = json.loads(stdout.strip().splitlines()[-1])
    if proc.returncode != 0:  # (it may have finished first)
        assert proc.returncode == 143 and "stopped by SIGTERM" in last["error"], stderr
    assert _leftovers(target) == []
    _assert_each_file_old_or_new(target, done)


def test_cancel_while_the_pictures_are_drawn_leaves_nothing_beside(runs, tmp_path,
                                                                   monkeypatch):
    """Cancel as the report's pictures are drawn (in a process of their own, into the run's
    staging folder): that process has ended before the staging folder is removed, so it cannot
    write into the folder as it goes and leave it behind (the Debian 12 suite once found
    ``.out.floodmesh-….staging`` beside the folder after SIGTERM)."""
    source, root, done = runs
    target = tmp_path / "out"
    _start_from_previous(root, target)
    before, seen, alive = child_processes(os.getpid()), [], []
    remove = shutil.rmtree

    def removing(path, *args, **kwargs):
        if str(path).endswith(".staging"):
            alive.append(sorted(child_processes(os.getpid()) - before))
        return remove(path, *args, **kwargs)

    monkeypatch.setattr(shutil, "rmtree", removing)
    with pytest.raises(Cancelled):  # at the poll after the pictures are handed over
        run_pipeline(source, target, AFTER, log=seen.append,
                     cancelled=lambda: "figures..." in seen)
    assert alive == [[]], "the picture process was still there as its folder was removed"
    assert _leftovers(target) == []
    assert set(_assert_each_file_old_or_new(target, done).values()) == {"old"}
