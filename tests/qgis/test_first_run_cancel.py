"""Cancel during the first run's setup of the managed environment (a plugin installed from its
ZIP): the real `python -m venv` and `pip install`, against a package index that accepts the
connection and never answers (a slow or hung mirror), end within a second of Cancel, pip's
process group with them, and no half-made environment is left for a later run to take."""
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import zipfile

import pytest
from qgis.core import QgsProcessingException, QgsProcessingFeedback

from floodmesh.algorithms import child

from .conftest import REPO


def _pip_of(venv):
    """The pid of the pip installing into ``venv``, if it runs yet."""
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as fh:
                command = fh.read().split(b"\0")
        except (OSError, ValueError):
            continue
        if b"pip" in command and b"install" in command and command[0].startswith(
                str(venv).encode()):
            return int(entry)
    return None


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _hung_index():
    """A package index that accepts connections and never answers, and pip's settings for it."""
    hung = socket.socket()
    hung.bind(("127.0.0.1", 0))
    hung.listen(64)  # the kernel completes the connections; nothing ever answers
    return hung, {"PIP_CONFIG_FILE": "/dev/null",  # no mirror from the machine's pip.conf
                  "PIP_INDEX_URL": f"http://127.0.0.1:{hung.getsockname()[1]}/simple/",
                  "PIP_DEFAULT_TIMEOUT": "120"}


def test_cancel_kills_the_first_run_pip_install_and_keeps_no_half_made_venv(tmp_path,
                                                                             monkeypatch):
    hung, settings = _hung_index()
    for name, value in settings.items():
        monkeypatch.setenv(name, value)
    venv = tmp_path / "profile" / "floodmesh" / "venv"
    feedback = QgsProcessingFeedback()
    seen = {}

    def cancel_once_pip_waits():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and "pip" not in seen:
            pid = _pip_of(venv)
            if pid:
                seen["pip"] = pid
                time.sleep(2.0)  # pip is waiting on the index
                seen["cancelled"] = time.monotonic()
                feedback.cancel()
            time.sleep(0.1)

    watcher = threading.Thread(target=cancel_once_pip_waits, daemon=True)
    watcher.start()
    try:
        with pytest.raises(QgsProcessingException, match="Cancelled while FloodMesh set up"):
            child.create_managed_venv(venv, feedback)
        ended = time.monotonic()
    finally:
        hung.close()
    watcher.join(timeout=5)
    assert "pip" in seen, "pip never started"
    assert ended - seen["cancelled"] < 2.0  # not pip's 120 s timeout
    assert not _alive(seen["pip"])
    assert not venv.exists()  # nothing a later run could mistake for a set-up environment


def test_an_unmarked_venv_from_a_killed_first_run_is_not_taken(tmp_path, monkeypatch):
    """QGIS killed mid-install leaves an environment without the ready mark: the next setup
    starts afresh instead of using it (here it fails at pip, and leaves nothing)."""
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").write_text("half made")
    monkeypatch.setenv("PIP_CONFIG_FILE", "/dev/null")
    monkeypatch.setenv("PIP_INDEX_URL", "http://127.0.0.1:9/simple/")  # refused at once
    monkeypatch.setenv("PIP_RETRIES", "0")
    with pytest.raises(QgsProcessingException, match="could not set up its Python packages"):
        child.create_managed_venv(venv, QgsProcessingFeedback())
    assert not venv.exists()


