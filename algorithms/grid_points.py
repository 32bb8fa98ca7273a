"""Grid LiDAR points: points to a DEM by linear (TIN) interpolation."""
from qgis.core import (QgsProcessingParameterCrs, QgsProcessingParameterFile,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination,
                       QgsProcessingParameterString, QgsProcessingParameterVectorDestination)

from ..core.options import check_cell_size, check_holdout, check_max_gap, parse_classes
from .compat import DOUBLE, INTEGER
from .base import FloodMeshAlgorithm, crs_or_none, distance, point_cloud_parameter
from .tiles import add_tile_parameters, dask_settings, input_or_tiles, skip_unreadable

POINT_FILTER = "Point clouds (*.las *.laz *.xyz *.txt *.csv);;All files (*.*)"


class GridPointsAlgorithm(FloodMeshAlgorithm):
    NAME = "gridpoints"
    DISPLAY_NAME = "Grid LiDAR points"
    TAGS = ("point cloud", "lidar", "las", "laz", "xyz", "dem", "tin", "interpolation",
            "gridding", "raster")
    GROUP, GROUP_ID = "2 · Terrain analysis", "terrain"
    HELP = ("Grids LiDAR ground points (LAS/LAZ class 2 when classified, or XYZ/CSV) to a DEM of "
            "cell size d (m) by linear interpolation on their Delaunay TIN; cells are aligned to "
            "whole multiples of d. Triangles with an edge longer than the maximum gap (m, default "
            "10 d) are not used, so water and voids stay nodata. A fraction of the points can be "
            "held out (by seed) for the accuracy assessment.")
    INPUT, CRS, CLASSES, CELL_SIZE, MAX_GAP = "INPUT", "CRS", "CLASSES", "CELL_SIZE", "MAX_GAP"
    HOLDOUT, SEED, OUTPUT, HOLDOUT_OUTPUT = "HOLDOUT", "SEED", "OUTPUT", "HOLDOUT_OUTPUT"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(point_cloud_parameter(self, "LiDAR point cloud layer"))
        self.addParameter(QgsProcessingParameterFile(self.INPUT, self.tr(
            "… or LiDAR points from a file (LAS/LAZ, XYZ/CSV)"),
            fileFilter=POINT_FILTER, optional=True))
        add_tile_parameters(self, "LAS/LAZ/XYZ point tiles")
        self.addParameter(QgsProcessingParameterCrs(
            self.CRS, self.tr("CRS of the points (when the file has none)"), optional=True))
        self.addParameter(QgsProcessingParameterString(
            self.CLASSES, self.tr("LAS classes to grid, e.g. 2,9 (empty: 2 when classified)"),
            optional=True))
        self.addParameter(distance(self, self.CELL_SIZE, "Cell size d", 1.0))
        self.addParameter(distance(self, self.MAX_GAP, "Maximum gap bridged (empty: 10 cells)",
                                   None, optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            self.HOLDOUT, self.tr("Fraction of points held out"),
            DOUBLE, 0.0, minValue=0.0, maxValue=1.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.SEED, self.tr("Random seed"), INTEGER, 0))
        self.addParameter(QgsProcessingParameterRasterDestination(self.OUTPUT, self.tr("DEM")))
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.HOLDOUT_OUTPUT, self.tr("Held-out points"), optional=True,
            createByDefault=False))

    def max_gap(self, parameters, context):
        return (self.parameterAsDouble(parameters, self.MAX_GAP, context)
                if parameters.get(self.MAX_GAP) not in (None, "") else None)

    def check_values(self, parameters, context):
        check_cell_size(self.parameterAsDouble(parameters, self.CELL_SIZE, context))
        check_max_gap(self.max_gap(parameters, context))
        check_holdout(self.parameterAsDouble(parameters, self.HOLDOUT, context))
        parse_classes(self.parameterAsString(parameters, self.CLASSES, context))

    def process(self, parameters, context, feedback):
        classes = parse_classes(self.parameterAsString(parameters, self.CLASSES, context))
        out = self.parameterAsOutputLayer(parameters, self.OUTPUT, context)
        holdout_out = self.parameterAsOutputLayer(parameters, self.HOLDOUT_OUTPUT, context)
        result = self.run_step("grid", {
            "input": input_or_tiles(self, parameters, context, self.INPUT),
            **dask_settings(self, parameters, context),
            **skip_unreadable(self, parameters, context),
            "crs": crs_or_none(self, parameters, self.CRS, context), "classes": classes,
            "cell_size": self.parameterAsDouble(parameters, self.CELL_SIZE, context),
            "max_gap": self.max_gap(parameters, context),
            "holdout": self.parameterAsDouble(parameters, self.HOLDOUT, context),
            "seed": self.parameterAsInt(parameters, self.SEED, context),
            "output": out, "holdout_output": holdout_out or None}, feedback, out, holdout_out)
        return {k: v for k, v in result.items() if k in (self.OUTPUT, self.HOLDOUT_OUTPUT)}
