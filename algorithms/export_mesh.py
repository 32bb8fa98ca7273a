"""Export mesh: a FloodMesh mesh (SMS 2DM) written for a solver."""
from pathlib import Path

from qgis.core import (QgsProcessingOutputFile,
                       QgsProcessingParameterBoolean, QgsProcessingParameterCrs,
                       QgsProcessingParameterEnum, QgsProcessingParameterFeatureSource,
                       QgsProcessingParameterField, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterMeshLayer, QgsProcessingParameterNumber)
from .compat import DOUBLE, VECTOR_LINE, VECTOR_POLYGON

from ..core.options import EXPORT_EXTENSIONS as EXTENSIONS
from ..core.options import EXPORT_FORMAT_LABELS, EXPORT_FORMATS
from .base import FloodMeshAlgorithm, crs_or_none, distance, layer_file, vector_file
from .styles import load_results, style_breaklines, style_mesh, style_triangles

GPKG_LAYERS = ("breaklines", "boundary", "nodes", "triangles")  # what write_gpkg writes
FILE_FILTER = ";;".join(f"{label} (*{EXTENSIONS[f]})"
                        for f, label in zip(EXPORT_FORMATS, EXPORT_FORMAT_LABELS))


class ExportMeshAlgorithm(FloodMeshAlgorithm):
    NAME = "exportmesh"
    DISPLAY_NAME = "Export mesh"
    TAGS = ("export", "2dm", "telemac", "selafin", "slf", "adcirc", "fort.14", "schism", "gr3",
            "ugrid", "netcdf", "hec-ras", "tuflow", "basement", "d-flow", "solver",
            "boundary conditions")
    GROUP, GROUP_ID = "4 · Mesh", "mesh"
    HELP = ("Writes a FloodMesh mesh (SMS 2DM) in a solver's format: SMS 2DM with material ids "
            "and node strings (BASEMENT, TUFLOW FV, SRH-2D), TELEMAC Selafin with its boundary "
            "conditions file (.cli), ADCIRC fort.14 and SCHISM hgrid.gr3 (depth positive down), "
            "UGRID netCDF (D-Flow FM, QGIS) or GeoPackage layers (HEC-RAS). The whole boundary "
            "is land (solid wall) except where an open boundary line (inflow, outflow section) "
            "passes within the snapping distance (m) of its nodes. Region polygons set material "
            "ids by triangle centroid (their integer field, or 2, 3, … in order; 1 elsewhere). "
            "The datum offset (m) is added to every elevation.")
    INPUT, FORMAT, OUTPUT, CRS = "INPUT", "FORMAT", "OUTPUT", "CRS"
    OPEN_BOUNDARIES, SNAP = "OPEN_BOUNDARIES", "SNAP"
    REGIONS, MATERIAL_FIELD = "REGIONS", "MATERIAL_FIELD"
    DATUM_OFFSET, ELEMENT_ELEVATIONS, BREAKLINES = "DATUM_OFFSET", "ELEMENT_ELEVATIONS", "BREAKLINES"
    CLI = "CLI"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterMeshLayer(self.INPUT, self.tr("Mesh (SMS 2DM)")))
        self.addParameter(QgsProcessingParameterEnum(
            self.FORMAT, self.tr("Format"), options=list(EXPORT_FORMAT_LABELS), defaultValue=0))
        self.addParameter(QgsProcessingParameterCrs(
            self.CRS, self.tr("CRS of the mesh (when the layer has none)"), optional=True))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.OPEN_BOUNDARIES, self.tr("Open boundary lines (inflow, outflow sections)"),
            [VECTOR_LINE], optional=True))
        self.addParameter(distance(self, self.SNAP, "Snapping distance to open boundary lines",
                                   1.0, minimum=0.001))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.REGIONS, self.tr("Region polygons (material ids)"),
            [VECTOR_POLYGON], optional=True))
        self.addParameter(QgsProcessingParameterField(
            self.MATERIAL_FIELD, self.tr("Material id field"), parentLayerParameterName=self.REGIONS,
            type=QgsProcessingParameterField.Numeric, optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            self.DATUM_OFFSET, self.tr("Vertical datum offset added to elevations (m)"),
            DOUBLE, 0.0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.ELEMENT_ELEVATIONS, self.tr("2DM: element-centre elevations (BASEMENT 3)"),
            defaultValue=False))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.BREAKLINES, self.tr("Break lines (GeoPackage layer)"),
            [VECTOR_LINE], optional=True))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT, self.tr("Exported mesh"), fileFilter=FILE_FILTER))
        self.addOutput(QgsProcessingOutputFile(self.CLI, self.tr("TELEMAC boundary conditions")))

    def process(self, parameters, context, feedback):
        fmt = EXPORT_FORMATS[self.parameterAsEnum(parameters, self.FORMAT, context)]
        mesh_layer = self.parameterAsMeshLayer(parameters, self.INPUT, context)
        crs = crs_or_none(self, parameters, self.CRS, context)
        if crs is None and mesh_layer is not None and mesh_layer.crs().isValid():
            crs = mesh_layer.crs().toWkt()
        files = {name: vector_file(self, parameters, name, context, feedback)
                 for name in (self.OPEN_BOUNDARIES, self.REGIONS, self.BREAKLINES)}
        out = Path(self.parameterAsFileOutput(parameters, self.OUTPUT, context))
        if out.suffix.lower() != EXTENSIONS[fmt]:  # the format chosen decides the extension
            out = out.with_suffix(EXTENSIONS[fmt])
        result = self.run_step("export", {
            "mesh": layer_file(mesh_layer, "Mesh"), "output": str(out), "fmt": fmt, "crs": crs,
            "open_boundaries": files[self.OPEN_BOUNDARIES], "regions": files[self.REGIONS],
            "material_field": self.parameterAsString(parameters, self.MATERIAL_FIELD,
                                                     context) or None,
            "breaklines": files[self.BREAKLINES],
            "snap": self.parameterAsDouble(parameters, self.SNAP, context),
            "datum_offset": self.parameterAsDouble(parameters, self.DATUM_OFFSET, context),
            "element_elevations": self.parameterAsBool(parameters, self.ELEMENT_ELEVATIONS,
                                                       context)}, feedback, out)
        self.load_export(context, out, fmt, crs)
        return {k: v for k, v in result.items() if k in (self.OUTPUT, self.CLI)}

    def load_export(self, context, out: Path, fmt: str, crs) -> None:
        """Load what QGIS opens of the export, as Build mesh loads its mesh: a 2DM or UGRID
        netCDF as a mesh layer shaded by elevation; a GeoPackage's layers in one group named
        after the file; the solvers' own formats (Selafin, fort.14, gr3) are left unloaded."""
        from qgis.core import QgsMeshLayer, QgsVectorLayer

        if fmt in ("2dm", "nc"):
            layers = [(QgsMeshLayer(str(out), "Exported mesh", "mdal"), style_mesh)]
        elif fmt == "gpkg":
            styles = {"breaklines": style_breaklines, "triangles": style_triangles}
            layers = [(QgsVectorLayer(f"{out}|layername={name}", name, "ogr"),
                       styles.get(name, lambda _: None)) for name in GPKG_LAYERS]
        else:
            return
        load_results(context, crs, [(layer, style, self.OUTPUT) for layer, style in layers
                                    if layer.isValid()],
                     **({"group": out.name, "folder": out} if fmt == "gpkg" else {}))
