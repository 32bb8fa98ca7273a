"""Block-by-block processing of raster steps with a halo, in memory or streaming file to file.

One engine serves both: a step is a *kernel* ``func(padded) -> interior`` that receives a block
padded by ``halo`` cells on every side (``fill``, NaN, beyond the raster) and returns the block's
interior. ``map_overlap`` runs it over an array; ``map_raster`` streams it from one GeoTIFF to
another, reading each window with its halo, computing, and writing the window, so that only a
few blocks are ever in memory whatever the raster's size. Windows run one after the other in
one thread: GDAL 3.6 hung when a reader thread ran beside the writer, or with its own workers.

The result equals applying the kernel to the whole NaN-padded raster, for any window list.
"""
from __future__ import annotations

from typing import Callable, Iterable, Sequence

import numpy as np

DEFAULT_BLOCK_ROWS = 2048
# File to file: strips of this many rows (a multiple of the tile size), the full width.
STREAM_BLOCK_ROWS = 512
TILE = 256
# GDAL's block cache (MB) while streaming: a strip of tiles in and out, not 5 % of the RAM.
GDAL_CACHE_MB = 128
FLOAT_NODATA = -9999.0
BYTE_NODATA = 255
# Chosen by measurement (benchmarks/run.py --only codec, 4000² DEM, slope and breakpoints):
# ZSTD level 1 without a predictor costs 0.19 s of CPU per 64 MB written (none: 0.06, DEFLATE:
# 1.0-1.2, LZW with a predictor: 0.85-0.94, ZSTD 1 with the floating-point predictor: 0.45) and
# reads back as fast as no compression, at 80 % of the size (the predictor saves another 15-30 %
# but makes reading 3-5x slower). GDAL's own worker threads (NUM_THREADS, GDAL_NUM_THREADS)
# are not used: GDAL 3.6's multi-threaded decoding hung in RasterIO (CPLJobQueue) in the tests.
CREATION_OPTIONS = dict(compress="zstd", zstd_level=1, tiled=True, blockxsize=TILE,
                        blockysize=TILE, bigtiff="if_safer")

Window = tuple  # (row_off, col_off, height, width)


def row_windows(shape: tuple[int, int], block_rows: int) -> list[Window]:
    """Full-width strips of ``block_rows`` rows covering a raster of ``shape``."""
    rows, cols = shape
    return [(r0, 0, min(block_rows, rows - r0), cols) for r0 in range(0, rows, block_rows)]


def _padded(read: Callable, shape, window: Window, halo: int, fill, dtype) -> np.ndarray:
    """The window grown by ``halo`` on every side; ``read(r0, r1, c0, c1)`` gives the part
    inside the raster, ``fill`` elsewhere."""
    rows, cols = shape
    r0, c0, h, w = window
    lo_r, hi_r = max(0, r0 - halo), min(rows, r0 + h + halo)
    lo_c, hi_c = max(0, c0 - halo), min(cols, c0 + w + halo)
    block = np.full((h + 2 * halo, w + 2 * halo), fill, dtype=dtype)
    top, left = halo - (r0 - lo_r), halo - (c0 - lo_c)
    block[top:top + hi_r - lo_r, left:left + hi_c - lo_c] = read(lo_r, hi_r, lo_c, hi_c)
    return block


def run_blocks(read: Callable, write: Callable, shape: tuple[int, int],
               func: Callable[[np.ndarray], np.ndarray], *, halo: int,
               windows: Sequence[Window], fill=np.nan, dtype=np.float64,
               progress: Callable[[float], None] | None = None,
               cancelled: Callable[[], bool] | None = None) -> None:
    """The engine: for each window, ``read(r0, r1, c0, c1)`` → pad → ``func`` →
    ``write(window, interior)``, one window after the other in this thread (a reader thread
    beside the writer deadlocked GDAL 3.6)."""
    from .errors import Cancelled

    windows = list(windows)
    for k, window in enumerate(windows):
        if cancelled is not None and cancelled():
            raise Cancelled()
        write(window, func(_padded(read, shape, window, halo, fill, dtype)))
        if progress is not None:
            progress((k + 1) / len(windows))

