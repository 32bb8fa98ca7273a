"""Assess accuracy: residuals of check points against a mesh's TIN."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber, QgsProcessingParameterMeshLayer,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterVectorDestination)

from .compat import VECTOR_POINT
from .base import FloodMeshAlgorithm, layer_file, vector_crs, vector_file
from .styles import style_residuals, style_when_loaded


class AssessAccuracyAlgorithm(FloodMeshAlgorithm):
    NAME = "assessaccuracy"
    DISPLAY_NAME = "Assess accuracy"
    TAGS = ("accuracy", "rmse", "nssda", "fema", "residuals", "check points", "point cloud",
            "lidar", "validation")
    GROUP, GROUP_ID = "4 · Mesh", "mesh"
    HELP = ("Residual = check point z − mesh TIN z (linear in the triangle holding the point), "
            "for held-out LiDAR points. Reports RMSE, mean, standard deviation, skew, 1.96·RMSE, "
            "the maximum, the FEMA/NSSDA sample test and the shares of residuals under 10 cm, "
            "10–25 cm and over 25 cm; the points get their residual and class.")
    MESH, POINTS, OUTPUT, REPORT, RMSE = "MESH", "POINTS", "OUTPUT", "REPORT", "RMSE"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterMeshLayer(self.MESH, self.tr("Mesh (SMS 2DM)")))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.POINTS, self.tr("Check points (3-D)"), [VECTOR_POINT]))
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.OUTPUT, self.tr("Residuals"), VECTOR_POINT))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.REPORT, self.tr("Statistics (JSON)"), fileFilter="JSON (*.json)",
            optional=True, createByDefault=False))
        self.addOutput(QgsProcessingOutputNumber(self.RMSE, self.tr("RMSE (m)")))

    def process(self, parameters, context, feedback):
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        report = self.parameterAsFileOutput(parameters, self.REPORT, context)
        result = self.run_step("assess", {
            "mesh": layer_file(self.parameterAsMeshLayer(parameters, self.MESH, context), "Mesh"),
            "points": vector_file(self, parameters, self.POINTS, context, feedback),
            "crs": vector_crs(self, parameters, self.POINTS, context),
            "output": out, "report": report or None}, feedback, out, report)
        style_when_loaded(context, out, style_residuals)
        return {k: v for k, v in result.items() if k in (self.OUTPUT, self.RMSE, self.REPORT)}
