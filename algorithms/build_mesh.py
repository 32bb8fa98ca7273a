"""Build mesh: break lines and the DEM's extent as a PSLG, refined by Triangle."""
from qgis.core import (QgsProcessingOutputNumber, QgsProcessingParameterDefinition,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterLayer,
                       QgsProcessingParameterVectorDestination)
from .compat import DOUBLE, INTEGER, VECTOR_LINE, VECTOR_POLYGON

from ..core.options import (DEFAULT_MAX_TRIANGLES, MAX_MIN_ANGLE, check_flow_area,
                            check_max_area, check_max_triangles, check_min_angle)
from .base import FloodMeshAlgorithm, add_domain_parameters, layer_file, mesh_input_args
from .styles import load_mesh, style_triangles, style_when_loaded


class BuildMeshAlgorithm(FloodMeshAlgorithm):
    NAME = "buildmesh"
    DISPLAY_NAME = "Build mesh"
    TAGS = ("mesh", "triangle", "triangulation", "pslg", "quality mesh", "2dm", "sms",
            "finite element")
    GROUP, GROUP_ID = "4 · Mesh", "mesh"
    HELP = ("Meshes the DEM's valid area with Triangle (conforming Delaunay refinement), "
            "honouring the break lines: no angle below the minimum (degrees, default 25, at most "
            "34) and no triangle above the maximum area (m², default 100). Break-line vertices "
            "keep their z; other nodes take z bilinearly from the DEM. A model domain polygon "
            "(with holes for buildings or islands) replaces the data's extent; your own lines "
            "are kept as mesh edges. A size field raster (m², nodata: no limit) sets a local "
            "maximum area, and so does the flow area (m², default 23 cells; 0: off) on ground "
            "less than 1 m above a drainage line (height above the nearest drainage), where a "
            "flood goes first, wherever the mesh without it misses that ground's relief "
            "(kerbs, gutters, swales; a plane floodplain keeps its larger triangles). Writes "
            "SMS 2DM and, optionally, the triangles as PolygonZ.")
    DEM, BREAKLINES, MIN_ANGLE, MAX_AREA = "DEM", "BREAKLINES", "MIN_ANGLE", "MAX_AREA"
    SIZE_FIELD, MAX_TRIANGLES, FLOW_AREA = "SIZE_FIELD", "MAX_TRIANGLES", "FLOW_AREA"
    OUTPUT, TRIANGLES, NODES, TRIANGLE_COUNT = "OUTPUT", "TRIANGLES", "NODES", "TRIANGLE_COUNT"

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(self.DEM, self.tr("DEM")))
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.BREAKLINES, self.tr("Break lines"), [VECTOR_LINE],
            optional=True))
        add_domain_parameters(self)
        self.addParameter(QgsProcessingParameterNumber(
            self.MIN_ANGLE, self.tr("Minimum angle (degrees)"),
            DOUBLE, 25.0, minValue=0.0, maxValue=MAX_MIN_ANGLE))
        self.addParameter(QgsProcessingParameterNumber(
            self.MAX_AREA, self.tr("Maximum triangle area (m²)"),
            DOUBLE, 100.0, minValue=0.0))
        self.addParameter(QgsProcessingParameterRasterLayer(
            self.SIZE_FIELD, self.tr("Size field: local maximum area (m²)"), optional=True))
        self.addParameter(flow_area_parameter(self.FLOW_AREA, self.tr))
        self.addParameter(max_triangles_parameter(self.MAX_TRIANGLES, self.tr))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT, self.tr("Mesh (SMS 2DM)"), fileFilter="SMS 2DM (*.2dm)"))
        self.addParameter(QgsProcessingParameterVectorDestination(
            self.TRIANGLES, self.tr("Triangles"), VECTOR_POLYGON, optional=True,
            createByDefault=False))
        self.addOutput(QgsProcessingOutputNumber(self.NODES, self.tr("Nodes")))
        self.addOutput(QgsProcessingOutputNumber(self.TRIANGLE_COUNT, self.tr("Triangles")))

    def check_values(self, parameters, context):
        check_min_angle(self.parameterAsDouble(parameters, self.MIN_ANGLE, context))
        check_max_area(self.parameterAsDouble(parameters, self.MAX_AREA, context))
        check_max_triangles(self.parameterAsInt(parameters, self.MAX_TRIANGLES, context))
        check_flow_area(self.optional_number(parameters, self.FLOW_AREA, context))

    def process(self, parameters, context, feedback):
        size_layer = self.parameterAsRasterLayer(parameters, self.SIZE_FIELD, context)
        out = self.parameterAsFileOutput(parameters, self.OUTPUT, context)
        triangles_out = self.parameterAsOutputLayer(parameters, self.TRIANGLES, context)
        result = self.run_step("build_mesh", {
            **mesh_input_args(self, parameters, context, feedback),
            "min_angle": self.parameterAsDouble(parameters, self.MIN_ANGLE, context),
            "max_area": self.parameterAsDouble(parameters, self.MAX_AREA, context),
            "size_field": layer_file(size_layer, "Size field") if size_layer else None,
            "max_triangles": self.parameterAsInt(parameters, self.MAX_TRIANGLES, context),
            "flow_area": self.optional_number(parameters, self.FLOW_AREA, context),
            "output": out, "triangles": triangles_out or None}, feedback, out, triangles_out)
        load_mesh(context, out, "Mesh", self.OUTPUT, result["crs"])
        if triangles_out:
            style_when_loaded(context, triangles_out, style_triangles)
        return {k: v for k, v in result.items()
                if k in (self.OUTPUT, self.NODES, self.TRIANGLE_COUNT, self.TRIANGLES)}


def flow_area_parameter(name, tr):
    """Optional: the triangle area (m²) where water flows, shared with LiDAR to mesh."""
    return QgsProcessingParameterNumber(
        name, tr("Triangle area where water flows: low ground by the drainage lines (m²; "
                 "empty: 23 cells, 0: off)"), DOUBLE, optional=True, minValue=0.0)


def max_triangles_parameter(name, tr):
    """The advanced parameter that caps the mesh size, shared with LiDAR to mesh."""
    parameter = QgsProcessingParameterNumber(
        name, tr("Maximum number of triangles (refused before meshing above it)"),
        INTEGER, DEFAULT_MAX_TRIANGLES, minValue=1)
    parameter.setFlags(parameter.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
    return parameter
