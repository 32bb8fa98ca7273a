"""Headless QGIS for the plugin tests: one QgsApplication, Processing, and the provider."""
import os
import sys
import tempfile

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
if "XDG_RUNTIME_DIR" not in os.environ:
    runtime = tempfile.mkdtemp(prefix="xdg-")
    os.chmod(runtime, 0o700)
    os.environ["XDG_RUNTIME_DIR"] = runtime
sys.path.append("/usr/share/qgis/python/plugins")  # the Processing framework

import pytest  # noqa: E402

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
