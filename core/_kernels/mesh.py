"""Compiled point location in a triangular mesh (numba): which triangle holds each point, and
the mesh's linear (TIN) elevation there. Kept out of ``mesh`` so that importing it does not load
numba.

The triangles are counting-sorted into square buckets (about two triangles' width) by their
bounding boxes; a point tests the triangles of its bucket. An edge's orientation test is always
computed from its lower node to its higher, so the two triangles sharing an edge decide a point
on it with exactly opposite signs: no point of the mesh falls between them. Memory is some 30 B
a triangle, where matplotlib's trapezoid map took about 1 kB (and 6 s for 260,000 triangles).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange


def locate(xy: np.ndarray, triangles: np.ndarray, points: np.ndarray,
           z: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(index of the triangle holding each of ``points`` (k, 2+), -1 outside; with node
    elevations ``z`` (n,), the linear interpolation there, NaN outside). A point on an edge or
    a node takes the lowest-index triangle holding it."""
    return Locator(xy, triangles)(points, z)


class Locator:
    """``locate`` with its buckets built once, for points given in parts (``locator(points,
    z=None)``: the same answer as ``locate(xy, triangles, points, z)``)."""

    def __init__(self, xy: np.ndarray, triangles: np.ndarray):
        xy = np.asarray(xy, float)[:, :2]
        self.triangles = np.ascontiguousarray(triangles, np.int64)
        if not len(self.triangles):
            return
        self.origin = xy.min(axis=0)  # local coordinates: the tests keep their precision
        self.local = np.ascontiguousarray(xy - self.origin)
        span = self.local.max(axis=0)
        self.cell = float(max(np.sqrt(span[0] * span[1] / max(len(self.triangles) / 2.0, 1.0)),
                              span.max() / 4096.0, 1e-9))
        self.cols, self.rows = int(span[0] // self.cell) + 1, int(span[1] // self.cell) + 1
        self.bounds, self.members = _buckets(self.local, self.triangles, self.cell, self.cols,
                                             self.rows)

    def __call__(self, points: np.ndarray,
                 z: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        points = np.asarray(points, float)
        found = np.full(len(points), -1, np.int64)
        values = None if z is None else np.full(len(points), np.nan)
        if not len(points) or not len(self.triangles):
            return found, values
        px = np.ascontiguousarray(points[:, 0] - self.origin[0])
        py = np.ascontiguousarray(points[:, 1] - self.origin[1])
        _locate(self.local, self.triangles, self.bounds, self.members, self.cell, self.cols,
                self.rows, px, py, found)
        if z is not None:
            _interpolate(self.local, self.triangles, np.asarray(z, float), px, py, found, values)
        return found, values


@njit(cache=True, nogil=True)
def _buckets(xy, triangles, cell, cols, rows):
    """CSR (first member of each bucket + the end, triangle indices) of the buckets each
    triangle's bounding box covers, each bucket's triangles ascending."""
    m = triangles.shape[0]
    bounds = np.zeros(rows * cols + 1, np.int64)
    for stage in range(2):  # count, then fill
        if stage == 1:
            for k in range(rows * cols):
                bounds[k + 1] += bounds[k]
            fill = bounds[:-1].copy()
            members = np.empty(bounds[-1], np.int64)
        for t in range(m):
            a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            x0 = min(xy[a, 0], xy[b, 0], xy[c, 0])
            x1 = max(xy[a, 0], xy[b, 0], xy[c, 0])
            y0 = min(xy[a, 1], xy[b, 1], xy[c, 1])
            y1 = max(xy[a, 1], xy[b, 1], xy[c, 1])
            c0, c1 = int(x0 // cell), min(int(x1 // cell), cols - 1)
            r0, r1 = int(y0 // cell), min(int(y1 // cell), rows - 1)
            for r in range(r0, r1 + 1):
                for q in range(c0, c1 + 1):
                    if stage == 0:
                        bounds[r * cols + q + 1] += 1
                    else:
                        members[fill[r * cols + q]] = t
                        fill[r * cols + q] += 1
    return bounds, members


@njit(cache=True, inline="always")
def _side(xy, i, j, x, y):
    """Orientation of (x, y) against the edge from node i to node j (positive: left), computed
    from the lower node to the higher whichever way the edge is given."""
    if i < j:
        return ((xy[j, 0] - xy[i, 0]) * (y - xy[i, 1])
                - (xy[j, 1] - xy[i, 1]) * (x - xy[i, 0]))
    return -((xy[i, 0] - xy[j, 0]) * (y - xy[j, 1])
             - (xy[i, 1] - xy[j, 1]) * (x - xy[j, 0]))


@njit(cache=True, nogil=True, parallel=True)
def _locate(xy, triangles, bounds, members, cell, cols, rows, px, py, found):
    """Each point's triangle (on all cores: every point is its own search)."""
    for p in prange(px.shape[0]):
        x, y = px[p], py[p]
        if not (x >= 0.0 and y >= 0.0):  # also NaN
            continue
        q, r = int(x // cell), int(y // cell)
        if q >= cols or r >= rows:
            continue
        k = r * cols + q
        for s in range(bounds[k], bounds[k + 1]):
            t = members[s]
            a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            d1, d2, d3 = _side(xy, a, b, x, y), _side(xy, b, c, x, y), _side(xy, c, a, x, y)
            if (d1 >= 0.0 and d2 >= 0.0 and d3 >= 0.0) or (d1 <= 0.0 and d2 <= 0.0
                                                          and d3 <= 0.0):
                if d1 == 0.0 and d2 == 0.0 and d3 == 0.0:
                    continue  # a degenerate triangle (no area) holds nothing
                found[p] = t
                break


@njit(cache=True, nogil=True, parallel=True)
def _interpolate(xy, triangles, z, px, py, found, values):
    """Barycentric interpolation of the node elevations in each point's triangle."""
    for p in prange(px.shape[0]):
        t = found[p]
        if t < 0:
            continue
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        area = _side(xy, a, b, xy[c, 0], xy[c, 1])
        wa = _side(xy, b, c, px[p], py[p]) / area
        wb = _side(xy, c, a, px[p], py[p]) / area
        values[p] = wa * z[a] + wb * z[b] + (1.0 - wa - wb) * z[c]
