"""Flood on mesh: ANUGA run on a FloodMesh mesh with a scenario (core.flood.model), in a child
process; its maxima load as rasters on colour ramps, dry cells clear."""
from pathlib import Path

from qgis.core import (QgsProcessingOutputFile, QgsProcessingOutputRasterLayer,
                       QgsProcessingOutputVectorLayer, QgsProcessingParameterCrs,
                       QgsProcessingParameterFile, QgsProcessingParameterFolderDestination,
                       QgsProcessingParameterMeshLayer, QgsRasterLayer, QgsVectorLayer)

from ..core.flood.summary import time_step_summary
from ..core.options import RESULT_RASTERS
from .base import FloodMeshAlgorithm, crs_or_none, layer_file
from .child import flood_env
from .styles import (load_results, run_group_name, style_arrival, style_max_depth,
                     style_max_level, style_max_speed)

RASTERS = (("MAX_DEPTH", "Maximum depth (m)", "max_depth", style_max_depth),
           ("MAX_LEVEL", "Maximum water level (m)", "max_stage", style_max_level),
           ("MAX_SPEED", "Maximum speed (m/s)", "max_speed", style_max_speed),
           ("ARRIVAL", "Arrival time (s)", "arrival_s", style_arrival))


class FloodOnMeshAlgorithm(FloodMeshAlgorithm):
    NAME = "floodonmesh"
    DISPLAY_NAME = "Flood on mesh (ANUGA)"
    TAGS = ("flood", "anuga", "hydrodynamic", "inundation", "depth", "hydrograph", "simulation")
    GROUP, GROUP_ID = "5 · Flood", "flood"
    HELP = ("Runs a flood on a FloodMesh mesh (SMS 2DM) with ANUGA, Geoscience Australia's "
            "finite-volume shallow-water solver (flow algorithm DE0, one thread), in a child "
            "process; Cancel stops it. The scenario is a JSON file (see docs/user-guide.md, The "
            "scenario): inflows (a discharge in m³/s, or a hydrograph, into a polygon or circle "
            "or across a line), boundaries (wall, outflow, level; by side or by line), "
            "Manning's n (one value, polygons with values), buildings (raised, or holes), duration. Writes maximum "
            "depth, maximum water level, maximum speed and arrival time as GeoTIFFs in the "
            "mesh's CRS, the triangles that set the solver's time step (points, with their share "
            "of the steps: where a sliver or a fast jet makes the flood dear), the outflow "
            "hydrograph, the stage at observation points and report.json (mass balance, "
            "hydraulic checks of the mesh, cost). ANUGA needs an environment of its own: "
            "make setup builds it for a checkout; after an install from the ZIP, make it once "
            "in <QGIS profile>/floodmesh/venv-flood (the first run says the command; see "
            "docs/qgis.md, Flood on mesh and ANUGA).")
    MESH, SCENARIO, CRS, OUTPUT = "MESH", "SCENARIO", "CRS", "OUTPUT_FOLDER"
    HYDROGRAPH, REPORT, TIME_STEP = "HYDROGRAPH", "REPORT", "TIME_STEP"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterMeshLayer(self.MESH, self.tr("Mesh (SMS 2DM)")))
        self.addParameter(QgsProcessingParameterFile(
            self.SCENARIO, self.tr("Scenario (JSON)"), extension="json"))
        self.addParameter(QgsProcessingParameterCrs(
            self.CRS, self.tr("CRS of the mesh (when the layer has none)"), optional=True))
        self.addParameter(QgsProcessingParameterFolderDestination(
            self.OUTPUT, self.tr("Output folder")))
        for name, label, *_ in RASTERS:
            self.addOutput(QgsProcessingOutputRasterLayer(name, self.tr(label)))
        self.addOutput(QgsProcessingOutputVectorLayer(
            self.TIME_STEP, self.tr("Where the time step was set")))
        self.addOutput(QgsProcessingOutputFile(self.HYDROGRAPH, self.tr("Outflow hydrograph")))
        self.addOutput(QgsProcessingOutputFile(self.REPORT, self.tr("Report")))

    def process(self, parameters, context, feedback):
        mesh_layer = self.parameterAsMeshLayer(parameters, self.MESH, context)
        mesh_path = layer_file(mesh_layer, "Mesh")
        crs = crs_or_none(self, parameters, self.CRS, context)
        if crs is None and mesh_layer.crs().isValid():
            crs = mesh_layer.crs().toWkt()
        out = Path(self.parameterAsString(parameters, self.OUTPUT, context))
        report = self.run_step("flood", {
            "mesh": mesh_path, "scenario": self.parameterAsFile(parameters, self.SCENARIO, context),
            "output": str(out), "crs": crs, "own_env": str(flood_env())}, feedback, out)
        mb = report["mass_balance"]
        feedback.pushInfo(f"ANUGA: {report['cpu_s']:.1f} s CPU, {report['time_steps']} steps; "
                          f"flooded {report['flooded_area_m2']:.0f} m², mass balance error "
                          f"{mb['error_m3']:.3g} m³")
        setter = time_step_summary(report)
        if setter:
            feedback.pushInfo(setter)
        results = {self.OUTPUT: str(out), self.HYDROGRAPH: str(out / "hydrograph.csv"),
                   self.REPORT: str(out / "report.json")}
        results[self.TIME_STEP] = str(out / "time_step.gpkg")
        layers = [(QgsVectorLayer(f"{results[self.TIME_STEP]}|layername=time_step_set_by",
                                  "Where the time step was set"), lambda layer: None,
                   self.TIME_STEP)]
        for name, label, key, style in RASTERS:
            results[name] = str(out / RESULT_RASTERS[key])
            layers.append((QgsRasterLayer(results[name], label), style, name))
        load_results(context, crs, layers, group=run_group_name(out, mesh_path),
                     folder=out)
        return results
