"""What the steps run on: kernels over padded blocks in memory or file to file (``blocks``),
point tiles gridded on Dask (``tiles``), size and memory guards (``limits``), the point index
the terrain fits share (``nearest``), numba's compiles as the user sees them (``compiles``) and
small array helpers (``arrays``)."""
