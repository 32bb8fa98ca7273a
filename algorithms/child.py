"""Every FloodMesh algorithm's core work runs in a child process (``core/frontends/worker.py``),
as QGIS's GRASS, SAGA and point-cloud algorithms run theirs: the QGIS process never imports shapely,
Triangle, numba or laspy, so a second GEOS, a segfault or an out-of-memory kill cannot take QGIS
down; Cancel ends the child at once and its memory goes back to the system.

Which Python runs the worker (the first that exists):
1. the environment variable ``FLOODMESH_PYTHON``;
2. the QGIS setting ``floodmesh/python`` (Settings › Options › Advanced);
3. ``.venv/bin/python`` of the plugin's own folder (a checkout set up with ``make setup``);
4. the managed environment ``<QGIS profile>/floodmesh/venv``, which ``ensure_python`` creates
   on the first run from the system's Python (``--system-site-packages``, so that it keeps
   the system's numpy, GDAL and rasterio) and fills from PyPI (``MANAGED_PACKAGES``).
"""
from __future__ import annotations

import hashlib
import json
import os
import queue
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from qgis.core import QgsMessageLog, QgsProcessingException

PLUGIN_DIR = Path(__file__).resolve().parent.parent
PACKAGE = __name__.split(".")[0]  # "floodmesh" as QGIS and pip install it
ENV_VARIABLE, SETTING = "FLOODMESH_PYTHON", "floodmesh/python"
SYSTEM_PYTHON = "/usr/bin/python3"
# what Debian/Ubuntu's QGIS lacks: core/requirements.txt (the one list of dependencies) but
# numpy, which stays the system's (pinned), so that its GDAL still loads
_REQUIREMENTS = (PLUGIN_DIR / "core" / "requirements.txt").read_text(encoding="utf-8")
MANAGED_PACKAGES = tuple(line.split("#")[0].strip() for line in _REQUIREMENTS.splitlines()
                         if line.split("#")[0].strip() not in ("", "numpy"))
# core.frontends.worker.PARTIAL_GLOB (not imported: core stays out of QGIS)
PARTIAL_GLOB = ".*.partial*"
LOG_TAG = "FloodMesh"
READY = ".floodmesh-ready"  # written into the managed environment once pip has succeeded
FIRST_RUN_MESSAGE = (
    "FloodMesh's first run sets up its Python packages (Triangle, laspy, numba, shapely) in "
    "a virtual environment of its own beside your QGIS profile: a minute or two, with the "
    "internet; then numba compiles FloodMesh's kernels, once (about 2 minutes). Or set "
    "FLOODMESH_PYTHON to a Python that has them. QGIS itself never loads them.")


def managed_venv() -> Path:
    from qgis.core import QgsApplication

    return Path(QgsApplication.qgisSettingsDirPath()) / "floodmesh" / "venv"


def flood_env() -> Path:
    """Where ANUGA's environment goes beside the profile (a ZIP install has no ``make setup``):
    core's ``flood_python`` looks there too, and says how to make it."""
    return managed_venv().parent / "venv-flood"


def find_python() -> str | None:
    """The Python that runs the worker, or None when there is none yet."""
    given = os.environ.get(ENV_VARIABLE)
    if given:
        return given
    from qgis.core import QgsSettings

    setting = QgsSettings().value(SETTING, "")
    if setting:
        return str(setting)
    checkout = PLUGIN_DIR / ".venv" / "bin" / "python"
    if checkout.exists():
        return str(checkout)
    if (managed_venv() / READY).exists():  # only once pip has filled it
        return str(managed_venv() / "bin" / "python")
    return None


def ensure_python(feedback) -> str:
    """The worker's Python; on the first run of a plugin installed from its ZIP, the managed
    environment is created first (once; a minute or two, from PyPI)."""
    python = find_python()
    if python:
        return python
    import fcntl

    venv = managed_venv()
    venv.parent.mkdir(parents=True, exist_ok=True)
    # one setup at a time (two first runs at once): the second waits, then takes the first's
    with open(venv.parent / "venv.lock", "w") as lock:
        while True:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                _deliver_cancel()
                if feedback.isCanceled():
                    raise QgsProcessingException("Cancelled while waiting for another run to set "
                                                 "up FloodMesh's Python packages") from None
                time.sleep(0.2)
        if not (venv / READY).exists():
            feedback.pushInfo(f"{FIRST_RUN_MESSAGE} Setting up {venv} …")
            create_managed_venv(venv, feedback)
            compile_kernels(str(venv / "bin" / "python"), feedback)
    return str(venv / "bin" / "python")


