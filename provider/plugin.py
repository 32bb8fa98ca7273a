"""The plugin QGIS loads: it registers the Processing provider and gives a mesh opened by hand
its CRS from the ``.prj`` beside it."""
from pathlib import Path

from qgis.core import QgsApplication, QgsCoordinateReferenceSystem, QgsMapLayerType, QgsProject


def crs_from_prj(layer) -> None:
    """An SMS 2DM has no place for a CRS and MDAL's 2DM driver reads none (QGIS 3.22 to 3.40):
    FloodMesh writes it as WKT to ``<mesh>.prj``. A mesh layer without a CRS whose file has one
    takes it, as a shapefile takes its own .prj."""
    if layer.type() != QgsMapLayerType.MeshLayer or layer.crs().isValid():
        return
    from qgis.core import QgsProviderRegistry

    # the source is MDAL's URI, e.g. 2DM:"/path/mesh.2dm"
    path = QgsProviderRegistry.instance().decodeUri(layer.providerType(), layer.source()).get(
        "path") or layer.source()
    prj = Path(path).with_suffix(".prj")
    if prj.is_file():
        crs = QgsCoordinateReferenceSystem.fromWkt(prj.read_text(errors="replace"))
        if crs.isValid():
            layer.setCrs(crs)


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
        QgsProject.instance().layersAdded.connect(self._layers_added)
        from ..algorithms.child import FIRST_RUN_MESSAGE, find_python

        if find_python() is None and self.iface is not None:
            from qgis.core import Qgis

            # stays until dismissed (duration 0): a timed message goes by behind the dialog
            # of the plugin manager that installed the plugin
            self.iface.messageBar().pushMessage("FloodMesh", FIRST_RUN_MESSAGE, Qgis.Info, 0)

    @staticmethod
    def _layers_added(layers):
        for layer in layers:
            crs_from_prj(layer)

    def unload(self):
        try:
            QgsProject.instance().layersAdded.disconnect(self._layers_added)
        except TypeError:  # initGui never ran (qgis_process loads initProcessing only)
            pass
        if self.provider:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
