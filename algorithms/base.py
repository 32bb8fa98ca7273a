"""What every FloodMesh algorithm shares: names, groups, help, and turning core errors into
messages QGIS shows."""
from pathlib import Path

from qgis.core import QgsProcessingAlgorithm, QgsProcessingException
from qgis.PyQt.QtCore import QCoreApplication
from .compat import VECTOR_LINE, VECTOR_POLYGON

from ..core.dependencies import install_hint, missing_dependencies
from ..core.errors import Cancelled, FloodMeshError


class FloodMeshAlgorithm(QgsProcessingAlgorithm):
    """Subclasses set NAME, DISPLAY_NAME, GROUP, GROUP_ID and HELP, and implement
    ``initAlgorithm`` and ``process`` (importing the numerical core there, so that the plugin
    loads even where a dependency is missing); they keep no state on ``self``."""

    NAME = DISPLAY_NAME = GROUP = GROUP_ID = HELP = ""

    def name(self):
        return self.NAME

    def displayName(self):  # noqa: N802
        return self.tr(self.DISPLAY_NAME)

    def group(self):
        return self.tr(self.GROUP)

    def groupId(self):  # noqa: N802
        return self.GROUP_ID

    def shortHelpString(self):  # noqa: N802
        return self.tr(self.HELP)

    def checkParameterValues(self, parameters, context):  # noqa: N802
        missing = missing_dependencies()
        if missing:
            return False, install_hint(missing)
        try:
            self.check_values(parameters, context)
        except FloodMeshError as exc:  # core's own message, before QGIS's generic range check
            return False, str(exc)
        return super().checkParameterValues(parameters, context)

    def check_values(self, parameters, context):
        """Check parameter values with core's checks (raising FloodMeshError) before the run;
        subclasses override it. Core checks them again when it runs, with the same message."""

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        missing = missing_dependencies()
        if missing:
            raise QgsProcessingException(install_hint(missing))
        from ..core.outputs import check_outputs

        run_core(check_outputs, *self.files(parameters, context))
        return self.process(parameters, context, feedback)

    def files(self, parameters, context) -> tuple[list, list]:
        """(files read, files written) by the parameters, for core's check that no output is
        or replaces an input (a folder output is checked by the core call it goes to)."""
        from qgis.core import (QgsProcessing, QgsProcessingOutputLayerDefinition,
                               QgsProcessingParameterFeatureSource, QgsProcessingParameterFile,
                               QgsProcessingParameterFolderDestination,
                               QgsProcessingParameterMeshLayer,
                               QgsProcessingParameterRasterLayer,
                               QgsProcessingParameterVectorLayer)

        inputs, outputs = [], []
        for p in self.parameterDefinitions():
            name = p.name()
            if p.isDestination():
                # the value as given (parameterAsOutputLayer would add a layer to load)
                value = parameters.get(name)
                if isinstance(value, QgsProcessingOutputLayerDefinition):
                    value = value.sink.staticValue()
                if (isinstance(value, str) and value != QgsProcessing.TEMPORARY_OUTPUT
                        and not isinstance(p, QgsProcessingParameterFolderDestination)):
                    outputs.append(value)
            elif isinstance(p, QgsProcessingParameterFile):
                inputs.append(self.parameterAsFile(parameters, name, context))
            elif isinstance(p, QgsProcessingParameterRasterLayer):
                layer = self.parameterAsRasterLayer(parameters, name, context)
                inputs.append(layer.source() if layer else None)
            elif isinstance(p, QgsProcessingParameterMeshLayer):
                layer = self.parameterAsMeshLayer(parameters, name, context)
                inputs.append(layer.source() if layer else None)
            elif isinstance(p, (QgsProcessingParameterFeatureSource,
                                QgsProcessingParameterVectorLayer)):
                layer = self.parameterAsVectorLayer(parameters, name, context)
                inputs.append(layer.source().split("|")[0] if layer else None)
        return inputs, [o for o in outputs if o and not o.startswith(("memory:", "ogr:"))]

    def process(self, parameters, context, feedback):
        raise NotImplementedError

    def createInstance(self):  # noqa: N802
        return type(self)()

    def tr(self, text):
        return QCoreApplication.translate("FloodMesh", text)


def run_core(func, *args, **kwargs):
    """Call a core function; bad input becomes a QgsProcessingException with the same message."""
    try:
        return func(*args, **kwargs)
    except FloodMeshError as exc:
        raise QgsProcessingException(str(exc)) from None
    except Cancelled:
        raise QgsProcessingException("Cancelled; no partial output was written") from None


def feedback_callables(feedback):
    """Progress and cancellation as the plain callables core takes."""
    return {"progress": lambda f: feedback.setProgress(100 * f),
            "cancelled": feedback.isCanceled}


def layer_file(layer, what: str) -> str:
    """The file behind a raster or vector layer (without a GeoPackage layer suffix)."""
    if layer is None:
        raise QgsProcessingException(f"{what}: no layer given")
    path = layer.source().split("|")[0]
    if not Path(path).is_file():
        raise QgsProcessingException(f"{what} must be a file-based layer (GeoTIFF, GeoPackage…); "
                                     f"{layer.name()} is not: save it to a file first")
    return path


def crs_or_none(algorithm, parameters, name, context):
    """The CRS parameter as core takes it: its EPSG code where it has one (so that messages name
    it as the command line does), else its WKT; None when not given."""
    crs = algorithm.parameterAsCrs(parameters, name, context)
    if not crs.isValid():
        return None
    return crs.authid() if crs.authid().upper().startswith("EPSG:") else crs.toWkt()


BOUNDARY, USER_LINES = "BOUNDARY", "USER_LINES"


def add_domain_parameters(algorithm):
    """The optional model-domain polygon and the modeller's own lines, as in Build mesh."""
    from qgis.core import QgsProcessingParameterFeatureSource

    algorithm.addParameter(QgsProcessingParameterFeatureSource(
        BOUNDARY, algorithm.tr("Model domain polygon (holes left out; default: the data's "
                               "extent)"), [VECTOR_POLYGON], optional=True))
    algorithm.addParameter(QgsProcessingParameterFeatureSource(
        USER_LINES, algorithm.tr("Own break or structure lines (2-D lines take z from the DEM)"),
        [VECTOR_LINE], optional=True))


def domain_files(algorithm, parameters, context) -> tuple:
    """(boundary file or None, user line file or None) from add_domain_parameters."""
    def path(name, what):
        layer = algorithm.parameterAsVectorLayer(parameters, name, context)
        return layer_file(layer, what) if layer is not None else None

    return path(BOUNDARY, "Model domain polygon"), path(USER_LINES, "Own lines")


def read_mesh_inputs(algorithm, parameters, context) -> tuple:
    """(DEM, break lines plus own lines, domain) from the DEM, BREAKLINES, BOUNDARY and
    USER_LINES parameters of a meshing algorithm."""
    from ..core import io
    from ..core.pipeline import mesh_constraints

    dem = run_core(io.read_raster, layer_file(
        algorithm.parameterAsRasterLayer(parameters, "DEM", context), "DEM"))
    lines_layer = algorithm.parameterAsVectorLayer(parameters, "BREAKLINES", context)
    lines = (run_core(io.read_lines_gpkg, layer_file(lines_layer, "Break lines"))
             if lines_layer is not None else [])
    domain, own_lines = run_core(mesh_constraints, dem,
                                 *domain_files(algorithm, parameters, context))
    return dem, lines + own_lines, domain
