"""Breakpoints: cells whose slope reaches the critical slope S_crit, thinned as the method says.

Thinning drops every breakpoint whose eight neighbours are all breakpoints; what remains outlines
each steep band, which the tracer joins into break lines.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from .errors import FloodMeshError
from .raster import Grid


def classify_breakpoints(slope: Grid, s_crit: float, *, thin: bool = True) -> Grid:
    """Binary (uint8) breakpoint grid: slope ≥ ``s_crit`` degrees, then thinned."""
    if not 0 < s_crit < 90:
        raise FloodMeshError(f"critical slope S_crit must be between 0 and 90 degrees, got {s_crit}")
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
