"""Compiled point location in a triangular mesh (numba): which triangle holds each point, and
the mesh's linear (TIN) elevation there; and the PSLG check's exact test of segments that share
an end (``overlap_beyond_shared_end``). Kept out of ``mesh`` so that importing it does not load
numba.

The triangles are counting-sorted into square buckets (half a triangle's area) by their
bounding boxes; the points are counting-sorted into the same buckets and each tests the
triangles of its bucket, which stay in cache for all the bucket's points. An edge's orientation
test is always computed from its lower node to its higher, so the two triangles sharing an edge
decide a point on it with exactly opposite signs: no point of the mesh falls between them.
Memory is some 100 B a triangle and 40 B a point, where matplotlib's trapezoid map took about
1 kB a triangle (and 6 s for 260,000 triangles).
"""
from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from ..engine.nearest import cell_of, cell_sort
from .delaunay import WORKSPACE, orient2d


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
        # half a triangle's area a bucket: some 5 triangles' boxes reach into each (8 at twice
        # the side, where the tests took 1.4x as long)
        self.cell = float(max(np.sqrt(span[0] * span[1] / max(2.0 * len(self.triangles), 1.0)),
                              span.max() / 8192.0, 1e-9))
        self.cols, self.rows = int(span[0] / self.cell) + 1, int(span[1] / self.cell) + 1
        self.bounds, self.members = _buckets(self.local, self.triangles, self.cell, self.cols,
                                             self.rows)

    def __call__(self, points: np.ndarray,
                 z: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        points = np.asarray(points, float)
        found = np.full(len(points), -1, np.int64)
        values = None if z is None else np.full(len(points), np.nan)
        if not len(points) or not len(self.triangles):
            return found, values
        # each point's bucket as the triangles' (local x from 0), each bucket's points together:
        # in their own order (a survey file's, or random) each test was a cache miss, 2.25 M
        # points in 0.28 s where these took 0.09 s
        order, first, ordered = cell_sort(
            points[:, 0] - self.origin[0], points[:, 1] - self.origin[1], 0.0, 0.0, self.cell,
            self.cols, self.rows, np.int64,
            max(1, min(numba.get_num_threads(), len(points) // (self.rows * self.cols))))
        _locate(self.local, self.triangles, self.bounds, self.members, order, first, ordered,
                found, np.empty(0) if z is None else np.asarray(z, float),
                np.empty(0) if values is None else values)
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
            # the points' buckets (``cell_sort``) by the same monotone ``cell_of``: a point in
            # the box falls in one of its buckets
            c0, c1 = cell_of(x0, 0.0, cell, cols), cell_of(x1, 0.0, cell, cols)
            r0, r1 = cell_of(y0, 0.0, cell, rows), cell_of(y1, 0.0, cell, rows)
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
def _locate(xy, triangles, bounds, members, order, first, ordered, found, z, values):
    """Each point's triangle, and with node elevations ``z`` (else empty) the barycentric
    interpolation there in ``values``, from the points counting-sorted into the buckets
    (``cell_sort``: original index, first of each bucket + the end, local x, y), taken bucket by
    bucket on all cores. A point's answer does not depend on the order."""
    interpolate = z.shape[0] > 0
    for k in prange(first.shape[0] - 1):
        for i in range(first[k], first[k + 1]):
            x, y = ordered[i, 0], ordered[i, 1]
            for s in range(bounds[k], bounds[k + 1]):
                t = members[s]
                a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
                d1, d2, d3 = (_side(xy, a, b, x, y), _side(xy, b, c, x, y),
                              _side(xy, c, a, x, y))
                if (d1 >= 0.0 and d2 >= 0.0 and d3 >= 0.0) or (d1 <= 0.0 and d2 <= 0.0
                                                              and d3 <= 0.0):
                    if d1 == 0.0 and d2 == 0.0 and d3 == 0.0:
                        continue  # a degenerate triangle (no area) holds nothing
                    found[order[i]] = t
                    if interpolate:  # barycentric
                        area = _side(xy, a, b, xy[c, 0], xy[c, 1])
                        wa, wb = _side(xy, b, c, x, y) / area, _side(xy, c, a, x, y) / area
                        values[order[i]] = wa * z[a] + wb * z[b] + (1.0 - wa - wb) * z[c]
                    break


@njit(cache=True, nogil=True)
def overlap_beyond_shared_end(xy, first, second):
    """Whether any pair of segments ``first[k]``, ``second[k]`` ((k, 2) indices into the
    vertices ``xy`` (n, 2)), each pair sharing an end, meets beyond it: both ends shared, or
    the other two ends exactly collinear with the shared one (Shewchuk's orientation test) and
    on one side of it."""
    ws = np.empty(WORKSPACE)
    for k in range(first.shape[0]):
        a0, a1, b0, b1 = first[k, 0], first[k, 1], second[k, 0], second[k, 1]
        if (a0 == b0 and a1 == b1) or (a0 == b1 and a1 == b0):
            return True
        p, u, v = (a0, a1, b1) if a0 == b0 else ((a0, a1, b0) if a0 == b1 else (
            (a1, a0, b1) if a1 == b0 else (a1, a0, b0)))
        px, py = xy[p, 0], xy[p, 1]
        if (orient2d(px, py, xy[u, 0], xy[u, 1], xy[v, 0], xy[v, 1], ws) == 0.0
                and (xy[u, 0] - px) * (xy[v, 0] - px) + (xy[u, 1] - py) * (xy[v, 1] - py) > 0):
            return True
    return False
