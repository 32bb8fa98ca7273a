"""A QGIS user's chains of the steps: the layers a previous step, a QGIS algorithm or the user
hands a FloodMesh step are what it reads — a memory layer, selected features only, a layer's
filter, one layer of a GeoPackage of several — in processing.run and in a model of one's own."""
import json
import subprocess
from pathlib import Path

import pytest
from qgis.core import (QgsApplication, QgsCoordinateTransformContext, QgsMeshLayer, QgsProcessing,
                       QgsProcessingFeatureSourceDefinition, QgsProcessingModelAlgorithm,
                       QgsProcessingModelChildAlgorithm, QgsProcessingModelChildDependency,
                       QgsProcessingModelChildParameterSource, QgsProcessingModelOutput,
                       QgsProcessingModelParameter, QgsProcessingParameterFile,
                       QgsProcessingParameterRasterLayer, QgsProject, QgsVectorFileWriter,
                       QgsVectorLayer)

LONG = "length_m > 20"  # the filter the tests apply to the traced lines


@pytest.fixture(scope="module")
def traced(processing, demo_points_file, tmp_path_factory):
    """The demo's DEM, held-out points and traced break lines at 2 m, by the steps."""
    t = tmp_path_factory.mktemp("chaining")
    grid = processing.run("floodmesh:gridpoints", {
        "INPUT": str(demo_points_file), "CELL_SIZE": 2.0, "HOLDOUT": 0.01,
        "OUTPUT": str(t / "dem.tif"), "HOLDOUT_OUTPUT": str(t / "holdout.gpkg")})
    slope = processing.run("floodmesh:slope", {"INPUT": grid["OUTPUT"],
                                               "OUTPUT": str(t / "slope.tif")})["OUTPUT"]
    bp = processing.run("floodmesh:classifybreakpoints", {
        "INPUT": slope, "OUTPUT": str(t / "bp.tif")})["OUTPUT"]
    lines = processing.run("floodmesh:tracebreaklines", {
        "BREAKPOINTS": bp, "SLOPE": slope, "DEM": grid["OUTPUT"],
        "OUTPUT": str(t / "lines.gpkg")})["OUTPUT"]
    long_lines = processing.run("native:extractbyexpression", {
        "INPUT": lines, "EXPRESSION": LONG, "OUTPUT": str(t / "long.gpkg")})["OUTPUT"]
    return {"folder": t, "dem": grid["OUTPUT"], "holdout": grid["HOLDOUT_OUTPUT"],
            "slope": slope, "bp": bp, "lines": lines, "long": long_lines}


def count(layer_or_path):
    layer = (layer_or_path if isinstance(layer_or_path, QgsVectorLayer)
             else QgsVectorLayer(layer_or_path, "l", "ogr"))
    return layer.featureCount()


def mesh_size(path):
    layer = QgsMeshLayer(path, "m", "mdal")
    return layer.dataProvider().vertexCount(), layer.dataProvider().faceCount()


def simplified(processing, lines, out):
    return processing.run("floodmesh:simplifybreaklines", {
        "INPUT": lines, "MIN_DISTANCE": 1.0, "OUTPUT": str(out)})["OUTPUT"]


def test_a_memory_layer_from_a_qgis_algorithm_is_simplified(processing, traced, tmp_path):
    """native:extractbyexpression's temporary layer (memory) between two FloodMesh steps is
    read as its file would be, not refused with a traceback."""
    memory = processing.run("native:extractbyexpression", {
        "INPUT": traced["lines"], "EXPRESSION": LONG, "OUTPUT": "memory:"})["OUTPUT"]
    assert memory.providerType() == "memory"
    from_memory = simplified(processing, memory, tmp_path / "a.gpkg")
    from_file = simplified(processing, traced["long"], tmp_path / "b.gpkg")
    assert 0 < count(from_memory) == count(from_file) < count(traced["lines"])


