"""What every FloodMesh algorithm shares: names, groups, help, parameter checks, and running
the core step in the worker process (``child.run_step``).

Only ``core.options`` and ``core.errors`` (plain Python) are imported into QGIS; the numerical
core runs in the worker."""
import html
from pathlib import Path

from qgis.core import QgsProcessingAlgorithm, QgsProcessingException
from qgis.PyQt.QtCore import QCoreApplication

from ..core.errors import FloodMeshError
from ..core.options import is_point_source, wrong_geometry
from .compat import (METRES, OWN_GEOMETRY_CHECK, SKIP_INVALID, VECTOR_LINE, VECTOR_POINT,
                     VECTOR_POLYGON, temporary_file)
from .child import run_step
from .styles import drop_unasked_loads, reload_rewritten, stack_when_loaded


# what toolbox searches find every FloodMesh algorithm by (each adds its own, ``TAGS``)
TAGS = ("floodmesh",)
GLOSSARY = ("<p><i>d</i>: the grid cell size (m); <i>Δ = d/2</i>: the scale of detail; "
            "<i>S_crit</i>: the critical slope (degrees) from which a cell is a breakpoint; "
            "<i>α</i>: the break-line simplification tolerance in units of Δ; a "
            "<i>system</i>: break lines joined to each other.</p>")
# what the enum parameters show, by core's ids (core/options.py)
LABELS = {"max-slope": "Maximum slope (Shanholtz)", "one-over-distance":
          "One over distance (NOAA)", "sharpnack-akin": "Sharpnack & Akin (= Horn)",
          "wood": "Constrained quadratic (Wood)", "zevenbergen-thorne":
          "Quadratic surface (Zevenbergen & Thorne)", "ritter": "Diagonal (Ritter)",
          "log": "Laplacian of Gaussian (LoG)", "pratt": "Pratt's 3x3 mask",
          "analytic": "Analytic LoG kernel", "auto": "Automatic (steep where the median slope "
          "reaches S_crit)", "flat": "Flat: least slope", "steep": "Steep: least change of slope"}




def _number(source_type) -> int:
    """A Processing source type as a number (QGIS >= 3.36 gives enum members)."""
    return int(getattr(source_type, "value", source_type))


# what a layer parameter of one source type needs, as GEOMETRY_KINDS names it
SOURCE_GEOMETRIES = {_number(VECTOR_POINT): "points", _number(VECTOR_LINE): "lines",
                     _number(VECTOR_POLYGON): "polygons"}
# what a layer holds by its geometry type (QGIS's GeometryType enum, moved into Qgis in 3.30:
# Point 0, Line 1, Polygon 2 before and after), as GEOMETRY_KINDS names it
LAYER_GEOMETRIES = {0: "points", 1: "lines", 2: "polygons"}

