"""Nearest-neighbour look-ups shared by the steps: the nearest line to each point, and the
index of the measured points that every terrain fit of a run queries (LiDAR points, or a DEM's
cell centres)."""
from __future__ import annotations

import numpy as np
from numba import njit


def nearest_line(xy: np.ndarray, lines: list) -> tuple[np.ndarray, np.ndarray]:
    """(index of the nearest of ``lines`` ((k, 2+) arrays, k ≥ 2), horizontal distance in m)
    for each point of ``xy`` (n, 2+); where two lines are equally near, the lower index.

    The STR tree holds the lines' segments, not the lines: a long line's bounding box reaches
    far, so a tree of whole lines computes the exact distance to most lines for most points
    (4.4 s of CPU for 140,000 points and 558 lines, against 0.8 s). The distance to a line is the
    least distance to its segments (GEOS computes it so), so the distances are the same."""
    # lazy: GEOS loads only when this runs
    import shapely

    if not len(lines):
        raise ValueError("nearest_line needs at least one line")
    sizes = np.array([len(c) for c in lines])
    vertices = np.concatenate([np.asarray(c, float)[:, :2] for c in lines])
    starts = np.r_[0, np.cumsum(sizes)]
    first = np.setdiff1d(np.arange(len(vertices) - 1), starts[1:-1] - 1)  # segment starts
    owner = np.searchsorted(starts, first, side="right") - 1
    segments = shapely.linestrings(np.stack([vertices[first], vertices[first + 1]], axis=1))
    (point, segment), distance = shapely.STRtree(segments).query_nearest(
        shapely.points(np.asarray(xy, float)[:, :2]), return_distance=True, all_matches=True)
    # every tie is listed: per point, the lowest line index among its nearest segments
    order = np.lexsort((owner[segment], point))
    point, line, distance = point[order], owner[segment][order], distance[order]
    pick = np.r_[True, point[1:] != point[:-1]]
    nearest = np.empty(len(xy), np.int64)
    found = np.empty(len(xy))
    nearest[point[pick]], found[point[pick]] = line[pick], distance[pick]
    return nearest, found


def point_index(points: np.ndarray) -> "PointIndex":
    """The index of ``points``' x, y (n, 2+) that the terrain fits (``localise``) query."""
    return PointIndex(points)


class PointIndex:
    """Points' x, y counting-sorted into square cells holding about 64 points each (at the
    mean density of their bounding box), for radius queries.

    It answers as scipy's cKDTree ``query_ball_point`` does (the same points, distance
    ≤ r by the same sum of squares, each centre's sorted by index), in CSR form: building it
    for 9 M points in random order takes about as long as the tree's (3–4 s of CPU on the
    shared machine; 13 s with scipy's default median split), its queries half as long, with
    no Python list per centre."""

    def __init__(self, points: np.ndarray):
        xy = np.ascontiguousarray(np.asarray(points)[:, :2], dtype=float)
        if not len(xy) or not np.isfinite(xy).all():
            raise ValueError("a point index needs finite points")
        n = len(xy)
        self.lo = xy.min(axis=0)
        span = xy.max(axis=0) - self.lo
        cells = max(n / 64.0, 1.0)  # fewer, larger cells: the sort's scatter stays in cache
        self.cell = float(max(np.sqrt(span[0] * span[1] / cells), span.max() / cells, 1e-9))
        self.cols = int(span[0] // self.cell) + 1
        self.rows = int(span[1] // self.cell) + 1
        self.order, self.bounds, self.xy = _cell_sort(xy, self.lo[0], self.lo[1], self.cell,
                                                      self.cols, self.rows)

    def neighbours(self, centres: np.ndarray, radius) -> tuple[np.ndarray, np.ndarray]:
        """CSR (indptr, indices) of the points within ``radius`` (m, one or one per centre) of
        each of ``centres`` (k, 2+), each centre's indices ascending."""
        centres = np.ascontiguousarray(np.asarray(centres, float)[:, :2])
        radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, float),
                                                      (len(centres),)))
        return _ball_csr(self.xy, self.order, self.bounds, self.lo[0], self.lo[1], self.cell,
                         self.cols, self.rows, centres, radius)