def model_with_a_qgis_step(path):
    """A model of one's own: break lines → native:extractbyexpression (its temporary output, a
    memory layer) → Simplify break lines → Build mesh; saved as path (.model3)."""
    model = QgsProcessingModelAlgorithm("Long break lines to mesh", "tests")
    model.addModelParameter(QgsProcessingParameterFile("lines", "Break lines"),
                            QgsProcessingModelParameter("lines"))
    model.addModelParameter(QgsProcessingParameterRasterLayer("dem", "DEM"),
                            QgsProcessingModelParameter("dem"))

    def child(child_id, algorithm, after=None, **sources):
        step = QgsProcessingModelChildAlgorithm(algorithm)
        step.setChildId(child_id)
        step.setDescription(child_id)
        for name, source in sources.items():
            step.addParameterSources(name, [source])
        if after:
            step.setDependencies([QgsProcessingModelChildDependency(after)])
        return step

    source = QgsProcessingModelChildParameterSource
    model.addChildAlgorithm(child("filter", "native:extractbyexpression",
                                  INPUT=source.fromModelParameter("lines"),
                                  EXPRESSION=source.fromStaticValue(LONG)))
    model.addChildAlgorithm(child("simplify", "floodmesh:simplifybreaklines", "filter",
                                  INPUT=source.fromChildOutput("filter", "OUTPUT"),
                                  MIN_DISTANCE=source.fromStaticValue(1.0)))
    mesh = child("mesh", "floodmesh:buildmesh", "simplify",
                 DEM=source.fromModelParameter("dem"),
                 BREAKLINES=source.fromChildOutput("simplify", "OUTPUT"))
    output = QgsProcessingModelOutput("mesh", "Mesh")
    output.setChildId("mesh")
    output.setChildOutputName("OUTPUT")
    # QGIS 3.40 takes a value for an output only with a default (as scripts/make_model.py)
    output.setDefaultValue(QgsProcessing.TEMPORARY_OUTPUT)
    output.setMandatory(True)
    mesh.setModelOutputs({"mesh": output})
    model.addChildAlgorithm(mesh)
    model.updateDestinationParameters()
    assert model.toFile(str(path))
    return path


