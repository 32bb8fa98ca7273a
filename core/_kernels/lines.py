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
