"""Breakpoints: cells whose slope reaches the critical slope S_crit, thinned as the method says.

Thinning drops every breakpoint whose eight neighbours are all breakpoints; what remains outlines
each steep band, which the tracer joins into break lines. Each rule is a block kernel with a
halo (``core.engine.blocks``), so the grid in memory and a file streamed block by block give the
same breakpoints, across block edges too.
"""
from __future__ import annotations

import numpy as np

from ..engine.blocks import BYTE_NODATA, map_overlap, map_raster
from ..errors import FloodMeshError
from ..io import check_quantity
from ..options import check_s_crit, check_sensitivity
from ..raster import Grid, step_grid


def classify_breakpoints(slope: Grid, s_crit: float, *, thin: bool = True) -> Grid:
    """Binary (uint8) breakpoint grid: slope ≥ ``s_crit`` degrees, then thinned; marked as
    breakpoints (``Grid.quantity``), refused where a DEM or a slope belongs."""
    step_grid(slope, "the slope", "slope", "give terrain_slope(dem), or for a LoG response "
              "log_breakpoints")
    block, halo = _threshold_block(check_s_crit(s_crit), thin)
    return slope.with_values(map_overlap(slope.values, block, halo=halo).astype(np.uint8),
                             "breakpoints")


def log_breakpoints(response: Grid, sensitivity: float, *, zero_crossings: bool = False) -> Grid:
    """Breakpoints from a Laplacian-of-Gaussian response (m), as a thinned binary grid.

    By default a cell is a breakpoint where |response| ≥ ``sensitivity`` metres: the convex
    crests and concave toes where slope breaks. With ``zero_crossings`` it is where the response
    changes sign (zero counts as positive) between a cell and its right or lower neighbour by at
    least ``sensitivity``; the cell of the pair nearer to zero is marked (Marr & Hildreth 1980,
    doi:10.1098/rspb.1980.0020): the mid-slope edges. Marked as breakpoints (``Grid.quantity``).
    """
    step_grid(response, "the LoG response", "log", "give laplacian_of_gaussian(dem), or for a "
              "slope classify_breakpoints")
    block, halo = _log_block(check_sensitivity(sensitivity), zero_crossings)
    return response.with_values(map_overlap(response.values, block, halo=halo)
                                .astype(np.uint8), "breakpoints")


def breakpoints_file(src_path, out_path, *, s_crit: float | None = None,
                     sensitivity: float | None = None, zero_crossings: bool = False, crs=None,
                     windows=None, input_dtype=np.float32, progress=None,
                     cancelled=None) -> int:
    """Breakpoints of a slope raster (``s_crit``) or of a LoG response (``sensitivity``) into a
    uint8 GeoTIFF (1 breakpoint, 0 not, 255 where the input is nodata), streamed block by block
    (``blocks.map_raster``; ``windows`` and ``input_dtype``, what the rules compare, as there).
    Returns the number of breakpoints, tagged as such (``io.describe_band``). A raster a step
    tagged as holding another quantity (``io.check_quantity``) is refused, and so are
    ``zero_crossings`` without a ``sensitivity``."""
    if sensitivity is None:
        check_quantity(src_path, "slope", "give its LoG sensitivity to take its breakpoints "
                       "(--sensitivity, e.g. 0.02, or LoG sensitivity in QGIS), or the slope of "
                       "the DEM (floodmesh slope DEM, without --method log)")
    if sensitivity is not None or zero_crossings:
        check_quantity(src_path, "log", "leave out the LoG sensitivity and zero crossings "
                       "(--sensitivity, --zero-crossings, or those parameters in QGIS) to take "
                       "breakpoints where the slope reaches S_crit, or give the DEM's LoG "
                       "response (floodmesh slope DEM --method log)")
    if sensitivity is None and zero_crossings:  # a raster without the tag: nothing said yet
        raise FloodMeshError("breakpoints at zero crossings are taken of a LoG response, at "
                             "least its sensitivity apart: give the sensitivity too "
                             "(--sensitivity, e.g. 0.02, or LoG sensitivity in QGIS), or leave "
                             "out the zero crossings to take breakpoints where the slope "
                             "reaches S_crit")
    if sensitivity is None:
        block, halo = _threshold_block(check_s_crit(s_crit), True)
    else:
        block, halo = _log_block(check_sensitivity(sensitivity), zero_crossings)
    count = [0]

    def with_nodata(padded):
        out = block(padded).astype(np.uint8)
        count[0] += int(out.sum())
        out[np.isnan(padded[halo:padded.shape[0] - halo, halo:padded.shape[1] - halo])] = \
            BYTE_NODATA
        return out

    map_raster(src_path, out_path, with_nodata, halo=halo, dtype="uint8", crs=crs,
               windows=windows, input_dtype=input_dtype, quantity="breakpoints",
               progress=progress, cancelled=cancelled)
    return count[0]


