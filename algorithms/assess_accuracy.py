"""Assess accuracy: residuals of check points against a mesh's TIN."""
import json

from qgis.core import (QgsProcessingOutputNumber, QgsProcessingParameterFile,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterVectorDestination)
from .compat import VECTOR_POINT

from .base import FloodMeshAlgorithm, layer_file, run_core
from .styles import style_residuals, style_when_loaded


class AssessAccuracyAlgorithm(FloodMeshAlgorithm):
    NAME = "assessaccuracy"
    DISPLAY_NAME = "Assess accuracy"
    GROUP, GROUP_ID = "Mesh", "mesh"
    HELP = ("Residual = check point z − mesh TIN z (linear in the triangle holding the point), "
            "for held-out LiDAR points. Reports RMSE, mean, standard deviation, skew, 1.96·RMSE, "
            "the maximum, the FEMA/NSSDA sample test and the shares of residuals under 10 cm, "
            "10–25 cm and over 25 cm; the points get their residual and class.")
    MESH, POINTS, OUTPUT, REPORT, RMSE = "MESH", "POINTS", "OUTPUT", "REPORT", "RMSE"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterFile(self.MESH, self.tr("Mesh (SMS 2DM)"),
                                                     fileFilter="SMS 2DM (*.2dm)"))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.POINTS, self.tr("Check points (3-D)"), [VECTOR_POINT]))
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.OUTPUT, self.tr("Residuals"), VECTOR_POINT))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.REPORT, self.tr("Statistics (JSON)"), fileFilter="JSON (*.json)",
            optional=True, createByDefault=False))
        self.addOutput(QgsProcessingOutputNumber(self.RMSE, self.tr("RMSE (m)")))

    def process(self, parameters, context, feedback):
        from ..core import io
        from ..core.accuracy import accuracy_statistics, residuals
        from ..core.mesh import Mesh
        from ..core.raster import require_metric_crs

        layer = self.parameterAsVectorLayer(parameters, self.POINTS, context)
        xyz = run_core(io.read_points_vector, layer_file(layer, "Check points"))
        crs = run_core(require_metric_crs, layer.crs().toWkt() or None, layer.name())
        nodes, triangles = run_core(io.read_mesh_2dm,
                                    self.parameterAsFile(parameters, self.MESH, context))
        res = residuals(Mesh(nodes, triangles, crs), xyz)
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        run_core(io.write_residuals, out, xyz, res, crs)
        style_when_loaded(context, out, style_residuals)
        stats = accuracy_statistics(res)
        feedback.pushInfo(json.dumps(stats, indent=1))
        results = {self.OUTPUT: out, self.RMSE: stats["rmse_m"]}
        report = self.parameterAsFileOutput(parameters, self.REPORT, context)
        if report:
            run_core(io.write_json, report, stats)
            results[self.REPORT] = report
        return results