def test_ctrl_c_in_qgis_process_stops_the_first_run_setup(tmp_path, real_data):
    """The plugin installed from its ZIP into a fresh profile, as on a stock QGIS: Ctrl-C
    (SIGINT) to qgis_process while pip waits ends the run at once, with the message once from
    FloodMesh and no environment left in the profile."""
    exe = shutil.which("qgis_process.bin") or shutil.which("qgis_process")
    built = subprocess.run([sys.executable, str(REPO / "scripts" / "build_plugin_zip.py"),
                            str(tmp_path / "dist")], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    profile = tmp_path / "home" / "data" / "QGIS" / "QGIS3" / "profiles" / "default"
    with zipfile.ZipFile(next((tmp_path / "dist").glob("floodmesh-*.zip"))) as z:
        z.extractall(profile / "python" / "plugins")
    hung, settings = _hung_index()
    env = {k: v for k, v in os.environ.items()
           if k not in ("QGIS_PLUGINPATH", "PYTHONPATH", "FLOODMESH_PYTHON")}
    env.update(QT_QPA_PLATFORM="offscreen", HOME=str(tmp_path / "home"),
               XDG_DATA_HOME=str(tmp_path / "home" / "data"), **settings)
    subprocess.run([exe, "plugins", "enable", "floodmesh"], env=env, capture_output=True,
                   timeout=120)
    venv = profile / "floodmesh" / "venv"
    run = subprocess.Popen([exe, "run", "floodmesh:slope", "--",
                            f"INPUT={real_data / 'merewether_topography1.asc'}",
                            f"OUTPUT={tmp_path / 'slope.tif'}"], env=env, text=True,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while _pip_of(venv) is None and time.monotonic() < deadline and run.poll() is None:
            time.sleep(0.1)
        pip = _pip_of(venv)
        assert pip is not None, "pip never started"
        time.sleep(2.0)
        run.send_signal(signal.SIGINT)
        output, _ = run.communicate(timeout=20)  # not pip's 120 s timeout
    finally:
        hung.close()
        if run.poll() is None:
            run.kill()
    assert run.returncode == 1 and "Cancelled while FloodMesh set up" in output, output
    assert "Traceback" not in output
    assert not _alive(pip) and not venv.exists()


class _Said(QgsProcessingFeedback):
    """A feedback that keeps what the dialog would show: progress text, info and warnings."""

    def __init__(self):
        super().__init__()
        self.lines = []

    def setProgressText(self, text):
        self.lines.append(("progress", text))

    def pushInfo(self, info):
        self.lines.append(("info", info))

    def reportError(self, error, fatalError=False):
        self.lines.append(("error", error))


def _project_python():
    return str(REPO / ".venv" / "bin" / "python")


def test_the_install_compiles_the_kernels_in_a_step_of_its_own_so_the_first_run_waits_for_none(
        tmp_path, monkeypatch):
    """A fresh install's numba cache is empty (here an empty NUMBA_CACHE_DIR): the setup's last
    step compiles the kernels, said as a progress step with its real duration, and the first
    run that follows compiles nothing and says nothing of compiling."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba-cache"))
    feedback = _Said()
    seconds = child.compile_kernels(_project_python(), feedback)
    assert seconds is not None and seconds > 5  # a real compile, not a cache load
    assert feedback.lines[0] == ("progress", "Compiling FloodMesh's kernels (once, about 2 "
                                             "minutes)"), feedback.lines
    assert feedback.lines[-1] == ("info", f"compiled FloodMesh's kernels in {seconds:.0f} s "
                                          "(once)"), feedback.lines
    assert any((tmp_path / "numba-cache").rglob("*.nbc"))
    points = tmp_path / "points.laz"
    made = subprocess.run([_project_python(), "-c", (
        "import sys; from floodmesh.core import io; "
        "from floodmesh.core.frontends.demo import synthetic_floodplain; "
        "io.write_points_las(sys.argv[1], synthetic_floodplain(density=1.0)[0])"), str(points)],
        capture_output=True, text=True, env=child._child_env())
    assert made.returncode == 0, made.stderr
    run = subprocess.run([_project_python(), "-m", "floodmesh.core.frontends.cli", "run",
                          str(points), "--out", str(tmp_path / "out"), "--cell-size", "2"],
                         capture_output=True, text=True, env=child._child_env())
    assert run.returncode == 0, run.stderr
    assert "compil" not in run.stderr.lower(), run.stderr


def test_cancel_stops_the_kernels_compile_at_once(tmp_path, monkeypatch):
    """Cancel while the install's compile runs ends it within a second, with the message that
    the next run compiles what is left."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba-cache"))
    feedback = _Said()
    timer = threading.Timer(3.0, feedback.cancel)
    timer.start()
    started = time.monotonic()
    with pytest.raises(QgsProcessingException, match="Cancelled while FloodMesh compiled"):
        child.compile_kernels(_project_python(), feedback)
    assert time.monotonic() - started < 4.5
