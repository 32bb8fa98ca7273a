"""Many machines for real: a scheduler and two workers started by Dask's own command line
(``dask scheduler``, ``dask worker ADDRESS``), each worker in a working folder of its own, run
``floodmesh run TILES --scheduler ADDRESS`` to the local cluster's result; a worker killed
mid-run leaves a finished run or one clean error, and nothing half-written."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from floodmesh.core import io

from ..conftest import survey_tiles

DASK = Path(sys.executable).parent / "dask"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """(scheduler address, worker processes) of `dask scheduler` and two `dask worker`s."""
    if not DASK.exists():
        pytest.skip("Dask's command line (dask) is not installed beside this Python")
    root = tmp_path_factory.mktemp("cluster")
    address_file = root / "scheduler.json"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    processes = [subprocess.Popen(
        [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
         "--scheduler-file", str(address_file)], cwd=root, env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not address_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(address_file.read_text())["address"]
        for k in range(2):
            folder = root / f"worker-{k}"
            folder.mkdir()
            processes.append(subprocess.Popen(
                [str(DASK), "worker", address, "--nworkers", "1", "--nthreads", "1",
                 "--local-directory", str(folder), "--no-dashboard", "--host", "127.0.0.1"],
                cwd=folder, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address, processes[1:]
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                process.terminate()
        for process in processes:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    return survey_tiles(tmp_path_factory.mktemp("survey"), density=2.0)


def _run(tiles, out, *options):
    return subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run", str(tiles),
                           "--out", str(out), "--max-area", "400", *options],
                          capture_output=True, text=True, timeout=900)


def test_separate_scheduler_and_workers_give_the_local_result(cluster, survey, tmp_path):
    address, _ = cluster
    remote = _run(survey / "tiles", tmp_path / "remote", "--scheduler", address)
    assert remote.returncode == 0, remote.stderr[-3000:]
    local = _run(survey / "tiles", tmp_path / "local", "--workers", "2")
    assert local.returncode == 0, local.stderr[-3000:]
    np.testing.assert_array_equal(io.read_raster(tmp_path / "remote" / "dem.tif").values,
                                  io.read_raster(tmp_path / "local" / "dem.tif").values)
    assert ((tmp_path / "remote" / "mesh.2dm").read_bytes()
            == (tmp_path / "local" / "mesh.2dm").read_bytes())
    assert "Traceback" not in remote.stderr


def test_a_worker_killed_mid_run_leaves_a_finished_run_or_one_clean_error(cluster, survey,
                                                                         tmp_path):
    address, workers = cluster
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-m", "floodmesh.core.frontends.cli", "run",
                            str(survey / "tiles"), "--out", str(out), "--max-area", "400",
                            "--scheduler", address],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)
    workers[0].send_signal(signal.SIGKILL)
    _, stderr = run.communicate(timeout=900)
    lines = [line for line in stderr.splitlines() if line.strip()]
    if run.returncode == 0:  # the other worker took the dead one's tasks
        assert (out / "mesh.2dm").exists() and (out / "report.json").exists()
    else:
        assert run.returncode == 2 and len(lines) == 1 and lines[0].startswith(
            "floodmesh: error:"), stderr
        assert not out.exists()
    assert "Traceback" not in stderr
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out.")]  # no staging left
