"""Classify breakpoints: slope ≥ S_crit (or a LoG response), thinned."""
from qgis.core import (QgsProcessingParameterBoolean, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterDestination, QgsProcessingParameterRasterLayer)
from .compat import DOUBLE

from ..core.options import check_s_crit, check_sensitivity
from .base import FloodMeshAlgorithm, layer_file, run_core


class ClassifyBreakpointsAlgorithm(FloodMeshAlgorithm):
    NAME = "classifybreakpoints"
    DISPLAY_NAME = "Classify breakpoints"
    GROUP, GROUP_ID = "Terrain analysis", "terrain"
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
        import numpy as np
        from ..core import io
        from ..core.breakpoints import classify_breakpoints, log_breakpoints

        grid = run_core(io.read_raster, layer_file(
            self.parameterAsRasterLayer(parameters, self.INPUT, context), "Slope"))
        if parameters.get(self.LOG_SENSITIVITY) not in (None, ""):
            breakpoints = run_core(
                log_breakpoints, grid,
                self.parameterAsDouble(parameters, self.LOG_SENSITIVITY, context),
                zero_crossings=self.parameterAsBool(parameters, self.ZERO_CROSSINGS, context))
        else:
            breakpoints = run_core(classify_breakpoints, grid, self.parameterAsDouble(
                parameters, self.CRITICAL_SLOPE, context))
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        run_core(io.write_raster, out, breakpoints, valid=np.isfinite(grid.values))
        return {self.OUTPUT: out}
