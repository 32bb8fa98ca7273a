"""Parameter types as QGIS users expect them: horizontal distances are distance parameters that
show their unit (the parent layer's or CRS parameter's, metres when none is set), areas are
numbers labelled m², and the LiDAR input is also a point-cloud layer."""
from qgis.core import (QgsApplication, QgsProcessingParameterDistance,
                       QgsProcessingParameterNumber, QgsProcessingParameterPointCloudLayer)

from floodmesh.algorithms.compat import METRES

DISTANCES = {
    "lidartomesh": {"CELL_SIZE": "CRS", "MAX_GAP": "CRS", "SIGMA": "CRS", "TOLERANCE": "CRS"},
    "gridpoints": {"CELL_SIZE": "CRS", "MAX_GAP": "CRS"},
    "slope": {"SIGMA": "INPUT"},
    "tracebreaklines": {"MIN_LENGTH": "DEM"},
    "simplifybreaklines": {"TOLERANCE": "INPUT", "MIN_DISTANCE": "INPUT"},
    "exportmesh": {"SNAP": "INPUT"},
}


def test_distances_are_distance_parameters_with_their_parent_and_metres(processing):
    registry = QgsApplication.processingRegistry()
    for name, distances in DISTANCES.items():
        algorithm = registry.algorithmById(f"floodmesh:{name}")
        for parameter_name, parent in distances.items():
            parameter = algorithm.parameterDefinition(parameter_name)
            assert isinstance(parameter, QgsProcessingParameterDistance), (name, parameter_name)
            assert parameter.parentParameterName() == parent
            assert algorithm.parameterDefinition(parent) is not None
            assert parameter.defaultUnit() == METRES
        for parameter in algorithm.parameterDefinitions():
            if "m²" in parameter.description():
                assert isinstance(parameter, QgsProcessingParameterNumber)


def test_the_lidar_input_is_also_a_point_cloud_layer(processing):
    registry = QgsApplication.processingRegistry()
    for name in ("lidartomesh", "gridpoints", "refinemesh"):
        parameter = registry.algorithmById(f"floodmesh:{name}").parameterDefinition("POINT_CLOUD")
        assert isinstance(parameter, QgsProcessingParameterPointCloudLayer), name
