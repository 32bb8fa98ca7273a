"""What every FloodMesh algorithm shares: names, groups, help, parameter checks, and running
the core step in the worker process (``child.run_step``).

Only ``core.options`` and ``core.errors`` (plain Python) are imported into QGIS; the numerical
core runs in the worker."""
from pathlib import Path

from qgis.core import QgsProcessingAlgorithm, QgsProcessingException
from qgis.PyQt.QtCore import QCoreApplication

from ..core.errors import FloodMeshError
from .child import run_step


class FloodMeshAlgorithm(QgsProcessingAlgorithm):
    """Subclasses set NAME, DISPLAY_NAME, GROUP, GROUP_ID and HELP, and implement
    ``initAlgorithm`` and ``process``, which hands plain arguments to ``self.run_step`` (the
    core step in the worker process); they keep no state on ``self``."""

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
        try:
            self.check_values(parameters, context)
        except FloodMeshError as exc:  # core's own message, before QGIS's generic range check
            return False, str(exc)
        return super().checkParameterValues(parameters, context)

    def check_values(self, parameters, context):
        """Check parameter values with core's checks (raising FloodMeshError) before the run;
        subclasses override it. Core checks them again when it runs, with the same message."""

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        return self.process(parameters, context, feedback)

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
    from qgis.core import QgsProcessing, QgsProcessingParameterFeatureSource

    algorithm.addParameter(QgsProcessingParameterFeatureSource(
        BOUNDARY, algorithm.tr("Model domain polygon (holes left out; default: the data's "
                               "extent)"), [QgsProcessing.TypeVectorPolygon], optional=True))
    algorithm.addParameter(QgsProcessingParameterFeatureSource(
        USER_LINES, algorithm.tr("Own break or structure lines (2-D lines take z from the DEM)"),
        [QgsProcessing.TypeVectorLine], optional=True))


def domain_files(algorithm, parameters, context) -> tuple:
    """(boundary file or None, user line file or None) from add_domain_parameters."""
    def path(name, what):
        layer = algorithm.parameterAsVectorLayer(parameters, name, context)
        return layer_file(layer, what) if layer is not None else None

    return path(BOUNDARY, "Model domain polygon"), path(USER_LINES, "Own lines")


def mesh_input_args(algorithm, parameters, context) -> dict:
    """The worker's arguments for the DEM, BREAKLINES, BOUNDARY and USER_LINES parameters of a
    meshing algorithm."""
    lines = algorithm.parameterAsVectorLayer(parameters, "BREAKLINES", context)
    boundary, user_lines = domain_files(algorithm, parameters, context)
    return {"dem": layer_file(algorithm.parameterAsRasterLayer(parameters, "DEM", context), "DEM"),
            "breaklines": layer_file(lines, "Break lines") if lines is not None else None,
            "boundary": boundary, "user_lines": user_lines}
