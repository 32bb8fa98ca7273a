"""The front ends over ``core.chain``: the ``floodmesh`` command (``cli``, ``flood_cli``,
``console``), the QGIS plugin's worker process (``worker``, ``dependencies``), the built-in demo
(``demo``) and the kernels compiled at setup (``warmup``). They import the steps on first use,
so that ``floodmesh --help`` and a worker start without numba, rasterio or Triangle."""
