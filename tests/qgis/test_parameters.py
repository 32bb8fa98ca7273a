"""Parameter types as QGIS users expect them: horizontal distances are distance parameters in
metres (no parent: FloodMesh's data are in metres, and an unset parent shows '<unknown>'; the
desktop test reads what the dialog shows), areas are numbers labelled m², and the LiDAR input is
also a point-cloud layer."""
from qgis.core import (QgsApplication, QgsProcessingParameterDistance,
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