def test_own_model_with_a_qgis_step_between_floodmesh_steps(processing, qgis_process, traced,
                                                            tmp_path):
    """The model runs through processing.run and qgis_process, and meshes what the steps
    give on the file of the same lines."""
    expected = processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"],
        "BREAKLINES": simplified(processing, traced["long"], tmp_path / "s.gpkg"),
        "OUTPUT": str(tmp_path / "expected.2dm")})["OUTPUT"]
    path = model_with_a_qgis_step(tmp_path / "long_lines.model3")
    model = QgsProcessingModelAlgorithm()
    assert model.fromFile(str(path))
    # the mesh output's name as this QGIS gives it (its parameter, its result)
    (given,) = [d.name() for d in model.destinationParameterDefinitions()]
    (named,) = [d.name() for d in model.outputDefinitions()]
    result = processing.run(model, {"lines": traced["lines"], "dem": traced["dem"],
                                    given: str(tmp_path / "model.2dm")})
    assert result[named] == str(tmp_path / "model.2dm"), (given, named, result)
    assert mesh_size(result[named]) == mesh_size(expected)

    exe, env = qgis_process
    run = subprocess.run(
        [exe, "run", str(path), "--json", "--", f"lines={traced['lines']}",
         f"dem={traced['dem']}", f"{given}={tmp_path / 'headless.2dm'}"],
        env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    results = json.loads(run.stdout[run.stdout.index("{"):])["results"]
    assert mesh_size(results[named]) == mesh_size(expected)


def test_selected_features_only(processing, traced, tmp_path):
    """Ticking 'Selected features only' meshes and simplifies the selected lines: the same
    mesh as from a file of just those lines (not all the lines, nor none)."""
    layer = QgsVectorLayer(traced["lines"], "traced lines", "ogr")
    QgsProject.instance().addMapLayer(layer)
    try:
        layer.selectByExpression(LONG)
        assert 0 < layer.selectedFeatureCount() < layer.featureCount()
        selected = QgsProcessingFeatureSourceDefinition(layer.id(), True)
        meshes = [processing.run("floodmesh:buildmesh", {
            "DEM": traced["dem"], "BREAKLINES": lines,
            "OUTPUT": str(tmp_path / f"{name}.2dm")})["OUTPUT"]
            for name, lines in (("selected", selected), ("long", traced["long"]))]
        assert mesh_size(meshes[0]) == mesh_size(meshes[1])
        assert count(simplified(processing, selected, tmp_path / "s.gpkg")) == count(
            simplified(processing, traced["long"], tmp_path / "l.gpkg"))
    finally:
        QgsProject.instance().removeMapLayer(layer.id())


def test_a_layer_filter_is_kept(processing, traced, tmp_path):
    """A layer filtered in QGIS (Query Builder: a subset string) gives its filtered lines."""
    layer = QgsVectorLayer(traced["lines"], "traced lines", "ogr")
    assert layer.setSubsetString(LONG)
    assert count(simplified(processing, layer, tmp_path / "s.gpkg")) == count(
        simplified(processing, traced["long"], tmp_path / "l.gpkg"))


def test_one_layer_of_a_geopackage_of_several(processing, traced, tmp_path):
    """Break lines and check points as layers of one GeoPackage (as a user gathers a model's
    inputs): each step reads the layer it is given."""
    gpkg = str(tmp_path / "inputs.gpkg")
    for name, source in (("holdout", traced["holdout"]), ("lines", traced["lines"])):
        options = QgsVectorFileWriter.SaveVectorOptions()
        options.driverName, options.layerName = "GPKG", name
        if name == "lines":
            options.actionOnExistingFile = QgsVectorFileWriter.CreateOrOverwriteLayer
        error = QgsVectorFileWriter.writeAsVectorFormatV3(
            QgsVectorLayer(source, name, "ogr"), gpkg, QgsCoordinateTransformContext(),
            options)
        assert error[0] == QgsVectorFileWriter.NoError, error
    lines = QgsVectorLayer(f"{gpkg}|layername=lines", "lines", "ogr")
    points = QgsVectorLayer(f"{gpkg}|layername=holdout", "holdout", "ogr")
    assert lines.isValid() and points.isValid()
    simple = simplified(processing, lines, tmp_path / "s.gpkg")
    assert count(simple) == count(simplified(processing, traced["lines"], tmp_path / "l.gpkg"))
    mesh = processing.run("floodmesh:buildmesh", {"DEM": traced["dem"], "BREAKLINES": simple,
                                                  "OUTPUT": str(tmp_path / "m.2dm")})["OUTPUT"]
    residuals = [processing.run("floodmesh:assessaccuracy", {
        "MESH": mesh, "POINTS": check, "OUTPUT": str(tmp_path / f"r{i}.gpkg")})["RMSE"]
        for i, check in enumerate((points, traced["holdout"]))]
    assert residuals[0] == residuals[1] > 0


def test_an_output_into_the_input_geopackage_is_refused(processing, traced):
    """One layer of a GeoPackage named as input, the same GeoPackage as output: refused in one
    line, the input untouched."""
    from qgis.core import QgsProcessingException

    before = count(traced["lines"])
    with pytest.raises(QgsProcessingException, match="is the input"):
        simplified(processing, QgsVectorLayer(f"{traced['lines']}|layername=breaklines", "l",
                                              "ogr"),
                   traced["lines"])
    assert count(traced["lines"]) == before
    assert QgsApplication.processingRegistry().algorithmById("floodmesh:simplifybreaklines")


@pytest.fixture(scope="module")
def in_utm33(processing, traced):
    """The traced lines and the held-out points reprojected to UTM zone 33N by QGIS, as a
    model's step of another CRS hands them on (the DEM and mesh stay in 32N)."""
    return {name: processing.run("native:reprojectlayer", {
        "INPUT": traced[name], "TARGET_CRS": "EPSG:25833",
        "OUTPUT": str(traced["folder"] / f"{name}_33.gpkg")})["OUTPUT"]
        for name in ("lines", "holdout")}


def test_break_lines_of_another_crs_are_refused(processing, traced, in_utm33, tmp_path):
    """Build mesh and Refine mesh refuse break lines in another CRS than the DEM's, in one
    line with the fix, instead of meshing without them (they lie off the DEM)."""
    from qgis.core import QgsProcessingException

    for algorithm, extra in (("buildmesh", {}),
                             ("refinemesh", {"POINTS": traced["holdout"], "MAX_ROUNDS": 1})):
        with pytest.raises(QgsProcessingException) as error:
            processing.run(f"floodmesh:{algorithm}", {
                "DEM": traced["dem"], "BREAKLINES": in_utm33["lines"], **extra,
                "OUTPUT": str(tmp_path / f"{algorithm}.2dm")})
        message = str(error.value)
        assert "lines_33.gpkg is in ETRS89 / UTM zone 33N" in message, message
        assert "reproject it to the DEM's CRS" in message and "\n" not in message.strip()
        assert not (tmp_path / f"{algorithm}.2dm").exists()


def test_check_points_of_another_crs_are_refused(processing, traced, in_utm33, tmp_path):
    """Assess accuracy and Refine mesh's check points in another CRS than the mesh's or DEM's
    are refused with the fix, not assessed off the mesh."""
    from qgis.core import QgsProcessingException

    mesh = processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"], "OUTPUT": str(tmp_path / "m.2dm")})["OUTPUT"]
    runs = (("assessaccuracy", {"MESH": mesh, "POINTS": in_utm33["holdout"],
                                "OUTPUT": str(tmp_path / "r.gpkg")}, "mesh"),
            ("refinemesh", {"DEM": traced["dem"], "POINTS": traced["holdout"],
                            "CHECK": in_utm33["holdout"], "MAX_ROUNDS": 1,
                            "OUTPUT": str(tmp_path / "refined.2dm")}, "DEM"))
    for algorithm, parameters, against in runs:
        with pytest.raises(QgsProcessingException) as error:
            processing.run(f"floodmesh:{algorithm}", parameters)
        message = str(error.value)
        assert "holdout_33.gpkg is in ETRS89 / UTM zone 33N" in message, message
        assert f"reproject it to the {against}'s CRS" in message
    assert not (tmp_path / "r.gpkg").exists() and not (tmp_path / "refined.2dm").exists()


def test_lines_where_check_points_belong_are_refused(processing, traced, tmp_path):
    """Break lines handed to Assess accuracy as its check points: one line naming the layer and
    what to give, not the worker's numpy error."""
    from qgis.core import QgsProcessingException

    mesh = processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"], "OUTPUT": str(tmp_path / "m.2dm")})["OUTPUT"]
    with pytest.raises(QgsProcessingException) as error:
        processing.run("floodmesh:assessaccuracy", {
            "MESH": mesh, "POINTS": traced["lines"], "OUTPUT": str(tmp_path / "r.gpkg")})
    message = str(error.value).strip()  # QGIS puts "Unable to execute algorithm" above it
    assert message.splitlines()[-1].startswith("lines.gpkg has lines"), message
    assert "points are needed" in message and "worker" not in message
    assert not (tmp_path / "r.gpkg").exists()


WRONG_RASTERS = [  # (algorithm, parameter given the wrong raster, which, what the message says)
    ("classifybreakpoints", "INPUT", "dem", "holds elevations in metres"),
    ("classifybreakpoints", "INPUT", "bp", "holds breakpoints"),
    ("tracebreaklines", "SLOPE", "dem", "holds elevations in metres"),
    ("tracebreaklines", "SLOPE", "bp", "holds breakpoints"),
    ("tracebreaklines", "BREAKPOINTS", "dem", "holds elevations in metres"),
    ("tracebreaklines", "BREAKPOINTS", "slope", "holds a slope in degrees"),
    ("tracebreaklines", "DEM", "bp", "holds breakpoints"),
    ("buildmesh", "DEM", "bp", "holds breakpoints"),
    ("buildmesh", "SIZE_FIELD", "slope", "holds a slope in degrees"),
    ("buildmesh", "SIZE_FIELD", "dem", "holds elevations in metres"),
]


@pytest.mark.parametrize("algorithm, name, which, held", WRONG_RASTERS)
def test_a_step_s_raster_where_another_belongs_is_refused(processing, traced, tmp_path,
                                                          algorithm, name, which, held):
    """A raster of one step wired to the wrong input of the next (the DEM as the slope, the
    breakpoints as the DEM, the slope as the size field…): one line naming what it holds,
    no output, instead of a run on the wrong quantity."""
    from qgis.core import QgsProcessingException

    right = {"classifybreakpoints": {"INPUT": traced["slope"]},
             "tracebreaklines": {"BREAKPOINTS": traced["bp"], "SLOPE": traced["slope"],
                                 "DEM": traced["dem"]},
             "buildmesh": {"DEM": traced["dem"]}}[algorithm]
    out = tmp_path / ("out.2dm" if algorithm == "buildmesh" else
                      "out.gpkg" if algorithm == "tracebreaklines" else "out.tif")
    with pytest.raises(QgsProcessingException) as error:
        processing.run(f"floodmesh:{algorithm}", {**right, name: traced[which],
                                                   "OUTPUT": str(out)})
    message = str(error.value).strip()
    assert f"{Path(traced[which]).name} {held}" in message and "\n" not in message, message
    assert not out.exists()


@pytest.mark.parametrize("destination", [
    "ogr:dbname='{folder}/project.gpkg' table=\"simple\" (geom)",  # Save to GeoPackage…
    "memory:"])
def test_an_output_into_a_geopackage_table_or_memory_says_what_to_give(processing, traced,
                                                                      tmp_path, destination):
    """The dialog's 'Save to GeoPackage…' (a table in a GeoPackage) and a memory layer as a
    step's output: one line saying that the step writes a file of its own and what to give,
    not a garbled file name; nothing written."""
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as error:
        processing.run("floodmesh:simplifybreaklines", {
            "INPUT": traced["lines"], "OUTPUT": destination.format(folder=tmp_path)})
    message = str(error.value).strip()
    assert message.startswith("Simplified break lines: FloodMesh writes each output as a "
                              "file of its own"), message
    assert "give a file name ending in .gpkg or a temporary output" in message
    assert not list(tmp_path.iterdir())


@pytest.fixture(scope="module")
def domains(traced):
    """Two domain GeoPackages: a valid polygon inside the DEM, and the same beside a polygon
    whose ring crosses itself (a bowtie: invalid for QGIS and GEOS)."""
    from qgis.core import QgsFeature, QgsGeometry, QgsRasterLayer

    dem = QgsRasterLayer(traced["dem"], "dem")
    e = dem.extent()
    x0, y0, x1, y1 = e.xMinimum() + 20, e.yMinimum() + 20, e.xMaximum() - 20, e.yMaximum() - 20
    rings = {"valid": f"(({x0} {y0},{x1} {y0},{x1} {y1},{x0} {y1},{x0} {y0}))",
             "bowtie": f"(({x0} {y0},{x1} {y1},{x1} {y0},{x0} {y1},{x0} {y0}))"}
    files = {}
    for name, polygons in (("valid", ["valid"]), ("with_bowtie", ["valid", "bowtie"])):
        memory = QgsVectorLayer(f"Polygon?crs={dem.crs().authid()}", name, "memory")
        for polygon in polygons:
            feature = QgsFeature()
            feature.setGeometry(QgsGeometry.fromWkt(f"POLYGON{rings[polygon]}"))
            assert memory.dataProvider().addFeature(feature)
        files[name] = str(traced["folder"] / f"{name}.gpkg")
        options = QgsVectorFileWriter.SaveVectorOptions()
        options.driverName = "GPKG"
        error = QgsVectorFileWriter.writeAsVectorFormatV3(
            memory, files[name], QgsCoordinateTransformContext(), options)
        assert error[0] == QgsVectorFileWriter.NoError, error
    return files


def test_invalid_features_are_skipped_where_the_input_says_so(processing, traced, domains,
                                                              feedback_log, tmp_path):
    """The domain input's 'Invalid feature filtering: Skip (ignore) features with invalid
    geometries' (its advanced options in the dialog): the bowtie beside the domain is left
    out, as QGIS's own algorithms leave it out, and the mesh is that of the valid domain; the
    log says which feature was skipped. Not the same refusal as without the option."""
    from floodmesh.algorithms.compat import OWN_GEOMETRY_CHECK, SKIP_INVALID

    skip = QgsProcessingFeatureSourceDefinition(domains["with_bowtie"], False, -1,
                                                OWN_GEOMETRY_CHECK, SKIP_INVALID)
    meshes = [processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"], "BOUNDARY": boundary, "OUTPUT": str(tmp_path / f"{i}.2dm")},
        feedback=feedback_log)["OUTPUT"] for i, boundary in enumerate((skip, domains["valid"]))]
    assert mesh_size(meshes[0]) == mesh_size(meshes[1])
    skipped = " ".join(feedback_log.errors + feedback_log.warnings)
    assert "has invalid geometry" in skipped, skipped