def compile_kernels(python: str, feedback) -> float | None:
    """numba compiles FloodMesh's kernels with ``python`` (``core.frontends.warmup``) as a step
    of its own, right after the install, saying so and how long it took: the user's first run
    then waits for nothing unsaid. Cancel stops it (the environment stays; the next run
    compiles what is left). Returns the seconds, or None where it failed (said as a warning:
    the first run compiles then)."""
    feedback.setProgressText("Compiling FloodMesh's kernels (once, about 2 minutes)")
    feedback.pushInfo("numba compiles FloodMesh's kernels once, now, so that no run waits for "
                      "it later: about 2 minutes")
    start = time.monotonic()
    code, output = _run_cancellable([python, "-m", f"{PACKAGE}.core.frontends.warmup"],
                                    feedback, env=_child_env())
    if code is None:
        raise QgsProcessingException(
            "Cancelled while FloodMesh compiled its kernels; the packages are set up, and the "
            "next run compiles what is left (it says so)")
    seconds = time.monotonic() - start
    if code != 0:
        tail = output.strip().splitlines()[-1:] or [""]
        feedback.reportError(f"FloodMesh could not compile its kernels ahead ({tail[0]}); the "
                             "first run compiles them instead (about 2 minutes)",
                             fatalError=False)
        return None
    feedback.pushInfo(f"compiled FloodMesh's kernels in {seconds:.0f} s (once)")
    return seconds


def create_managed_venv(venv: Path, feedback) -> None:
    """Create ``venv`` from the system's Python and pip-install MANAGED_PACKAGES into it, each
    command a child process in its own group that Cancel kills at once. Only a complete
    environment gets the READY mark; a cancelled or failed one is removed, and so is one that
    an earlier run left unmarked (QGIS killed mid-install), so no run takes a half-made one."""
    import shutil

    if venv.exists() and not (venv / READY).exists():
        shutil.rmtree(venv, ignore_errors=True)
    numpy = subprocess.run([SYSTEM_PYTHON, "-c", "import numpy; print(numpy.__version__)"],
                           capture_output=True, text=True)
    pin = [f"numpy=={numpy.stdout.strip()}"] if numpy.returncode == 0 else []
    commands = [[SYSTEM_PYTHON, "-m", "venv", "--system-site-packages", str(venv)],
                [str(venv / "bin" / "python"), "-m", "pip", "install", "--disable-pip-version-check",
                 "-q", *MANAGED_PACKAGES, *pin]]
    try:
        for command in commands:
            code, output = _run_cancellable(command, feedback)
            if code is None:
                raise QgsProcessingException(
                    "Cancelled while FloodMesh set up its Python packages; the unfinished "
                    f"environment {venv} was removed, the next run sets it up again")
            if code != 0:
                tail = output.strip().splitlines()[-1:] or [""]
                raise QgsProcessingException(
                    f"FloodMesh could not set up its Python packages ({' '.join(command[:4])}…: "
                    f"{tail[0]}); on Debian/Ubuntu install python3-venv (apt install "
                    f"python3-venv) and check the internet connection, or set {ENV_VARIABLE} to "
                    f"a Python with triangle, laspy[lazrs], numba and shapely 2 (see "
                    f"docs/qgis.md, Which Python the worker uses)")
        proj = venv / "share" / "proj"
        if not proj.exists() and Path("/usr/share/proj").is_dir():
            proj.parent.mkdir(parents=True, exist_ok=True)
            proj.symlink_to("/usr/share/proj")
        (venv / READY).write_text(" ".join(MANAGED_PACKAGES + tuple(pin)) + "\n")
    except BaseException:
        shutil.rmtree(venv, ignore_errors=True)
        raise


def _deliver_cancel() -> None:
    """Let a Cancel that waits in the event queue through: qgis_process runs the algorithm in
    its main thread and turns Ctrl-C into feedback.cancel() only when events are processed (the
    dialog runs it in a task thread, whose Cancel needs none of this)."""
    from qgis.PyQt.QtCore import QCoreApplication, QThread

    app = QCoreApplication.instance()
    if app is not None and QThread.currentThread() == app.thread():
        QCoreApplication.processEvents()


def _run_cancellable(command, feedback, env=None) -> tuple:
    """(exit code, output) of ``command`` (in ``env``, default this process's), or (None, "")
    when Cancel ended it: it runs in a process group of its own (pip's own children
    included), killed whole on Cancel."""
    with tempfile.TemporaryFile("w+", encoding="utf-8", errors="replace") as log:
        child = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                 stdin=subprocess.DEVNULL, start_new_session=True, env=env)
        while True:
            try:
                code = child.wait(timeout=0.2)
                break
            except subprocess.TimeoutExpired:
                _deliver_cancel()
                if feedback is not None and feedback.isCanceled():
                    try:
                        os.killpg(child.pid, signal.SIGKILL)
                    except OSError:
                        child.kill()
                    child.wait()
                    return None, ""
        log.seek(0)
        return code, log.read()


