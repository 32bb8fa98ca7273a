"""Nearest-neighbour look-ups shared by the steps: the nearest line to each point, and the
index of the measured points that every terrain fit of a run queries (LiDAR points, or a DEM's
cell centres)."""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import numba
from numba import njit, prange

# Tasks (centres, points) below which a parallel kernel runs on one thread: waking the others
# costs more than they save (345 queries of 10 centres: 0.09 s on two threads, 0.03 s on one;
# on a busy machine each wake-up can wait a scheduler's time slice)
PARALLEL_MIN = 2000


@contextmanager
def threads_for(tasks: int):
    """Numba's threads for the parallel kernels called inside: one for fewer than
    ``PARALLEL_MIN`` tasks, else all (numba's setting is the calling thread's own)."""
    if tasks >= PARALLEL_MIN:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def nearest_line(xy: np.ndarray, lines: list) -> tuple[np.ndarray, np.ndarray]:
    """(index of the nearest of ``lines`` ((k, 2+) arrays, k ≥ 2), horizontal distance in m)
    for each point of ``xy`` (n, 2+); where two lines are equally near, the lower index.

    The distance to a line is the least distance to its segments, each by GEOS's formula
    (``Distance::pointToSegment``, as an STR tree of the lines answers, to the last bit). The
    segments are bucketed in square cells; each point reads the cells in rings around its own
    until the next ring lies farther than the nearest found (on all cores: 0.005 s for 27,000
    mesh nodes and 370 lines, where GEOS's STR tree of the segments took 0.1 s)."""
    if not len(lines):
        raise ValueError("nearest_line needs at least one line")
    sizes = np.array([len(c) for c in lines])
    vertices = np.concatenate([np.asarray(c, float)[:, :2] for c in lines])
    starts = np.r_[0, np.cumsum(sizes)]
    first = np.setdiff1d(np.arange(len(vertices) - 1), starts[1:-1] - 1)  # segment starts
    if not len(first):
        raise ValueError("nearest_line needs a line of two vertices or more")
    owner = np.searchsorted(starts, first, side="right") - 1
    with threads_for(len(xy)):
        return _nearest_segment(np.ascontiguousarray(np.asarray(xy, float)[:, :2]),
                                np.ascontiguousarray(vertices[first]),
                                np.ascontiguousarray(vertices[first + 1]), owner)


def z_along_lines(xy: np.ndarray, lines: list, *, within: float):
    """(horizontal distance in m from each point of ``xy`` (n, 2+) to the nearest of ``lines``
    ((k, 3) arrays; fewer than 2 vertices: left out), indices of the points within ``within`` m
    of a line with z, their z along it): the nearest such line's z interpolated linearly along
    its segment there. A line without z (a modeller's 2-D line, read with NaN z) gives none,
    nor hides one that has: a node at a 2-D line's crossing with a 3-D line takes the 3-D
    line's z, whichever is listed first. Where two lines with z are equally near (a crossing, a
    shared vertex), the one listed first. The one rule for a node on a line, in the mesh and in
    the terrain fits."""
    # lazy: GEOS loads only when this runs
    import shapely

    usable = [np.asarray(c, float) for c in lines if len(c) >= 2]
    if not usable or not len(xy):
        return np.full(len(xy), np.inf), np.zeros(0, np.int64), np.zeros(0)
    nearest, distance = nearest_line(xy, usable)
    with_z = [c for c in usable if c.shape[1] >= 3 and np.isfinite(c[:, 2]).any()]
    if not with_z:
        return distance, np.zeros(0, np.int64), np.zeros(0)
    if len(with_z) < len(usable):  # the nearest line that has z
        nearest, near_z = nearest_line(xy, with_z)
    else:
        near_z = distance
    pick = np.flatnonzero(near_z <= within)
    at = np.array([shapely.LineString(c[:, :3]) for c in with_z], dtype=object)[nearest[pick]]
    on = np.asarray(xy, float)[pick, :2]
    # NaN where the line has no z there: a vertex read without z
    z = shapely.get_z(shapely.line_interpolate_point(at, shapely.line_locate_point(
        at, shapely.points(on))))
    known = np.isfinite(z)
    return distance, pick[known], z[known]


