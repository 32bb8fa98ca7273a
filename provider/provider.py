"""The FloodMesh Processing provider: a flat list of algorithms."""
from pathlib import Path

from qgis.core import QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from ..algorithms.assess_accuracy import AssessAccuracyAlgorithm
from ..algorithms.breakpoints import ClassifyBreakpointsAlgorithm
from ..algorithms.build_mesh import BuildMeshAlgorithm
from ..algorithms.grid_points import GridPointsAlgorithm
from ..algorithms.lidar_to_mesh import LidarToMeshAlgorithm
from ..algorithms.simplify_breaklines import SimplifyBreaklinesAlgorithm
from ..algorithms.slope import SlopeAlgorithm
from ..algorithms.trace_breaklines import TraceBreaklinesAlgorithm

ALGORITHMS = (GridPointsAlgorithm, SlopeAlgorithm, ClassifyBreakpointsAlgorithm,
              TraceBreaklinesAlgorithm, SimplifyBreaklinesAlgorithm, BuildMeshAlgorithm,
              AssessAccuracyAlgorithm, LidarToMeshAlgorithm)

ICON = Path(__file__).resolve().parent.parent / "icons" / "floodmesh.svg"


class FloodMeshProvider(QgsProcessingProvider):
    def id(self):
        return "floodmesh"

    def name(self):
        return "FloodMesh"

    def icon(self):
        return QIcon(str(ICON))

    def svgIconPath(self):  # noqa: N802
        return str(ICON)

    def loadAlgorithms(self):  # noqa: N802
        for algorithm in ALGORITHMS:
            self.addAlgorithm(algorithm())
