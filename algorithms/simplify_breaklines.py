"""Simplify break lines: every n-th point, Douglas–Peucker or a cubic smoothing spline."""
from qgis.core import (QgsProcessingParameterEnum,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterNumber,
                       QgsProcessingParameterVectorDestination)
from .compat import INTEGER, VECTOR_LINE

from ..core.options import SIMPLIFY_METHODS
from .base import FloodMeshAlgorithm, distance, vector_crs, vector_file
from .styles import style_breaklines, style_when_loaded

METHODS = ("keep every n-th point", "Douglas-Peucker", "cubic smoothing spline")


class SimplifyBreaklinesAlgorithm(FloodMeshAlgorithm):
    NAME = "simplifybreaklines"
    DISPLAY_NAME = "Simplify break lines"
    TAGS = ("break lines", "douglas-peucker", "spline", "generalise", "levee", "embankment")
    GROUP, GROUP_ID = "3 · Break lines", "breaklines"
    HELP = ("Thins break-line vertices within a tolerance α·Δ (Δ = d/2): keep every n-th point "
            "(default 4, both ends always kept); Douglas–Peucker, which keeps every dropped "
            "vertex within the tolerance (m) of the simplified line, horizontally and "
            "vertically; or a cubic smoothing spline within the same bound. The result stays a "
            "valid mesh input: segments that would cross another line get their vertices back, "
            "parts of a line closer than the minimum distance (m) to a longer line merge into "
            "it, and vertices closer than it to the previous one are dropped. The minimum "
            "distance is 0 (off) by default, as in floodmesh simplify; LiDAR to mesh takes half "
            "the cell size, d/2: give that for its lines.")
    INPUT, METHOD, KEEP_EVERY, TOLERANCE, MIN_DISTANCE, OUTPUT = (
        "INPUT", "METHOD", "KEEP_EVERY", "TOLERANCE", "MIN_DISTANCE", "OUTPUT")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.INPUT, self.tr("Break lines"), [VECTOR_LINE]))
        self.addParameter(QgsProcessingParameterEnum(self.METHOD, self.tr("Method"),
                                                     options=list(METHODS), defaultValue=0))
        self.addParameter(QgsProcessingParameterNumber(
            self.KEEP_EVERY, self.tr("Keep every n-th point"),
            INTEGER, 4, minValue=1))
        self.addParameter(distance(self, self.TOLERANCE, "Tolerance for Douglas–Peucker or "
                                   "spline", 0.9))
        self.addParameter(distance(self, self.MIN_DISTANCE, "Minimum distance between lines "
                                   "(0: off; d/2 as LiDAR to mesh)", 0.0))
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.OUTPUT, self.tr("Simplified break lines"), VECTOR_LINE))

    def process(self, parameters, context, feedback):
        method = SIMPLIFY_METHODS[self.parameterAsEnum(parameters, self.METHOD, context)]
        amount = (self.parameterAsInt(parameters, self.KEEP_EVERY, context)
                  if method == "keep-every"
                  else self.parameterAsDouble(parameters, self.TOLERANCE, context))
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        self.run_step("simplify", {
            "input": vector_file(self, parameters, self.INPUT, context, feedback),
            "crs": vector_crs(self, parameters, self.INPUT, context),
            "method": method, "amount": amount,
            "min_distance": self.parameterAsDouble(parameters, self.MIN_DISTANCE, context),
            "output": out}, feedback, out)
        style_when_loaded(context, out, style_breaklines)
        return {self.OUTPUT: out}
