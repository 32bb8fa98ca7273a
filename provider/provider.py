"""The FloodMesh Processing provider: a flat list of algorithms."""
from pathlib import Path

from qgis.core import QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from ..algorithms.lidar_to_mesh import LidarToMeshAlgorithm

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
        for algorithm in (LidarToMeshAlgorithm(),):
            self.addAlgorithm(algorithm)
