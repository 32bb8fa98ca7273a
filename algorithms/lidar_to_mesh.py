"""LiDAR to mesh: the whole FloodMesh chain in one Processing algorithm."""
from pathlib import Path

from qgis.core import (QgsMeshLayer, QgsProcessing, QgsProcessingException, QgsProcessingOutputFile,
                       QgsProcessingOutputHtml,
                       QgsProcessingParameterBoolean,
                       QgsProcessingOutputNumber, QgsProcessingOutputVectorLayer,
                       QgsProcessingParameterCrs, QgsProcessingParameterEnum,
                       QgsProcessingParameterFile, QgsProcessingParameterFolderDestination,
                       QgsProcessingParameterDefinition, QgsProcessingParameterNumber,
                       QgsProcessingParameterString, QgsVectorLayer)

from ..core.errors import FloodMeshError
from ..core.options import (BREAKPOINT_METHODS, EXPORT_FORMAT_LABELS, EXPORT_FORMATS, LOG_KERNELS,
                            MAX_MIN_ANGLE, NODE_ELEVATIONS, RunOptions, parse_classes)
from .compat import DOUBLE, INTEGER, VECTOR_LINE
from .base import (FloodMeshAlgorithm, add_domain_parameters, crs_or_none, distance, domain_files,
                   labels, point_cloud_parameter)
from .build_mesh import flow_area_parameter, max_triangles_parameter
from .simplify_breaklines import METHODS as SIMPLIFY_LABELS
from .tiles import add_tile_parameters, dask_settings, input_or_tiles, skip_unreadable
from .styles import load_results, run_group_name, style_breaklines, style_mesh, style_residuals

INPUT_FILTER = ("Point clouds and DEMs (*.las *.laz *.xyz *.txt *.csv *.tif *.tiff *.asc);;"
                "All files (*.*)")
METHODS = list(BREAKPOINT_METHODS)


SIMPLIFY_OPTION = ("keep_every", "tolerance", "spline")  # RunOptions field per method


