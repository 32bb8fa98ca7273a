"""Slope: one of the six first-order kernels, or the Laplacian of Gaussian."""
from qgis.core import (QgsProcessingParameterEnum,
                       QgsProcessingParameterRasterDestination, QgsProcessingParameterRasterLayer)

from ..core.options import BREAKPOINT_METHODS, LOG_KERNELS
from .base import FloodMeshAlgorithm, distance, labels, layer_file


class SlopeAlgorithm(FloodMeshAlgorithm):
    NAME = "slope"
    DISPLAY_NAME = "Slope for break lines"
    TAGS = ("slope", "gradient", "horn", "laplacian", "log", "curvature", "dem")
    GROUP, GROUP_ID = "2 · Terrain analysis", "terrain"
    HELP = ("Slope of a DEM in degrees from its 3x3 neighbourhood: maximum slope (Shanholtz), "
            "one-over-distance (NOAA, default), Sharpnack & Akin (= Horn), constrained quadratic "
            "(Wood), quadratic surface (Zevenbergen & Thorne) or diagonal (Ritter). Edges and "
            "nodata neighbours are extrapolated linearly, so planes keep their exact slope. "
            "'log' gives the Laplacian-of-Gaussian response in metres instead (Gaussian sigma in "
            "m, Pratt's 3x3 mask or the analytic kernel), positive on crests.")
    INPUT, METHOD, SIGMA, LOG_KERNEL, OUTPUT = "INPUT", "METHOD", "SIGMA", "LOG_KERNEL", "OUTPUT"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(self.INPUT, self.tr("DEM")))
        self.addParameter(QgsProcessingParameterEnum(
            self.METHOD, self.tr("Method"), options=labels(BREAKPOINT_METHODS),
            defaultValue=BREAKPOINT_METHODS.index("one-over-distance")))
        self.addParameter(distance(self, self.SIGMA, "LoG: Gaussian sigma", 1.0))
        self.addParameter(QgsProcessingParameterEnum(
            self.LOG_KERNEL, self.tr("LoG: Laplacian kernel"), options=labels(LOG_KERNELS),
            defaultValue=0))
        self.addParameter(QgsProcessingParameterRasterDestination(
            self.OUTPUT, self.tr("Slope (degrees) or LoG response (m)")))

    def process(self, parameters, context, feedback):
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        method = BREAKPOINT_METHODS[self.parameterAsEnum(parameters, self.METHOD, context)]
        if context.willLoadLayerOnCompletion(out):  # the layer says which of the two it holds
            context.layerToLoadOnCompletionDetails(out).name = self.tr(
                "LoG response (m)" if method == "log" else "Slope (degrees)")
        return {self.OUTPUT: self.run_step("slope", {
            "input": layer_file(self.parameterAsRasterLayer(parameters, self.INPUT, context),
                                "DEM"),
            "method": method,
            "sigma": self.parameterAsDouble(parameters, self.SIGMA, context),
            "log_kernel": LOG_KERNELS[self.parameterAsEnum(parameters, self.LOG_KERNEL, context)],
            "output": out}, feedback, out)["OUTPUT"]}
