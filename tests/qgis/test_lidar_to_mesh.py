"""The "LiDAR to mesh" algorithm in real QGIS: through processing.run and through qgis_process,
with its mesh read back by QGIS's own mesh reader (MDAL)."""
import json
import subprocess

import pytest
from qgis.core import (QgsCoordinateTransformContext, QgsFeature, QgsGeometry, QgsMeshLayer,
                       QgsProcessingContext, QgsProcessingFeedback, QgsVectorFileWriter,
                       QgsVectorLayer)

from floodmesh.core import io


def _mesh_counts(path):
    layer = QgsMeshLayer(str(path), "mesh", "mdal")
    assert layer.isValid(), f"QGIS cannot open {path} as a mesh"
    provider = layer.dataProvider()
    return provider.vertexCount(), provider.faceCount()


def test_processing_run_writes_and_loads_the_mesh(processing, demo_points_file, tmp_path):
    out = tmp_path / "run"
    context = QgsProcessingContext()
    result = processing.run("floodmesh:lidartomesh", {
        "INPUT": str(demo_points_file), "CELL_SIZE": 1.0, "CRITICAL_SLOPE": 10.0,
        "KEEP_EVERY": 4, "MIN_ANGLE": 25.0, "MAX_AREA": 100.0, "HOLDOUT": 0.01, "SEED": 0,
        "OUTPUT_FOLDER": str(out)}, context=context, feedback=QgsProcessingFeedback())
    report = json.loads((out / "report.json").read_text())
    nodes, faces = _mesh_counts(result["MESH"])
    assert (nodes, faces) == (report["nodes"], report["triangles"])
    assert (result["NODES"], result["TRIANGLES"]) == (nodes, faces)
    assert report["min_angle_deg"] >= 25.0 - 1e-6 and report["max_area_m2"] <= 100.0
    lines = QgsVectorLayer(result["BREAKLINES"], "lines", "ogr")
    assert lines.isValid() and lines.featureCount() == report["n_breaklines"] > 10
    # both layers are handed to QGIS to load when the algorithm ends
    to_load = context.layersToLoadOnCompletion()
    names = {details.name for details in to_load.values()}
    assert names == {"Break lines", "Mesh", "Residuals"}
    layers = {details.name: context.temporaryLayerStore().mapLayer(layer_id)
              for layer_id, details in to_load.items()}
    # break lines: one legend entry (a line on a halo); residuals: the three classes (+ outside)
    renderer = layers["Break lines"].renderer()
    assert renderer.type() == "singleSymbol" and renderer.symbol().symbolLayerCount() == 2
    classes = layers["Residuals"].renderer()
    assert classes.classAttribute() == "class"
    assert {c.value() for c in classes.categories()} == {0, 1, 2, -1}
    # the mesh: shaded by elevation, its edges drawn, in the run's CRS (a 2DM has none)
    settings = layers["Mesh"].rendererSettings()
    assert settings.activeScalarDatasetGroup() == 0 and settings.nativeMeshSettings().isEnabled()
    assert layers["Mesh"].crs().authid() == "EPSG:" + report["crs"].split(":")[-1]


def test_bad_input_is_a_processing_exception(processing, tmp_path):
    from qgis.core import QgsProcessingException

    bad = tmp_path / "empty.xyz"
    bad.write_text("")
    with pytest.raises(QgsProcessingException, match="is empty"):
        processing.run("floodmesh:lidartomesh", {"INPUT": str(bad), "CRS": "EPSG:25832",
                                                 "OUTPUT_FOLDER": str(tmp_path / "out")})
    assert not (tmp_path / "out" / "mesh.2dm").exists()


