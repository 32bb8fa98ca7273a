"""The compiled loops of ``steps.hydraulic_lines``: a line's vertices thinned to a spacing
and its spikes dropped, as index arrays of the vertices kept (the arithmetic of the NumPy
definitions they replace, operation for operation)."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def thinned(coords, spacing, chords, firm, plan, height):
    """The indices of the vertices ``thin_vertices`` keeps (``chords``: with its tolerance)."""
    n = coords.shape[0]
    keep = np.empty(n, np.int64)
    keep[0], kept = 0, 1
    for i in range(1, n - 1):
        j = keep[kept - 1]
        gap = np.hypot(coords[i, 0] - coords[j, 0], coords[i, 1] - coords[j, 1])
        if gap >= spacing[i] or (chords and gap >= firm
                                 and not _holds(coords, j, i, i + 1, plan, height)):
            keep[kept] = i
            kept += 1
    while kept > 1:  # the last kept inner vertex gives way to the end on the same terms
        j = keep[kept - 1]
        gap = np.hypot(coords[n - 1, 0] - coords[j, 0], coords[n - 1, 1] - coords[j, 1])
        if gap >= max(spacing[n - 1], spacing[j]) or (
                chords and gap >= firm
                and not _holds(coords, keep[kept - 2], j, j + 1, plan, height)):
            break
        kept -= 1
    keep[kept] = n - 1
    return keep[:kept + 1]


@numba.njit(cache=True, nogil=True)
def _holds(coords, a: int, inner: int, b: int, plan: float, height: float) -> bool:
    """Whether the chord from vertex a to vertex b passes within ``plan`` m in plan and
    ``height`` m in height of vertex ``inner``."""
    abx, aby = coords[b, 0] - coords[a, 0], coords[b, 1] - coords[a, 1]
    along = (coords[inner, 0] - coords[a, 0]) * abx + (coords[inner, 1] - coords[a, 1]) * aby
    t = min(max(along / max(abx * abx + aby * aby, 1e-12), 0.0), 1.0)
    off = np.hypot(coords[a, 0] + t * abx - coords[inner, 0],
                   coords[a, 1] + t * aby - coords[inner, 1])
    rise = (abs(coords[a, 2] + t * (coords[b, 2] - coords[a, 2]) - coords[inner, 2])
            if coords.shape[1] > 2 else 0.0)
    return off <= plan and rise <= height


@numba.njit(cache=True, nogil=True)
def unspiked(coords, where, cos_min):
    """The indices of the vertices ``drop_spikes`` keeps (``cos_min``: the cosine of its
    least angle)."""
    keep = np.arange(coords.shape[0])
    kept, i = coords.shape[0], 1
    while i < kept - 1:
        a, b, c = keep[i - 1], keep[i], keep[i + 1]
        ux, uy = coords[a, 0] - coords[b, 0], coords[a, 1] - coords[b, 1]
        vx, vy = coords[c, 0] - coords[b, 0], coords[c, 1] - coords[b, 1]
        cos = (ux * vx + uy * vy) / max(np.hypot(ux, uy) * np.hypot(vx, vy), 1e-12)
        if where[b] and cos > cos_min:
            keep[i:kept - 1] = keep[i + 1:kept].copy()
            kept -= 1
            i = max(1, i - 1)
        else:
            i += 1
    return keep[:kept]


@numba.njit(cache=True, nogil=True)
def narrow_crests(z, rise, start, reach, out):
    """``steps.breaklines.narrow_crest_cells`` into ``out`` (uint8): ``rise`` the least fall
    a cell out on the axes (m), ``start`` the share of the fall under way at the mid reach,
    ``reach`` the (mid, far) reaches in cells on the axes (row 0) and the diagonals (row 1).
    Beyond the grid, and where a height is NaN, no crest."""
    rows, cols = z.shape
    k = reach.max() + 1  # the far reach and the crest's neighbour beyond it
    padded = np.full((rows + 2 * k, cols + 2 * k), np.nan)
    padded[k:k + rows, k:k + cols] = z
    mean = np.full(padded.shape, np.nan)
    out[:] = 0
    for d in range(4):
        dr, dc = _CREST_DR[d], _CREST_DC[d]
        diagonal = dr != 0 and dc != 0
        mid_k, far_k = reach[1 if diagonal else 0, 0], reach[1 if diagonal else 0, 1]
        drop = rise * (np.sqrt(2.0) if diagonal else 1.0) * far_k
        # the mean of each cell and its two neighbours along the crest (across dr, dc)
        for i in range(1, padded.shape[0] - 1):
            for j in range(1, padded.shape[1] - 1):
                mean[i, j] = (padded[i, j] + padded[i - dc, j + dr] + padded[i + dc, j - dr]) / 3
        for i in range(rows):
            for j in range(cols):
                p, q = i + k, j + k
                here = mean[p, q]
                for sign in (1.0, -1.0):  # crests, then troughs
                    h = sign * here
                    fall_a = h - sign * mean[p + far_k * dr, q + far_k * dc]
                    fall_b = h - sign * mean[p - far_k * dr, q - far_k * dc]
                    if (h >= sign * mean[p + dr, q + dc] and h > sign * mean[p - dr, q - dc]
                            and fall_a >= drop and fall_b >= drop
                            and h - sign * mean[p + mid_k * dr, q + mid_k * dc] >= start * fall_a
                            and h - sign * mean[p - mid_k * dr, q - mid_k * dc] >= start * fall_b):
                        out[i, j] = 1


# the four directions across a crest, as (row, column) steps
_CREST_DR = np.array([0, 1, 1, 1])
_CREST_DC = np.array([1, 0, 1, -1])
