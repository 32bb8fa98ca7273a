"""Build models/lidar_to_mesh_steps.model3: the seven step algorithms chained in the Graphical
Modeler (run with the QGIS Python: QT_QPA_PLATFORM=offscreen .venv/bin/python scripts/...).
Every mandatory child parameter is bound, to a model input, another step's output or the
step's own default, so that the Modeler opens the model valid and it runs with its inputs."""
import os
import sys
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
from qgis.core import (QgsApplication, QgsProcessing, QgsProcessingModelAlgorithm,  # noqa: E402
                       QgsProcessingModelChildAlgorithm, QgsProcessingModelChildParameterSource,
                       QgsProcessingModelOutput, QgsProcessingModelParameter,
                       QgsProcessingParameterFile, QgsProcessingParameterNumber)
from qgis.PyQt.QtCore import QPointF  # noqa: E402

app = QgsApplication([], False)
app.initQgis()
sys.path.append("/usr/share/qgis/python/plugins")  # the Processing framework
from processing.core.Processing import Processing  # noqa: E402

from floodmesh.provider.provider import FloodMeshProvider  # noqa: E402

Processing.initialize()
provider = FloodMeshProvider()  # the steps' parameters come from the algorithms themselves
QgsApplication.processingRegistry().addProvider(provider)

model = QgsProcessingModelAlgorithm("LiDAR to mesh step by step", "Models", "models")
model.setHelpContent({"ALG_DESC": "The FloodMesh chain as separate steps: grid, slope, "
                      "breakpoints, break lines, simplification, mesh and assessment. Open it "
                      "in the Graphical Modeler to change or extend a step."})
inputs = [
    (QgsProcessingParameterFile("points", "LiDAR points",
                                fileFilter="Point clouds (*.las *.laz *.xyz *.txt *.csv)"), 0),
    (QgsProcessingParameterNumber("cell_size", "Cell size d (m)",
                                  QgsProcessingParameterNumber.Double, 1.0, minValue=0.01), 1),
    (QgsProcessingParameterNumber("s_crit", "Critical slope S_crit (degrees)",
                                  QgsProcessingParameterNumber.Double, 10.0, minValue=0.01,
                                  maxValue=89.99), 2),
    (QgsProcessingParameterNumber("min_angle", "Minimum angle (degrees)",
                                  QgsProcessingParameterNumber.Double, 25.0, minValue=0.01,
                                  maxValue=34.0), 3),
    (QgsProcessingParameterNumber("max_area", "Maximum triangle area (m²)",
                                  QgsProcessingParameterNumber.Double, 100.0, minValue=0.0001), 4),
]
for parameter, row in inputs:
    component = QgsProcessingModelParameter(parameter.name())
    component.setPosition(QPointF(120, 60 + 70 * row))
    model.addModelParameter(parameter, component)


def param(name):
    return [QgsProcessingModelChildParameterSource.fromModelParameter(name)]


def child_output(child, output):
    return [QgsProcessingModelChildParameterSource.fromChildOutput(child, output)]


def static(value):
    return [QgsProcessingModelChildParameterSource.fromStaticValue(value)]


steps = [
    ("grid", "floodmesh:gridpoints", {"INPUT": param("points"), "CELL_SIZE": param("cell_size"),
                                      "HOLDOUT": static(0.01), "SEED": static(0),
                                      "HOLDOUT_OUTPUT": static("TEMPORARY_OUTPUT")}, {}),
    ("slope", "floodmesh:slope", {"INPUT": child_output("grid", "OUTPUT"), "METHOD": static(1)},
     {}),
    ("breakpoints", "floodmesh:classifybreakpoints",
     {"INPUT": child_output("slope", "OUTPUT"), "CRITICAL_SLOPE": param("s_crit")}, {}),
    ("trace", "floodmesh:tracebreaklines",
     {"BREAKPOINTS": child_output("breakpoints", "OUTPUT"), "SLOPE": child_output("slope", "OUTPUT"),
      "DEM": child_output("grid", "OUTPUT"), "CRITICAL_SLOPE": param("s_crit")}, {}),
    ("simplify", "floodmesh:simplifybreaklines",
     # the minimum distance d/2, as LiDAR to mesh takes it (the step alone knows no cell size)
     {"INPUT": child_output("trace", "OUTPUT"), "METHOD": static(0), "KEEP_EVERY": static(4),
      "MIN_DISTANCE": [QgsProcessingModelChildParameterSource.fromExpression("@cell_size / 2")]},
     {"breaklines": ("Break lines", "OUTPUT")}),
    ("mesh", "floodmesh:buildmesh",
     {"DEM": child_output("grid", "OUTPUT"), "BREAKLINES": child_output("simplify", "OUTPUT"),
      "MIN_ANGLE": param("min_angle"), "MAX_AREA": param("max_area")},
     {"mesh": ("Mesh (SMS 2DM)", "OUTPUT")}),
    ("assess", "floodmesh:assessaccuracy",
     {"MESH": child_output("mesh", "OUTPUT"), "POINTS": child_output("grid", "HOLDOUT_OUTPUT")},
     {"residuals": ("Residuals", "OUTPUT")}),
]
for row, (child_id, algorithm, sources, outputs) in enumerate(steps):
    child = QgsProcessingModelChildAlgorithm(algorithm)
    child.setChildId(child_id)
    child.setDescription(child_id.capitalize())
    child.setPosition(QPointF(420, 60 + 90 * row))
    for name, source in sources.items():
        child.addParameterSources(name, source)
    for definition in child.algorithm().parameterDefinitions():  # the rest at their defaults
        if not (definition.name() in sources or definition.isDestination()
                or definition.flags() & definition.FlagOptional):
            child.addParameterSources(definition.name(), static(definition.defaultValue()))
    model_outputs = {}
    for output_id, (description, child_output_name) in outputs.items():
        out = QgsProcessingModelOutput(output_id, description)
        out.setChildOutputName(child_output_name)
        out.setChildId(child_id)
        # written to a temporary file unless the user names one: the model runs with only its
        # inputs (QGIS 3.40 refuses an output with no value and no default)
        out.setDefaultValue(QgsProcessing.TEMPORARY_OUTPUT)
        out.setMandatory(True)
        out.setPosition(QPointF(720, 60 + 90 * row))
        model_outputs[output_id] = out
    child.setModelOutputs(model_outputs)
    model.addChildAlgorithm(child)

model.updateDestinationParameters()
valid, issues = model.validate()
if not valid:
    sys.exit("the model is not valid: " + "; ".join(issues))
target = Path(__file__).resolve().parent.parent / "models" / "lidar_to_mesh_steps.model3"
if not model.toFile(str(target)):
    sys.exit(f"could not write {target}")
print(f"written {target}")