# per-parameter help (the tooltip), by parameter name: one text for the same parameter everywhere
PARAMETER_HELP = {
    "CELL_SIZE": "Grid cell size d in metres; the scale of detail Δ is d/2. About the point "
                 "spacing: 1 m for 9 points/m².",
    "CLASSES": "LAS classification codes gridded as terrain, e.g. 2 (ground) or 2,9 (ground "
               "and water, so that lakes are meshed instead of left as holes).",
    "MAX_GAP": "Triangles of the points' TIN with an edge longer than this (m) are not "
               "interpolated: wider gaps (water, voids) stay nodata and become mesh holes.",
    "CRITICAL_SLOPE": "S_crit, degrees: cells at least this steep are breakpoints; break lines "
                      "change slope by less than S_crit from point to point. 10° is the "
                      "reference case.",
    "SLOPE_METHOD": "The 3x3 slope kernel, or the Laplacian of Gaussian (crests and toes).",
    "METHOD": "The method of this step (see the help).",
    "SIGMA": "Standard deviation of the Gaussian smoothing of the LoG, in metres.",
    "SENSITIVITY": "LoG breakpoints where the |response| reaches this (m).",
    "LOG_SENSITIVITY": "LoG breakpoints where the |response| reaches this (m); empty: the input "
                       "is a slope in degrees.",
    "KEEP_EVERY": "Keep every n-th traced break-line point (both ends always): 4 in the "
                  "reference case.",
    "TOLERANCE": "Douglas–Peucker or spline tolerance in metres (α·Δ), horizontal and "
                 "vertical.",
    "MIN_ANGLE": "No triangle angle below this (degrees); at most 34. 25° is usual for solvers.",
    "MAX_AREA": "No triangle larger than this (m²).",
    "FLOW_AREA": "No triangle larger than this (m²) on ground less than 1 m above a "
                 "drainage line, where a flood goes first, wherever that ground has relief "
                 "(more than 1 cm RMS beyond the DEM's noise) that a larger triangle's "
                 "plane misses (empty: 23 cells, 23 m² at 1 m; 0: off).",
    "MAX_TRIANGLES": "Refuse, before meshing, a mesh estimated above this many triangles.",
    "HOLDOUT": "Share of the points kept out of the grid to measure the mesh's error (at "
               "least 20 points for the FEMA/NSSDA test; 0: no assessment).",
    "SEED": "Random seed of the holdout and of tie breaks: the same seed, the same result.",
    "BOUNDARY": "Polygon layer of the model domain; its holes (buildings, islands) stay "
                "unmeshed. Must be in the DEM's CRS.",
    "USER_LINES": "Your own break or structure lines (dykes, walls), kept as mesh edges.",
    "CRS": "The CRS when the file carries none: a projected CRS in metres.",
    "FORMATS": "Solver formats written beside mesh.2dm as mesh.<ext>.",
    "REFINE": "Step 9: insert measured points and refine triangles until the residual bounds "
              "(10 cm RMS, 25 cm) hold.",
    "MAX_NODES": "Stop refining when the mesh reaches this many nodes.",
    "MAX_ROUNDS": "Stop after this many rounds of refinement.",
    "LOWER": "Triangles whose points misfit by more than this RMS (m) get a quarter of their "
             "area as a local maximum.",
    "UPPER": "Measured points misfitting by more than this (m) become mesh nodes.",
    "POINTS": "3-D points (z) that drive the refinement, e.g. Grid LiDAR points' held-out "
              "points.",
    "POINTS_FILE": "A LAS/LAZ (ground class) or XYZ file of measured points, instead of a layer.",
    "POINT_CLOUD": "A point cloud layer of the project: LAS/LAZ (QGIS with PDAL), COPC or an "
                   "EPT index (ept.json). Debian's QGIS opens no plain LAS/LAZ as a layer: give "
                   "the file below instead. On the command line: ept:///path/ept.json.",
    "TILE_FOLDER": "A folder whose LAS/LAZ/XYZ (or GeoTIFF DEM) files are the tiles (not "
                   "recursive).",
    "CHECK": "3-D points only measured each round, never inserted: an independent check.",
    "SNAP": "Boundary nodes within this distance (m) of an open boundary line become open.",
    "REGIONS": "Polygons whose triangles (by centroid) get a material id.",
    "DATUM_OFFSET": "Added to every elevation before writing (m).",
    "OUTPUT_FOLDER": "Folder for dem.tif, slope.tif, breakpoints.tif, breaklines.gpkg, "
                     "mesh.2dm (+ mesh.prj), mesh.gpkg, residuals.gpkg, the report's "
                     "pictures (PNG), report.json and report.html.",
}


def distance(algorithm, name, label, default, *, optional=False, minimum=0.0):
    """A horizontal distance in metres as QGIS's distance parameter: the dialog shows metres and
    converts from other units. It has no parent layer or CRS parameter: FloodMesh's data are
    in metres (core refuses any other unit), and QGIS 3.22 shows an unset parent's unit as
    '<unknown>' (the optional CRS, an input file QGIS cannot open as a layer). Vertical amounts
    (residuals, offsets, LoG responses) stay numbers with (m)."""
    from qgis.core import QgsProcessingParameterDistance

    parameter = QgsProcessingParameterDistance(name, algorithm.tr(label), default, "",
                                               optional, minimum)
    parameter.setDefaultUnit(METRES)
    return parameter


def labels(ids) -> list:
    """The labels an enum parameter shows for core's option ids (in their order)."""
    return [LABELS.get(i, i) for i in ids]


