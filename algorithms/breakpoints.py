"""Classify breakpoints: slope ≥ S_crit (or a LoG response), thinned."""
from qgis.core import (QgsProcessingParameterBoolean, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterDestination, QgsProcessingParameterRasterLayer)
from .compat import DOUBLE

from ..core.options import check_s_crit, check_sensitivity
from .base import FloodMeshAlgorithm, layer_file


class ClassifyBreakpointsAlgorithm(FloodMeshAlgorithm):
    NAME = "classifybreakpoints"
    DISPLAY_NAME = "Classify breakpoints"
    TAGS = ("breakpoints", "critical slope", "levee", "bank", "embankment", "crest", "toe")
    GROUP, GROUP_ID = "2 · Terrain analysis", "terrain"
    HELP = ("Breakpoints (1) where slope ≥ the critical slope S_crit (degrees, default 10), "
            "thinned: breakpoints whose eight neighbours are all breakpoints are dropped. With a "
            "LoG sensitivity (m) the input is read as a Laplacian-of-Gaussian response instead: "
            "breakpoints where |response| ≥ sensitivity, or at its zero crossings.")
    INPUT, CRITICAL_SLOPE, LOG_SENSITIVITY = "INPUT", "CRITICAL_SLOPE", "LOG_SENSITIVITY"
    ZERO_CROSSINGS, OUTPUT = "ZERO_CROSSINGS", "OUTPUT"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(
            self.INPUT, self.tr("Slope (degrees) or LoG response (m)")))
        self.addParameter(QgsProcessingParameterNumber(
            self.CRITICAL_SLOPE, self.tr("Critical slope S_crit (degrees)"),
            DOUBLE, 10.0, minValue=0.0, maxValue=90.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.LOG_SENSITIVITY, self.tr("LoG sensitivity (m; only for a LoG response)"),
            DOUBLE, None, optional=True, minValue=0.0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.ZERO_CROSSINGS, self.tr("LoG: breakpoints at zero crossings"), False))
        self.addParameter(QgsProcessingParameterRasterDestination(
            self.OUTPUT, self.tr("Breakpoints")))

    def check_values(self, parameters, context):
        if parameters.get(self.LOG_SENSITIVITY) not in (None, ""):
            check_sensitivity(self.parameterAsDouble(parameters, self.LOG_SENSITIVITY, context))
        else:
            check_s_crit(self.parameterAsDouble(parameters, self.CRITICAL_SLOPE, context))

    def process(self, parameters, context, feedback):
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        return {self.OUTPUT: self.run_step("breakpoints", {
            "input": layer_file(self.parameterAsRasterLayer(parameters, self.INPUT, context),
                                "Slope"),
            "s_crit": self.parameterAsDouble(parameters, self.CRITICAL_SLOPE, context),
            "sensitivity": self.optional_number(parameters, self.LOG_SENSITIVITY, context),
            "zero_crossings": self.parameterAsBool(parameters, self.ZERO_CROSSINGS, context),
            "output": out}, feedback, out)["OUTPUT"]}
