"""The plugin QGIS loads: it only registers the Processing provider."""
from qgis.core import QgsApplication


class FloodMeshPlugin:
    def __init__(self, iface):
        self.iface = iface
        self.provider = None

    def initProcessing(self):  # noqa: N802 (QGIS's name)
        if not self.provider:
            from .provider import FloodMeshProvider

            self.provider = FloodMeshProvider()
            QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802
        self.initProcessing()
        from ..core.dependencies import install_hint, missing_dependencies

        missing = missing_dependencies()
        if missing and self.iface is not None:
            self.iface.messageBar().pushWarning("FloodMesh", install_hint(missing))

    def unload(self):
        if self.provider:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
