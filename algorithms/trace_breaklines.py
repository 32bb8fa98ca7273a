"""Trace break lines through thinned breakpoints."""
from qgis.core import (QgsProcessingParameterBoolean, QgsProcessingParameterDefinition,
                       QgsProcessingParameterEnum, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterLayer, QgsProcessingParameterVectorDestination)
from .compat import DOUBLE, INTEGER, VECTOR_LINE

from ..core.options import TRACING_MODES as MODES
from ..core.options import check_min_points, check_s_crit, check_seed
from .base import FloodMeshAlgorithm, distance, labels, layer_file
from .styles import style_breaklines, style_when_loaded


class TraceBreaklinesAlgorithm(FloodMeshAlgorithm):
    NAME = "tracebreaklines"
    DISPLAY_NAME = "Trace break lines"
    TAGS = ("break lines", "levee", "bank", "embankment", "crest", "toe", "structure lines")
    GROUP, GROUP_ID = "3 · Break lines", "breaklines"
    HELP = ("Joins breakpoints into break lines: only breakpoints, only grid neighbours; slope "
            "changes by less than S_crit (degrees) between consecutive points; no turn over 90° "
            "from the line's trend; no line crosses another. In flat terrain the next point is "
            "the candidate of least slope, in steep terrain the one of least change of slope "
            "(auto: steep when the median slope reaches S_crit); ties widen the kernel to 5x5, "
            "then 7x7, then go to a random choice fixed by the seed. Pieces cut at the "
            "staircase corners of bands oblique to the grid are joined end to end. Lines with "
            "fewer points, or shorter (m), than the minimum are dropped. Output: LineStringZ "
            "with z from the DEM, coloured by connected break-line system.")
    BREAKPOINTS, SLOPE, DEM, CRITICAL_SLOPE = "BREAKPOINTS", "SLOPE", "DEM", "CRITICAL_SLOPE"
    MODE, MIN_POINTS, MIN_LENGTH, JOIN, SEED, OUTPUT = ("MODE", "MIN_POINTS", "MIN_LENGTH",
                                                        "JOIN", "SEED", "OUTPUT")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(self.BREAKPOINTS,
                                                            self.tr("Breakpoints")))
        self.addParameter(QgsProcessingParameterRasterLayer(self.SLOPE,
                                                            self.tr("Slope (degrees)")))
        self.addParameter(QgsProcessingParameterRasterLayer(self.DEM, self.tr("DEM")))
        self.addParameter(QgsProcessingParameterNumber(
            self.CRITICAL_SLOPE, self.tr("Critical slope S_crit (degrees)"),
            DOUBLE, 10.0, minValue=0.0, maxValue=90.0))
        self.addParameter(QgsProcessingParameterEnum(self.MODE, self.tr("Terrain"),
                                                     options=labels(MODES), defaultValue=0))
        self.addParameter(QgsProcessingParameterNumber(
            self.MIN_POINTS, self.tr("Minimum points per line"),
            INTEGER, 3, minValue=2))
        self.addParameter(distance(self, self.MIN_LENGTH, "Minimum line length", 0.0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.JOIN, self.tr("Join pieces cut at staircase corners"), defaultValue=True))
        seed = QgsProcessingParameterNumber(self.SEED, self.tr("Random seed for ties"),
                                            INTEGER, 0, minValue=0)
        seed.setFlags(seed.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
        self.addParameter(seed)
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.OUTPUT, self.tr("Break lines"), VECTOR_LINE))

    def check_values(self, parameters, context):
        check_s_crit(self.parameterAsDouble(parameters, self.CRITICAL_SLOPE, context))
        check_min_points(self.parameterAsDouble(parameters, self.MIN_POINTS, context))
        check_seed(self.parameterAsInt(parameters, self.SEED, context))

    def process(self, parameters, context, feedback):
        def raster(name, what):
            return layer_file(self.parameterAsRasterLayer(parameters, name, context), what)

        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        self.run_step("trace", {
            "breakpoints": raster(self.BREAKPOINTS, "Breakpoints"),
            "slope": raster(self.SLOPE, "Slope"), "dem": raster(self.DEM, "DEM"),
            "s_crit": self.parameterAsDouble(parameters, self.CRITICAL_SLOPE, context),
            "mode": MODES[self.parameterAsEnum(parameters, self.MODE, context)],
            "min_points": self.parameterAsInt(parameters, self.MIN_POINTS, context),
            "min_length": self.parameterAsDouble(parameters, self.MIN_LENGTH, context),
            "join": self.parameterAsBool(parameters, self.JOIN, context),
            "seed": self.parameterAsInt(parameters, self.SEED, context), "output": out},
            feedback, out)
        style_when_loaded(context, out, style_breaklines)
        return {self.OUTPUT: out}