def map_overlap(values: np.ndarray, func: Callable[[np.ndarray], np.ndarray], *, halo: int,
                block_rows: int = DEFAULT_BLOCK_ROWS, fill=np.nan, dtype=None,
                windows: Iterable[Window] | None = None,
                cancelled: Callable[[], bool] | None = None) -> np.ndarray:
    """Apply a neighbourhood function to blocks of ``values`` with ``halo`` cells of context.

    ``func`` receives a block padded by ``halo`` on every side (``fill`` beyond the raster) and
    returns the block's interior. The result equals applying ``func`` to the whole padded raster.
    Blocks are full-width strips of ``block_rows`` rows unless ``windows`` are given.
    """
    out = []

    def write(window, result):
        if not out:
            out.append(np.empty(values.shape, dtype=dtype or result.dtype))
        r0, c0, h, w = window
        out[0][r0:r0 + h, c0:c0 + w] = result

    windows = row_windows(values.shape, block_rows) if windows is None else windows
    run_blocks(lambda r0, r1, c0, c1: values[r0:r1, c0:c1], write, values.shape, func,
               halo=halo, windows=windows, fill=fill,
               dtype=np.result_type(values.dtype, np.asarray(fill).dtype), cancelled=cancelled)
    return out[0] if out else np.empty(values.shape, dtype=dtype or values.dtype)


def raster_profile(shape, transform, crs, dtype, nodata) -> dict:
    """A tiled, compressed GeoTIFF profile (rasters under a tile stay striped)."""
    profile = dict(driver="GTiff", height=shape[0], width=shape[1], count=1, dtype=dtype,
                   crs=crs.to_wkt(), transform=transform, nodata=nodata, **CREATION_OPTIONS)
    if shape[0] < TILE or shape[1] < TILE:
        for key in ("tiled", "blockxsize", "blockysize"):
            profile.pop(key)
    return profile


def map_raster(src_path, dst_path, func: Callable[[np.ndarray], np.ndarray], *, halo: int,
               dtype="float32", nodata=None, windows: Iterable[Window] | None = None,
               block_rows: int = STREAM_BLOCK_ROWS, input_dtype=np.float32, crs=None,
               progress: Callable[[float], None] | None = None,
               cancelled: Callable[[], bool] | None = None) -> None:
    """Stream ``func`` (a kernel as for ``map_overlap``) from band 1 of ``src_path`` to a tiled,
    compressed GeoTIFF ``dst_path`` on the same grid, window by window.

    The kernel receives ``input_dtype`` (float32) blocks with NaN for nodata, ±inf and beyond the
    raster, and returns the interior in any dtype; NaN in a float result is written as
    ``nodata`` (default −9999; 255 for integer outputs). ``windows`` are
    (row_off, col_off, height, width) of the output (default: full-width strips of
    ``block_rows`` rows); windows not listed are left nodata, so tiles of one raster can be
    computed by separate calls into separate files. Peak memory is a few blocks. The output is
    written under a temporary name and moved into place only when complete.

    This is the unit a tiled or distributed run calls per tile: it reads only the windows (plus
    halo) it is given.
    """
    import rasterio

    from .io import _read_band, _require_file, atomic_output, no_valid_cells, raster_crs

    if nodata is None:
        nodata = FLOAT_NODATA if np.dtype(dtype).kind == "f" else BYTE_NODATA
    src_path = _require_file(src_path, "raster")
    valid = [False]
    check_valid = np.dtype(input_dtype).kind == "f"
    # GDAL sizes its block cache when first used: the environment comes before the first open
    with rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB), \
            _open(src_path) as src:
        crs = raster_crs(src, src_path, crs)
        shape = (src.height, src.width)
        windows = row_windows(shape, block_rows) if windows is None else list(windows)

        def read(r0, r1, c0, c1):
            from rasterio.windows import Window as RioWindow

            block = _read_band(src, RioWindow(c0, r0, c1 - c0, r1 - r0), input_dtype)
            if check_valid and not valid[0]:
                valid[0] = bool(np.isfinite(block).any())
            return block

        profile = raster_profile(shape, src.transform, crs, dtype, nodata)
        with atomic_output(dst_path) as tmp:
            with rasterio.open(tmp, "w", **profile) as dst:
                def write(window, result):
                    from rasterio.windows import Window as RioWindow

                    result = np.asarray(result)
                    if result.dtype.kind == "f":
                        result = np.where(np.isnan(result), nodata, result)
                    r0, c0, h, w = window
                    dst.write(result.astype(dtype, copy=False), 1,
                              window=RioWindow(c0, r0, w, h))

                run_blocks(read, write, shape, func, halo=halo, windows=windows,
                           dtype=input_dtype, progress=progress, cancelled=cancelled)
            if check_valid and not valid[0]:
                raise no_valid_cells(src_path)  # before the move: no output is left


def _open(path):
    import rasterio

    from .errors import FloodMeshError

    try:
        return rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        raise FloodMeshError(f"{path.name} is not a readable raster ({exc})") from None


def cell_size(path) -> float:
    """The cell size d (m) of a raster file, for kernels that need it."""
    import rasterio

    from .io import _require_file

    with rasterio.open(_require_file(path, "raster")) as src:
        return float(src.transform.a)
