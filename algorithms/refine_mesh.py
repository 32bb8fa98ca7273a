"""Refine mesh: local refinement and point insertion until the residuals meet a target."""
from qgis.core import (QgsProcessing, QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterFile,
                       QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterLayer)

from ..core.errors import FloodMeshError
from ..core.options import check_refinement
from .compat import DOUBLE, INTEGER, VECTOR_LINE, VECTOR_POINT
from .base import (FloodMeshAlgorithm, add_domain_parameters, mesh_input_args,
                   point_cloud_file, point_cloud_parameter, vector_file)
from .grid_points import POINT_FILTER
from .styles import load_mesh


class RefineMeshAlgorithm(FloodMeshAlgorithm):
    NAME = "refinemesh"
    DISPLAY_NAME = "Refine mesh"
    TAGS = ("refine", "mesh", "2dm", "accuracy", "point cloud", "lidar", "residuals")
    GROUP, GROUP_ID = "4 · Mesh", "mesh"
    HELP = ("Meshes the DEM with its break lines as Build mesh does, then refines in rounds: "
            "measured points whose residual exceeds the upper bound (m, default 0.25) go into "
            "the mesh as nodes with their measured z; triangles whose points' RMS residual "
            "exceeds the lower bound (m, default 0.10) get a quarter of their area as a local "
            "maximum. Stops when the target RMSE and/or maximum residual (m) holds, at the "
            "node budget, or after the last round. Check points, if given, are assessed each "
            "round and never used for refinement: measured points at a check point's x, y are "
            "left out of it.")
    DEM, BREAKLINES, POINTS, POINTS_FILE, CHECK = ("DEM", "BREAKLINES", "POINTS", "POINTS_FILE",
                                                   "CHECK")
    MIN_ANGLE, MAX_AREA, LOWER, UPPER, NOISE = ("MIN_ANGLE", "MAX_AREA", "LOWER", "UPPER",
                                                "NOISE")
    TARGET_RMSE, TARGET_MAX, MAX_NODES, MAX_ROUNDS = ("TARGET_RMSE", "TARGET_MAX", "MAX_NODES",
                                                      "MAX_ROUNDS")
    OUTPUT, REPORT, NODES, RMSE = "OUTPUT", "REPORT", "NODES", "RMSE"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(self.DEM, self.tr("DEM")))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.BREAKLINES, self.tr("Break lines"), [VECTOR_LINE],
            optional=True))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.POINTS, self.tr("Measured points (3-D layer) driving the refinement"),
            [VECTOR_POINT], optional=True))
        self.addParameter(point_cloud_parameter(
            self, "… or measured points from a LiDAR point cloud layer (ground class)"))
        self.addParameter(QgsProcessingParameterFile(
            self.POINTS_FILE, self.tr("… or measured points from a LiDAR file (LAS/LAZ ground, "
                                      "XYZ)"), fileFilter=POINT_FILTER, optional=True))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.CHECK, self.tr("Check points (3-D), never used for refinement"),
            [VECTOR_POINT], optional=True))
        add_domain_parameters(self)

        def number(name, label, default, minimum, optional=False, kind=None):
            self.addParameter(QgsProcessingParameterNumber(
                name, self.tr(label), kind or DOUBLE, default,
                optional=optional, minValue=minimum))

        number(self.MIN_ANGLE, "Minimum angle (degrees)", 25.0, 0.01)
        number(self.MAX_AREA, "Maximum triangle area (m²)", 100.0, 0.0001)
        number(self.LOWER, "Lower bound: refine where RMS residual exceeds the noise by (m, in "
               "quadrature)", 0.10, 0.0001)
        number(self.UPPER, "Upper bound: insert points whose residual exceeds (m)", 0.25, 0.0001)
        number(self.NOISE, "Vertical noise of the points (m; default estimated from them, 0: "
               "exact)", None, 0.0, optional=True)
        number(self.TARGET_RMSE, "Target RMSE (m)", None, 0.0, optional=True)
        number(self.TARGET_MAX, "Target maximum residual (m)", None, 0.0, optional=True)
        number(self.MAX_NODES, "Node budget", 1_000_000, 3,
               kind=INTEGER)
        number(self.MAX_ROUNDS, "Rounds at most", 8, 1, kind=INTEGER)
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT, self.tr("Refined mesh (SMS 2DM)"), fileFilter="SMS 2DM (*.2dm)"))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.REPORT, self.tr("Rounds (JSON)"), fileFilter="JSON (*.json)", optional=True,
            createByDefault=False))
        self.addOutput(QgsProcessingOutputNumber(self.NODES, self.tr("Nodes")))
        self.addOutput(QgsProcessingOutputNumber(self.RMSE, self.tr("RMSE of the points (m)")))

    def measured_points(self, parameters, context, feedback=None):
        given = [g for g in (vector_file(self, parameters, self.POINTS, context, feedback),
                             point_cloud_file(self, parameters, context),
                             self.parameterAsFile(parameters, self.POINTS_FILE, context)) if g]
        if len(given) > 1:
            raise FloodMeshError("Refine mesh takes one set of measured points: a 3-D point "
                                 "layer, a point cloud layer or a LiDAR file, not several")
        if not given:
            raise FloodMeshError("Refine mesh needs measured points: a 3-D point layer (e.g. "
                                 "Grid LiDAR points' held-out points), a point cloud layer or a "
                                 "LiDAR file")
        return given[0]

    def refinement(self, parameters, context) -> dict:
        """The refinement's bounds, noise and targets (m) and budget, as core takes them."""
        return {"lower": self.parameterAsDouble(parameters, self.LOWER, context),
                "upper": self.parameterAsDouble(parameters, self.UPPER, context),
                "noise": self.optional_number(parameters, self.NOISE, context),
                "target_rmse": self.optional_number(parameters, self.TARGET_RMSE, context),
                "target_max": self.optional_number(parameters, self.TARGET_MAX, context),
                "max_nodes": self.parameterAsInt(parameters, self.MAX_NODES, context),
                "max_rounds": self.parameterAsInt(parameters, self.MAX_ROUNDS, context)}

    def check_values(self, parameters, context):
        self.measured_points(parameters, context)
        check_refinement(**self.refinement(parameters, context))

    def process(self, parameters, context, feedback):
        out = self.parameterAsFileOutput(parameters, self.OUTPUT, context)
        report = self.parameterAsFileOutput(parameters, self.REPORT, context)
        result = self.run_step("refine_mesh", {
            **mesh_input_args(self, parameters, context, feedback),
            "points": self.measured_points(parameters, context, feedback),
            "check": vector_file(self, parameters, self.CHECK, context, feedback),
            "min_angle": self.parameterAsDouble(parameters, self.MIN_ANGLE, context),
            "max_area": self.parameterAsDouble(parameters, self.MAX_AREA, context),
            **self.refinement(parameters, context), "output": out,
            "report": report or None}, feedback, out, report)
        load_mesh(context, out, "Refined mesh", self.OUTPUT, result["crs"])
        return {k: v for k, v in result.items()
                if k in (self.OUTPUT, self.NODES, self.RMSE, self.REPORT)}