def test_qgis_process_runs_the_algorithm(qgis_process, demo_points_file, tmp_path):
    exe, env = qgis_process
    out = tmp_path / "headless"
    run = subprocess.run(
        [exe, "run", "floodmesh:lidartomesh", "--json", "--", f"INPUT={demo_points_file}",
         "MAX_AREA=200", "HOLDOUT=0.01", f"OUTPUT_FOLDER={out}"],
        env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    results = json.loads(run.stdout[run.stdout.index("{"):])["results"]
    nodes, triangles = io.read_mesh_2dm(results["MESH"])
    assert results["NODES"] == len(nodes) and results["TRIANGLES"] == len(triangles)
    assert _mesh_counts(results["MESH"]) == (len(nodes), len(triangles))
    assert json.loads((out / "report.json").read_text())["max_area_m2"] <= 200


def test_qgis_process_reports_bad_input_without_traceback(qgis_process, tmp_path):
    exe, env = qgis_process
    run = subprocess.run(
        [exe, "run", "floodmesh:lidartomesh", "--", f"INPUT={tmp_path / 'missing.laz'}",
         f"OUTPUT_FOLDER={tmp_path / 'out'}"], env=env, capture_output=True, text=True,
        timeout=120)
    assert run.returncode != 0
    assert "does not exist" in run.stdout + run.stderr
    assert "Traceback" not in run.stdout + run.stderr


@pytest.mark.parametrize("at_percent", [5, 20, 60])
def test_cancel_mid_run_leaves_no_partial_output(processing, demo_points_file, tmp_path,
                                                 at_percent):
    """Cancel pressed part-way (as the dialog's Cancel button does): the run stops with a
    message, and the folder holds no mesh and no half-written file."""
    from qgis.core import QgsProcessingException

    feedback = QgsProcessingFeedback()
    seen = []

    def on_progress(percent):
        seen.append(percent)
        if percent >= at_percent:
            feedback.cancel()

    feedback.progressChanged.connect(on_progress)
    out = tmp_path / "cancelled"
    with pytest.raises(QgsProcessingException, match="Cancelled"):
        processing.run("floodmesh:lidartomesh", {"INPUT": str(demo_points_file),
                                                 "OUTPUT_FOLDER": str(out)}, feedback=feedback)
    assert max(seen) < 100
    assert not (out / "mesh.2dm").exists() and not (out / "report.json").exists()
    assert [p.name for p in out.glob("*partial*")] == []


def test_spline_and_refinement_through_the_one_step_algorithm(processing, demo_points_file,
                                                               tmp_path):
    """The simplification enum reaches the chain: the report names the spline and its
    tolerance, and fewer break-line points are kept than traced."""
    out = tmp_path / "spline"
    processing.run("floodmesh:lidartomesh", {
        "INPUT": str(demo_points_file), "SIMPLIFY": 2, "TOLERANCE": 0.75, "HOLDOUT": 0.01,
        "REFINE": True, "OUTPUT_FOLDER": str(out)})
    report = json.loads((out / "report.json").read_text())
    assert report["simplification"]["method"] == "spline"
    assert report["simplification"]["value"] == 0.75
    assert report["breakline_points_kept"] < 0.5 * report["breakline_points_traced"]
    assert len(report["refinement"]) >= 2  # and the refinement switch reaches it too


def test_terrain_fit_options_reach_the_chain(processing, demo_points_file, tmp_path):
    """Localisation, node elevations, conforming Delaunay and the far field are parameters: the
    report states what ran (and the fit's window and radius); the lines carry their fit RMS."""
    runs = {}
    for name, extra in (("fitted", {"FAR_FIELD_AREA": 400.0}),
                        ("plain", {"LOCALISE": False, "NODE_ELEVATION": 1, "CONFORMING": True})):
        out = tmp_path / name
        processing.run("floodmesh:lidartomesh", {"INPUT": str(demo_points_file), "HOLDOUT": 0.01,
                                                 "OUTPUT_FOLDER": str(out), **extra})
        runs[name] = json.loads((out / "report.json").read_text()), out
    fitted, plain = runs["fitted"][0], runs["plain"][0]
    assert fitted["options"]["localise"] and fitted["options"]["node_elevation"] == "plane"
    assert fitted["options"]["far_field_area"] == 400.0 and not fitted["options"]["conforming"]
    assert fitted["terrain_fit"]["node_radius"] > 0 and fitted["terrain_fit"]["vertices_localised"]
    # localised pieces are joined in QGIS too (the default gap: six cells)
    assert fitted["terrain_fit"]["join_gap_m"] == 10.0 and fitted["terrain_fit"]["pieces_joined"] >= 0
    assert not plain["options"]["localise"] and plain["options"]["node_elevation"] == "dem"
    assert plain["options"]["conforming"] and "node_radius" not in plain["terrain_fit"]
    lines = QgsVectorLayer(str(runs["fitted"][1] / "breaklines.gpkg"), "lines", "ogr")
    assert lines.fields().indexOf("fit_rms_m") >= 0


def test_results_load_lines_above_the_mesh_in_the_runs_crs(processing, demo_points_file,
                                                          tmp_path):
    """As from the toolbox: the break lines stack above the residuals above the mesh (which
    would hide them), and the mesh comes in the run's CRS, not none."""
    from qgis.core import QgsProject

    project = QgsProject.instance()
    project.clear()
    processing.runAndLoadResults("floodmesh:lidartomesh", {
        "INPUT": str(demo_points_file), "MAX_AREA": 200, "HOLDOUT": 0.01,
        "OUTPUT_FOLDER": str(tmp_path / "loaded")})
    order = [node.layer().name() for node in project.layerTreeRoot().findLayers()]
    assert order == ["Break lines", "Residuals", "Mesh"], order
    mesh = project.mapLayersByName("Mesh")[0]
    assert mesh.crs().isValid() and mesh.crs().authid() == "EPSG:25832"
    project.clear()


def rectangles(path, *spans):
    """A GeoPackage at ``path`` of rectangles over the demo, one per (x0, x1) span (from 20 to
    220 m north of its origin), as a layer of the project's kind."""
    from floodmesh.core.frontends.demo import DEMO_ORIGIN

    y = DEMO_ORIGIN[1]
    memory = QgsVectorLayer("Polygon?crs=EPSG:25832", path.stem, "memory")
    for x0, x1 in spans:
        feature = QgsFeature()
        feature.setGeometry(QgsGeometry.fromWkt(
            f"POLYGON(({x0} {y + 20},{x1} {y + 20},{x1} {y + 220},{x0} {y + 220},{x0} {y + 20}))"))
        assert memory.dataProvider().addFeature(feature)
    options = QgsVectorFileWriter.SaveVectorOptions()
    options.driverName = "GPKG"
    written = QgsVectorFileWriter.writeAsVectorFormatV3(
        memory, str(path), QgsCoordinateTransformContext(), options)
    assert written[0] == QgsVectorFileWriter.NoError, written
    return QgsVectorLayer(str(path), path.stem, "ogr")


def test_a_domain_of_selected_features_meshes_within_it(processing, demo_points_file, tmp_path):
    """The model domain as 'Selected features only' of a layer of two polygons (what the
    dialog hands on): LiDAR to mesh checks and runs (QGIS 3.22 crashed while checking the
    parameters) and meshes the selected polygon only."""
    from qgis.core import QgsProcessingFeatureSourceDefinition, QgsProject

    from floodmesh.core.frontends.demo import DEMO_ORIGIN

    x = DEMO_ORIGIN[0]
    layer = rectangles(tmp_path / "domains.gpkg", (x + 20, x + 120), (x + 160, x + 280))
    QgsProject.instance().addMapLayer(layer)
    try:
        layer.selectByIds([sorted(layer.allFeatureIds())[0]])
        processing.run("floodmesh:lidartomesh", {
            "INPUT": str(demo_points_file), "CELL_SIZE": 2.0, "MAX_AREA": 200.0,
            "BOUNDARY": QgsProcessingFeatureSourceDefinition(layer.id(), True),
            "OUTPUT_FOLDER": str(tmp_path / "out")})
    finally:
        QgsProject.instance().removeMapLayer(layer.id())
    nodes = io.read_2dm(tmp_path / "out" / "mesh.2dm").nodes
    assert nodes[:, 0].min() >= x + 20 - 1e-6 and nodes[:, 0].max() <= x + 120 + 1e-6


def test_a_domain_read_from_a_copy_in_the_output_folder_is_kept(processing, demo_points_file,
                                                                tmp_path):
    """The domain GeoPackage kept in the output folder under a name the run writes
    (mesh.gpkg), given with 'Selected features only': refused before the run, the file kept
    (the run overwrote it with its triangles, as it cannot see the file behind the copy)."""
    from qgis.core import (QgsProcessingException, QgsProcessingFeatureSourceDefinition,
                           QgsProject)

    from floodmesh.core.frontends.demo import DEMO_ORIGIN

    x = DEMO_ORIGIN[0]
    out = tmp_path / "run"
    out.mkdir()
    layer = rectangles(out / "mesh.gpkg", (x + 20, x + 200))
    before = (out / "mesh.gpkg").read_bytes()
    QgsProject.instance().addMapLayer(layer)
    try:
        layer.selectAll()
        with pytest.raises(QgsProcessingException, match="lies in the output folder"):
            processing.run("floodmesh:lidartomesh", {
                "INPUT": str(demo_points_file), "CELL_SIZE": 2.0, "MAX_AREA": 200.0,
                "BOUNDARY": QgsProcessingFeatureSourceDefinition(layer.id(), True),
                "OUTPUT_FOLDER": str(out)})
    finally:
        QgsProject.instance().removeMapLayer(layer.id())
    assert (out / "mesh.gpkg").read_bytes() == before
    assert not (out / "mesh.2dm").exists()