def thin_breakpoints(breakpoints: np.ndarray) -> np.ndarray:
    """Drop the breakpoints completely surrounded by breakpoints (all 8 neighbours set).

    Cells on the raster edge have missing neighbours, so they are never 'completely surrounded'.
    """
    return _thin_interior(np.pad(np.asarray(breakpoints, bool), 1))


def _thin_interior(marks: np.ndarray) -> np.ndarray:
    """Thinned breakpoints of the interior of ``marks`` padded by one cell (False beyond)."""
    rows, cols = marks.shape[0] - 2, marks.shape[1] - 2
    centre = marks[1:1 + rows, 1:1 + cols]
    surrounded = centre.copy()
    for dr in range(3):
        for dc in range(3):
            if dr != 1 or dc != 1:
                surrounded &= marks[dr:dr + rows, dc:dc + cols]
    return centre & ~surrounded


def _threshold_block(s_crit: float, thin: bool):
    """(kernel, halo): slope ≥ ``s_crit`` (NaN is not), thinned when ``thin``."""
    def block(padded):
        with np.errstate(invalid="ignore"):
            marks = padded >= _threshold_for(padded.dtype, s_crit)
        return _thin_interior(marks) if thin else marks
    return block, 1 if thin else 0


def _threshold_for(dtype, value: float):
    """The ``dtype`` number t with x ≥ t ⇔ x ≥ ``value`` (exact) for every x of that dtype: a
    float32 slope is compared as if it were float64, without a float64 copy."""
    t = np.dtype(dtype).type(value)
    if float(t) < value:
        t = np.nextafter(t, np.dtype(dtype).type(np.inf))
    return t


def _log_block(sensitivity: float, zero_crossings: bool):
    """(kernel, halo) of the LoG rules: a mark needs the cell's right and lower neighbours (and,
    for zero crossings, its left and upper ones mark it too), thinning one more cell."""
    def marks_of(padded):
        padded = padded.astype(np.float64, copy=False)
        valid = np.isfinite(padded)
        r = np.where(valid, padded, 0.0)
        if not zero_crossings:
            return valid & (np.abs(r) >= sensitivity)
        marks = np.zeros(r.shape, bool)
        for axis in (0, 1):
            a = r[:-1, :] if axis == 0 else r[:, :-1]
            b = r[1:, :] if axis == 0 else r[:, 1:]
            ok = (valid[:-1, :] & valid[1:, :]) if axis == 0 else (valid[:, :-1] & valid[:, 1:])
            crossing = ok & ((a < 0) != (b < 0)) & (np.abs(a - b) >= sensitivity)
            first = crossing & (np.abs(a) <= np.abs(b))
            if axis == 0:
                marks[:-1, :] |= first
                marks[1:, :] |= crossing & ~first
            else:
                marks[:, :-1] |= first
                marks[:, 1:] |= crossing & ~first
        return marks

    halo = 2 if zero_crossings else 1

    def block(padded):
        marks = marks_of(padded)
        if zero_crossings:  # the outer ring lacks the pairs beyond the block
            marks = marks[1:-1, 1:-1]
        return _thin_interior(marks)

    return block, halo
