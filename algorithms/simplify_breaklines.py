"""Simplify break lines: every n-th point, or Douglas–Peucker within a tolerance."""
from qgis.core import (QgsProcessing, QgsProcessingParameterEnum,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterNumber,
                       QgsProcessingParameterVectorDestination)

from .base import FloodMeshAlgorithm, layer_file, run_core

METHODS = ("keep every n-th point", "Douglas-Peucker")


class SimplifyBreaklinesAlgorithm(FloodMeshAlgorithm):
    NAME = "simplifybreaklines"
    DISPLAY_NAME = "Simplify break lines"
    GROUP, GROUP_ID = "Break lines", "breaklines"
    HELP = ("Thins break-line vertices within a tolerance α·Δ (Δ = d/2): keep every n-th point "
            "(default 4, both ends always kept), or Douglas–Peucker, which keeps every dropped "
            "vertex within the tolerance (m) of the simplified line, horizontally and "
            "vertically.")
    INPUT, METHOD, KEEP_EVERY, TOLERANCE, OUTPUT = ("INPUT", "METHOD", "KEEP_EVERY", "TOLERANCE",
                                                    "OUTPUT")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.INPUT, self.tr("Break lines"), [QgsProcessing.TypeVectorLine]))
        self.addParameter(QgsProcessingParameterEnum(self.METHOD, self.tr("Method"),
                                                     options=list(METHODS), defaultValue=0))
        self.addParameter(QgsProcessingParameterNumber(
            self.KEEP_EVERY, self.tr("Keep every n-th point"),
            QgsProcessingParameterNumber.Integer, 4, minValue=1))
        self.addParameter(QgsProcessingParameterNumber(
            self.TOLERANCE, self.tr("Douglas–Peucker tolerance (m)"),
            QgsProcessingParameterNumber.Double, 0.9, minValue=0.0))
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.OUTPUT, self.tr("Simplified break lines"), QgsProcessing.TypeVectorLine))

    def process(self, parameters, context, feedback):
        from ..core import io
        from ..core.raster import require_metric_crs
        from ..core.simplify import simplify_douglas_peucker, simplify_keep_every

        layer = self.parameterAsVectorLayer(parameters, self.INPUT, context)
        path = layer_file(layer, "Break lines")
        crs = run_core(require_metric_crs, layer.crs().toWkt() or None, layer.name())
        lines = run_core(io.read_breaklines, path)
        if self.parameterAsEnum(parameters, self.METHOD, context) == 1:
            lines = run_core(simplify_douglas_peucker, lines,
                             self.parameterAsDouble(parameters, self.TOLERANCE, context))
        else:
            lines = run_core(simplify_keep_every, lines,
                             self.parameterAsInt(parameters, self.KEEP_EVERY, context))
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        run_core(io.write_breaklines, out, lines, crs)
        return {self.OUTPUT: out}