class CellIndex:
    """The index of a DEM's cell centres taken as the measured points: point ``i`` is the centre
    of flat cell ``cells[i]`` (row-major), at x = (col + 0.5)·a + c, y = (row + 0.5)·e + f of
    the DEM's ``transform``, with the DEM's z (as ``pipeline``'s ``_cell_points`` builds
    them).

    It answers as ``PointIndex`` on those points does (the same points, by the same sum of
    squares of the same coordinates, each centre's sorted by index), from each cell's point
    number (4 B a cell) instead of a sorted copy of the points' x, y and their order (24 B a
    point): the cells within a radius are found from the grid itself."""

    def __init__(self, transform, shape: tuple[int, int], cells: np.ndarray):
        self.rows, self.cols = int(shape[0]), int(shape[1])
        self.rank = np.full(self.rows * self.cols, -1,
                            np.int32 if len(cells) < 2 ** 31 else np.int64)
        self.rank[cells] = np.arange(len(cells), dtype=self.rank.dtype)
        self.a, self.c, self.e, self.f = (float(transform.a), float(transform.c),
                                          float(transform.e), float(transform.f))

    def neighbours(self, centres: np.ndarray, radius) -> tuple[np.ndarray, np.ndarray]:
        """CSR (indptr, indices) of the points within ``radius`` (m, one or one per centre) of
        each of ``centres`` (k, 2+), each centre's indices ascending."""
        centres = np.ascontiguousarray(np.asarray(centres, float)[:, :2])
        radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, float),
                                                      (len(centres),)))
        return _cells_csr(self.rank, self.rows, self.cols, self.a, self.c, self.e, self.f,
                          centres, radius)


@njit(cache=True, nogil=True)
def _cells_csr(rank, rows, cols, a, c, e, f, centres, radius):
    indptr, found, k = _csr_start(centres.shape[0])
    for i in range(centres.shape[0]):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        # the columns and rows whose centres can lie within r, a cell wider to each side
        # against round-off (the distance test decides), clipped to the grid
        u0, u1 = (cx - r - c) / a - 0.5, (cx + r - c) / a - 0.5
        v0, v1 = (cy - r - f) / e - 0.5, (cy + r - f) / e - 0.5
        c0 = max(int(np.floor(min(u0, u1))) - 1, 0)
        c1 = min(int(np.ceil(max(u0, u1))) + 1, cols - 1)
        for row in range(max(int(np.floor(min(v0, v1))) - 1, 0),
                         min(int(np.ceil(max(v0, v1))) + 1, rows - 1) + 1):
            dy = ((row + 0.5) * e + f) - cy
            for col in range(c0, c1 + 1):
                q = rank[row * cols + col]
                dx = ((col + 0.5) * a + c) - cx
                if q >= 0 and dx * dx + dy * dy <= r * r:
                    found, k = _push(found, k, q)
        indptr[i + 1] = k
    return _sorted_csr(indptr, found)


@njit(cache=True, nogil=True)
def _csr_start(m):
    """(indptr of ``m`` centres, room for the points found, the first free place)."""
    return np.zeros(m + 1, np.int64), np.empty(max(16, 8 * m), np.int64), 0


@njit(cache=True, nogil=True)
def _push(found, k, value):
    """``found`` with ``value`` at ``k`` (doubled when full), and the next free place."""
    if k == found.shape[0]:
        grown = np.empty(2 * k, found.dtype)
        grown[:k] = found
        found = grown
    found[k] = value
    return found, k + 1


@njit(cache=True, nogil=True)
def _sorted_csr(indptr, found):
    """CSR (indptr, indices) of the centres' points in ``found``, each centre's ascending."""
    indices = found[:indptr[-1]]
    for i in range(indptr.shape[0] - 1):
        indices[indptr[i]:indptr[i + 1]].sort()
    return indptr, indices


@njit(cache=True, nogil=True)
def _cell_sort(xy, x0, y0, cell, cols, rows):
    """(original index of each point in cell order, first point of each cell + the end,
    the points' x, y in cell order)."""
    n = xy.shape[0]
    key = np.empty(n, np.int64)
    bounds = np.zeros(rows * cols + 1, np.int64)
    for p in range(n):
        c = min(int((xy[p, 0] - x0) // cell), cols - 1)
        r = min(int((xy[p, 1] - y0) // cell), rows - 1)
        key[p] = r * cols + c
        bounds[key[p] + 1] += 1
    for k in range(rows * cols):
        bounds[k + 1] += bounds[k]
    fill = bounds[:-1].copy()
    order = np.empty(n, np.int64)
    ordered = np.empty((n, 2))
    for p in range(n):
        k = fill[key[p]]
        fill[key[p]] += 1
        order[k] = p
        ordered[k, 0] = xy[p, 0]
        ordered[k, 1] = xy[p, 1]
    return order, bounds, ordered


@njit(cache=True, nogil=True)
def _ball_csr(xy, order, bounds, x0, y0, cell, cols, rows, centres, radius):
    indptr, found, k = _csr_start(centres.shape[0])
    for i in range(centres.shape[0]):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        # clipped so that a centre off the points indexes no cell (an empty range)
        c0 = min(max(int((cx - r - x0) // cell), 0), cols)
        c1 = max(min(int((cx + r - x0) // cell), cols - 1), -1)
        for row in range(max(int((cy - r - y0) // cell), 0),
                         min(int((cy + r - y0) // cell), rows - 1) + 1):
            for q in range(bounds[row * cols + c0], bounds[row * cols + c1 + 1]):
                dx = xy[q, 0] - cx
                dy = xy[q, 1] - cy
                if dx * dx + dy * dy <= r * r:
                    found, k = _push(found, k, order[q])
        indptr[i + 1] = k
    return _sorted_csr(indptr, found)
