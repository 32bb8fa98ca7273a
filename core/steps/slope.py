"""Slope in degrees from a 3x3 neighbourhood, named as in the method's kernel figure::

    z1 z2 z3
    z8 z9 z4
    z7 z6 z5

with north up and cell size d (m). Missing neighbours (raster edges, nodata) are filled by
linear extrapolation: from the opposite neighbour through the centre (2·z9 − z_opposite), else
for a diagonal from its two orthogonal neighbours (z3 = z2 + z4 − z9), else z9. A plane keeps its
exact slope up to the edges and corners, and no artificial cliff appears; a nodata centre gives
nodata. The kernels run compiled, block by block with a one-cell halo.

References: Shanholtz et al. (1981) maximum slope; NOAA one-over-distance (Unwin 1981);
Sharpnack & Akin (1969) (= Horn 1981, doi:10.1109/PROC.1981.11918); Wood (1996) constrained
quadratic; Zevenbergen & Thorne (1987) doi:10.1002/esp.3290120107; Ritter (1987) diagonal
differences.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .._kernels import aot as compiled
from ..engine.blocks import cell_size, map_overlap, map_raster
from ..errors import FloodMeshError
from ..io import require_file
from ..options import LOG_KERNELS, SLOPE_METHOD_NAMES, check_choice, check_sigma_fits
from ..raster import Grid, usable_dem

SQRT2 = math.sqrt(2.0)

# name → (code, summary); the code selects the kernel inside the compiled loop
SLOPE_METHODS = dict(zip(SLOPE_METHOD_NAMES, (
    (0, "maximum slope to a neighbour (Shanholtz)"),
    (1, "one-over-distance weighted differences (NOAA)"),
    (2, "neighbourhood method (Sharpnack & Akin = Horn)"),
    (3, "constrained quadratic surface (Wood)"),
    (4, "quadratic surface (Zevenbergen & Thorne)"),
    (5, "diagonal differences (Ritter)"),
)))


def _method_code(method: str) -> int:
    try:
        return SLOPE_METHODS[method][0]
    except KeyError:
        raise FloodMeshError(f"unknown slope method {method!r}; choose one of "
                             f"{', '.join(SLOPE_METHODS)}") from None


def slope_block(padded: np.ndarray, d: float, method: str = "one-over-distance", *,
                diagonal_distance: bool = True, dtype=np.float64) -> np.ndarray:
    """Slope (degrees) of the interior of a block padded by one cell (NaN beyond the data).

    The unit of work for tiled or distributed runs: ``map_overlap(values, slope_block, halo=1)``
    in memory, ``slope_file`` file to file. ``padded`` may be float32 or float64 (the arithmetic
    is float64); the result is ``dtype``. ``diagonal_distance`` applies to "max-slope":
    diagonal neighbours at √2·d (True) or d.
    """
    # lazy: numba loads only when this runs
    from .._kernels.raster import slope_kernel

    diagonal = SQRT2 * d if diagonal_distance else d
    padded = np.asarray(padded)
    if padded.dtype not in (np.float32, np.float64):
        padded = padded.astype(np.float64)
    out = np.empty((padded.shape[0] - 2, padded.shape[1] - 2), dtype)
    return slope_kernel(padded, out, float(d), _method_code(method), diagonal)


def slope(dem: Grid, method: str = "one-over-distance", *, diagonal_distance: bool = True,
          cancelled=None, note=None) -> Grid:
    """Slope of a DEM in degrees by one of ``SLOPE_METHODS``, computed block by block. Cells
    no ground has (-9999, inf) are nodata, as in a DEM file (``raster.usable_dem``, ``note``
    told)."""
    _method_code(method)
    dem = usable_dem(dem, "the DEM", note)
    d = dem.cell_size
    values = map_overlap(
        dem.values,
        lambda padded: slope_block(padded, d, method, diagonal_distance=diagonal_distance),
        halo=1, cancelled=cancelled)
    return dem.with_values(values, "slope")


def slope_file(dem_path, out_path, method: str = "one-over-distance", *,
               diagonal_distance: bool = True, crs=None, windows=None, note=None, progress=None,
               cancelled=None) -> None:
    """Slope (degrees, float32) of a DEM file into a GeoTIFF, streamed block by block in float32
    (``blocks.map_raster``; ``windows``, and ``note`` told of cells no ground has, as there);
    the same values as ``slope`` on the DEM."""
    code, d = _method_code(method), cell_size(dem_path)
    diagonal = SQRT2 * d if diagonal_distance else d
    kernel = compiled.kernel("slope_f32")
    # the ahead-of-time kernel runs in one thread: a helper takes the block's upper half (numba's
    # own kernel is parallel already)
    helpers = 1 if compiled.ahead_of_time() else 0

    def block(padded):
        out = np.empty((padded.shape[0] - 2, padded.shape[1] - 2), np.float32)
        half = out.shape[0] // 2 if helpers else 0
        upper = pool.submit(kernel, padded[:half + 2], out[:half], d, code, diagonal) \
            if half else None
        kernel(padded[half:], out[half:], d, code, diagonal)
        if upper is not None:
            upper.result()
        return out

    with ThreadPoolExecutor(max(helpers, 1), thread_name_prefix="floodmesh-slope") as pool:
        map_raster(dem_path, out_path, block, halo=1, crs=crs, windows=windows,
                   elevations=True, note=note, quantity="slope", progress=progress,
                   cancelled=cancelled)


# ---------------------------------------------------------------------------------------------
# second order: Laplacian of Gaussian


def laplacian_of_gaussian(dem: Grid, sigma: float, *, kernel: str = "pratt",
                          cancelled=None, note=None) -> Grid:
    """Laplacian-of-Gaussian response in metres, positive on crests and negative in troughs.

    The DEM is smoothed by a Gaussian of ``sigma`` metres (0: no smoothing), then the Laplacian
    is taken with Pratt's gain-normalised 3x3 mask ``(8·z9 − Σ neighbours) / 8`` — how far the
    centre stands above the mean of its eight neighbours. ``kernel="analytic"`` convolves with
    the sampled analytic ∇²G_σ instead, scaled to the same units (−3d²/8 · ∇²z). Both are exact on
    quadratic surfaces. Cells whose kernel reaches nodata or beyond the raster (4σ plus one cell)
    are nodata: a one-sided window would bias the response there. Cells no ground has (-9999,
    inf) are nodata, as in a DEM file (``raster.usable_dem``, ``note`` told).

    Reference: Pratt, Digital Image Processing (2007), ch. 15; Marr & Hildreth (1980)
    doi:10.1098/rspb.1980.0020.
    """
    dem = usable_dem(dem, "the DEM", note)
    block, halo = _log_block(sigma, dem.cell_size, kernel, dem.shape)
    return dem.with_values(map_overlap(dem.values, block, halo=halo, cancelled=cancelled), "log")


def laplacian_of_gaussian_file(dem_path, out_path, sigma: float, *, kernel: str = "pratt",
                               crs=None, windows=None, note=None, progress=None,
                               cancelled=None) -> None:
    """``laplacian_of_gaussian`` of a DEM file into a float32 GeoTIFF, streamed block by block
    (``blocks.map_raster``; ``note`` as there); the same values as in memory."""
    # lazy: GDAL loads only when this runs
    import rasterio

    with rasterio.open(require_file(dem_path, "raster")) as src:
        d, shape = float(src.transform.a), (src.height, src.width)
    block, halo = _log_block(sigma, d, kernel, shape)
    map_raster(dem_path, out_path, block, halo=halo, crs=crs, windows=windows,
               elevations=True, note=note, quantity="log", progress=progress,
               cancelled=cancelled)


def _log_block(sigma: float, d: float, kernel: str, shape):
    """(block kernel, halo) of the LoG response for ``map_overlap`` / ``map_raster``; the block
    is computed in float64."""
    check_choice(kernel, LOG_KERNELS, "LoG kernel")
    sigma = check_sigma_fits(sigma, *shape, d)
    if kernel == "analytic" and sigma < d:
        raise FloodMeshError(f"the analytic LoG kernel needs sigma of at least one cell ({d} m), "
                             f"got {sigma}; use the pratt kernel for less smoothing")
    reach = int(math.ceil(4 * sigma / d))
    if kernel == "pratt":
        halo = reach + 1

        def block(padded):
            # lazy: SciPy loads only when this runs
            from scipy import ndimage

            padded = padded.astype(np.float64, copy=False)
            smooth = _gaussian_nan(padded, sigma / d) if sigma > 0 else padded
            c = smooth[1:-1, 1:-1]
            total = (smooth[:-2, :-2] + smooth[:-2, 1:-1] + smooth[:-2, 2:] + smooth[1:-1, :-2]
                     + smooth[1:-1, 2:] + smooth[2:, :-2] + smooth[2:, 1:-1] + smooth[2:, 2:])
            touched = ndimage.maximum_filter(~np.isfinite(padded), size=2 * halo + 1,
                                             mode="constant", cval=True)[1:-1, 1:-1]
            out = np.where(touched, np.nan, (8.0 * c - total) / 8.0)
            return out[reach:out.shape[0] - reach, reach:out.shape[1] - reach]
    else:
        halo = reach
        weights = _analytic_log_kernel(sigma, d, reach)

        def block(padded):
            # lazy: SciPy loads only when this runs
            from scipy import ndimage

            padded = padded.astype(np.float64, copy=False)
            valid = np.isfinite(padded)
            out = ndimage.correlate(np.where(valid, padded, 0.0), weights, mode="constant")
            touched = ndimage.maximum_filter(~valid, size=2 * halo + 1, mode="constant",
                                             cval=True)
            out = np.where(touched, np.nan, -3.0 * d * d / 8.0 * out)
            return out[halo:-halo, halo:-halo] if halo else out

    return block, halo


def _gaussian_nan(values, sigma_cells):
    """Gaussian smoothing that ignores NaN (normalised convolution); NaN stays NaN."""
    # lazy: SciPy loads only when this runs
    from scipy import ndimage

    valid = np.isfinite(values)
    num = ndimage.gaussian_filter(np.where(valid, values, 0.0), sigma_cells, mode="constant",
                                  truncate=4.0)
    den = ndimage.gaussian_filter(valid.astype(float), sigma_cells, mode="constant",
                                  truncate=4.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(valid, num / den, np.nan)


def _analytic_log_kernel(sigma, d, reach):
    """∇²G_σ sampled at cell offsets, zero-sum, scaled so that Σ K·(x²+y²) = 4 (exact on
    quadratics)."""
    offsets = np.arange(-reach, reach + 1) * d
    x, y = np.meshgrid(offsets, offsets)
    r2 = x * x + y * y
    k = (r2 - 2 * sigma ** 2) / (2 * np.pi * sigma ** 6) * np.exp(-r2 / (2 * sigma ** 2))
    k -= k.mean()
    return k * (4.0 / (k * r2).sum())


def slope_raster_file(dem_path, out_path, method: str = "one-over-distance", *, sigma: float = 1.0,
                      log_kernel: str = "pratt", crs=None, note=None, progress=None,
                      cancelled=None) -> None:
    """Slope (degrees) or, with ``method="log"``, the LoG response of a DEM file into a GeoTIFF,
    streamed block by block; ``note`` is told of cells no ground has, taken as nodata."""
    if method == "log":
        laplacian_of_gaussian_file(dem_path, out_path, sigma, kernel=log_kernel, crs=crs,
                                   note=note, progress=progress, cancelled=cancelled)
    else:
        slope_file(dem_path, out_path, method, crs=crs, note=note, progress=progress,
                   cancelled=cancelled)
