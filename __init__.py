"""FloodMesh: LiDAR to finite-element meshes. QGIS loads the plugin through ``classFactory``;
without QGIS the same package is a plain library (``floodmesh.core``) and the ``floodmesh``
command."""


def classFactory(iface):  # noqa: N802 (QGIS's name)
    from .provider.plugin import FloodMeshPlugin

    return FloodMeshPlugin(iface)
