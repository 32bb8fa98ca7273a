"""A far-field size: triangles grow from the maximum area near break lines to a far-field area
where the terrain is plane: no breakpoint near, and a curvature that a linear triangle of that
size follows within a vertical tolerance (edge h with h²·κ/8 ≤ tolerance, κ the largest
curvature of the DEM smoothed over 3 cells)."""
from __future__ import annotations

import numpy as np

from ..raster import Grid, nearest_value


def far_field_size(dem: Grid, breakpoints: Grid, *, max_area: float, far_field_area: float,
                   tolerance: float) -> Grid:
    """Local maximum triangle areas (m²): ``max_area`` within two cells of a breakpoint, growing
    over half a far-field triangle's edge to ``far_field_area``, or to the largest equilateral
    triangle that the smoothed DEM's curvature allows within ``tolerance`` m."""
    # lazy: SciPy loads only when this runs
    from scipy.ndimage import distance_transform_edt, gaussian_filter

    d = dem.cell_size
    marked = np.asarray(breakpoints.values) > 0
    distance = (distance_transform_edt(~marked) * d if marked.any()
                else np.full(marked.shape, np.inf))
    t = np.clip((distance - 2 * d) / (np.sqrt(far_field_area) / 2), 0.0, 1.0)
    area = max_area * (far_field_area / max_area) ** t
    valid = np.isfinite(dem.values)
    z = np.where(valid, dem.values, np.nanmean(dem.values))
    smooth = gaussian_filter(z, 3.0)
    zyy, zyx = np.gradient(np.gradient(smooth, d, axis=0), d, axis=(0, 1))
    zxx = np.gradient(np.gradient(smooth, d, axis=1), d, axis=1)
    # the Hessian's largest eigenvalue magnitude
    curvature = np.abs(zxx + zyy) / 2 + np.sqrt(((zxx - zyy) / 2) ** 2 + zyx ** 2)
    with np.errstate(divide="ignore"):
        edge = np.sqrt(8 * tolerance / curvature)
    allowed = np.sqrt(3) / 4 * edge ** 2
    return dem.with_values(np.clip(np.minimum(area, allowed), max_area, far_field_area))


def finer(size: Grid | None, other: Grid) -> Grid:
    """The smaller of two size fields (local maximum triangle areas, m²; NaN: no limit) cell by
    cell on ``other``'s grid (``size`` taken at its cell centres, nearest cell, if its grid
    differs: a user's size-field raster); ``other`` alone where ``size`` is None."""
    if size is None:
        return other
    values = np.asarray(size.values, float)
    if size.shape != other.shape or size.transform != other.transform:
        values = nearest_value(size, *other.cell_centres(*np.indices(other.shape)))
    return other.with_values(np.fmin(other.values, values))