class FloodMeshAlgorithm(QgsProcessingAlgorithm):
    """Subclasses set NAME, DISPLAY_NAME, GROUP, GROUP_ID and HELP, and implement
    ``initAlgorithm`` and ``process``, which hands plain arguments to ``self.run_step`` (the
    core step in the worker process); they keep no state on ``self``."""

    NAME = DISPLAY_NAME = GROUP = GROUP_ID = HELP = ""
    TAGS = ()  # the algorithm's own search words (what it reads, writes and finds), beside TAGS

    def name(self):
        return self.NAME

    def addParameter(self, parameter, createOutput=True):  # noqa: N802
        """QGIS's addParameter, with the shared tooltip of PARAMETER_HELP."""
        text = PARAMETER_HELP.get(parameter.name())
        if text and not parameter.help():
            parameter.setHelp(self.tr(text))
        return super().addParameter(parameter, createOutput)

    def displayName(self):  # noqa: N802
        return self.tr(self.DISPLAY_NAME)

    def group(self):
        return self.tr(self.GROUP)

    def groupId(self):  # noqa: N802
        return self.GROUP_ID

    def shortHelpString(self):  # noqa: N802
        """The help QGIS renders beside the dialog: what the step does, each parameter, the
        method's terms."""
        rows = "".join(
            f"<dt><b>{html.escape(p.description(), quote=False)}</b></dt>"
            f"<dd>{html.escape(p.help(), quote=False)}</dd>"
            for p in self.parameterDefinitions() if p.help())
        return (f"<p>{html.escape(self.tr(self.HELP), quote=False)}</p>"
                f"{f'<dl>{rows}</dl>' if rows else ''}{GLOSSARY}")

    def shortDescription(self):  # noqa: N802
        return self.tr(self.HELP.split(". ")[0].split(": ")[0].rstrip(".") + ".")

    def tags(self):
        return [*TAGS, *self.TAGS]

    def helpUrl(self):  # noqa: N802
        # the help is the rendered text beside the dialog (shortHelpString): the project has no
        # public documentation address yet, and a file:// URL opens no browser on many desktops
        return ""

    def checkParameterValues(self, parameters, context):  # noqa: N802
        try:
            self.check_values(parameters, context)
            self.check_geometries(parameters, context)
            self.check_inputs_kept(parameters, context)
        except FloodMeshError as exc:  # core's own message, before QGIS's generic range check
            return False, str(exc)
        return super().checkParameterValues(parameters, context)

    def check_values(self, parameters, context):
        """Check parameter values with core's checks (raising FloodMeshError) before the run;
        subclasses override it. Core checks them again when it runs, with the same message."""

    def check_geometries(self, parameters, context):
        """A layer of points, lines or polygons given where another kind belongs (a file chosen
        with the dialog's … button, a path in a script or model): core's one line, before the
        run."""
        from qgis.core import QgsProcessingParameterFeatureSource

        for definition in self.parameterDefinitions():
            if (not isinstance(definition, QgsProcessingParameterFeatureSource)
                    or parameters.get(definition.name()) in (None, "")):
                continue
            needed = {SOURCE_GEOMETRIES.get(_number(t)) for t in definition.dataTypes()}
            layer = source_layer(self, parameters, definition.name(), context)
            if len(needed) != 1 or None in needed or layer is None or not layer.isValid():
                continue
            has = LAYER_GEOMETRIES.get(_number(layer.geometryType()))
            if has is not None and has not in needed:
                raise wrong_geometry(Path(layer.source().split("|")[0]).name or layer.name(),
                                     has, *needed)

    def check_inputs_kept(self, parameters, context):
        """An output named as the file of a vector input: refused, as core refuses it, also
        where the step reads the input from a temporary copy (selected features, a filter,
        unsaved edits), which is all core sees."""
        import os

        from qgis.core import (QgsProcessingOutputLayerDefinition,
                               QgsProcessingParameterFeatureSource,
                               QgsProcessingParameterFolderDestination)

        inputs, copied = {}, {}
        for definition in self.parameterDefinitions():
            if isinstance(definition, QgsProcessingParameterFeatureSource):
                layer = source_layer(self, parameters, definition.name(), context)
                own = layer.source().split("|")[0] if layer is not None else ""
                if own and os.path.isfile(own):
                    inputs[os.path.realpath(own)] = own
                    if read_from_copy(parameters.get(definition.name()), layer, context):
                        copied[os.path.dirname(os.path.realpath(own))] = own
        for definition in self.destinationParameterDefinitions():
            out = parameters.get(definition.name())
            if isinstance(out, QgsProcessingOutputLayerDefinition):
                out = out.sink.staticValue()
            if (out and isinstance(definition, QgsProcessingParameterFolderDestination)
                    and os.path.realpath(str(out)) in copied):
                raise FloodMeshError(
                    f"{copied[os.path.realpath(str(out))]} lies in the output folder {out} and "
                    f"is read from a copy (selected features, a filter, unsaved edits), so "
                    f"FloodMesh cannot tell whether the run would overwrite it: give another "
                    f"output folder")
            if out and os.path.realpath(str(out)) in inputs:
                raise FloodMeshError(
                    f"the output {out} is the input {inputs[os.path.realpath(str(out))]}: "
                    f"FloodMesh never overwrites an input; give the output another name or "
                    f"folder")

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        # core's step (core.steps) checks its files before any work: no output is or replaces
        # an input, each output folder is writable
        try:
            results = self.process(parameters, context, feedback)
        except FloodMeshError as exc:
            raise QgsProcessingException(str(exc)) from None
        drop_unasked_loads(self, parameters, context)
        return results

    def postProcessAlgorithm(self, context, feedback):  # noqa: N802
        # in QGIS's main thread, after the run, before QGIS loads its results
        reload_rewritten(context)
        stack_when_loaded(context)
        return {}

    def parameterAsOutputLayer(self, parameters, name, context):  # noqa: N802
        """QGIS's, refusing what is no file of its own: a table of a GeoPackage or database (the
        dialog's 'Save to GeoPackage…', 'Save to Database Table…') or a memory layer."""
        out = super().parameterAsOutputLayer(parameters, name, context)
        if out and (out.startswith("memory:") or "dbname=" in out):
            definition = self.parameterDefinition(name)
            raise FloodMeshError(
                f"{definition.description()}: FloodMesh writes each output as a file of its "
                f"own, not into a GeoPackage or database table nor a memory layer: give a file "
                f"name ending in .{definition.defaultFileExtension()} or a temporary output")
        return out

    def run_step(self, step, args, feedback, *outputs):
        """Core's ``step`` on ``args`` in the worker process (see ``child.run_step``); the
        ``outputs`` (files or folders) are where a killed worker's temporaries are removed."""
        return run_step(step, args, feedback, outputs=outputs, what=self.displayName())

    def optional_number(self, parameters, name, context):
        """A number parameter's value, or None when left empty."""
        if parameters.get(name) in (None, ""):
            return None
        return self.parameterAsDouble(parameters, name, context)

    def process(self, parameters, context, feedback):
        raise NotImplementedError

    def createInstance(self):  # noqa: N802
        return type(self)()

    def tr(self, text):
        return QCoreApplication.translate("FloodMesh", text)


