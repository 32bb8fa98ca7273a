"""FloodMesh core: LiDAR points to break lines, quality meshes and their error, without QGIS.

The pipeline, one module per step: ``io`` (reading points and rasters, writing outputs) →
``grid`` → ``slope`` → ``breakpoints`` → ``breaklines`` → ``simplify`` → ``mesh`` →
``accuracy``; ``pipeline`` chains them and ``cli`` is the command line.
"""