def test_invalid_features_are_skipped_where_processing_s_setting_says_so(processing, traced,
                                                                          domains, tmp_path):
    """Processing's own setting 'Invalid features filtering: Skip' (Settings › Options ›
    Processing › General) holds for FloodMesh's inputs too; left at 'Stop', the run stops
    with one line naming the invalid polygon and no mesh."""
    from processing.tools import dataobjects
    from qgis.core import QgsProcessingException

    from floodmesh.algorithms.compat import SKIP_INVALID

    context = dataobjects.createContext()
    context.setInvalidGeometryCheck(SKIP_INVALID)
    mesh = processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"], "BOUNDARY": domains["with_bowtie"],
        "OUTPUT": str(tmp_path / "skipped.2dm")}, context=context)["OUTPUT"]
    valid = processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"], "BOUNDARY": domains["valid"],
        "OUTPUT": str(tmp_path / "valid.2dm")})["OUTPUT"]
    assert mesh_size(mesh) == mesh_size(valid)
    with pytest.raises(QgsProcessingException, match="with_bowtie.gpkg is not a valid polygon"):
        processing.run("floodmesh:buildmesh", {
            "DEM": traced["dem"], "BOUNDARY": domains["with_bowtie"],
            "OUTPUT": str(tmp_path / "stopped.2dm")})
    assert not (tmp_path / "stopped.2dm").exists()