@njit(cache=True, nogil=True, parallel=True)
def _nearest_segment(p, a, b, owner):
    """(owner of the nearest segment a–b, its distance) per point of ``p``, the lowest owner
    among equally near segments."""
    lo = np.array([min(a[:, 0].min(), b[:, 0].min()), min(a[:, 1].min(), b[:, 1].min())])
    span_x = max(a[:, 0].max(), b[:, 0].max()) - lo[0]
    span_y = max(a[:, 1].max(), b[:, 1].max()) - lo[1]
    count = a.shape[0]
    length = 0.0
    for s in range(count):
        length += np.hypot(b[s, 0] - a[s, 0], b[s, 1] - a[s, 1])
    # some one segment a cell, and no cell shorter than the mean segment
    cell = max(np.sqrt(span_x * span_y / count), max(span_x, span_y) / count,
               length / count, 1e-9)
    cols, rows = int(span_x // cell) + 1, int(span_y // cell) + 1
    room = np.zeros(rows * cols + 1, np.int64)
    _bucket(a, b, lo, cell, cols, rows, room, np.empty(0, np.int64))
    bounds = np.cumsum(room)
    held = np.empty(bounds[-1], np.int64)
    _bucket(a, b, lo, cell, cols, rows, bounds[:-1].copy(), held)
    nearest = np.empty(p.shape[0], np.int64)
    found = np.empty(p.shape[0])
    for i in prange(p.shape[0]):
        x, y = p[i, 0], p[i, 1]
        ci, cj = cell_at(y, lo[1], cell), cell_at(x, lo[0], cell)
        # the rings that reach the grid: from the grid's nearest cell to its farthest
        near = max(0, -ci, ci - (rows - 1), -cj, cj - (cols - 1))
        far = max(abs(ci), abs(ci - (rows - 1)), abs(cj), abs(cj - (cols - 1)))
        best, line = np.inf, -1
        # the bounds below less the round-off of bucketing and of themselves
        slack = 1e-6 * cell + 1e-12 * (abs(x) + abs(y) + abs(lo[0]) + abs(lo[1]))
        for r in range(near, far + 1):
            inside = min(x - (lo[0] + (cj - r + 1) * cell), lo[0] + (cj + r) * cell - x,
                         y - (lo[1] + (ci - r + 1) * cell), lo[1] + (ci + r) * cell - y)
            if inside - slack > best:
                break  # every cell beyond ring r - 1 lies farther than the nearest found
            for row in range(max(ci - r, 0), min(ci + r, rows - 1) + 1):
                edge = row == ci - r or row == ci + r  # the ring's whole row, else its ends
                for col in range(max(cj - r, 0) if edge else cj - r,
                                 (min(cj + r, cols - 1) if edge else cj + r) + 1,
                                 1 if edge else 2 * r):
                    if (col < 0 or col >= cols
                            or _off_cell(x, y, lo, cell, col, row) - slack > best):
                        continue
                    k = row * cols + col
                    for h in range(bounds[k], bounds[k + 1]):
                        s = held[h]
                        d = _point_segment(x, y, a[s, 0], a[s, 1], b[s, 0], b[s, 1])
                        if d < best or (d == best and owner[s] < line):
                            best, line = d, owner[s]
        nearest[i], found[i] = line, best
    return nearest, found


@njit(cache=True, nogil=True)
def _off_cell(x, y, lo, cell, col, row):
    """The distance from (x, y) to the cell at ``col``, ``row``."""
    dx = max(lo[0] + col * cell - x, x - (lo[0] + (col + 1) * cell), 0.0)
    dy = max(lo[1] + row * cell - y, y - (lo[1] + (row + 1) * cell), 0.0)
    return np.sqrt(dx * dx + dy * dy)


@njit(cache=True, nogil=True)
def _bucket(a, b, lo, cell, cols, rows, room, held):
    """Each segment a–b put in the cells that its pieces (a cell long at most) reach: counted
    into ``room[k + 1]`` of cell k where ``held`` is empty, else its number written into
    ``held`` at ``room[k]`` (then advanced)."""
    for s in range(a.shape[0]):
        dx, dy = b[s, 0] - a[s, 0], b[s, 1] - a[s, 1]
        pieces = max(1, int(np.ceil(np.hypot(dx, dy) / cell)))
        for t in range(pieces):
            x0, x1 = a[s, 0] + dx * t / pieces, a[s, 0] + dx * (t + 1) / pieces
            y0, y1 = a[s, 1] + dy * t / pieces, a[s, 1] + dy * (t + 1) / pieces
            for row in range(cell_of(min(y0, y1), lo[1], cell, rows),
                             cell_of(max(y0, y1), lo[1], cell, rows) + 1):
                for col in range(cell_of(min(x0, x1), lo[0], cell, cols),
                                 cell_of(max(x0, x1), lo[0], cell, cols) + 1):
                    k = row * cols + col
                    if held.size:
                        held[room[k]] = s
                        room[k] += 1
                    else:
                        room[k + 1] += 1


@njit(cache=True, nogil=True)
def cell_at(v, v0, cell):
    """The cell of coordinate ``v`` in cells of ``cell`` from ``v0``, on or off the grid
    (within ±10¹⁵ cells): the floor of the rounded quotient, monotonic in ``v`` (points and
    queries bucketed by it agree), where Python's exact ``//`` took 5 ns."""
    return int(np.floor(min(max((v - v0) / cell, -1e15), 1e15)))


@njit(cache=True, nogil=True)
def cell_of(v, v0, cell, cells):
    """The cell (0 to ``cells`` - 1) of coordinate ``v`` in cells of ``cell`` from ``v0``."""
    return min(max(cell_at(v, v0, cell), 0), cells - 1)


@njit(cache=True, nogil=True)
def _point_segment(px, py, ax, ay, bx, by):
    """Distance from (px, py) to segment a–b as GEOS computes it (``Distance::pointToSegment``,
    the same operations in the same order)."""
    if ax == bx and ay == by:
        return np.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    len2 = (bx - ax) * (bx - ax) + (by - ay) * (by - ay)
    r = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / len2
    if r <= 0.0:
        return np.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    if r >= 1.0:
        return np.sqrt((px - bx) * (px - bx) + (py - by) * (py - by))
    s = ((ay - py) * (bx - ax) - (ax - px) * (by - ay)) / len2
    return abs(s) * np.sqrt(len2)


def point_index(points: np.ndarray) -> "PointIndex":
    """The index of ``points``' x, y (n, 2+) that the terrain fits (``localise``) query."""
    return PointIndex(points)


class PointIndex:
    """Points' x, y counting-sorted into square cells holding about 64 points each (at the
    mean density of their bounding box), for radius queries.

    It answers as scipy's cKDTree ``query_ball_point`` does (the same points, distance
    ≤ r by the same sum of squares, each centre's sorted by index), in CSR form, with no Python
    list per centre. Built and queried on all cores (numba threads): 9 M points in random order
    take about 0.25 s to index on two cores (scipy's cKDTree 3–4 s of CPU), 30,000 queries of
    some 110 points each 0.12 s."""

    def __init__(self, points: np.ndarray):
        points = np.asarray(points)
        x, y = (np.asarray(points[:, k], dtype=float) for k in (0, 1))  # float64: views
        box = _bounding_box(x, y) if len(x) else np.full(4, np.nan)
        if not np.isfinite(box).all():
            raise ValueError("a point index needs finite points")
        n = len(x)
        self.box = box  # xmin, ymin, xmax, ymax (m)
        self.lo = box[:2]
        span = box[2:] - self.lo
        cells = max(n / 64.0, 1.0)  # fewer, larger cells: the sort's scatter stays in cache
        self.cell = float(max(np.sqrt(span[0] * span[1] / cells), span.max() / cells, 1e-9))
        self.cols = int(span[0] // self.cell) + 1
        self.rows = int(span[1] // self.cell) + 1
        self.order, self.bounds, self.xy = cell_sort(
            x, y, self.lo[0], self.lo[1], self.cell, self.cols, self.rows,
            np.int32 if n < 2 ** 31 else np.int64, numba.get_num_threads())

    def neighbours(self, centres: np.ndarray, radius, *,
                   ascending: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """CSR (indptr, indices) of the points within ``radius`` (m, one or one per centre) of
        each of ``centres`` (k, 2+), each centre's indices ascending (``ascending=False``: in
        the index's own order, the same for the same points, for uses that do not need it: a
        fit's 500 points sorted took more than half of the query)."""
        centres, radius = _queries(centres, radius)
        with threads_for(len(centres)):
            return _ball_csr(self.xy, self.order, self.bounds, self.lo[0], self.lo[1],
                             self.cell, self.cols, self.rows, centres, radius, ascending)


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
        x = self.c + self.a * np.array([0.5, self.cols - 0.5])
        y = self.f + self.e * np.array([0.5, self.rows - 0.5])
        self.box = np.array([x.min(), y.min(), x.max(), y.max()])  # of the cells' centres (m)

    def neighbours(self, centres: np.ndarray, radius, *,
                   ascending: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """CSR (indptr, indices) of the points within ``radius`` (m, one or one per centre) of
        each of ``centres`` (k, 2+), each centre's indices ascending, whatever ``ascending``
        (``PointIndex``'s; a DEM's cells are few a query, cheap to sort, and a fit on them the
        same to the bit in any run)."""
        del ascending
        centres, radius = _queries(centres, radius)
        with threads_for(len(centres)):
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
    return _packed_csr(room, count, found, True)


@njit(cache=True, nogil=True)
def _scratch(room):
    """(first place of each centre's points, a place for every point of them all, their
    counts to fill) from the most points each centre may have (centre i's at ``room[i + 1]``,
    0 first)."""
    room = np.cumsum(room)
    return room, np.empty(room[-1], np.int64), np.empty(room.shape[0] - 1, np.int64)


@njit(cache=True, nogil=True, parallel=True)
def _packed_csr(room, count, found, ascending):
    """CSR (indptr, indices) of the centres' points: centre i's ``count[i]`` points at
    ``found[room[i]:]``, each centre's sorted ascending if ``ascending``."""
    m = count.shape[0]
    indptr = np.zeros(m + 1, np.int64)
    indptr[1:] = np.cumsum(count)
    indices = np.empty(indptr[-1], np.int64)
    for i in prange(m):
        mine = found[room[i]:room[i] + count[i]]
        if ascending:
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
def cell_sort(x, y, x0, y0, cell, cols, rows, index_type, blocks):
    """Points counting-sorted into ``rows`` x ``cols`` square cells of ``cell`` from (x0, y0),
    those off the grid in its edge cells: (original index of each point in cell order, of
    ``index_type``; first point of each cell + the end; the points' x, y in cell order). A
    point with a coordinate not finite is left out. Stable: a cell's points keep their order.
    Each of ``blocks`` threads counts and places one block of the points (a count of every
    cell each: no more blocks than points per cell keeps that within the points' memory)."""
    n, cells = x.shape[0], rows * cols
    key = np.empty(n, index_type)  # some 64 points a cell: cell numbers fit too
    counts = np.zeros((blocks, cells), np.int64)
    for t in prange(blocks):
        for p in range(t * n // blocks, (t + 1) * n // blocks):
            key[p] = -1
            if np.isfinite(x[p]) and np.isfinite(y[p]):
                key[p] = cell_of(y[p], y0, cell, rows) * cols + cell_of(x[p], x0, cell, cols)
                counts[t, key[p]] += 1
    bounds = np.zeros(cells + 1, np.int64)
    for k in range(cells):  # the blocks' first places in each cell, in block order
        start = bounds[k]
        for t in range(blocks):
            counts[t, k], start = start, start + counts[t, k]
        bounds[k + 1] = start
    order = np.empty(bounds[cells], index_type)
    ordered = np.empty((bounds[cells], 2))
    for t in prange(blocks):
        fill = counts[t]
        for p in range(t * n // blocks, (t + 1) * n // blocks):
            if key[p] >= 0:
                k = fill[key[p]]
                fill[key[p]] += 1
                order[k] = p
                ordered[k, 0] = x[p]
                ordered[k, 1] = y[p]
    return order, bounds, ordered


@njit(cache=True, nogil=True, parallel=True)
def _ball_csr(xy, order, bounds, x0, y0, cell, cols, rows, centres, radius, ascending):
    m = centres.shape[0]
    span = np.empty((m, 4), np.int64)
    room = np.zeros(m + 1, np.int64)
    for i in prange(m):
        cx, cy, r = centres[i, 0], centres[i, 1], radius[i]
        # clipped so that a centre off the points indexes no cell (an empty range)
        span[i, 0] = min(max(cell_at(cx - r, x0, cell), 0), cols)
        span[i, 1] = max(min(cell_at(cx + r, x0, cell), cols - 1), -1)
        span[i, 2] = max(cell_at(cy - r, y0, cell), 0)
        span[i, 3] = min(cell_at(cy + r, y0, cell), rows - 1)
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
    return _packed_csr(room, count, found, ascending)
