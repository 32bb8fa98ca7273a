"""Fast 2-D Delaunay triangulation of point sets, compiled with numba: a port of the sweep-hull
algorithm of Mapbox's `delaunator <https://github.com/mapbox/delaunator>`_ (ISC licence,
Vladimir Agafonkin), which this module credits as the source of the algorithm. Points are sorted
by distance from a seed triangle's circumcentre and added one by one outside an advancing convex
hull (found through an angular hash of hull edges), new triangles being made Delaunay by edge
flips. Unlike delaunator, the orientation and in-circle tests here are exact (Shewchuk's floating
point filters with an exact expansion-arithmetic fallback) and the seed triangle is a true
Delaunay triangle (empty circumcircle), so that every distinct input point becomes a vertex.
"""
from __future__ import annotations

import warnings

import numba
import numpy as np

from .points import extent

__all__ = ["WORKSPACE", "average_repeats", "delaunay", "delaunay_in_sweep_order", "orient2d"]

_EPS = 2.0 ** -53                       # Shewchuk's epsilon (half an ulp of 1)
_SPLITTER = 134217729.0                  # 2**27 + 1, splits a double into two 26-bit halves
_CCW_BOUND = (3.0 + 16.0 * _EPS) * _EPS  # orient2d error bound (stage A)
_ICC_BOUND = (10.0 + 96.0 * _EPS) * _EPS  # incircle error bound (stage A)
_DUP_EPS = 2.0 ** -52                    # delaunator's near-duplicate tolerance
_SMALL_SORT = 24                         # insertion sort below this many items

# --------------------------------------------------------------------------------------------
# Exact arithmetic (Shewchuk, "Adaptive precision floating-point arithmetic and fast robust
# geometric predicates", 1997). Expansions are arrays of non-overlapping doubles, increasing in
# magnitude; their sum is exact and its sign is the sign of the last component.


@numba.njit(cache=True, nogil=True, inline="always")
def _two_sum(a, b):
    x = a + b
    bv = x - a
    av = x - bv
    return x, (a - av) + (b - bv)


@numba.njit(cache=True, nogil=True, inline="always")
def _two_diff(a, b):
    x = a - b
    bv = a - x
    av = x + bv
    return x, (a - av) + (bv - b)


@numba.njit(cache=True, nogil=True, inline="always")
def _split(a):
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


@numba.njit(cache=True, nogil=True, inline="always")
def _two_product(a, b):
    x = a * b
    ahi, alo = _split(a)
    bhi, blo = _split(b)
    err = x - ahi * bhi
    err = err - alo * bhi
    err = err - ahi * blo
    return x, alo * blo - err


@numba.njit(cache=True, nogil=True)
def _grow(e, elen, b):
    """Add the double b to the expansion e[:elen] in place (e needs room for elen + 1)."""
    q = b
    h = 0
    for i in range(elen):
        q, hh = _two_sum(q, e[i])
        if hh != 0.0:
            e[h] = hh
            h += 1
    if q != 0.0 or h == 0:
        e[h] = q
        h += 1
    return h


@numba.njit(cache=True, nogil=True)
def _scale(e, elen, b, out):
    """out = e[:elen] * b; returns its length (out needs room for 2 * elen)."""
    q, hh = _two_product(e[0], b)
    h = 0
    if hh != 0.0:
        out[h] = hh
        h += 1
    for i in range(1, elen):
        p1, p0 = _two_product(e[i], b)
        s, hh = _two_sum(q, p0)
        if hh != 0.0:
            out[h] = hh
            h += 1
        q = p1 + s  # fast two-sum, |p1| >= |s|
        hh = s - (q - p1)
        if hh != 0.0:
            out[h] = hh
            h += 1
    if q != 0.0 or h == 0:
        out[h] = q
        h += 1
    return h


@numba.njit(cache=True, nogil=True)
def _mul(e, elen, f, flen, out, tmp):
    """out = e[:elen] * f[:flen] (out: room for 2 elen flen, tmp: 2 elen); returns length."""
    n = _scale(e, elen, f[0], out)
    for j in range(1, flen):
        m = _scale(e, elen, f[j], tmp)
        for i in range(m):
            n = _grow(out, n, tmp[i])
    return n


@numba.njit(cache=True, nogil=True)
def _add_to(e, elen, f, flen, sign):
    """e[:elen] += sign * f[:flen] in place (e: room for elen + flen); returns length."""
    for i in range(flen):
        elen = _grow(e, elen, sign * f[i])
    return elen


@numba.njit(cache=True, nogil=True, inline="always")
def _copy(e, elen, out):
    """out[:elen] = e[:elen], element by element (a slice assignment may allocate)."""
    for i in range(elen):
        out[i] = e[i]


