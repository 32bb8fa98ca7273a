"""Nearest-neighbour look-ups shared by the steps: the nearest line to each point, and the
index of the measured points that every terrain fit of a run queries (LiDAR points, or a DEM's
cell centres)."""
from __future__ import annotations

import numpy as np
import numba
from numba import njit, prange


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
    ≤ r by the same sum of squares, each centre's sorted by index), in CSR form, with no Python
    list per centre. Built and queried on all cores (numba threads): 9 M points in random order
    take about 0.25 s to index on two cores (scipy's cKDTree 3–4 s of CPU), 36,000 queries of
    some 110 points each 0.1 s."""

    def __init__(self, points: np.ndarray):
        points = np.asarray(points)
        x, y = (np.asarray(points[:, k], dtype=float) for k in (0, 1))  # float64: views
        box = _bounding_box(x, y) if len(x) else np.full(4, np.nan)
        if not np.isfinite(box).all():
            raise ValueError("a point index needs finite points")
        n = len(x)
        self.lo = box[:2]
        span = box[2:] - self.lo
        cells = max(n / 64.0, 1.0)  # fewer, larger cells: the sort's scatter stays in cache
        self.cell = float(max(np.sqrt(span[0] * span[1] / cells), span.max() / cells, 1e-9))
        self.cols = int(span[0] // self.cell) + 1
        self.rows = int(span[1] // self.cell) + 1
        self.order, self.bounds, self.xy = _cell_sort(
            x, y, self.lo[0], self.lo[1], self.cell, self.cols, self.rows,
            np.int32 if n < 2 ** 31 else np.int64, numba.get_num_threads())

    def neighbours(self, centres: np.ndarray, radius) -> tuple[np.ndarray, np.ndarray]:
        """CSR (indptr, indices) of the points within ``radius`` (m, one or one per centre) of
        each of ``centres`` (k, 2+), each centre's indices ascending."""
        centres, radius = _queries(centres, radius)
        return _ball_csr(self.xy, self.order, self.bounds, self.lo[0], self.lo[1], self.cell,
                         self.cols, self.rows, centres, radius)


def _queries(centres, radius) -> tuple[np.ndarray, np.ndarray]:
    """``centres``' x, y (k, 2) and a radius per centre, as the kernels take them."""
    centres = np.ascontiguousarray(np.asarray(centres, float)[:, :2])
    return centres, np.ascontiguousarray(np.broadcast_to(np.asarray(radius, float),
                                                         (len(centres),)))


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
        centres, radius = _queries(centres, radius)
        return _cells_csr(self.rank, self.rows, self.cols, self.a, self.c, self.e, self.f,
                          centres, radius)


@njit(cache=True, nogil=True, parallel=True)
def _cells_csr(rank, rows, cols, a, c, e, f, centres, radius):
    m = centres.shape[0]
    span = np.empty((m, 4), np.int64)
    room = np.zeros(m + 1, np.int64)
    for i in prange(m):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        # the columns and rows whose centres can lie within r, a cell wider to each side
        # against round-off (the distance test decides), clipped to the grid
        u0, u1 = (cx - r - c) / a - 0.5, (cx + r - c) / a - 0.5
        v0, v1 = (cy - r - f) / e - 0.5, (cy + r - f) / e - 0.5
        span[i, 0] = max(int(np.floor(min(u0, u1))) - 1, 0)
        span[i, 1] = min(int(np.ceil(max(u0, u1))) + 1, cols - 1)
        span[i, 2] = max(int(np.floor(min(v0, v1))) - 1, 0)
        span[i, 3] = min(int(np.ceil(max(v0, v1))) + 1, rows - 1)
        room[i + 1] = (max(span[i, 1] - span[i, 0] + 1, 0)
                       * max(span[i, 3] - span[i, 2] + 1, 0))
    room, found, count = _scratch(room)
    for i in prange(m):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        k = room[i]
        for row in range(span[i, 2], span[i, 3] + 1):
            dy = ((row + 0.5) * e + f) - cy
            for col in range(span[i, 0], span[i, 1] + 1):
                q = rank[row * cols + col]
                dx = ((col + 0.5) * a + c) - cx
                if q >= 0 and dx * dx + dy * dy <= r * r:
                    found[k] = q
                    k += 1
        count[i] = k - room[i]
    return _sorted_csr(room, count, found)


@njit(cache=True, nogil=True)
def _scratch(room):
    """(first place of each centre's points, a place for every point of them all, their
    counts to fill) from the most points each centre may have (centre i's at ``room[i + 1]``,
    0 first)."""
    room = np.cumsum(room)
    return room, np.empty(room[-1], np.int64), np.empty(room.shape[0] - 1, np.int64)


@njit(cache=True, nogil=True, parallel=True)
def _sorted_csr(room, count, found):
    """CSR (indptr, indices) of the centres' points: centre i's ``count[i]`` points at
    ``found[room[i]:]``, each centre's sorted ascending."""
    m = count.shape[0]
    indptr = np.zeros(m + 1, np.int64)
    indptr[1:] = np.cumsum(count)
    indices = np.empty(indptr[-1], np.int64)
    for i in prange(m):
        mine = found[room[i]:room[i] + count[i]]
        mine.sort()
        indices[indptr[i]:indptr[i + 1]] = mine
    return indptr, indices


@njit(cache=True, nogil=True)
def _bounding_box(x, y):
    """(least x, least y, largest x, largest y); NaN if any coordinate is not finite."""
    box = np.array([np.inf, np.inf, -np.inf, -np.inf])
    for p in range(x.shape[0]):
        if not (np.isfinite(x[p]) and np.isfinite(y[p])):
            box[:] = np.nan
            return box
        box[0], box[1] = min(box[0], x[p]), min(box[1], y[p])
        box[2], box[3] = max(box[2], x[p]), max(box[3], y[p])
    return box


@njit(cache=True, nogil=True, parallel=True)
def _cell_sort(x, y, x0, y0, cell, cols, rows, index_type, blocks):
    """(original index of each point in cell order, of ``index_type``; first point of each
    cell + the end; the points' x, y in cell order). Stable: a cell's points keep their
    order. Each of ``blocks`` threads counts and places one block of the points."""
    n, cells = x.shape[0], rows * cols
    key = np.empty(n, index_type)  # some 64 points a cell: cell numbers fit too
    counts = np.zeros((blocks, cells), np.int64)
    for t in prange(blocks):
        for p in range(t * n // blocks, (t + 1) * n // blocks):
            c = min(int((x[p] - x0) // cell), cols - 1)
            r = min(int((y[p] - y0) // cell), rows - 1)
            key[p] = r * cols + c
            counts[t, key[p]] += 1
    bounds = np.zeros(cells + 1, np.int64)
    for k in range(cells):  # the blocks' first places in each cell, in block order
        start = bounds[k]
        for t in range(blocks):
            counts[t, k], start = start, start + counts[t, k]
        bounds[k + 1] = start
    order = np.empty(n, index_type)
    ordered = np.empty((n, 2))
    for t in prange(blocks):
        fill = counts[t]
        for p in range(t * n // blocks, (t + 1) * n // blocks):
            k = fill[key[p]]
            fill[key[p]] += 1
            order[k] = p
            ordered[k, 0] = x[p]
            ordered[k, 1] = y[p]
    return order, bounds, ordered


@njit(cache=True, nogil=True, parallel=True)
def _ball_csr(xy, order, bounds, x0, y0, cell, cols, rows, centres, radius):
    m = centres.shape[0]
    span = np.empty((m, 4), np.int64)
    room = np.zeros(m + 1, np.int64)
    for i in prange(m):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        # clipped so that a centre off the points indexes no cell (an empty range)
        span[i, 0] = min(max(int((cx - r - x0) // cell), 0), cols)
        span[i, 1] = max(min(int((cx + r - x0) // cell), cols - 1), -1)
        span[i, 2] = max(int((cy - r - y0) // cell), 0)
        span[i, 3] = min(int((cy + r - y0) // cell), rows - 1)
        for row in range(span[i, 2], span[i, 3] + 1):  # room for every point of the cells
            room[i + 1] += (bounds[row * cols + span[i, 1] + 1]
                            - bounds[row * cols + span[i, 0]])
    room, found, count = _scratch(room)
    for i in prange(m):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        k = room[i]
        for row in range(span[i, 2], span[i, 3] + 1):
            for q in range(bounds[row * cols + span[i, 0]],
                           bounds[row * cols + span[i, 1] + 1]):
                dx = xy[q, 0] - cx
                dy = xy[q, 1] - cy
                if dx * dx + dy * dy <= r * r:
                    found[k] = order[q]
                    k += 1
        count[i] = k - room[i]
    return _sorted_csr(room, count, found)
