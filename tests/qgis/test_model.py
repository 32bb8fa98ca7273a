"""The Graphical Modeler model shipped with the plugin: listed by the provider, run through
processing.run and headless through qgis_process from its id."""
import json
import subprocess

from qgis.core import QgsApplication, QgsMeshLayer, QgsVectorLayer


MODEL_ID = "floodmesh:LiDAR to mesh step by step"


def test_model_is_in_the_toolbox_with_its_outputs(processing):
    model = QgsApplication.processingRegistry().algorithmById(MODEL_ID)
    assert model is not None
    assert {o.name() for o in model.outputDefinitions()} == {
        "mesh:mesh", "simplify:breaklines", "assess:residuals"}


def test_model_runs_through_processing_run(processing, demo_points_file, tmp_path):
    """At 2 m cells; the simplification merges lines closer than d/2, 1 m, as LiDAR to mesh
    does (not a fixed 0.5 m, nor the step's own default, off)."""
    result = processing.run(MODEL_ID, {
        "points": str(demo_points_file), "cell_size": 2.0, "s_crit": 10.0, "min_angle": 25.0,
        "max_area": 100.0, "mesh:mesh": str(tmp_path / "mesh.2dm"),
        "simplify:breaklines": str(tmp_path / "lines.gpkg"),
        "assess:residuals": str(tmp_path / "residuals.gpkg")})
    mesh = QgsMeshLayer(result["mesh:mesh"], "mesh", "mdal")
    assert mesh.isValid() and mesh.dataProvider().faceCount() > 1000
    assert QgsVectorLayer(result["simplify:breaklines"], "l", "ogr").featureCount() >= 10
    assert result["CHILD_INPUTS"]["simplify"]["MIN_DISTANCE"] == 1.0
    assert QgsVectorLayer(result["assess:residuals"], "r", "ogr").featureCount() == round(
        0.01 * 2 * 300 * 240)


def test_model_runs_headless(qgis_process, demo_points_file, tmp_path):
    exe, env = qgis_process
    run = subprocess.run(
        [exe, "run", MODEL_ID, "--json", "--", f"points={demo_points_file}", "max_area=150",
         f"mesh:mesh={tmp_path / 'mesh.2dm'}", f"simplify:breaklines={tmp_path / 'l.gpkg'}",
         f"assess:residuals={tmp_path / 'r.gpkg'}"],
        env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    results = json.loads(run.stdout[run.stdout.index("{"):])["results"]
    layer = QgsMeshLayer(results["mesh:mesh"], "mesh", "mdal")
    assert layer.isValid() and layer.dataProvider().vertexCount() > 500


def test_model_runs_with_only_its_inputs(processing, demo_points_file):
    """As the model's dialog runs it with only the points given: every output at its default, a
    temporary file."""
    model = QgsApplication.processingRegistry().algorithmById(MODEL_ID)
    ok, issues = model.validate()
    assert ok, issues
    outputs = {d.name(): d.defaultValue() for d in model.destinationParameterDefinitions()}
    assert set(outputs.values()) == {"TEMPORARY_OUTPUT"}
    result = processing.run(MODEL_ID, {"points": str(demo_points_file), **outputs})
    mesh = QgsMeshLayer(result["mesh:mesh"], "mesh", "mdal")
    assert mesh.isValid() and mesh.dataProvider().faceCount() > 1000
    assert QgsVectorLayer(result["assess:residuals"], "r", "ogr").featureCount() > 20