@numba.njit(cache=True, nogil=True, inline="always")
def _sign(v):
    return 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)


# the exact predicates' workspace, in doubles: handed down, so that the sweep allocates nothing
# and runs without numba's reference counts (see _sweep_points)
WORKSPACE = 2140


@numba.njit(cache=True, nogil=True)
def _orient_exact(ax, ay, bx, by, cx, cy, ws):
    """Exact sign of (a - c) x (b - c) = ax by - ax cy - cx by - ay bx + ay cx + bx cy (``ws``:
    a workspace of ``WORKSPACE`` doubles)."""
    n = 0
    for i in range(6):
        if i == 0:
            hi, lo = _two_product(ax, by)
        elif i == 1:
            hi, lo = _two_product(-ax, cy)
        elif i == 2:
            hi, lo = _two_product(-cx, by)
        elif i == 3:
            hi, lo = _two_product(-ay, bx)
        elif i == 4:
            hi, lo = _two_product(ay, cx)
        else:
            hi, lo = _two_product(bx, cy)
        n = _grow(ws, n, lo)
        n = _grow(ws, n, hi)
    return _sign(ws[n - 1])


@numba.njit(cache=True, nogil=True, inline="always")
def orient2d(ax, ay, bx, by, cx, cy, ws):
    """Shewchuk's orient2d: > 0 if a, b, c turn counter-clockwise, < 0 clockwise, 0 collinear
    (the sign is exact; the magnitude is not). ``ws``: a workspace of ``WORKSPACE`` doubles."""
    detleft = (ax - cx) * (by - cy)
    detright = (ay - cy) * (bx - cx)
    det = detleft - detright
    if detleft > 0.0:
        if detright <= 0.0:
            return det
        detsum = detleft + detright
    elif detleft < 0.0:
        if detright >= 0.0:
            return det
        detsum = -detleft - detright
    else:
        return det
    bound = _CCW_BOUND * detsum
    if det >= bound or -det >= bound:
        return det
    return _orient_exact(ax, ay, bx, by, cx, cy, ws)


@numba.njit(cache=True, nogil=True, inline="always")
def _diff_exp(a, b, out):
    hi, lo = _two_diff(a, b)
    if lo != 0.0:
        out[0] = lo
        out[1] = hi
        return 2
    out[0] = hi
    return 1


@numba.njit(cache=True, nogil=True)
def _incircle_exact(ax, ay, bx, by, cx, cy, dx, dy, ws):
    """Exact sign of the incircle determinant, sum over the cyclic (p, u, v) of (a, b, c) of
    |p - d|^2 ((u - d) x (v - d)), in expansion arithmetic (``ws``: ``WORKSPACE`` doubles)."""
    # ws layout: 6 differences of 2, products 8 + 8, lift 16, cross 16, term 512, tmp 32,
    # total 1536
    dif = ws[0:12]
    nd = (_diff_exp(ax, dx, dif[0:2]), _diff_exp(ay, dy, dif[2:4]),
          _diff_exp(bx, dx, dif[4:6]), _diff_exp(by, dy, dif[6:8]),
          _diff_exp(cx, dx, dif[8:10]), _diff_exp(cy, dy, dif[10:12]))
    p1 = ws[12:20]
    p2 = ws[20:28]
    lift = ws[28:44]
    cross = ws[44:60]
    term = ws[60:572]
    tmp = ws[572:604]
    total = ws[604:2140]
    ntotal = 0
    for k in range(3):
        ip = 2 * k            # index of p's x difference (p = a, b, c)
        iu = 2 * ((k + 1) % 3)
        iv = 2 * ((k + 2) % 3)
        px = dif[2 * ip:2 * ip + 2]
        py = dif[2 * ip + 2:2 * ip + 4]
        ux = dif[2 * iu:2 * iu + 2]
        uy = dif[2 * iu + 2:2 * iu + 4]
        vx = dif[2 * iv:2 * iv + 2]
        vy = dif[2 * iv + 2:2 * iv + 4]
        n1 = _mul(px, nd[ip], px, nd[ip], p1, tmp)
        n2 = _mul(py, nd[ip + 1], py, nd[ip + 1], p2, tmp)
        _copy(p1, n1, lift)
        nlift = _add_to(lift, n1, p2, n2, 1.0)
        n1 = _mul(ux, nd[iu], vy, nd[iv + 1], p1, tmp)
        n2 = _mul(vx, nd[iv], uy, nd[iu + 1], p2, tmp)
        _copy(p1, n1, cross)
        ncross = _add_to(cross, n1, p2, n2, -1.0)
        nterm = _mul(lift, nlift, cross, ncross, term, tmp)
        if ntotal == 0:
            _copy(term, nterm, total)
            ntotal = nterm
        else:
            ntotal = _add_to(total, ntotal, term, nterm, 1.0)
    return _sign(total[ntotal - 1])


