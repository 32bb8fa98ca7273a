"""The compiled loops (numba), private to ``floodmesh.core``: raster passes and the slope
kernels (``raster``), point location in a mesh (``mesh``), passes over all points (``points``),
the sweep-hull Delaunay with exact predicates (``delaunay``) and the raster kernels built ahead
of time (``aot``). The steps call them; nothing outside core should."""