def layer_file(layer, what: str) -> str:
    """The file behind a raster or vector layer (without a GeoPackage layer suffix)."""
    if layer is None:
        raise QgsProcessingException(f"{what}: no layer given")
    path = layer.source().split("|")[0]
    if not Path(path).is_file():
        raise QgsProcessingException(f"{what} must be a file-based layer (GeoTIFF, GeoPackage…); "
                                     f"{layer.name()} is not: save it to a file first")
    return path


# vector formats core reads as QGIS has them; any other layer is saved to a GeoPackage first
VECTOR_FILES = ["gpkg", "shp", "geojson", "json", "fgb"]


def source_layer(algorithm, parameters, name, context):
    """The layer of the vector parameter ``name``, also where it comes with options (selected
    features only, a feature limit or filter, its invalid-geometry handling), for which QGIS's
    parameterAsVectorLayer gives none."""
    from qgis.core import QgsProcessingFeatureSourceDefinition

    value = parameters.get(name)
    if isinstance(value, QgsProcessingFeatureSourceDefinition):
        parameters = {**parameters, name: value.source}
    return algorithm.parameterAsVectorLayer(parameters, name, context)


def read_from_copy(value, layer, context) -> bool:
    """Whether a step reads the vector input ``value`` (of ``layer``) from a temporary copy,
    not from the layer's file: input options, a layer filter, unsaved edits, skipped invalid
    geometries."""
    from qgis.core import QgsProcessingFeatureSourceDefinition

    return (isinstance(value, QgsProcessingFeatureSourceDefinition) or layer.isModified()
            or bool(layer.subsetString()) or skips_invalid(value, context))