@numba.njit(cache=True, nogil=True)
def _incircle_static_bound(pts):
    """A bound above Shewchuk's stage-A error bound of every incircle test among ``pts``
    (n, 2): that bound, ``_ICC_BOUND`` times the permanent, evaluated as ``_incircle``
    evaluates it with every coordinate difference replaced by the points' largest extent D
    (rounding is monotonic, so no difference, product or sum of them exceeds D's). A
    determinant beyond it has the sign the adaptive test would give: one comparison where the
    permanent cost 10-13 % of the triangulation. Tiles of some 130 m: about 7e-6 m⁴, where
    neighbours 0.3 m apart give 1e-2."""
    if pts.shape[0] == 0:
        return 0.0
    xmin, ymin, xmax, ymax = extent(pts[:, 0], pts[:, 1])
    d = max(xmax - xmin, ymax - ymin)
    product = d * d
    lift = product + product
    permanent = ((product + product) * lift + (product + product) * lift
                 + (product + product) * lift)
    return _ICC_BOUND * permanent


@numba.njit(cache=True, nogil=True, inline="always")
def _incircle(ax, ay, bx, by, cx, cy, dx, dy, static, ws):
    """Shewchuk's incircle: > 0 if d is inside the circle through a, b, c when those turn
    counter-clockwise (< 0 inside when they turn clockwise), 0 on it; the sign is exact.
    ``static``: ``_incircle_static_bound`` of points holding these four (inf: none); ``ws``:
    a workspace of ``WORKSPACE`` doubles."""
    adx = ax - dx
    bdx = bx - dx
    cdx = cx - dx
    ady = ay - dy
    bdy = by - dy
    cdy = cy - dy
    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    alift = adx * adx + ady * ady
    cdxady = cdx * ady
    adxcdy = adx * cdy
    blift = bdx * bdx + bdy * bdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    clift = cdx * cdx + cdy * cdy
    det = alift * (bdxcdy - cdxbdy) + blift * (cdxady - adxcdy) + clift * (adxbdy - bdxady)
    if det > static or -det > static:
        return det
    permanent = ((abs(bdxcdy) + abs(cdxbdy)) * alift + (abs(cdxady) + abs(adxcdy)) * blift
                 + (abs(adxbdy) + abs(bdxady)) * clift)
    bound = _ICC_BOUND * permanent
    if det > bound or -det > bound:
        return det
    return _incircle_exact(ax, ay, bx, by, cx, cy, dx, dy, ws)


# --------------------------------------------------------------------------------------------
# Sorting by squared distance from the centre, on (distance, x, y) so that equal points end up
# next to each other. Two cache-friendly counting-sort passes (a coarse one into a few thousand
# buckets, then a fine one inside each coarse bucket, about two points a bucket) move the
# coordinates with the keys, so that the sweep reads them in order; small insertion sorts finish.