def with_options(layer, option):
    """``layer`` as its input's options in the dialog hand it on: 'Selected features only', a
    feature limit, or (QGIS >= 3.32) a feature filter expression."""
    if option == "selected":
        return QgsProcessingFeatureSourceDefinition(layer.id(), True)
    if option == "limit":
        return QgsProcessingFeatureSourceDefinition(layer.id(), False, 5)
    definition = QgsProcessingFeatureSourceDefinition(layer.id(), False)
    if not hasattr(definition, "filterExpression"):
        pytest.skip("QGIS before 3.32 has no feature filter on an input")
    definition.filterExpression = "$id > 0"
    return definition


@pytest.mark.parametrize("option", ["selected", "limit", "filter"])
def test_a_layer_of_the_wrong_geometry_with_input_options_is_refused(processing, traced, option,
                                                                     tmp_path):
    """Held-out points given as break lines, or break lines as check points, with 'Selected
    features only', a feature limit or a filter: refused before the run in one line naming the
    layer, as without the options (not meshed without lines, nor a message about a temporary
    file the user never named)."""
    from qgis.core import QgsProcessingException

    points = QgsVectorLayer(traced["holdout"], "holdout", "ogr")
    lines = QgsVectorLayer(traced["lines"], "traced lines", "ogr")
    QgsProject.instance().addMapLayers([points, lines])
    try:
        for layer in (points, lines):
            layer.selectByIds(sorted(layer.allFeatureIds())[:5])
        mesh = processing.run("floodmesh:buildmesh", {
            "DEM": traced["dem"], "OUTPUT": str(tmp_path / "m.2dm")})["OUTPUT"]
        runs = (("buildmesh", {"DEM": traced["dem"], "BREAKLINES": with_options(points, option),
                               "OUTPUT": str(tmp_path / "b.2dm")},
                 "holdout.gpkg has points; lines are needed here"),
                ("assessaccuracy", {"MESH": mesh, "POINTS": with_options(lines, option),
                                    "OUTPUT": str(tmp_path / "r.gpkg")},
                 "lines.gpkg has lines; points are needed here"))
        for algorithm, parameters, message in runs:
            with pytest.raises(QgsProcessingException) as error:
                processing.run(f"floodmesh:{algorithm}", parameters)
            assert message in str(error.value), str(error.value)
        assert not (tmp_path / "b.2dm").exists() and not (tmp_path / "r.gpkg").exists()
    finally:
        QgsProject.instance().removeMapLayers([points.id(), lines.id()])