def skips_invalid(value, context) -> bool:
    """Whether invalid geometries of the input ``value`` are to be skipped: its own 'Invalid
    feature filtering' (the dialog's advanced options of the input) or else Processing's."""
    from qgis.core import QgsProcessingFeatureSourceDefinition

    check = context.invalidGeometryCheck()
    if isinstance(value, QgsProcessingFeatureSourceDefinition) and value.flags & OWN_GEOMETRY_CHECK:
        check = value.geometryCheck
    return _number(check) == _number(SKIP_INVALID)


def features_file(algorithm, parameters, name, context, feedback=None):
    """A temporary GeoPackage of the features QGIS gives for the vector parameter ``name``:
    its selection, filter and limit, the layer's unsaved edits, less invalid geometries where
    they are skipped (QGIS reports each)."""
    from qgis.core import QgsVectorFileWriter

    source = algorithm.parameterAsSource(parameters, name, context)
    if source is None:
        return None
    path = temporary_file(f"{name}.gpkg", context)
    options = QgsVectorFileWriter.SaveVectorOptions()
    options.driverName = "GPKG"
    writer = QgsVectorFileWriter.create(path, source.fields(), source.wkbType(),
                                        source.sourceCrs(), context.transformContext(), options)
    for feature in source.getFeatures():
        if feedback is not None and feedback.isCanceled():
            break
        writer.addFeature(feature)
    error = writer.errorMessage() if writer.hasError() else ""
    del writer  # closes the file
    if error:
        raise QgsProcessingException(
            f"{algorithm.parameterDefinition(name).description()}: could not save its valid "
            f"features to {path} ({error}): check the free space of the temporary folder")
    return path


def vector_file(algorithm, parameters, name, context, feedback=None):
    """The file core reads for the vector parameter ``name``, None when it is not given: the
    layer's own file (``file.gpkg|layername=NAME`` for one layer of a GeoPackage), or, for
    what only QGIS holds (a memory or database layer, selected features only, a layer's
    filter, a filter expression or feature limit of the input), a temporary GeoPackage of those
    features, as QGIS hands layers to GDAL's tools; without the invalid ones where invalid
    features are to be skipped (the input's or Processing's setting), and of a layer with
    unsaved edits (what QGIS shows, not its file)."""
    from qgis.core import QgsProcessingFeedback

    if feedback is None:  # QGIS 3.22 dereferences it while it copies features: a crash
        feedback = QgsProcessingFeedback()
    given = source_layer(algorithm, parameters, name, context)
    if given is not None and (skips_invalid(parameters.get(name), context) or given.isModified()):
        path, layer = features_file(algorithm, parameters, name, context, feedback), ""
    else:
        path, layer = algorithm.parameterAsCompatibleSourceLayerPathAndLayerName(
            parameters, name, context, VECTOR_FILES, "gpkg", feedback)
    if not path:
        return None
    if given is not None and is_copy(path, given):
        path = named_after_layer(path, given)
        check_features_left(path, given, parameters.get(name))
    return f"{path}|layername={layer}" if layer else path


def is_copy(path: str, layer) -> bool:
    """Whether ``path`` is a temporary copy of ``layer``'s features, not its own file."""
    import os

    own = layer.source().split("|")[0]
    return not own or os.path.realpath(own) != os.path.realpath(path)


def named_after_layer(path: str, layer) -> str:
    """A temporary copy of ``layer``'s features (``path``, which QGIS names after the
    parameter, e.g. BREAKLINES.gpkg) renamed after the layer, so that core's messages name the
    layer the user gave."""
    import os

    from qgis.core import QgsFileUtils

    named = Path(path).with_name(QgsFileUtils.stringToSafeFilename(layer.name())
                                 + Path(path).suffix)
    if not layer.name() or named.exists():
        return path
    os.replace(path, named)
    return str(named)


def check_features_left(path: str, layer, value) -> None:
    """Refuse a copy that the input's options (``value``: selected features only, a feature
    limit or filter, skipping invalid geometries) left empty, where the layer itself has
    features: the step would otherwise run without them (a mesh without its lines) or blame the
    layer. A filter expression that does not parse or names no field of the layer says so."""
    from qgis.core import QgsVectorLayer

    total = layer.featureCount()
    if total <= 0 or QgsVectorLayer(path, "copy", "ogr").featureCount() > 0:
        return
    problem = filter_problem(getattr(value, "filterExpression", ""), layer)
    if problem:
        raise FloodMeshError(f"{layer.name()}: {problem}: correct the input's feature filter")
    raise FloodMeshError(
        f"{layer.name()}: none of its {total} features is left by the input's options "
        f"(selected features only, a feature limit or filter, invalid geometries skipped): "
        f"select features or change the options")


