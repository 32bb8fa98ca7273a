"""Breakpoints: cells whose slope reaches the critical slope S_crit, thinned as the method says.

Thinning drops every breakpoint whose eight neighbours are all breakpoints; what remains outlines
each steep band, which the tracer joins into break lines.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from .options import check_s_crit, check_sensitivity
from .raster import Grid


def classify_breakpoints(slope: Grid, s_crit: float, *, thin: bool = True) -> Grid:
    """Binary (uint8) breakpoint grid: slope ≥ ``s_crit`` degrees, then thinned."""
    s_crit = check_s_crit(s_crit)
    with np.errstate(invalid="ignore"):
        breakpoints = slope.values >= s_crit
    if thin:
        breakpoints = thin_breakpoints(breakpoints)
    return slope.with_values(breakpoints.astype(np.uint8))


def thin_breakpoints(breakpoints: np.ndarray) -> np.ndarray:
    """Drop the breakpoints completely surrounded by breakpoints (all 8 neighbours set).

    Cells on the raster edge have missing neighbours, so they are never 'completely surrounded'.
    """
    surrounded = ndimage.binary_erosion(breakpoints, structure=np.ones((3, 3), bool),
                                        border_value=0)
    return breakpoints & ~surrounded


def log_breakpoints(response: Grid, sensitivity: float, *, zero_crossings: bool = False) -> Grid:
    """Breakpoints from a Laplacian-of-Gaussian response (m), as a thinned binary grid.

    By default a cell is a breakpoint where |response| ≥ ``sensitivity`` metres: the convex
    crests and concave toes where slope breaks. With ``zero_crossings`` it is where the response
    changes sign (zero counts as positive) between a cell and its right or lower neighbour by at
    least ``sensitivity``; the cell of the pair nearer to zero is marked (Marr & Hildreth 1980,
    doi:10.1098/rspb.1980.0020): the mid-slope edges.
    """
    sensitivity = check_sensitivity(sensitivity)
    valid = np.isfinite(response.values)
    r = np.where(valid, response.values, 0.0)
    if not zero_crossings:
        return response.with_values(thin_breakpoints(valid & (np.abs(r) >= sensitivity))
                                    .astype(np.uint8))
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
    return response.with_values(thin_breakpoints(marks).astype(np.uint8))