@pytest.mark.parametrize("option", ["selected", "limit", "filter"])
def test_errors_about_an_input_with_options_name_its_layer(processing, traced, in_utm33, option,
                                                           tmp_path):
    """Break lines of another CRS with 'Selected features only', a feature limit or a filter
    (read from a temporary copy of those features): the refusal names the user's layer, as
    without the options, not the copy's name (BREAKLINES.gpkg)."""
    from qgis.core import QgsProcessingException

    lines = QgsVectorLayer(in_utm33["lines"], "lines_33", "ogr")
    QgsProject.instance().addMapLayer(lines)
    try:
        lines.selectByIds(sorted(lines.allFeatureIds())[:5])
        with pytest.raises(QgsProcessingException) as error:
            processing.run("floodmesh:buildmesh", {
                "DEM": traced["dem"], "BREAKLINES": with_options(lines, option),
                "OUTPUT": str(tmp_path / "b.2dm")})
        message = str(error.value)
        assert "lines_33.gpkg is in ETRS89 / UTM zone 33N" in message, message
        assert not (tmp_path / "b.2dm").exists()
    finally:
        QgsProject.instance().removeMapLayer(lines.id())


@pytest.mark.parametrize("option", ["nothing selected", "filter"])
def test_input_options_that_leave_no_feature_are_refused(processing, traced, option, tmp_path):
    """A feature filter that matches nothing (a typo in a field value), or 'Selected features
    only' with nothing selected (a script, a batch row): one line naming the layer and the
    options, not a mesh without its break lines nor 'holdout.gpkg has no 3-D points'."""
    from qgis.core import QgsProcessingException

    lines = QgsVectorLayer(traced["lines"], "traced lines", "ogr")
    points = QgsVectorLayer(traced["holdout"], "holdout", "ogr")
    QgsProject.instance().addMapLayers([lines, points])
    try:
        def emptied(layer):
            if option == "nothing selected":
                return QgsProcessingFeatureSourceDefinition(layer.id(), True)
            definition = with_options(layer, "filter")
            definition.filterExpression = "$id < 0"
            return definition

        mesh = processing.run("floodmesh:buildmesh", {
            "DEM": traced["dem"], "OUTPUT": str(tmp_path / "m.2dm")})["OUTPUT"]
        runs = (("buildmesh", {"DEM": traced["dem"], "BREAKLINES": emptied(lines),
                               "OUTPUT": str(tmp_path / "b.2dm")}, lines),
                ("assessaccuracy", {"MESH": mesh, "POINTS": emptied(points),
                                    "OUTPUT": str(tmp_path / "r.gpkg")}, points))
        for algorithm, parameters, layer in runs:
            with pytest.raises(QgsProcessingException) as error:
                processing.run(f"floodmesh:{algorithm}", parameters)
            message = str(error.value).strip().splitlines()[-1]
            assert message.startswith(f"{layer.name()}: none of its {layer.featureCount()} "
                                      f"features is left by the input's options"), message
        assert not (tmp_path / "b.2dm").exists() and not (tmp_path / "r.gpkg").exists()
    finally:
        QgsProject.instance().removeMapLayers([lines.id(), points.id()])


