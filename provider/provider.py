"""The FloodMesh Processing provider: a flat list of algorithms."""
from pathlib import Path

from qgis.core import QgsApplication, QgsProcessingModelAlgorithm, QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from ..algorithms.assess_accuracy import AssessAccuracyAlgorithm
from ..algorithms.breakpoints import ClassifyBreakpointsAlgorithm
from ..algorithms.build_mesh import BuildMeshAlgorithm
from ..algorithms.export_mesh import ExportMeshAlgorithm
from ..algorithms.flood_on_mesh import FloodOnMeshAlgorithm
from ..algorithms.grid_points import GridPointsAlgorithm
from ..algorithms.lidar_to_mesh import LidarToMeshAlgorithm
from ..algorithms.refine_mesh import RefineMeshAlgorithm
from ..algorithms.simplify_breaklines import SimplifyBreaklinesAlgorithm
from ..algorithms.slope import SlopeAlgorithm
from ..algorithms.trace_breaklines import TraceBreaklinesAlgorithm

ALGORITHMS = (GridPointsAlgorithm, SlopeAlgorithm, ClassifyBreakpointsAlgorithm,
              TraceBreaklinesAlgorithm, SimplifyBreaklinesAlgorithm, BuildMeshAlgorithm,
              RefineMeshAlgorithm, AssessAccuracyAlgorithm, ExportMeshAlgorithm,
              LidarToMeshAlgorithm, FloodOnMeshAlgorithm)

# the only formats the steps write (core.chain.files: GEOTIFF, GEOPACKAGE; not imported: it
# loads the numerical core), so that a raster or layer output offers no other
RASTER_EXTENSIONS, VECTOR_EXTENSIONS = ["tif", "tiff"], ["gpkg"]

ROOT = Path(__file__).resolve().parent.parent
ICON = ROOT / "icons" / "floodmesh.svg"
MODELS = ROOT / "models"


class FloodMeshProvider(QgsProcessingProvider):
    def id(self):
        return "floodmesh"

    def name(self):
        return "FloodMesh"

    def icon(self):
        return QIcon(str(ICON))

    def svgIconPath(self):  # noqa: N802
        return str(ICON)

    def load(self):
        # The shipped models chain this provider's algorithms, which the registry can resolve
        # only once the provider is registered: load them again when it is.
        QgsApplication.processingRegistry().providerAdded.connect(self._registered)
        return super().load()

    def _registered(self, provider_id):
        if provider_id == self.id():
            QgsApplication.processingRegistry().providerAdded.disconnect(self._registered)
            self.refreshAlgorithms()

    def supportsNonFileBasedOutput(self):  # noqa: N802
        # core writes files; temporary outputs (as in models) must become files, not memory layers
        return False

    def supportedOutputRasterLayerExtensions(self):  # noqa: N802
        return list(RASTER_EXTENSIONS)

    def supportedOutputVectorLayerExtensions(self):  # noqa: N802
        return list(VECTOR_EXTENSIONS)

    def supportedOutputTableExtensions(self):  # noqa: N802
        return list(VECTOR_EXTENSIONS)

    def defaultRasterFileExtension(self):  # noqa: N802
        return RASTER_EXTENSIONS[0]

    def defaultVectorFileExtension(self, hasGeometry=True):  # noqa: N802, N803
        return VECTOR_EXTENSIONS[0]

    def loadAlgorithms(self):  # noqa: N802
        for algorithm in ALGORITHMS:
            self.addAlgorithm(algorithm())
        for path in sorted(MODELS.glob("*.model3")):
            model = QgsProcessingModelAlgorithm()
            if model.fromFile(str(path)):
                self.addAlgorithm(model)
