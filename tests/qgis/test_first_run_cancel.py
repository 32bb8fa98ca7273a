"""Cancel during the first run's setup of the managed environment (a plugin installed from its
ZIP): the real `python -m venv` and `pip install`, against a package index that accepts the
connection and never answers (a slow or hung mirror), end within a second of Cancel, pip's
process group with them, and no half-made environment is left for a later run to take."""
import os
import socket
import threading
import time

import pytest
from qgis.core import QgsProcessingException, QgsProcessingFeedback

from floodmesh.algorithms import child


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


def test_cancel_kills_the_first_run_pip_install_and_keeps_no_half_made_venv(tmp_path,
                                                                             monkeypatch):
    hung = socket.socket()
    hung.bind(("127.0.0.1", 0))
    hung.listen(64)  # the kernel completes the connections; nothing ever answers
    monkeypatch.setenv("PIP_CONFIG_FILE", "/dev/null")  # no mirror from the machine's pip.conf
    monkeypatch.setenv("PIP_INDEX_URL", f"http://127.0.0.1:{hung.getsockname()[1]}/simple/")
    monkeypatch.setenv("PIP_DEFAULT_TIMEOUT", "120")
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