@pytest.mark.parametrize("expression, says", [
    ("length_m >", "is not an expression"),
    ("lenght_m > 20", "'lenght_m' not found")])
def test_a_feature_filter_that_cannot_select_says_what_is_wrong(processing, traced, expression,
                                                                says, tmp_path):
    """A feature filter (QGIS >= 3.32) cut short or with a misspelt field selects nothing (QGIS
    hands on no features, silently): the refusal names the filter and its error."""
    from qgis.core import QgsProcessingException

    lines = QgsVectorLayer(traced["lines"], "traced lines", "ogr")
    QgsProject.instance().addMapLayer(lines)
    try:
        definition = with_options(lines, "filter")
        definition.filterExpression = expression
        with pytest.raises(QgsProcessingException) as error:
            simplified(processing, definition, tmp_path / "s.gpkg")
        message = str(error.value).strip().splitlines()[-1]
        assert message.startswith(f"traced lines: its feature filter {expression!r}"), message
        assert says in message and message.endswith("correct the input's feature filter")
        assert not (tmp_path / "s.gpkg").exists()
    finally:
        QgsProject.instance().removeMapLayer(lines.id())


def test_copies_of_inputs_go_to_the_run_s_temporary_folder(processing, traced, domains, tmp_path):
    """The copy of an input that skips invalid features goes where QGIS puts its own copies:
    the temporary folder set for the run (QGIS >= 3.32: the dialog's Algorithm Settings ›
    Temporary folder, e.g. a larger disk than /tmp)."""
    from processing.tools import dataobjects

    from floodmesh.algorithms.compat import SKIP_INVALID

    context = dataobjects.createContext()
    if not hasattr(context, "setTemporaryFolder"):
        pytest.skip("QGIS before 3.32 has no temporary folder per run")
    context.setTemporaryFolder(str(tmp_path / "scratch"))
    context.setInvalidGeometryCheck(SKIP_INVALID)
    processing.run("floodmesh:buildmesh", {
        "DEM": traced["dem"], "BOUNDARY": domains["with_bowtie"],
        "OUTPUT": str(tmp_path / "m.2dm")}, context=context)
    assert [p.name for p in (tmp_path / "scratch").rglob("*.gpkg")] == ["with_bowtie.gpkg"]


