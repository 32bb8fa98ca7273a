"""Refine mesh: local refinement and point insertion until the residuals meet a target."""
from dataclasses import asdict

from qgis.core import (QgsProcessingOutputNumber,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterLayer)
from .compat import DOUBLE, INTEGER, VECTOR_LINE, VECTOR_POINT

from .base import (FloodMeshAlgorithm, add_domain_parameters, layer_file, read_mesh_inputs,
                   run_core)
from .styles import load_mesh


class RefineMeshAlgorithm(FloodMeshAlgorithm):
    NAME = "refinemesh"
    DISPLAY_NAME = "Refine mesh"
    GROUP, GROUP_ID = "Mesh", "mesh"
    HELP = ("Meshes the DEM with its break lines as Build mesh does, then refines in rounds: "
            "measured points whose residual exceeds the upper bound (m, default 0.25) go into "
            "the mesh as nodes with their measured z; triangles whose points' RMS residual "
            "exceeds the lower bound (m, default 0.10) get a quarter of their area as a local "
            "maximum. Stops when the target RMSE and/or maximum residual (m) holds, at the "
            "node budget, or after the last round. Check points, if given, are assessed each "
            "round and never used for refinement.")
    DEM, BREAKLINES, POINTS, CHECK = "DEM", "BREAKLINES", "POINTS", "CHECK"
    MIN_ANGLE, MAX_AREA, LOWER, UPPER = "MIN_ANGLE", "MAX_AREA", "LOWER", "UPPER"
    TARGET_RMSE, TARGET_MAX, MAX_NODES, MAX_ROUNDS = ("TARGET_RMSE", "TARGET_MAX", "MAX_NODES",
                                                      "MAX_ROUNDS")
    OUTPUT, REPORT, NODES, RMSE = "OUTPUT", "REPORT", "NODES", "RMSE"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(self.DEM, self.tr("DEM")))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.BREAKLINES, self.tr("Break lines"), [VECTOR_LINE],
            optional=True))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.POINTS, self.tr("Measured points (3-D) driving the refinement"),
            [VECTOR_POINT]))
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
        number(self.LOWER, "Lower bound: refine where RMS residual exceeds (m)", 0.10, 0.0001)
        number(self.UPPER, "Upper bound: insert points whose residual exceeds (m)", 0.25, 0.0001)
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

    def process(self, parameters, context, feedback):
        from ..core import io
        from ..core.refine import refine_mesh

        dem, lines, domain = read_mesh_inputs(self, parameters, context)

        def points(name, what):
            layer = self.parameterAsVectorLayer(parameters, name, context)
            return run_core(io.read_points_vector, layer_file(layer, what)) if layer else None

        def optional(name):
            value = parameters.get(name)
            return None if value in (None, "") else self.parameterAsDouble(parameters, name,
                                                                           context)

        mesh, rounds = run_core(
            refine_mesh, dem, lines, points(self.POINTS, "Measured points"),
            check=points(self.CHECK, "Check points"), domain=domain,
            min_angle=self.parameterAsDouble(parameters, self.MIN_ANGLE, context),
            max_area=self.parameterAsDouble(parameters, self.MAX_AREA, context),
            lower=self.parameterAsDouble(parameters, self.LOWER, context),
            upper=self.parameterAsDouble(parameters, self.UPPER, context),
            target_rmse=optional(self.TARGET_RMSE), target_max=optional(self.TARGET_MAX),
            max_nodes=self.parameterAsInt(parameters, self.MAX_NODES, context),
            max_rounds=self.parameterAsInt(parameters, self.MAX_ROUNDS, context),
            progress=lambda f: feedback.setProgress(100 * f), cancelled=feedback.isCanceled)
        for k, r in enumerate(rounds, 1):
            feedback.pushInfo(f"round {k}: {r.nodes} nodes, RMSE {100 * r.rmse_m:.1f} cm, max "
                              f"{100 * r.max_abs_m:.1f} cm, check RMSE "
                              f"{100 * r.check_rmse_m:.1f} cm; {r.inserted} points inserted, "
                              f"{r.refined} triangles refined")
        out = self.parameterAsFileOutput(parameters, self.OUTPUT, context)
        run_core(io.write_mesh_2dm, out, mesh.nodes, mesh.triangles)
        load_mesh(context, out, "Refined mesh", self.OUTPUT)
        results = {self.OUTPUT: out, self.NODES: len(mesh.nodes), self.RMSE: rounds[-1].rmse_m}
        report = self.parameterAsFileOutput(parameters, self.REPORT, context)
        if report:
            run_core(io.write_json, report, {"rounds": [asdict(r) for r in rounds]})
            results[self.REPORT] = report
        return results
