"""The QGIS side of FloodMesh: the plugin class and the Processing provider."""