def test_a_layer_s_unsaved_edits_are_what_the_step_reads(processing, traced, tmp_path):
    """Break lines edited in QGIS and not yet saved (lines deleted, the layer still in edit
    mode): the step reads what the map shows, as QGIS's own algorithms do, not the file on
    disk; the file stays as it was."""
    layer = QgsVectorLayer(traced["lines"], "traced lines", "ogr")
    QgsProject.instance().addMapLayer(layer)
    try:
        deleted = sorted(layer.allFeatureIds())[:20]
        assert layer.startEditing() and layer.deleteFeatures(deleted)
        kept = processing.run("native:extractbyexpression", {
            "INPUT": traced["lines"], "OUTPUT": str(tmp_path / "kept.gpkg"),
            "EXPRESSION": f"$id NOT IN ({','.join(map(str, deleted))})"})["OUTPUT"]
        assert count(simplified(processing, layer, tmp_path / "edited.gpkg")) == count(
            simplified(processing, kept, tmp_path / "saved.gpkg"))
        assert count(traced["lines"]) == len(deleted) + count(kept)
    finally:
        layer.rollBack()
        QgsProject.instance().removeMapLayer(layer.id())


@pytest.mark.parametrize("option", ["selected", "unsaved edits"])
def test_an_output_onto_an_input_read_from_a_copy_is_refused(processing, traced, option,
                                                            tmp_path):
    """The input GeoPackage named as the output, where the step reads the input from a copy
    (its selected features, its unsaved edits): refused in one line as for the file itself,
    the user's GeoPackage untouched (it was overwritten with the simplified selection)."""
    import shutil

    from qgis.core import QgsProcessingException

    mine = tmp_path / "mine.gpkg"
    shutil.copy(traced["lines"], mine)
    layer = QgsVectorLayer(str(mine), "mine", "ogr")
    QgsProject.instance().addMapLayer(layer)
    try:
        first = sorted(layer.allFeatureIds())[:5]
        if option == "selected":
            layer.selectByIds(first)
            given = QgsProcessingFeatureSourceDefinition(layer.id(), True)
        else:
            assert layer.startEditing() and layer.deleteFeatures(first)
            given = layer
        with pytest.raises(QgsProcessingException, match="is the input"):
            simplified(processing, given, mine)
        layer.rollBack()
        assert count(str(mine)) == count(traced["lines"])
    finally:
        QgsProject.instance().removeMapLayer(layer.id())
