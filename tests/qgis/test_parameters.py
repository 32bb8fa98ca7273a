"""Parameter types as QGIS users expect them: horizontal distances are distance parameters in
metres (no parent: FloodMesh's data are in metres, and an unset parent shows '<unknown>'; the
desktop test reads what the dialog shows), areas are numbers labelled m², and the LiDAR input is
also a point-cloud layer."""
from pathlib import Path

from qgis.core import (QgsApplication, QgsProcessingModelAlgorithm,
                       QgsProcessingParameterDistance,
                       QgsProcessingParameterNumber, QgsProcessingParameterPointCloudLayer)

from floodmesh.algorithms.compat import METRES

DISTANCES = {
    "lidartomesh": ("CELL_SIZE", "MAX_GAP", "SIGMA", "TOLERANCE"),
    "gridpoints": ("CELL_SIZE", "MAX_GAP"),
    "slope": ("SIGMA",),
    "tracebreaklines": ("MIN_LENGTH",),
    "simplifybreaklines": ("TOLERANCE", "MIN_DISTANCE"),
    "exportmesh": ("SNAP",),
}


def test_distances_are_distance_parameters_in_metres(processing):
    registry = QgsApplication.processingRegistry()
    for name, distances in DISTANCES.items():
        algorithm = registry.algorithmById(f"floodmesh:{name}")
        for parameter_name in distances:
            parameter = algorithm.parameterDefinition(parameter_name)
            assert isinstance(parameter, QgsProcessingParameterDistance), (name, parameter_name)
            assert parameter.parentParameterName() == ""
            assert parameter.defaultUnit() == METRES
        for parameter in algorithm.parameterDefinitions():
            if "m²" in parameter.description():
                assert isinstance(parameter, QgsProcessingParameterNumber)


def test_the_lidar_input_is_also_a_point_cloud_layer(processing):
    registry = QgsApplication.processingRegistry()
    for name in ("lidartomesh", "gridpoints", "refinemesh"):
        parameter = registry.algorithmById(f"floodmesh:{name}").parameterDefinition("POINT_CLOUD")
        assert isinstance(parameter, QgsProcessingParameterPointCloudLayer), name


def test_the_parameters_page_lists_every_parameter_of_every_algorithm(processing):
    """docs/parameters.md has a table per algorithm (its heading names `floodmesh:ID`) with
    every parameter key the algorithm has (SKIP_UNREADABLE of two algorithms was missed)."""
    page = (Path(__file__).resolve().parents[2] / "docs" / "parameters.md").read_text("utf-8")
    provider = QgsApplication.processingRegistry().providerById("floodmesh")
    missing = []
    for algorithm in provider.algorithms():
        if isinstance(algorithm, QgsProcessingModelAlgorithm):  # its own paragraph
            continue
        heading = f"(`{algorithm.id()}`)\n"
        assert heading in page, f"docs/parameters.md has no table for {algorithm.id()}"
        table = page.split(heading, 1)[1].split("\n#", 1)[0]
        missing += [f"{algorithm.id()} {p.name()}" for p in algorithm.parameterDefinitions()
                    if f"| `{p.name()}` |" not in table]
    assert not missing, f"not in docs/parameters.md: {', '.join(missing)}"


def test_outputs_offer_only_the_formats_the_steps_write(processing):
    """Every raster output (the models' too) offers GeoTIFF alone and every layer output
    GeoPackage alone, in its extensions and its save dialog's filter: QGIS's default list (img,
    shp, geojson, …) offered names the steps then refuse."""
    import re

    from qgis.core import (QgsProcessingParameterRasterDestination,
                           QgsProcessingParameterVectorDestination)

    from floodmesh.core.chain.files import GEOPACKAGE, GEOTIFF

    provider = QgsApplication.processingRegistry().providerById("floodmesh")
    assert provider.supportedOutputRasterLayerExtensions() == ["tif", "tiff"]
    assert provider.supportedOutputVectorLayerExtensions() == ["gpkg"]
    seen = set()
    for algorithm in provider.algorithms():
        for parameter in algorithm.destinationParameterDefinitions():
            if isinstance(parameter, QgsProcessingParameterRasterDestination):
                offered, written = parameter.supportedOutputRasterLayerExtensions(), GEOTIFF
            elif isinstance(parameter, QgsProcessingParameterVectorDestination):
                offered, written = parameter.supportedOutputVectorLayerExtensions(), GEOPACKAGE
            else:
                continue
            seen.add(type(parameter))
            where = f"{algorithm.id()} {parameter.name()}"
            assert offered and {f".{e}" for e in offered} <= set(written[0]), (where, offered)
            assert parameter.defaultFileExtension() in offered, where
            in_filter = {e.lower() for e in re.findall(r"\*\.(\w+)", parameter.createFileFilter())}
            assert in_filter == set(offered), (where, parameter.createFileFilter())
    assert len(seen) == 2