def _import_root() -> Path:
    """A folder from which ``import floodmesh`` finds this very plugin: its parent when the
    folder is named so (a ZIP install), else a link under the temporary folder (a checkout)."""
    if PLUGIN_DIR.name == PACKAGE:
        return PLUGIN_DIR.parent
    digest = hashlib.sha1(str(PLUGIN_DIR).encode()).hexdigest()[:10]
    root = Path(tempfile.gettempdir()) / f"floodmesh-plugin-{os.getuid()}-{digest}"
    link = root / PACKAGE
    if not link.exists():
        root.mkdir(exist_ok=True)
        try:
            link.symlink_to(PLUGIN_DIR, target_is_directory=True)
        except FileExistsError:
            pass
    return root


def _child_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONHOME", "PYTHONSTARTUP")}
    env.update(PYTHONUNBUFFERED="1", PYTHONPATH=str(_import_root()))
    return env


def _remove_partials(outputs) -> None:
    """The hidden temporaries a killed worker leaves beside its outputs (none when it ended)."""
    for output in outputs:
        if not output:
            continue
        path = Path(output)
        folder = path if path.is_dir() else path.parent
        for leftover in folder.glob(PARTIAL_GLOB):
            try:
                leftover.unlink()
            except OSError:
                pass


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


def _reader(stream, sink):
    for line in iter(stream.readline, ""):
        sink.put(line)
    sink.put(None)


def run_step(step: str, args: dict, feedback, *, outputs=(), what: str = "") -> dict:
    """Run core's ``step`` with ``args`` in the worker and return its result; progress, info
    and notes go to ``feedback`` (notes also to the QGIS log), Cancel ends the child at once,
    core's error is raised once as a QgsProcessingException, and a crash or kill of the
    child becomes one too, with no partial output left among ``outputs`` (files or folders)."""
    python = ensure_python(feedback)
    what = what or step
    try:
        child = subprocess.Popen([python, "-m", f"{PACKAGE}.core.frontends.worker"],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, encoding="utf-8",
                                 errors="replace", env=_child_env(),
                                 start_new_session=True)  # its own children (ANUGA) go with it
    except OSError as exc:
        raise QgsProcessingException(
            f"FloodMesh could not start its worker {python} ({exc.strerror}): set "
            f"{ENV_VARIABLE} to a Python with FloodMesh's packages") from None
    lines, stderr = queue.Queue(), []
    threading.Thread(target=_reader, args=(child.stdout, lines), daemon=True).start()
    errors = threading.Thread(target=lambda: stderr.extend(iter(child.stderr.readline, "")),
                              daemon=True)
    errors.start()
    child.stdin.write(json.dumps({"step": step, "args": args}))
    child.stdin.close()
    result, error, cancelled = _relay(child, lines, stderr, feedback, what)
    code = child.wait()
    errors.join(timeout=2)
    child.stdout.close()
    child.stderr.close()
    if cancelled:
        _remove_partials(outputs)
        raise QgsProcessingException("Cancelled; no partial output was written")
    if error is not None:
        raise QgsProcessingException(error)
    if code != 0 or result is None:
        _remove_partials(outputs)
        raise QgsProcessingException(_failure(code, stderr, what))
    return result


def _relay(child, lines: queue.Queue, stderr: list, feedback, what: str):
    """(result, error, cancelled): the worker's messages passed on to ``feedback`` until its
    output ends; Cancel kills it and whatever it started."""
    result = error = None
    cancelled = False
    polled = time.monotonic()
    while True:
        if time.monotonic() - polled > 0.2:
            _deliver_cancel()
            polled = time.monotonic()
        if feedback is not None and feedback.isCanceled() and not cancelled:
            cancelled = True
            try:  # the worker and whatever it started
                os.killpg(child.pid, signal.SIGKILL)
            except OSError:
                child.kill()
        try:
            line = lines.get(timeout=0.1)
        except queue.Empty:
            continue
        if line is None:
            return result, error, cancelled
        try:
            message = json.loads(line)
        except ValueError:
            stderr.append(line)
            continue
        if "progress" in message:
            feedback.setProgress(100 * message["progress"])
        elif "info" in message:
            feedback.pushInfo(message["info"])
        elif "note" in message:
            feedback.pushWarning(message["note"])
            QgsMessageLog.logMessage(f"{what}: {message['note']}", LOG_TAG)
        elif "result" in message:
            result = message["result"]
        elif "error" in message:
            error = message["error"]


def _failure(code: int, stderr: list, what: str) -> str:
    """The one message for a worker that crashed, was killed or stopped without a result; its
    last output goes to the QGIS log."""
    trace = "".join(stderr[-40:]).strip()
    if trace:
        QgsMessageLog.logMessage(f"{what}: the worker's last output:\n{trace}", LOG_TAG)
    if code in (-9, -15):
        how = (f"was killed ({_signal_name(code)}; by the system when memory runs out: then "
               f"try a larger cell size or maximum area)")
    elif code < 0:
        how = f"crashed ({_signal_name(code)}; the log has its trace)"
    else:
        last = next((s.strip() for s in reversed(stderr) if s.strip()), "")
        how = f"stopped with exit code {code} ({last or 'no message'})"
    return (f"{what}: FloodMesh's worker process {how}; QGIS is unaffected and no partial "
            f"output was written")
