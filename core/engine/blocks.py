"""Block-by-block processing of raster steps with a halo, in memory or streaming file to file.

One engine serves both: a step is a *kernel* ``func(padded) -> interior`` that receives a block
padded by ``halo`` cells on every side (``fill``, NaN, beyond the raster) and returns the block's
interior. ``map_overlap`` runs it over an array; ``map_raster`` streams it from one GeoTIFF to
another, reading each window with its halo, computing, and writing the window, so that only a
few blocks are ever in memory whatever the raster's size. The kernel of one window runs in a
worker thread while the calling thread reads the next and writes the previous one; every GDAL
call stays in the calling thread (GDAL 3.6 hung when a reader thread ran beside the writer, or
with its own workers).

The result equals applying the kernel to the whole NaN-padded raster, for any window list.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Sequence

import numpy as np

from .._kernels.aot import kernel
from ..errors import FloodMeshError
from ..io import (atomic_output, band_scaling, dem_file, describe_band, implausible_note,
                  no_valid_cells, nodata_range, raster_crs_wkt, raster_profile, read_band,
                  refuse_non_elevations, require_file)
from ..raster import HIGHEST_GROUND_M, LOWEST_GROUND_M, require_metre_elevations
from .progress import poll

DEFAULT_BLOCK_ROWS = 2048
# File to file: strips of this many rows (a multiple of the tile size), the full width.
STREAM_BLOCK_ROWS = 512
# GDAL's block cache (MB) while streaming: a strip of tiles in and out, not 5 % of the RAM.
GDAL_CACHE_MB = 128
FLOAT_NODATA = -9999.0
BYTE_NODATA = 255


Window = tuple  # (row_off, col_off, height, width)


def row_windows(shape: tuple[int, int], block_rows: int) -> list[Window]:
    """Full-width strips of ``block_rows`` rows covering a raster of ``shape``."""
    rows, cols = shape
    return [(r0, 0, min(block_rows, rows - r0), cols) for r0 in range(0, rows, block_rows)]


def _fill_window(buffer: np.ndarray, read_into: Callable, shape, window: Window, halo: int,
                 fill) -> np.ndarray:
    """``buffer`` (the window grown by ``halo`` on every side) filled: ``read_into(view, r0, r1,
    c0, c1)`` writes the part inside the raster into ``view``, ``fill`` goes elsewhere."""
    rows, cols = shape
    r0, c0, h, w = window
    lo_r, hi_r = max(0, r0 - halo), min(rows, r0 + h + halo)
    lo_c, hi_c = max(0, c0 - halo), min(cols, c0 + w + halo)
    top, left = halo - (r0 - lo_r), halo - (c0 - lo_c)
    bottom, right = top + hi_r - lo_r, left + hi_c - lo_c
    buffer[:top], buffer[bottom:] = fill, fill
    buffer[top:bottom, :left], buffer[top:bottom, right:] = fill, fill
    read_into(buffer[top:bottom, left:right], lo_r, hi_r, lo_c, hi_c)
    return buffer


def run_blocks(read_into: Callable, write: Callable, shape: tuple[int, int],
               func: Callable[[np.ndarray], np.ndarray], *, halo: int,
               windows: Sequence[Window], fill=np.nan, dtype=np.float64,
               progress: Callable[[float], None] | None = None,
               cancelled: Callable[[], bool] | None = None) -> None:
    """The engine: for each window, ``read_into(view, r0, r1, c0, c1)`` fills a preallocated
    padded buffer, ``func`` computes the interior, ``write(window, interior)`` stores it.

    ``func`` runs in one worker thread while this thread reads the next window and writes the
    previous one, so reading, computing and writing overlap; ``read_into`` and ``write`` (the
    GDAL calls) stay in this thread: GDAL 3.6 hung with a reader thread beside a writer. Two
    buffers per window shape alternate, so the kernel may return a view of its input."""
    windows = list(windows)
    buffers: dict = {}
    pending = None  # (window, future) of the window being computed

    def finish(done, k):
        window, future = done
        write(window, future.result())
        if progress is not None:
            progress(k / len(windows))

    with ThreadPoolExecutor(1, thread_name_prefix="floodmesh-block") as pool:
        try:
            for k, window in enumerate(windows):
                poll(cancelled)
                size = (window[2] + 2 * halo, window[3] + 2 * halo)
                buffer = buffers.get((k % 2, size))
                if buffer is None:
                    buffer = buffers[k % 2, size] = np.empty(size, dtype)
                _fill_window(buffer, read_into, shape, window, halo, fill)
                previous, pending = pending, (window, pool.submit(func, buffer))
                if previous is not None:
                    finish(previous, k)
            if pending is not None:
                finish(pending, len(windows))
        finally:
            if pending is not None:
                pending[1].cancel()


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
    def read_into(view, r0, r1, c0, c1):
        view[...] = values[r0:r1, c0:c1]

    run_blocks(read_into, write, values.shape, func,
               halo=halo, windows=windows, fill=fill,
               dtype=np.result_type(values.dtype, np.asarray(fill).dtype), cancelled=cancelled)
    return out[0] if out else np.empty(values.shape, dtype=dtype or values.dtype)


def map_raster(src_path, dst_path, func: Callable[[np.ndarray], np.ndarray], *, halo: int,
               dtype="float32", nodata=None, windows: Iterable[Window] | None = None,
               block_rows: int = STREAM_BLOCK_ROWS, input_dtype=np.float32, crs=None,
               elevations: bool = False, note: Callable[[str], None] | None = None,
               quantity: str | None = None, progress: Callable[[float], None] | None = None,
               cancelled: Callable[[], bool] | None = None) -> None:
    """Stream ``func`` (a kernel as for ``map_overlap``) from band 1 of ``src_path`` to a tiled
    GeoTIFF ``dst_path`` (``io.raster_profile``) on the same grid, window by window; ``quantity``
    says what it holds (``io.describe_band``).

    The kernel receives ``input_dtype`` (float32) blocks with NaN for nodata, ±inf and beyond the
    raster (with ``elevations``, a DEM's, also for cells no ground has, which ``note`` is told
    of as ``io.read_raster`` tells it), and returns the interior in any dtype; NaN in a float
    result is written as ``nodata`` (default −9999; 255 for integer outputs). ``windows`` are
    (row_off, col_off, height, width) of the output (default: full-width strips of
    ``block_rows`` rows); windows not listed are left nodata, so tiles of one raster can be
    computed by separate calls into separate files. Peak memory is a few blocks. The output is
    written under a temporary name and moved into place only when complete.

    This is the unit a tiled or distributed run calls per tile: it reads only the windows (plus
    halo) it is given.
    """
    # lazy: GDAL loads only when this runs
    import rasterio
    from rasterio.windows import Window

    if nodata is None:
        nodata = FLOAT_NODATA if np.dtype(dtype).kind == "f" else BYTE_NODATA
    src_path = require_file(src_path, "raster")
    valid = [np.dtype(input_dtype).kind != "f"]  # whether a finite cell has been read
    # GDAL sizes its block cache when first used: the environment comes before the first open
    with rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB), \
            _open(src_path) as src:
        if elevations:
            refuse_non_elevations(src, f"raster {src_path.name}")
            require_metre_elevations(src.units[0], f"raster {src_path.name}")
        crs = raster_crs_wkt(src, src_path, crs)
        shape = (src.height, src.width)
        windows = row_windows(shape, block_rows) if windows is None else list(windows)

        read_band, to_nan, implausible = _band_reader(src, input_dtype, halo, elevations)
        nan_to_value = _kernel("nan_to_value", dtype)

        def read_into(view, r0, r1, c0, c1):
            read_band(view, Window(c0, r0, c1 - c0, r1 - r0))

        def compute(padded):
            """In the worker thread: the per-cell passes (nodata to NaN, the kernel, NaN to
            nodata), so that this thread only reads and writes."""
            if to_nan(padded) and not valid[0]:
                valid[0] = True
            result = np.asarray(func(padded))
            if result.dtype.kind == "f":
                kind = dtype if np.dtype(dtype).kind == "f" else result.dtype
                result = nan_to_value(np.ascontiguousarray(result, kind),
                                      np.dtype(kind).type(nodata))
            return result.astype(dtype, copy=False)

        profile = raster_profile(shape, src.transform, crs, dtype, nodata)
        with atomic_output(dst_path) as tmp:
            with rasterio.open(tmp, "w", **profile) as dst:
                describe_band(dst, quantity)

                def write(window, result):
                    r0, c0, h, w = window
                    dst.write(result, 1, window=Window(c0, r0, w, h))

                run_blocks(read_into, write, shape, compute, halo=halo, windows=windows,
                           dtype=input_dtype, progress=progress, cancelled=cancelled)
            if implausible[0] and note:
                note(implausible_note(dem_file(src_path.name, src.nodata), src_path.name,
                                      int(implausible[0]), *implausible[1:]))
            if not valid[0]:
                raise no_valid_cells(src_path)  # before the move: no output is left


def _band_reader(src, dtype, halo: int, elevations: bool):
    """``(read, to_nan, implausible)``: ``read(view, window)`` reads band 1 of the open ``src``
    in ``window`` into the array ``view`` (any strides) as ``dtype``, straight into the caller's
    buffer; ``to_nan(padded)``, on the whole padded buffer (NaN beyond the raster) in the worker
    thread, makes nodata (``io.nodata_range``) and ±inf NaN in floats, with ``elevations`` also
    cells no ground has, gathered in ``implausible`` (count, least, greatest; ``halo`` cells of
    the buffer are another window's), and returns whether a finite cell is in it. Files that
    mask cells by a mask band rather than a nodata value, and those whose values are packed
    (``io.band_scaling``), are read as ``io.read_band`` reads them, nodata NaN and unpacked."""
    # lazy: GDAL loads only when this runs
    from rasterio.enums import MaskFlags

    implausible = np.array([0.0, np.inf, -np.inf])
    flags = src.mask_flag_enums[0]
    whole = band_scaling(src) == (1.0, 0.0)
    if MaskFlags.per_dataset in flags or MaskFlags.alpha in flags or not whole or \
            np.dtype(dtype).kind != "f":
        def read(view, window):
            view[...] = read_band(src, window, dtype)
    else:
        def read(view, window):
            src.read(1, window=window, out=view)
    if np.dtype(dtype).kind != "f":
        return read, lambda padded: True, implausible
    cast = np.dtype(dtype).type
    # unpacked values are no longer the nodata tag's: read_band made those NaN
    low, high = (cast(v) for v in (nodata_range(src) if whole else (np.nan, np.nan)))
    lowest, highest = (cast(LOWEST_GROUND_M), cast(HIGHEST_GROUND_M)) if elevations else \
        (cast(-np.inf), cast(np.inf))
    missing_to_nan = _kernel("missing_to_nan", dtype)
    return read, lambda padded: missing_to_nan(padded, low, high, lowest, highest, halo,
                                               implausible), implausible


def _kernel(name: str, dtype):
    """The raster kernel ``name``: ahead of time for float32 (``compiled``), else numba's."""
    if np.dtype(dtype) == np.float32:
        return kernel(f"{name}_f32")
    # lazy: numba loads only when this runs
    from .._kernels import raster as raster_kernels

    return getattr(raster_kernels, name)


def _open(path):
    # lazy: GDAL loads only when this runs
    import rasterio

    try:
        return rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        raise FloodMeshError(f"{path.name} is not a readable raster ({exc})") from None


def cell_size(path) -> float:
    """The cell size d (m) of a raster file, for kernels that need it."""
    # lazy: GDAL loads only when this runs
    import rasterio

    with rasterio.open(require_file(path, "raster")) as src:
        return float(src.transform.a)
