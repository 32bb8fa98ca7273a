"""Compiled passes over all the points read (numba), kept out of ``points`` so that importing
it (every command does, through ``io``) does not load numba."""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, parallel=True)
def spread(x, y, blocks):
    """(largest bounding-box side, spread across and along the points' principal axis) in m:
    the extent of the points projected on the minor and major axes of their scatter matrix,
    in three passes without the copies that the numpy version made (about 1.2 s of CPU for
    9 M points, against 0.1 s), each of ``blocks`` threads a block of the points."""
    n = x.shape[0]
    part = np.empty((blocks, 6))
    for b in prange(blocks):
        xmin, xmax, ymin, ymax = np.inf, -np.inf, np.inf, -np.inf
        sx, sy = 0.0, 0.0
        for k in range(b * n // blocks, (b + 1) * n // blocks):
            xmin, xmax = min(xmin, x[k]), max(xmax, x[k])
            ymin, ymax = min(ymin, y[k]), max(ymax, y[k])
            sx += x[k]
            sy += y[k]
        part[b, 0], part[b, 1], part[b, 2], part[b, 3] = xmin, xmax, ymin, ymax
        part[b, 4], part[b, 5] = sx, sy
    side = max(part[:, 1].max() - part[:, 0].min(), part[:, 3].max() - part[:, 2].min())
    mx, my = part[:, 4].sum() / n, part[:, 5].sum() / n
    for b in prange(blocks):
        sxx, sxy, syy = 0.0, 0.0, 0.0
        for k in range(b * n // blocks, (b + 1) * n // blocks):
            dx, dy = x[k] - mx, y[k] - my
            sxx += dx * dx
            sxy += dx * dy
            syy += dy * dy
        part[b, 0], part[b, 1], part[b, 2] = sxx, sxy, syy
    sxx, sxy, syy = part[:, 0].sum(), part[:, 1].sum(), part[:, 2].sum()
    theta = 0.5 * math.atan2(2.0 * sxy, sxx - syy)  # the major axis
    c, s = math.cos(theta), math.sin(theta)
    for b in prange(blocks):
        umin, umax, vmin, vmax = np.inf, -np.inf, np.inf, -np.inf
        for k in range(b * n // blocks, (b + 1) * n // blocks):
            dx, dy = x[k] - mx, y[k] - my
            u, v = dx * c + dy * s, dy * c - dx * s
            umin, umax = min(umin, u), max(umax, u)
            vmin, vmax = min(vmin, v), max(vmax, v)
        part[b, 0], part[b, 1], part[b, 2], part[b, 3] = umin, umax, vmin, vmax
    return side, part[:, 3].max() - part[:, 2].min(), part[:, 1].max() - part[:, 0].min()


@njit(cache=True, nogil=True, parallel=True)
def hull_candidates(x, y, blocks):
    """Which points can be vertices of the points' convex hull: those not strictly inside the
    octagon of the eight extreme points (least and greatest x, y, x + y, x - y; Akl and
    Toussaint 1978), in two passes on all threads (the first a block to each of ``blocks``).
    On a survey's points a few thousand of millions."""
    n = x.shape[0]
    # anticlockwise from the least y: greatest -y, x - y, x, x + y, y, y - x, -x, -x - y; the
    # first point of the greatest value (each block's first, then the first block's)
    block_best = np.zeros((blocks, 8), np.int64)
    block_top = np.full((blocks, 8), -np.inf)
    for b in prange(blocks):
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            xp, yp = x[p], y[p]
            u = (-yp, xp - yp, xp, xp + yp, yp, yp - xp, -xp, -xp - yp)
            for k in range(8):
                if u[k] > block_top[b, k]:
                    block_top[b, k] = u[k]
                    block_best[b, k] = p
    best = np.zeros(8, np.int64)
    top = np.full(8, -np.inf)
    for b in range(blocks):
        for k in range(8):
            if block_top[b, k] > top[k]:
                top[k] = block_top[b, k]
                best[k] = block_best[b, k]
    ox, oy = x[best], y[best]
    vx, vy, ex, ey, tol = np.empty(8), np.empty(8), np.empty(8), np.empty(8), np.empty(8)
    scale = max(np.abs(ox).max(), np.abs(oy).max(), 1.0)
    m = 0
    for k in range(8):
        dx, dy = ox[(k + 1) % 8] - ox[k], oy[(k + 1) % 8] - oy[k]
        if dx != 0.0 or dy != 0.0:  # two extremes in one point make no edge
            vx[m], vy[m], ex[m], ey[m] = ox[k], oy[k], dx, dy
            tol[m] = 1e-9 * scale * (abs(dx) + abs(dy))
            m += 1
    keep = np.ones(n, np.bool_)
    for p in prange(n):
        # strictly left of every edge, beyond rounding (the octagon runs anticlockwise)
        inside = m >= 3
        for k in range(m):
            if ex[k] * (y[p] - vy[k]) - ey[k] * (x[p] - vx[k]) <= tol[k]:
                inside = False
                break
        keep[p] = not inside
    return keep


@njit(cache=True, nogil=True)
def monotone_chain(x, y):
    """Vertices (h, 2) of the convex hull of points sorted by x then y, anticlockwise, without
    collinear vertices (Andrew 1979)."""
    n = x.shape[0]
    hull = np.empty((2 * n + 1, 2))
    h = 0
    for rounds in range(2):
        start = h
        for i in range(n) if rounds == 0 else range(n - 1, -1, -1):
            while (h >= start + 2 and (hull[h - 1, 0] - hull[h - 2, 0]) * (y[i] - hull[h - 2, 1])
                   - (hull[h - 1, 1] - hull[h - 2, 1]) * (x[i] - hull[h - 2, 0]) <= 0.0):
                h -= 1
            hull[h, 0], hull[h, 1] = x[i], y[i]
            h += 1
        h -= 1  # each chain's last point starts the other
    return hull[:max(h, 1)]


@njit(cache=True, nogil=True, parallel=True)
def scaled_points(X, Y, Z, classification, keep, scales, offsets, blocks):
    """(m, 3) x, y, z in metres of the points whose class ``keep`` marks (a 256-entry table),
    from a LAS file's stored integers: ``stored · scale + offset``, as laspy scales them, in
    one pass (laspy's three scaled arrays and their stacking took 1 s for 9 M points), in
    the file's order; each of ``blocks`` threads counts, then fills, one block."""
    n = X.shape[0]
    starts = np.zeros(blocks + 1, np.int64)
    for b in prange(blocks):
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            if keep[classification[p]]:
                starts[b + 1] += 1
    starts = np.cumsum(starts)
    xyz = np.empty((starts[-1], 3))
    for b in prange(blocks):
        k = starts[b]
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            if keep[classification[p]]:
                xyz[k, 0] = X[p] * scales[0] + offsets[0]
                xyz[k, 1] = Y[p] * scales[1] + offsets[1]
                xyz[k, 2] = Z[p] * scales[2] + offsets[2]
                k += 1
    return xyz


@njit(cache=True, nogil=True, inline="always")
def _extent_of(x, y, first, stop):
    """(xmin, ymin, xmax, ymax) of points ``first`` to ``stop`` - 1, in one pass."""
    xmin, xmax, ymin, ymax = np.inf, -np.inf, np.inf, -np.inf
    for p in range(first, stop):
        xmin, xmax = min(xmin, x[p]), max(xmax, x[p])
        ymin, ymax = min(ymin, y[p]), max(ymax, y[p])
    return xmin, ymin, xmax, ymax


@njit(cache=True, nogil=True)
def extent(x, y):
    """(xmin, ymin, xmax, ymax) of the points, in one pass."""
    return _extent_of(x, y, 0, x.shape[0])


@njit(cache=True, nogil=True, parallel=True)
def extent_on_threads(x, y, blocks):
    """``extent`` with each of ``blocks`` threads a block of the points (9 M points: 94 ms
    on one)."""
    n = x.shape[0]
    part = np.empty((blocks, 4))
    for b in prange(blocks):
        part[b, 0], part[b, 1], part[b, 2], part[b, 3] = _extent_of(
            x, y, b * n // blocks, (b + 1) * n // blocks)
    xmin, ymin, xmax, ymax = np.inf, np.inf, -np.inf, -np.inf
    for b in range(blocks):
        xmin, ymin = min(xmin, part[b, 0]), min(ymin, part[b, 1])
        xmax, ymax = max(xmax, part[b, 2]), max(ymax, part[b, 3])
    return xmin, ymin, xmax, ymax


@njit(cache=True, nogil=True)
def repeated_positions(x, y, z, step):
    """(how many points repeat the x, y of an earlier point, both rounded to ``step`` m, with
    a different z; the largest such z difference in m), each point compared with the latest
    earlier point at its position.

    The rounded positions are counting-sorted, in the points' order, into about n / 8192
    blocks (one sequential scatter), then within each block into cells of about four points,
    where they are compared: 0.3 s for 9 M points in random order, where sorting one key per
    point took 1.0 s.
    """
    n = x.shape[0]
    xmin, ymin, xmax, ymax = extent(x, y)
    span_x = np.int64(np.rint((xmax - xmin) / step))
    span_y = np.int64(np.rint((ymax - ymin) / step))
    # cells of ``side`` steps, about four points each; blocks of ``group`` x ``group`` cells
    side = np.int64(max(1.0, np.ceil(2.0 * math.sqrt((span_x + 1.0) * (span_y + 1.0) / n))))
    cols, rows = span_x // side + 1, span_y // side + 1
    group = 46  # cells along a block's side: about 8k points a block
    block_cols = (cols + group - 1) // group
    n_blocks = block_cols * ((rows + group - 1) // group)
    starts = np.zeros(n_blocks + 1, np.int64)
    for p in range(n):
        cx = np.int64(np.rint((x[p] - xmin) / step)) // side
        cy = np.int64(np.rint((y[p] - ymin) / step)) // side
        starts[(cy // group) * block_cols + cx // group + 1] += 1
    for b in range(n_blocks):
        starts[b + 1] += starts[b]
    kx, ky, kz = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n)
    kc = np.empty(n, np.int32)  # the cell within its block: a division by ``side`` once a point
    fill = starts[:-1].copy()
    for p in range(n):
        px = np.int64(np.rint((x[p] - xmin) / step))
        py = np.int64(np.rint((y[p] - ymin) / step))
        cx, cy = px // side, py // side
        b = (cy // group) * block_cols + cx // group
        k = fill[b]
        kx[k], ky[k], kz[k], kc[k] = px, py, z[p], (cy % group) * group + cx % group
        fill[b] = k + 1
    largest_block = 0
    for b in range(n_blocks):
        largest_block = max(largest_block, starts[b + 1] - starts[b])
    cell_starts = np.empty(group * group + 1, np.int64)
    order = np.empty(largest_block, np.int64)
    repeats, largest = 0, 0.0
    for b in range(n_blocks):
        first, last = starts[b], starts[b + 1]
        if last - first < 2:
            continue
        cell_starts[:] = 0
        for p in range(first, last):
            cell_starts[kc[p] + 1] += 1
        for c in range(group * group):
            cell_starts[c + 1] += cell_starts[c]
        for p in range(first, last):
            order[cell_starts[kc[p]]] = p
            cell_starts[kc[p]] += 1
        cell_first = 0  # cell_starts[c] is now where cell c ends
        for c in range(group * group):
            cell_last = cell_starts[c]
            k = cell_last - cell_first
            if k > 32:  # many points in one cell: sorted by position there
                members = order[cell_first:cell_last]
                local = np.empty(k, np.int64)
                for i in range(k):
                    local[i] = (kx[members[i]] % side) * side + ky[members[i]] % side
                ranked = np.argsort(local, kind="mergesort")  # stable: in the points' order
                for i in range(1, k):
                    p, q = members[ranked[i]], members[ranked[i - 1]]
                    if local[ranked[i]] == local[ranked[i - 1]] and kz[p] != kz[q]:
                        repeats += 1
                        largest = max(largest, abs(kz[p] - kz[q]))
            else:
                for i in range(cell_first + 1, cell_last):
                    p = order[i]
                    for j in range(i - 1, cell_first - 1, -1):
                        q = order[j]
                        if kx[p] == kx[q] and ky[p] == ky[q]:
                            if kz[p] != kz[q]:
                                repeats += 1
                                largest = max(largest, abs(kz[p] - kz[q]))
                            break
            cell_first = cell_last
    return repeats, largest


@njit(cache=True, nogil=True, parallel=True)
def occupied_bins(x, y, x0, y0, size, cols, rows, blocks):
    """How many of the ``cols`` x ``rows`` square bins of ``size`` m from (x0, y0) hold a
    point (the points lie inside); each of ``blocks`` threads marks a block's bins (every
    mark the same value, so the count does not depend on which thread marks first)."""
    occupied = np.zeros(cols * rows, np.bool_)
    n = x.shape[0]
    for b in prange(blocks):
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            occupied[np.int64((y[p] - y0) / size) * cols + np.int64((x[p] - x0) / size)] = True
    count = 0
    for k in range(cols * rows):
        count += occupied[k]
    return count


@njit(cache=True, nogil=True, parallel=True)
def split_rows(xyz, taken, blocks):
    """(the rows of ``xyz`` that ``taken`` does not mark, those it marks), each in order (numpy's
    boolean indexing of an (n, 3) array took 0.6 s for 9 M points); each of ``blocks``
    threads counts, then copies, one block."""
    n, width = xyz.shape
    starts = np.zeros(blocks + 1, np.int64)  # rows taken before each block
    for b in prange(blocks):
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            if taken[p]:
                starts[b + 1] += 1
    starts = np.cumsum(starts)
    left = np.empty((n - starts[-1], width))
    out = np.empty((starts[-1], width))
    for b in prange(blocks):
        first = b * n // blocks
        k, j = first - starts[b], starts[b]
        for p in range(first, (b + 1) * n // blocks):
            if taken[p]:
                out[j] = xyz[p]
                j += 1
            else:
                left[k] = xyz[p]
                k += 1
    return left, out


@njit(cache=True, nogil=True, parallel=True)
def usable_rows(xyz, lowest, highest, blocks):
    """Which rows of ``xyz`` are finite throughout with z (column 2) within [``lowest``,
    ``highest``]; None where all are (no mask made). Each of ``blocks`` threads looks through a
    block of the rows."""
    n, m = xyz.shape
    usable = np.ones(blocks, np.bool_)
    for b in prange(blocks):
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            if not _usable_row(xyz, p, m, lowest, highest):
                usable[b] = False
                break
    if usable.all():
        return None
    rows = np.ones(n, np.bool_)
    for p in prange(n):
        rows[p] = _usable_row(xyz, p, m, lowest, highest)
    return rows


@njit(cache=True, nogil=True, inline="always")
def _usable_row(xyz, p, m, lowest, highest):
    for k in range(m):
        if not np.isfinite(xyz[p, k]):
            return False
    return lowest <= xyz[p, 2] <= highest


_MIX_X = np.uint64(0x9E3779B97F4A7C15)
_MIX_Y = np.uint64(0xC2B2AE3D27D4EB4F)
_MIX_Z = np.uint64(0x165667B19E3779F9)
_MIX_1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX_2 = np.uint64(0x94D049BB133111EB)


@njit(cache=True, nogil=True, inline="always")
def _point_hash(x, y, z, salt):
    """A 64-bit hash of a point's x, y, z to 0.1 mm, salted (splitmix64's finaliser): the point
    itself, whatever its place in the file."""
    h = (np.uint64(np.int64(np.rint(x * 1e4))) * _MIX_X) ^ (
        np.uint64(np.int64(np.rint(y * 1e4))) * _MIX_Y) ^ (
        np.uint64(np.int64(np.rint(z * 1e4))) * _MIX_Z) ^ salt
    h ^= h >> np.uint64(31)
    h *= _MIX_1
    h ^= h >> np.uint64(29)
    h *= _MIX_2
    return h ^ (h >> np.uint64(32))


@njit(cache=True, nogil=True, parallel=True)
def point_hashes(xyz, salt):
    """``_point_hash`` of every row of ``xyz`` (n, 3+), on all cores."""
    out = np.empty(xyz.shape[0], np.uint64)
    for p in prange(xyz.shape[0]):
        out[p] = _point_hash(xyz[p, 0], xyz[p, 1], xyz[p, 2], salt)
    return out


@njit(cache=True, nogil=True, parallel=True)
def rows_by_place(xyz, every, blocks):
    """The rows of ``xyz`` whose unsalted hash is a multiple of ``every`` (about one in
    ``every``), in order; each of ``blocks`` threads counts, then copies, one block."""
    n, width = xyz.shape
    k = np.uint64(every)
    zero = np.uint64(0)
    starts = np.zeros(blocks + 1, np.int64)
    for b in prange(blocks):
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            if _point_hash(xyz[p, 0], xyz[p, 1], xyz[p, 2], zero) % k == 0:
                starts[b + 1] += 1
    starts = np.cumsum(starts)
    out = np.empty((starts[-1], width))
    for b in prange(blocks):
        j = starts[b]
        for p in range(b * n // blocks, (b + 1) * n // blocks):
            if _point_hash(xyz[p, 0], xyz[p, 1], xyz[p, 2], zero) % k == 0:
                out[j] = xyz[p]
                j += 1
    return out