@numba.njit(cache=True, nogil=True, inline="always")
def _less(d, p, i, j):
    if d[i] != d[j]:
        return d[i] < d[j]
    if p[i, 0] != p[j, 0]:
        return p[i, 0] < p[j, 0]
    return p[i, 1] < p[j, 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _swap(d, p, ids, i, j):
    d[i], d[j] = d[j], d[i]
    p[i, 0], p[j, 0] = p[j, 0], p[i, 0]
    p[i, 1], p[j, 1] = p[j, 1], p[i, 1]
    ids[i], ids[j] = ids[j], ids[i]


@numba.njit(cache=True, nogil=True)
def _insertion_sort(d, p, ids, lo, hi):
    for i in range(lo + 1, hi):
        td = d[i]
        tx = p[i, 0]
        ty = p[i, 1]
        tid = ids[i]
        j = i - 1
        while j >= lo and (d[j] > td or (d[j] == td and (
                p[j, 0] > tx or (p[j, 0] == tx and p[j, 1] > ty)))):
            d[j + 1] = d[j]
            p[j + 1, 0] = p[j, 0]
            p[j + 1, 1] = p[j, 1]
            ids[j + 1] = ids[j]
            j -= 1
        d[j + 1] = td
        p[j + 1, 0] = tx
        p[j + 1, 1] = ty
        ids[j + 1] = tid


@numba.njit(cache=True, nogil=True)
def _quicksort(d, p, ids, lo, hi):
    """Sort [lo, hi) on (d, x, y): iterative Hoare quicksort, median of three."""
    stack = np.empty(256, np.int64)
    sp = 0
    while True:
        if hi - lo <= _SMALL_SORT:
            _insertion_sort(d, p, ids, lo, hi)
            if sp == 0:
                return
            sp -= 2
            lo = stack[sp]
            hi = stack[sp + 1]
            continue
        left = lo
        right = hi - 1
        mid = (left + right) >> 1
        i = left + 1
        _swap(d, p, ids, mid, i)
        if _less(d, p, right, left):
            _swap(d, p, ids, left, right)
        if _less(d, p, right, i):
            _swap(d, p, ids, i, right)
        if _less(d, p, i, left):
            _swap(d, p, ids, left, i)
        j = right
        # pivot at left + 1, sentinels at left and right
        while True:
            i += 1
            while _less(d, p, i, left + 1):
                i += 1
            j -= 1
            while _less(d, p, left + 1, j):
                j -= 1
            if j < i:
                break
            _swap(d, p, ids, i, j)
        _swap(d, p, ids, left + 1, j)
        # [lo, j) <= pivot at j <= [j + 1, hi): push the larger part, go on with the smaller
        if j - lo > hi - (j + 1):
            stack[sp] = lo
            stack[sp + 1] = j
            lo = j + 1
        else:
            stack[sp] = j + 1
            stack[sp + 1] = hi
            hi = j
        sp += 2


@numba.njit(cache=True, nogil=True, inline="always")
def _bucket(dd, dmin, scale, nb):
    k = int((dd - dmin) * scale)
    return k if k < nb else nb - 1


@numba.njit(cache=True, nogil=True)
def _squared_distances(xy, cx, cy):
    """The points' squared distances from (cx, cy), and their least and greatest."""
    n = xy.shape[0]
    d = np.empty(n)
    dmin = np.inf
    dmax = -np.inf
    for i in range(n):
        dx = xy[i, 0] - cx
        dy = xy[i, 1] - cy
        dd = dx * dx + dy * dy
        d[i] = dd
        dmin = min(dmin, dd)
        dmax = max(dmax, dd)
    return d, dmin, dmax


@numba.njit(cache=True, nogil=True)
def _coarse_sort(xy, d, dmin, scale, nb, shift, pts, ids):
    """Counting sort of the points, their distances d and indices into the nc coarse buckets
    (2**shift fine buckets each): fills pts and ids, returns the sorted distances and
    cstart, where coarse bucket c starts (nc + 1 entries)."""
    n = xy.shape[0]
    nc = ((nb - 1) >> shift) + 1
    cstart = np.zeros(nc + 1, np.int64)
    for i in range(n):
        cstart[(_bucket(d[i], dmin, scale, nb) >> shift) + 1] += 1
    for c in range(nc):
        cstart[c + 1] += cstart[c]
    pos = cstart[:nc].copy()
    ds = np.empty(n)
    for i in range(n):
        dd = d[i]
        c = _bucket(dd, dmin, scale, nb) >> shift
        q = pos[c]
        pos[c] = q + 1
        ds[q] = dd
        pts[q, 0] = xy[i, 0]
        pts[q, 1] = xy[i, 1]
        ids[q] = i
    return ds, cstart


@numba.njit(cache=True, nogil=True)
def _fine_sort(d, pts, ids, cstart, dmin, scale, nb, shift):
    """Finish the sort inside each coarse bucket: a counting sort into its fine buckets,
    through small buffers, then a comparison sort of each fine bucket."""
    nc = cstart.shape[0] - 1
    biggest = 0
    for c in range(nc):
        biggest = max(biggest, cstart[c + 1] - cstart[c])
    fw = 1 << shift
    fstart = np.empty(fw + 1, np.int64)
    bd = np.empty(biggest)
    bp = np.empty((biggest, 2))
    bi = np.empty(biggest, np.int32)
    for c in range(nc):
        lo = cstart[c]
        hi = cstart[c + 1]
        m = hi - lo
        if m <= 1:
            continue
        if m <= _SMALL_SORT:
            _insertion_sort(d, pts, ids, lo, hi)
            continue
        base = c << shift
        fstart[:] = 0
        for j in range(lo, hi):
            fstart[_bucket(d[j], dmin, scale, nb) - base + 1] += 1
        for f in range(fw):
            fstart[f + 1] += fstart[f]
        for j in range(lo, hi):
            f = _bucket(d[j], dmin, scale, nb) - base
            q = fstart[f]
            fstart[f] = q + 1
            bd[q] = d[j]
            bp[q, 0] = pts[j, 0]
            bp[q, 1] = pts[j, 1]
            bi[q] = ids[j]
        # fstart[f] is now the end of fine bucket f
        for j in range(m):
            d[lo + j] = bd[j]
            pts[lo + j, 0] = bp[j, 0]
            pts[lo + j, 1] = bp[j, 1]
            ids[lo + j] = bi[j]
        b0 = 0
        for f in range(fw):
            b1 = fstart[f]
            if b1 - b0 > 1:
                if b1 - b0 <= _SMALL_SORT:
                    _insertion_sort(d, pts, ids, lo + b0, lo + b1)
                else:
                    _quicksort(d, pts, ids, lo + b0, lo + b1)
            b0 = b1


@numba.njit(cache=True, nogil=True)
def _sort_by_distance(xy, cx, cy, pts, ids):
    """Fill pts (N, 2) and ids (N,) with the points and their indices in order of squared
    distance from (cx, cy), ties broken on x then y."""
    d, dmin, dmax = _squared_distances(xy, cx, cy)
    nb = max(xy.shape[0] // 2, 1)  # fine buckets (uniform in area for uniform points)
    span = dmax - dmin
    scale = nb / span if span > 0.0 else 0.0
    shift = 0  # 2**shift fine buckets to a coarse one, for at most 4096 coarse buckets
    while ((nb - 1) >> shift) >= 4096:
        shift += 1
    d, cstart = _coarse_sort(xy, d, dmin, scale, nb, shift, pts, ids)
    _fine_sort(d, pts, ids, cstart, dmin, scale, nb, shift)


# --------------------------------------------------------------------------------------------
# The sweep (delaunator). Triangle t has corners tri[3t], tri[3t + 1], tri[3t + 2], clockwise
# (delaunator's orientation); half-edge e runs from tri[e] to tri[next(e)] and half[e] is its twin
# in the neighbouring triangle, or -1 on the hull. Points are numbered by their rank in the sort.


@numba.njit(cache=True, nogil=True, inline="always")
def _next(e):
    return e - 2 if e % 3 == 2 else e + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _prev(e):
    return e + 2 if e % 3 == 0 else e - 1


@numba.njit(cache=True, nogil=True, inline="always")
def _hash_key(x, y, cx, cy, size):
    dx = x - cx
    dy = y - cy
    s = abs(dx) + abs(dy)
    if s == 0.0:
        return 0
    p = dx / s
    a = (3.0 - p) / 4.0 if dy > 0.0 else (1.0 + p) / 4.0  # pseudo-angle in [0, 1]
    k = int(a * size)
    return k - size if k >= size else k


@numba.njit(cache=True, nogil=True, inline="always")
def _link(half, a, b):
    half[a] = b
    if b != -1:
        half[b] = a


@numba.njit(cache=True, nogil=True, inline="always")
def _add_triangle(tri, half, t, i0, i1, i2, a, b, c):
    tri[t] = i0
    tri[t + 1] = i1
    tri[t + 2] = i2
    _link(half, t, a)
    _link(half, t + 1, b)
    _link(half, t + 2, c)


@numba.njit(cache=True, nogil=True, inline="always")
def _legalize(a, tri, half, pts, hull_start, hull_tri, hull_prev, stack, static, ws):
    """Flip edges from half-edge a (opposite the new point) until the triangles around the new
    point are Delaunay; returns the half-edge that then ends the fan on a's side. Each flip gives
    the new point one more edge, so a stack of N entries cannot overflow."""
    i = 0
    ar = 0
    while True:
        b = half[a]
        ar = _prev(a)
        if b == -1:  # hull edge
            if i == 0:
                break
            i -= 1
            a = stack[i]
            continue
        al = _next(a)
        bl = _prev(b)
        p0 = tri[ar]
        pr = tri[a]
        pl = tri[al]
        p1 = tri[bl]
        # (p0, pr, pl) turn clockwise: p1 inside their circle gives incircle < 0
        if _incircle(pts[p0, 0], pts[p0, 1], pts[pr, 0], pts[pr, 1], pts[pl, 0], pts[pl, 1],
                     pts[p1, 0], pts[p1, 1], static, ws) < 0.0:
            tri[a] = p1
            tri[b] = p0
            hbl = half[bl]
            if hbl == -1:  # edge swapped on the other side of the hull (rare)
                e = hull_start
                while True:
                    if hull_tri[e] == bl:
                        hull_tri[e] = a
                        break
                    e = hull_prev[e]
                    if e == hull_start:
                        break
            _link(half, a, hbl)
            _link(half, b, half[ar])
            _link(half, ar, bl)
            stack[i] = _next(b)
            i += 1
        else:
            if i == 0:
                break
            i -= 1
            a = stack[i]
    return ar


@numba.njit(cache=True, nogil=True)
def _nearest_to_middle(xy):
    """The point nearest the middle of the points' bounding box; -1 if a coordinate is not
    finite."""
    n = xy.shape[0]
    xmin = np.inf
    ymin = np.inf
    xmax = -np.inf
    ymax = -np.inf
    for i in range(n):
        x = xy[i, 0]
        y = xy[i, 1]
        if not (np.isfinite(x) and np.isfinite(y)):
            return -1
        xmin = min(xmin, x)
        xmax = max(xmax, x)
        ymin = min(ymin, y)
        ymax = max(ymax, y)
    mx = 0.5 * (xmin + xmax)
    my = 0.5 * (ymin + ymax)
    i0 = 0
    best = np.inf
    for i in range(n):
        dd = (xy[i, 0] - mx) ** 2 + (xy[i, 1] - my) ** 2
        if dd < best:
            best = dd
            i0 = i
    return i0


@numba.njit(cache=True, nogil=True)
def _nearest_neighbour(xy, i0):
    """The point nearest point i0 other than its copies; -1 if all points equal it."""
    x0 = xy[i0, 0]
    y0 = xy[i0, 1]
    i1 = -1
    best = np.inf
    for i in range(xy.shape[0]):
        dd = (xy[i, 0] - x0) ** 2 + (xy[i, 1] - y0) ** 2
        if 0.0 < dd < best:
            best = dd
            i1 = i
    return i1


@numba.njit(cache=True, nogil=True, _nrt=False)  # no reference count of ws a point
def _empty_circle_apex(xy, i0, i1, ws):
    """A point making a Delaunay triangle with the Delaunay edge i0-i1 (nearest neighbours);
    -1 if all points are collinear.

    On either side of the edge, the point whose circle through i0 and i1 has its centre
    furthest back (least t along that side's normal) makes a Delaunay triangle with them: an
    empty circle, so no point comes before the seeds in the sweep.
    t = (p - i0).(p - i1) / ((i1 - i0) x (p - i0)), in units of |i1 - i0| / 2. (delaunator
    takes the smallest circumcircle, which need not be empty.) ``ws``: ``WORKSPACE`` doubles."""
    x0 = xy[i0, 0]
    y0 = xy[i0, 1]
    x1 = xy[i1, 0]
    y1 = xy[i1, 1]
    ileft = -1
    tleft = np.inf
    iright = -1
    tright = np.inf
    for i in range(xy.shape[0]):
        px = xy[i, 0]
        py = xy[i, 1]
        o = orient2d(x0, y0, x1, y1, px, py, ws)
        if o == 0.0:
            continue
        dot = (px - x0) * (px - x1) + (py - y0) * (py - y1)
        cross = (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)
        if o > 0.0:
            t = dot / cross if cross > 0.0 else np.inf
            if ileft == -1 or t < tleft:
                tleft = t
                ileft = i
        else:
            t = -dot / cross if cross < 0.0 else np.inf
            if iright == -1 or t < tright:
                tright = t
                iright = i
    return ileft if ileft != -1 else iright


@numba.njit(cache=True, nogil=True)
def _seed(xy):
    """Seed triangle (i0, i1, i2), clockwise, of a Delaunay triangle near the middle, and its
    circumcentre; i2 = -1 if all points are collinear (or equal), i0 = -1 if one is not finite."""
    i0 = _nearest_to_middle(xy)
    if i0 == -1:
        return -1, -1, -1, 0.0, 0.0
    i1 = _nearest_neighbour(xy, i0)
    if i1 == -1:
        return i0, i1, -1, 0.0, 0.0
    ws = np.empty(WORKSPACE)
    i2 = _empty_circle_apex(xy, i0, i1, ws)
    if i2 == -1:
        return i0, i1, -1, 0.0, 0.0
    x0 = xy[i0, 0]
    y0 = xy[i0, 1]
    if orient2d(x0, y0, xy[i1, 0], xy[i1, 1], xy[i2, 0], xy[i2, 1], ws) > 0.0:
        i1, i2 = i2, i1  # clockwise, as delaunator
    cx, cy = circumcentre(x0, y0, xy[i1, 0], xy[i1, 1], xy[i2, 0], xy[i2, 1])
    return i0, i1, i2, cx, cy


@numba.njit(cache=True, nogil=True, inline="always")
def circumcentre(x0, y0, x1, y1, x2, y2):
    """The centre of the circle through three points (not collinear), from the first."""
    dx = x1 - x0
    dy = y1 - y0
    ex = x2 - x0
    ey = y2 - y0
    bl = dx * dx + dy * dy
    cl = ex * ex + ey * ey
    f = 0.5 / (dx * ey - dy * ex)
    return x0 + (ey * bl - dy * cl) * f, y0 + (dx * cl - ex * bl) * f


@numba.njit(cache=True, nogil=True)
def _seed_ranks(ids, i0, i1, i2):
    """The ranks in the sort of the seed points i0, i1, i2."""
    r0 = r1 = r2 = -1
    for k in range(ids.shape[0]):
        idk = ids[k]
        if idk == i0:
            r0 = k
        elif idk == i1:
            r1 = k
        elif idk == i2:
            r2 = k
    return r0, r1, r2


@numba.njit(cache=True, nogil=True)
def _start_hull(pts, r0, r1, r2, cx, cy, tri, half, hull_prev, hull_next, hull_tri, hull_hash):
    """The seed triangle (r0, r1, r2) as triangle 0 and as the first hull."""
    hash_size = hull_hash.shape[0]
    hull_next[r0] = r1
    hull_prev[r2] = r1
    hull_next[r1] = r2
    hull_prev[r0] = r2
    hull_next[r2] = r0
    hull_prev[r1] = r0
    hull_tri[r0] = 0
    hull_tri[r1] = 1
    hull_tri[r2] = 2
    hull_hash[_hash_key(pts[r0, 0], pts[r0, 1], cx, cy, hash_size)] = r0
    hull_hash[_hash_key(pts[r1, 0], pts[r1, 1], cx, cy, hash_size)] = r1
    hull_hash[_hash_key(pts[r2, 0], pts[r2, 1], cx, cy, hash_size)] = r2
    _add_triangle(tri, half, 0, r0, r1, r2, -1, -1, -1)


@numba.njit(cache=True, nogil=True)
def _sweep(pts, ids, i0, i1, i2, cx, cy, tri, half):
    """Triangulate the sorted points pts; returns the length used in tri (3 per triangle) and
    the number of distinct points that could not be inserted (0 but for pathological rounding
    in the sort)."""
    n = pts.shape[0]
    r0, r1, r2 = _seed_ranks(ids, i0, i1, i2)
    hash_size = max(int(np.ceil(np.sqrt(n))), 1)
    hull_prev = np.empty(n, np.int32)
    hull_next = np.empty(n, np.int32)
    hull_tri = np.empty(n, np.int32)
    hull_hash = np.full(hash_size, -1, np.int32)
    stack = np.empty(n + 16, np.int32)  # untouched pages cost no memory
    _start_hull(pts, r0, r1, r2, cx, cy, tri, half, hull_prev, hull_next, hull_tri, hull_hash)
    return _sweep_points(pts, r0, r1, r2, cx, cy, tri, half, hull_prev, hull_next, hull_tri,
                         hull_hash, stack, _incircle_static_bound(pts), np.empty(WORKSPACE))


# No reference counts: numba counts a reference to each array handed to an inlined helper
# (_legalize, _link) with an atomic increment and decrement, some 30 a point, which took a third
# of the sweep's time. Without numba's runtime nothing here may allocate: the exact
# predicates' workspace ``ws`` comes from _sweep.
@numba.njit(cache=True, nogil=True, _nrt=False)
def _sweep_points(pts, r0, r1, r2, cx, cy, tri, half, hull_prev, hull_next, hull_tri, hull_hash,
                  stack, static, ws):
    """_sweep's per-point loop, from the seed triangle (r0, r1, r2) as _start_hull leaves it.
    It stays whole: split into compiled helpers (hull search, forward and backward fans) it ran
    about 15 % slower on 2 M points."""
    n = pts.shape[0]
    hash_size = hull_hash.shape[0]
    hull_start = r0
    tlen = 3
    sx0, sy0 = pts[r0, 0], pts[r0, 1]
    sx1, sy1 = pts[r1, 0], pts[r1, 1]
    sx2, sy2 = pts[r2, 0], pts[r2, 1]
    skipped = 0
    xp = 0.0
    yp = 0.0
    for k in range(n):
        px = pts[k, 0]
        py = pts[k, 1]
        # skip near-duplicates (equal points are next to each other after the sort)
        if k > 0 and abs(px - xp) <= _DUP_EPS and abs(py - yp) <= _DUP_EPS:
            continue
        xp = px
        yp = py
        if ((px == sx0 and py == sy0) or (px == sx1 and py == sy1)
                or (px == sx2 and py == sy2)):
            continue  # a seed point or a copy of one
        # a visible hull edge, starting from the hash
        key = _hash_key(px, py, cx, cy, hash_size)
        start = 0
        for j in range(hash_size):
            kk = key + j
            if kk >= hash_size:
                kk -= hash_size
            start = hull_hash[kk]
            if start != -1 and start != hull_next[start]:
                break
        start = hull_prev[start]
        e = start
        while True:
            q = hull_next[e]
            if orient2d(px, py, pts[e, 0], pts[e, 1], pts[q, 0], pts[q, 1], ws) > 0.0:
                break
            e = q
            if e == start:
                e = -1
                break
        if e == -1:  # not outside the hull (rounding in the sort): cannot be inserted
            skipped += 1
            continue

        t = tlen
        _add_triangle(tri, half, t, e, k, hull_next[e], -1, -1, hull_tri[e])
        tlen += 3
        hull_tri[k] = _legalize(t + 2, tri, half, pts, hull_start, hull_tri, hull_prev, stack,
                                static, ws)
        hull_tri[e] = t
        # walk forward along the hull, adding triangles
        nn = hull_next[e]
        while True:
            q = hull_next[nn]
            if not orient2d(px, py, pts[nn, 0], pts[nn, 1], pts[q, 0], pts[q, 1], ws) > 0.0:
                break
            t = tlen
            _add_triangle(tri, half, t, nn, k, q, hull_tri[k], -1, hull_tri[nn])
            tlen += 3
            hull_tri[k] = _legalize(t + 2, tri, half, pts, hull_start, hull_tri, hull_prev,
                                    stack, static, ws)
            hull_next[nn] = nn  # removed
            nn = q

        # walk backward from the other side
        if e == start:
            while True:
                q = hull_prev[e]
                if not orient2d(px, py, pts[q, 0], pts[q, 1], pts[e, 0], pts[e, 1], ws) > 0.0:
                    break
                t = tlen
                _add_triangle(tri, half, t, q, k, e, -1, hull_tri[e], hull_tri[q])
                tlen += 3
                _legalize(t + 2, tri, half, pts, hull_start, hull_tri, hull_prev, stack, static,
                          ws)
                hull_tri[q] = t
                hull_next[e] = e  # removed
                e = q

        hull_start = e
        hull_prev[k] = e
        hull_next[e] = k
        hull_prev[nn] = k
        hull_next[k] = nn
        hull_hash[_hash_key(px, py, cx, cy, hash_size)] = k
        hull_hash[_hash_key(pts[e, 0], pts[e, 1], cx, cy, hash_size)] = e
    return tlen, skipped


@numba.njit(cache=True, nogil=True)
def _emit(tri, ids, out):
    """out[t] = the original indices of triangle t, counter-clockwise."""
    for t in range(out.shape[0]):
        out[t, 0] = ids[tri[3 * t]]
        out[t, 1] = ids[tri[3 * t + 2]]
        out[t, 2] = ids[tri[3 * t + 1]]


def delaunay(xy: np.ndarray) -> np.ndarray:
    """Delaunay triangles of points xy (N, 2) float64 as an (M, 3) int64 array of point indices,
    counter-clockwise. Duplicate points are ignored; collinear input gives (0, 3)."""
    _, ids, tri = delaunay_in_sweep_order(xy)
    out = np.empty((len(tri), 3), np.int64)
    _emit(tri.ravel(), ids, out)
    return out


def delaunay_in_sweep_order(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangulation as the sweep leaves it: (the points in the sweep's order (N, 2), their
    indices in xy (N,) int32, triangles (M, 3) int32 of indices into the former, clockwise).
    Triangles made one after another share points near one another in memory, so a pass over
    them reads the points almost in order; ``delaunay``'s array costs a pass and 24 bytes a
    triangle more."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"expected an (N, 2) array of points, got shape {xy.shape}")
    n = xy.shape[0]
    if n >= 2**31 // 6:
        raise ValueError(f"too many points for one triangulation: {n:,}")
    none = (np.empty((0, 2)), np.empty(0, np.int32), np.empty((0, 3), np.int32))
    if n < 3:
        return none
    i0, i1, i2, cx, cy = _seed(xy)
    if i0 == -1:
        raise ValueError("point coordinates must be finite")
    if i2 == -1:
        return none
    pts = np.empty((n, 2))
    ids = np.empty(n, np.int32)
    _sort_by_distance(xy, cx, cy, pts, ids)
    tri = np.empty(3 * (2 * n - 5), np.int32)
    half = np.empty(3 * (2 * n - 5), np.int32)
    tlen, skipped = _sweep(pts, ids, i0, i1, i2, cx, cy, tri, half)
    del half
    if skipped:
        warnings.warn(f"Delaunay triangulation left out {skipped} points that rounding placed "
                      "inside the hull", RuntimeWarning, stacklevel=3)
    return pts, ids, tri[:tlen].reshape(-1, 3)


@numba.njit(cache=True, nogil=True)
def average_repeats(pts, z):
    """Give each run of points at one place in ``pts`` (N, 2, the sweep's order: they sit next
    to one another after its sort; the sweep keeps the first) the mean of their ``z`` (N,), in
    place, summed in ascending order: the same value whatever order the survey held them in,
    where the first would follow that order. Returns ``z``."""
    n = pts.shape[0]
    k = 0
    while k < n:
        end = k + 1
        while end < n and pts[end, 0] == pts[k, 0] and pts[end, 1] == pts[k, 1]:
            end += 1
        if end - k > 1:
            values = np.sort(z[k:end])
            total = 0.0
            for v in values:
                total += v
            z[k:end] = total / (end - k)
        k = end
    return z
