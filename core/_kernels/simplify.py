"""Douglas–Peucker compiled (numba): one stack of stretches over a line's vertices, where the
NumPy version spent 20 µs of Python per stretch (a quarter of a second on the benchmark run)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _worst(coords, i, j, rank, lowest, ranked):
    """(index, deviation) of the vertex between i and j (of rank ``lowest`` where ``ranked``)
    farthest from the chord i–j, horizontally or vertically; NaN propagates as in NumPy's
    maximum and argmax (the first NaN wins)."""
    ax, ay, az = coords[i, 0], coords[i, 1], coords[i, 2]
    abx, aby, abz = coords[j, 0] - ax, coords[j, 1] - ay, coords[j, 2] - az
    length2 = abx * abx + aby * aby
    best, worst = -1, -np.inf
    for m in range(i + 1, j):
        if ranked and rank[m] != lowest:
            continue
        t = 0.0
        if length2 != 0:
            t = min(max(((coords[m, 0] - ax) * abx + (coords[m, 1] - ay) * aby) / length2,
                        0.0), 1.0)
        horizontal = math.hypot(coords[m, 0] - (ax + t * abx), coords[m, 1] - (ay + t * aby))
        vertical = abs(coords[m, 2] - (az + t * abz))
        if not np.isfinite(vertical):
            vertical = 0.0
        deviation = horizontal if math.isnan(horizontal) else max(horizontal, vertical)
        if math.isnan(deviation):
            return m, deviation
        if deviation > worst:
            best, worst = m, deviation
    return best, worst


@njit(cache=True, nogil=True)
def douglas_peucker_keep(coords, tolerance, rank, ranked):
    """Which vertices of ``coords`` (n, 3) Douglas–Peucker keeps within ``tolerance`` (m),
    horizontally and vertically; where ``ranked``, a stretch is split at the farthest of its
    vertices of the lowest ``rank`` (see ``simplify.douglas_peucker_mask``)."""
    n = coords.shape[0]
    keep = np.zeros(n, np.bool_)
    keep[0] = keep[n - 1] = True
    stack = np.empty((n + 1, 2), np.int64)
    stack[0, 0], stack[0, 1], top = 0, n - 1, 1
    while top:
        top -= 1
        i, j = stack[top, 0], stack[top, 1]
        if j - i < 2:
            continue
        m, worst = _worst(coords, i, j, rank, 0, False)
        if worst > tolerance:
            if ranked:
                lowest = rank[i + 1]
                for k in range(i + 2, j):
                    lowest = min(lowest, rank[k])
                m = _worst(coords, i, j, rank, lowest, True)[0]
            keep[m] = True
            stack[top, 0], stack[top, 1] = i, m
            stack[top + 1, 0], stack[top + 1, 1] = m, j
            top += 2
    return keep
