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
        from ..algorithms.child import FIRST_RUN_MESSAGE, find_python

        if find_python() is None and self.iface is not None:
            self.iface.messageBar().pushInfo("FloodMesh", FIRST_RUN_MESSAGE)

    def unload(self):
        if self.provider:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