class LidarToMeshAlgorithm(FloodMeshAlgorithm):
    NAME = "lidartomesh"
    DISPLAY_NAME = "LiDAR to mesh"
    TAGS = ("point cloud", "lidar", "las", "laz", "dem", "break lines", "levee", "embankment",
            "bank", "mesh", "triangle", "2dm", "telemac", "hec-ras", "adcirc", "schism",
            "workflow")
    GROUP, GROUP_ID = "1 · Workflows", "workflows"
    HELP = ("Runs the whole FloodMesh chain on a LiDAR point file (LAS/LAZ ground class, XYZ/CSV) "
            "or a DEM: grid (cell size d, m), slope (degrees), breakpoints (slope ≥ S_crit), "
            "break lines, simplification (every n-th point), a Triangle mesh with a minimum "
            "angle (degrees) and maximum area (m²), and the residuals of held-out points. "
            "Defaults are the method's reference case: 1 m grid, one-over-distance slope, "
            "S_crit 10°, every 4th point, 25°, 100 m². Writes dem.tif, slope.tif, "
            "breakpoints.tif, breaklines.gpkg, mesh.2dm, mesh.gpkg, residuals.gpkg, "
            "report.json, report.html (shown in the Results Viewer) and run.qlr (the run's "
            "layers, styled, for QGIS without the plugin) into the output folder, and loads "
            "the break lines, residuals and mesh in one group named after the folder. "
            "Solver formats chosen are written beside them as mesh.<ext> (the whole boundary "
            "a solid wall; Export mesh sets open boundaries and regions).")
    INPUT = "INPUT"
    CRS = "CRS"
    CELL_SIZE = "CELL_SIZE"
    SLOPE_METHOD = "SLOPE_METHOD"
    CRITICAL_SLOPE = "CRITICAL_SLOPE"
    KEEP_EVERY = "KEEP_EVERY"
    SIMPLIFY, TOLERANCE, REFINE = "SIMPLIFY", "TOLERANCE", "REFINE"
    CLASSES, MAX_GAP, SIGMA, SENSITIVITY = "CLASSES", "MAX_GAP", "SIGMA", "SENSITIVITY"
    LOG_KERNEL, ZERO_CROSSINGS = "LOG_KERNEL", "ZERO_CROSSINGS"
    LOCALISE, NODE_ELEVATION, MISFIT_PASSES = "LOCALISE", "NODE_ELEVATION", "MISFIT_PASSES"
    CONFORMING, FAR_FIELD_AREA, FLOW_AREA = "CONFORMING", "FAR_FIELD_AREA", "FLOW_AREA"
    MIN_ANGLE = "MIN_ANGLE"
    MAX_AREA = "MAX_AREA"
    MAX_TRIANGLES = "MAX_TRIANGLES"
    HOLDOUT = "HOLDOUT"
    SEED = "SEED"
    FORMATS = "FORMATS"
    OUTPUT_FOLDER = "OUTPUT_FOLDER"
    BREAKLINES = "BREAKLINES"
    MESH = "MESH"
    REPORT, REPORT_HTML = "REPORT", "REPORT_HTML"
    NODES = "NODES"
    TRIANGLES = "TRIANGLES"
    RMSE = "RMSE"

    def initAlgorithm(self, config=None):  # noqa: N802
        defaults = RunOptions()
        self._add_input_parameters(defaults)
        self._add_breakline_parameters(defaults)
        self._add_mesh_parameters(defaults)
        self._add_outputs()

    def _add_input_parameters(self, defaults: RunOptions):
        """The LiDAR or DEM: a layer, a file or tiles; its CRS, classes, cell size and gaps."""
        self.addParameter(point_cloud_parameter(self, "LiDAR point cloud layer"))
        self.addParameter(QgsProcessingParameterFile(
            self.INPUT, self.tr("… or LiDAR points or a DEM from a file"),
            fileFilter=INPUT_FILTER, optional=True))
        add_tile_parameters(self, "LAS/LAZ/XYZ point tiles, or GeoTIFF DEM tiles")
        self.addParameter(QgsProcessingParameterCrs(
            self.CRS, self.tr("CRS of the input (when the file has none)"), optional=True))
        self.addParameter(QgsProcessingParameterString(
            self.CLASSES, self.tr("LAS classes to grid, e.g. 2,9 for ground and water (empty: 2 "
                                  "when classified)"), optional=True))
        self.addParameter(distance(self, self.CELL_SIZE, "Grid cell size d", defaults.cell_size))
        self.addParameter(distance(self, self.MAX_GAP, "Maximum gap bridged (empty: 10 cells)",
                                   None, optional=True))

    def _add_breakline_parameters(self, defaults: RunOptions):
        """Steps 3 to 6: slope (or the LoG), S_crit and the simplification."""
        self.addParameter(QgsProcessingParameterEnum(
            self.SLOPE_METHOD, self.tr("Slope method"), options=labels(METHODS),
            defaultValue=METHODS.index(defaults.slope_method)))
        for parameter in (
                distance(self, self.SIGMA, "LoG: Gaussian sigma", defaults.sigma),
                QgsProcessingParameterNumber(
                    self.SENSITIVITY, self.tr("LoG: sensitivity, |response| (m)"), DOUBLE,
                    defaults.sensitivity, minValue=0.0)):
            parameter.setFlags(parameter.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
            self.addParameter(parameter)
        kernel = QgsProcessingParameterEnum(self.LOG_KERNEL, self.tr("LoG: Laplacian kernel"),
                                            options=labels(LOG_KERNELS), defaultValue=0)
        crossings = QgsProcessingParameterBoolean(
            self.ZERO_CROSSINGS, self.tr("LoG: breakpoints at zero crossings (mid-slope)"),
            defaultValue=defaults.zero_crossings)
        for parameter in (kernel, crossings):
            parameter.setFlags(parameter.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
            self.addParameter(parameter)
        self.addParameter(QgsProcessingParameterNumber(
            self.CRITICAL_SLOPE, self.tr("Critical slope S_crit (degrees)"),
            DOUBLE, defaults.s_crit, minValue=0.0, maxValue=90.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.KEEP_EVERY, self.tr("Keep every n-th break-line point"),
            INTEGER, 4, minValue=1))
        self.addParameter(QgsProcessingParameterEnum(
            self.SIMPLIFY, self.tr("Break-line simplification"), options=list(SIMPLIFY_LABELS),
            defaultValue=0))
        self.addParameter(distance(self, self.TOLERANCE, "Tolerance for Douglas–Peucker or "
                                   "spline", 0.9, minimum=0.001))

    def _add_mesh_parameters(self, defaults: RunOptions):
        """Steps 7 to 9: domain, angle and area bounds, holdout, exports, terrain fits, sizes."""
        add_domain_parameters(self)
        self.addParameter(QgsProcessingParameterNumber(
            self.MIN_ANGLE, self.tr("Minimum triangle angle (degrees)"),
            DOUBLE, defaults.min_angle, minValue=0.0,
            maxValue=MAX_MIN_ANGLE))
        self.addParameter(QgsProcessingParameterNumber(
            self.MAX_AREA, self.tr("Maximum triangle area (m²)"),
            DOUBLE, defaults.max_area, minValue=0.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.HOLDOUT, self.tr("Fraction of points held out for assessment"),
            DOUBLE, defaults.holdout, minValue=0.0, maxValue=1.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.SEED, self.tr("Random seed"), INTEGER,
            defaults.seed))
        self.addParameter(QgsProcessingParameterEnum(
            self.FORMATS, self.tr("Also write the mesh for solvers"),
            options=list(EXPORT_FORMAT_LABELS), allowMultiple=True, optional=True,
            defaultValue=[]))
        self.addParameter(QgsProcessingParameterBoolean(
            self.REFINE, self.tr("Refine until no triangle's points misfit by more than 10 cm "
                                 "RMS beyond their noise and none by more than 25 cm (step 9)"),
            defaultValue=False))
        self.addParameter(QgsProcessingParameterBoolean(
            self.LOCALISE, self.tr("Move break lines onto the crest and toe of a two-plane fit to "
                                   "the points"), defaultValue=defaults.localise))
        self.addParameter(QgsProcessingParameterEnum(
            self.NODE_ELEVATION, self.tr("Elevation of nodes off the break lines"),
            options=[self.tr("Local plane fit of the points"), self.tr("Bilinear from the DEM")],
            defaultValue=NODE_ELEVATIONS.index(defaults.node_elevation)))
        self.addParameter(QgsProcessingParameterNumber(
            self.MISFIT_PASSES, self.tr("Passes splitting triangles whose points misfit beyond "
                                        "their noise (crossings, junctions; 0: off)"), INTEGER,
            defaults.misfit_passes, minValue=0, maxValue=8))
        self.addParameter(QgsProcessingParameterBoolean(
            self.CONFORMING, self.tr("Conforming Delaunay mesh (Triangle's switch D)"),
            defaultValue=defaults.conforming))
        self.addParameter(QgsProcessingParameterNumber(
            self.FAR_FIELD_AREA, self.tr("Far-field triangle area where the terrain is plane "
                                         "(m²)"), DOUBLE, optional=True, minValue=0.0))
        self.addParameter(flow_area_parameter(self.FLOW_AREA, self.tr))
        self.addParameter(max_triangles_parameter(self.MAX_TRIANGLES, self.tr))

    def _add_outputs(self):
        """The run folder and what QGIS loads and lists from it."""
        self.addParameter(QgsProcessingParameterFolderDestination(
            self.OUTPUT_FOLDER, self.tr("Output folder")))
        self.addOutput(QgsProcessingOutputVectorLayer(
            self.BREAKLINES, self.tr("Break lines"), VECTOR_LINE))
        self.addOutput(QgsProcessingOutputFile(self.MESH, self.tr("Mesh (SMS 2DM)")))
        self.addOutput(QgsProcessingOutputFile(self.REPORT, self.tr("Report (JSON)")))
        # an HTML output is what QGIS's Results Viewer lists (as its statistics algorithms do)
        self.addOutput(QgsProcessingOutputHtml(self.REPORT_HTML, self.tr("Report")))
        self.addOutput(QgsProcessingOutputNumber(self.NODES, self.tr("Mesh nodes")))
        self.addOutput(QgsProcessingOutputNumber(self.TRIANGLES, self.tr("Mesh triangles")))
        self.addOutput(QgsProcessingOutputNumber(self.RMSE, self.tr("Holdout RMSE (m)")))

    def options(self, parameters, context) -> RunOptions:
        """The chain's options from the parameters; RunOptions checks their ranges."""
        boundary, user_lines = domain_files(self, parameters, context)
        simplify = self.parameterAsEnum(parameters, self.SIMPLIFY, context)
        return RunOptions(
            classes=parse_classes(self.parameterAsString(parameters, self.CLASSES, context)),
            max_gap=self.optional_number(parameters, self.MAX_GAP, context),
            sigma=self.parameterAsDouble(parameters, self.SIGMA, context),
            sensitivity=self.parameterAsDouble(parameters, self.SENSITIVITY, context),
            log_kernel=LOG_KERNELS[self.parameterAsEnum(parameters, self.LOG_KERNEL, context)],
            zero_crossings=self.parameterAsBool(parameters, self.ZERO_CROSSINGS, context),
            cell_size=self.parameterAsDouble(parameters, self.CELL_SIZE, context),
            slope_method=METHODS[self.parameterAsEnum(parameters, self.SLOPE_METHOD, context)],
            s_crit=self.parameterAsDouble(parameters, self.CRITICAL_SLOPE, context),
            **{SIMPLIFY_OPTION[simplify]: (
                self.parameterAsInt(parameters, self.KEEP_EVERY, context) if simplify == 0
                else self.parameterAsDouble(parameters, self.TOLERANCE, context))},
            min_angle=self.parameterAsDouble(parameters, self.MIN_ANGLE, context),
            max_area=self.parameterAsDouble(parameters, self.MAX_AREA, context),
            holdout=self.parameterAsDouble(parameters, self.HOLDOUT, context),
            seed=self.parameterAsInt(parameters, self.SEED, context),
            crs=crs_or_none(self, parameters, self.CRS, context), boundary=boundary,
            user_lines=user_lines,
            formats=tuple(EXPORT_FORMATS[i] for i in
                          self.parameterAsEnums(parameters, self.FORMATS, context)),
            max_triangles=self.parameterAsInt(parameters, self.MAX_TRIANGLES, context),
            refine=self.parameterAsBool(parameters, self.REFINE, context),
            localise=self.parameterAsBool(parameters, self.LOCALISE, context),
            node_elevation=NODE_ELEVATIONS[self.parameterAsEnum(parameters, self.NODE_ELEVATION,
                                                                context)],
            misfit_passes=self.parameterAsInt(parameters, self.MISFIT_PASSES, context),
            conforming=self.parameterAsBool(parameters, self.CONFORMING, context),
            far_field_area=self.optional_number(parameters, self.FAR_FIELD_AREA, context),
            flow_area=self.optional_number(parameters, self.FLOW_AREA, context),
            **dask_settings(self, parameters, context))

    def check_values(self, parameters, context):
        self.options(parameters, context)

    def process(self, parameters, context, feedback):
        from dataclasses import asdict

        try:
            options = self.options(parameters, context)
        except FloodMeshError as exc:
            raise QgsProcessingException(str(exc)) from None
        source = input_or_tiles(self, parameters, context, self.INPUT)
        out = Path(self.parameterAsString(parameters, self.OUTPUT_FOLDER, context))
        report = self.run_step("run", {"input": source, "output_folder": str(out),
                                       "options": asdict(options),
                                       **skip_unreadable(self, parameters, context)},
                               feedback, out)
        breaklines, mesh = str(out / "breaklines.gpkg"), str(out / "mesh.2dm")
        load_results(context, report["crs"], (
            (QgsMeshLayer(mesh, "Mesh", "mdal"), style_mesh, self.MESH),
            (QgsVectorLayer(str(out / "residuals.gpkg"), "Residuals", "ogr"), style_residuals,
             self.REPORT),
            (QgsVectorLayer(breaklines, "Break lines", "ogr"), style_breaklines,
             self.BREAKLINES)), group=run_group_name(out, source), folder=out)
        return {self.OUTPUT_FOLDER: str(out), self.BREAKLINES: breaklines, self.MESH: mesh,
                self.REPORT: str(out / "report.json"),
                self.REPORT_HTML: str(out / "report.html"), self.NODES: report["nodes"],
                self.TRIANGLES: report["triangles"], self.RMSE: report["rmse_m"]}
