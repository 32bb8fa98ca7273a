"""Headless QGIS for the plugin tests: one QgsApplication, Processing, and the provider."""
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
if "XDG_RUNTIME_DIR" not in os.environ:
    runtime = tempfile.mkdtemp(prefix="xdg-")
    os.chmod(runtime, 0o700)
    os.environ["XDG_RUNTIME_DIR"] = runtime
sys.path.append("/usr/share/qgis/python/plugins")  # the Processing framework

import pytest  # noqa: E402

from ..ept import write_ept  # noqa: E402,F401  (the QGIS tests' point-cloud layers)

qgis_core = pytest.importorskip("qgis.core", reason="QGIS (python3-qgis) is not installed")
QgsApplication = qgis_core.QgsApplication
_QGS = QgsApplication([], False)  # kept alive for the whole session; never exitQgis (segfaults)
_QGS.initQgis()


@pytest.fixture(scope="session")
def processing():
    import processing as qgis_processing
    from processing.core.Processing import Processing

    from floodmesh.provider.provider import FloodMeshProvider

    Processing.initialize()
    provider = FloodMeshProvider()  # the registry does not keep the Python object alive
    assert QgsApplication.processingRegistry().addProvider(provider)
    yield qgis_processing
    QgsApplication.processingRegistry().removeProvider(provider)


@pytest.fixture
def feedback_log():
    """A Processing feedback that keeps what an algorithm logs (``infos``, ``warnings``,
    ``errors``: what the dialog's log shows in red): the messages a user reads in the algorithm
    dialog's log."""
    class Recorder(qgis_core.QgsProcessingFeedback):
        def __init__(self):
            super().__init__()
            self.infos, self.warnings, self.errors = [], [], []

        def reportError(self, text, fatal=False):  # noqa: N802
            self.errors.append(text)

        def pushInfo(self, text):  # noqa: N802
            self.infos.append(text)

        def pushWarning(self, text):  # noqa: N802
            self.warnings.append(text)
    return Recorder()


REPO = Path(__file__).resolve().parent.parent.parent


def _qgis_process_env(home):
    """qgis_process as a user runs it: no PYTHONPATH (QGIS itself needs none of FloodMesh's
    packages; the plugin's worker runs the checkout's .venv)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(QT_QPA_PLATFORM="offscreen", HOME=str(home), XDG_DATA_HOME=str(home / "data"),
               QGIS_PLUGINPATH=str(REPO / "build" / "plugins"))
    return env


@pytest.fixture(scope="module")
def qgis_process(tmp_path_factory):
    exe = shutil.which("qgis_process.bin") or shutil.which("qgis_process")
    if exe is None:
        pytest.skip("qgis_process is not installed")
    if not (REPO / "build" / "plugins" / "floodmesh").exists():
        pytest.skip("build/plugins/floodmesh is missing: run scripts/setup.sh")
    home = tmp_path_factory.mktemp("qgis-home")
    env = _qgis_process_env(home)
    enable = subprocess.run([exe, "plugins", "enable", "floodmesh"], env=env,
                            capture_output=True, text=True, timeout=120)
    assert enable.returncode == 0, enable.stdout + enable.stderr
    return exe, env