def filter_problem(expression: str, layer) -> str:
    """Why the feature filter ``expression`` cannot select features of ``layer`` (it does not
    parse, or it names no field of the layer), or ''."""
    from qgis.core import QgsExpression, QgsExpressionContext, QgsExpressionContextUtils

    if not expression:
        return ""
    parsed = QgsExpression(expression)
    if parsed.hasParserError():
        return (f"its feature filter {expression!r} is not an expression "
                f"({' '.join(parsed.parserErrorString().split())})")
    context = QgsExpressionContext(QgsExpressionContextUtils.globalProjectLayerScopes(layer))
    if not parsed.prepare(context) and parsed.hasEvalError():
        return (f"its feature filter {expression!r} fails "
                f"({' '.join(parsed.evalErrorString().split())})")
    return ""


def vector_crs(algorithm, parameters, name, context):
    """The WKT of the vector parameter's CRS as QGIS has it (set on a file without one), or
    None."""
    source = algorithm.parameterAsSource(parameters, name, context)
    return (source.sourceCrs().toWkt() or None) if source is not None else None


def crs_or_none(algorithm, parameters, name, context):
    """The CRS parameter as core takes it: its EPSG code where it has one (so that messages name
    it as the command line does), else its WKT; None when not given."""
    crs = algorithm.parameterAsCrs(parameters, name, context)
    if not crs.isValid():
        return None
    return crs.authid() if crs.authid().upper().startswith("EPSG:") else crs.toWkt()


POINT_CLOUD = "POINT_CLOUD"


def point_cloud_parameter(algorithm, label):
    """A point-cloud layer (QGIS's own LAS/LAZ/COPC layers where QGIS has PDAL, EPT and COPC
    everywhere), optional beside the file parameters, which stay for qgis_process, models and
    QGIS builds without PDAL (Debian's)."""
    from qgis.core import QgsProcessingParameterPointCloudLayer

    return QgsProcessingParameterPointCloudLayer(POINT_CLOUD, algorithm.tr(label), optional=True)


def point_cloud_file(algorithm, parameters, context):
    """The file behind the POINT_CLOUD layer (LAS/LAZ, COPC or an EPT's ept.json), or None."""
    layer = algorithm.parameterAsPointCloudLayer(parameters, POINT_CLOUD, context)
    if layer is None:
        return None
    path = layer.source()
    if not Path(path).is_file() or not is_point_source(path):
        raise FloodMeshError(
            f"Point cloud layer {layer.name()} is not a LAS/LAZ, COPC or EPT (ept.json) file "
            f"FloodMesh can read ({path}): export it to LAZ first")
    return path


BOUNDARY, USER_LINES = "BOUNDARY", "USER_LINES"


def add_domain_parameters(algorithm):
    """The optional model-domain polygon and the modeller's own lines, as in Build mesh."""
    from qgis.core import QgsProcessing, QgsProcessingParameterFeatureSource

    algorithm.addParameter(QgsProcessingParameterFeatureSource(
        BOUNDARY, algorithm.tr("Model domain polygon (holes left out; default: the data's "
                               "extent)"), [VECTOR_POLYGON], optional=True))
    algorithm.addParameter(QgsProcessingParameterFeatureSource(
        USER_LINES, algorithm.tr("Own break or structure lines (2-D lines take z from the DEM)"),
        [VECTOR_LINE], optional=True))


def domain_files(algorithm, parameters, context, feedback=None) -> tuple:
    """(boundary file or None, user line file or None) from add_domain_parameters."""
    return tuple(vector_file(algorithm, parameters, name, context, feedback)
                 for name in (BOUNDARY, USER_LINES))


def mesh_input_args(algorithm, parameters, context, feedback=None) -> dict:
    """The worker's arguments for the DEM, BREAKLINES, BOUNDARY and USER_LINES parameters of a
    meshing algorithm."""
    boundary, user_lines = domain_files(algorithm, parameters, context, feedback)
    return {"dem": layer_file(algorithm.parameterAsRasterLayer(parameters, "DEM", context), "DEM"),
            "breaklines": vector_file(algorithm, parameters, "BREAKLINES", context, feedback),
            "boundary": boundary, "user_lines": user_lines}
