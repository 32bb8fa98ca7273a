"""Terrain fits to the measured points: break lines moved from grid cells onto the terrain's
actual crest and toe, and mesh node elevations with the measurement noise taken out.

Break-line localisation: at each vertex of a traced line, the measured points (LiDAR points put
into the grid, or DEM cell centres where the input is a DEM) in a window along the line are fitted
by two planes that meet in a line parallel to the traced one (a hinge; least squares, the hinge
offset searched across the window and refined by a parabola). Where the hinge explains the
points clearly better than one plane (an F ratio) and the slope changes across it by at least
half of tan(S_crit), the vertex moves onto the hinge and takes its z; the fit's RMS residual is
the vertex's confidence (m). The window follows point density and noise: it holds about
``40 + 800·σ`` points (σ in m), at least one and at most 1.5 cells to each side and at most
six cells along; where the two planes misfit the points beyond the noise (the ground bends
along the line: where it crosses an embankment, at a corner), the fit is repeated over half the
length, down to half the width. A kink that runs beside a localised line but that no traced
line follows (the toe of a narrow embankment whose band the tracer followed along its crest) is
found by probing parallel to each line (``_companions``) and becomes a line of its own.

Node elevations: nodes on break lines take z along the (localised) lines; every other node, z of
a least-squares plane of the measured points within a radius (shrunk so that the window stays
off the break lines). Points held out for the accuracy test are never among those fitted.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numba import njit, prange

from ..engine.arrays import distance_along, true_runs
from ..engine.nearest import nearest_line, point_index, threads_for, z_along_lines
from ..engine.progress import along, part, report
from ..errors import FloodMeshError
from ..points import step_points, xyz_array
from .breaklines import BreakLine, as_breaklines
from .joining import bridges, chains_through, join_pieces, snap_t_junctions
from .simplify import douglas_peucker_mask


# The fit window's least area, in cells: about the window of the reference survey (9 points/m²,
# 5 cm noise: 8.9 cells, left as it is), which denser or cleaner points no longer shrink (chosen
# on the corpus of benchmarks/corpus.py: RESULTS.md, "The evaluation corpus")
MIN_WINDOW_CELLS = 8.0
# A gap in a line is bridged where this share of the hinge fits along it find the line's kink
BRIDGE_HOLD = 0.6
# A hinge fit that misfits its points beyond the noise, or beyond LEAN_NOISE_FLOOR m where the
# noise is less (QL1 LiDAR's RMSEz; on clean points a window's slight curvature is no misfit),
# is fitted again over half the window's length (the ground bends along the line: a road
# crossing the crest, a corner), up to LEAN_ROUNDS times and no shorter than LEAN_LEAST of the
# window's half width (chosen on the corpus: RESULTS.md, "Crossings under sparse points")
LEAN_ROUNDS, LEAN_LEAST, LEAN_NOISE_FLOOR = 3, 0.5, 0.05
# Between two vertices the fit moved onto crests, a vertex it did not move stays where dropping
# it would move the line by more than UNMOVED_LATERAL cells: a crest's corner where an
# embankment meets a levee, not the raster's staircase; a toe's corner stays cut (where a
# traced toe turns from a river into a tributary, the corner sits a metre from the river's toe:
# a sliver in the wet channel). Chosen on the corpus: RESULTS.md, "Crossings under sparse
# points"
UNMOVED_LATERAL = 2.0
# A line is cut where it turns by more than CORNER_TURN degrees over CORNER_REACH hinge-window
# half widths before and after a vertex (a corner, not a bend)
CORNER_TURN, CORNER_REACH = 30.0, 4.0
# Companion kinks: probes centred COMPANION_PROBES hinge-window half widths to each side of a
# localised line look for a parallel kink the tracer missed (the toe beside a crest, the other
# crest of a narrow embankment); a run of at least COMPANION_RUN probe vertices (half a window
# apart along the line) that find one, farther than COMPANION_APART half widths from every
# line, becomes a line (the run chosen on the corpus: RESULTS.md, "The run length, chosen on the
# corpus")
COMPANION_PROBES = (1.25, 2.25)  # their reach: 0.55 to 2.95 half widths out
COMPANION_RUN = 3
COMPANION_APART = 0.45
# A line that lies, for SECOND_TRACE_SHARE of its vertices, within SECOND_TRACE_WITHIN cells of
# a longer line of its kind is a second trace of that kink (two raster traces of one band that
# the hinge fits moved onto the same kink, as at 45° to the grid) and is left out; chosen on
# the corpus (RESULTS.md, "One trace per kink"): a quarter cell keeps the two crest edges of
# a 1 m crest apart
SECOND_TRACE_WITHIN, SECOND_TRACE_SHARE = 0.25, 0.8

# Two pieces' ends are measured for a join at their last fitted vertices where the traced run
# beyond (the raster trace, which noise bends off the kink) spans at most JOIN_TAIL_CELLS cells;
# chosen on the corpus and Merewether's flood (RESULTS.md, "Joins between the kinks found")
JOIN_TAIL_CELLS = 6.0
# The bridges' second pass measures the ends still free at their last fitted vertices where the
# traced run beyond spans at most BRIDGE_TAIL_CELLS cells: a bridge's hinge fits check the gap,
# so a longer cut than the joins' is safe; chosen on the corpus and Merewether's flood
# (RESULTS.md, "Bridges between the kinks found")
BRIDGE_TAIL_CELLS = 12.0

# Rounds of places drawn for the noise estimate, for points that fill little of their bounding
# box (a reach at 45°, a tile with a lake: a fifth filled still gives the samples in 8), fitted
# NOISE_CHUNK places at a time (the bar moves, Cancel is heard, along a round)
NOISE_DRAWS, NOISE_CHUNK = 8, 50


@dataclass(frozen=True)
class FitWindow:
    """Window of the terrain fits: hinge fits ``half_width`` (m) across a line and
    ``half_length`` (m) along it; plane fits of node elevations within ``node_radius`` (m)."""

    half_width: float
    half_length: float
    node_radius: float
    density: float       # measured points per m²
    noise: float         # estimated vertical noise (m), the median RMS of local plane fits


def fit_window(points: np.ndarray, area: float, cell_size: float, *,
               node_radius: float | None = None, seed: int = 0, index=None, progress=None,
               cancelled=None) -> FitWindow:
    """The fitting windows for ``points`` (n, 3) covering ``area`` m² on a grid of
    ``cell_size`` m: sized from their density and their noise (estimated from them).
    ``index``: ``nearest.point_index(points)`` if built (here and in every fit below).
    ``progress`` and ``cancelled``: as ``estimate_noise`` takes them."""
    if not area > 0 or len(points) < 10:
        raise FloodMeshError("too few measured points to fit the terrain to; turn off break-line "
                             "localisation and plane node elevations (--no-localise "
                             "--node-elevation dem)")
    density = len(points) / area
    noise = estimate_noise(points, density, seed=seed, index=index, progress=progress,
                           cancelled=cancelled)
    # m² of window: 40 + 800·noise points, and no less than MIN_WINDOW_CELLS cells (dense or
    # clean points would otherwise shrink it below what places a hinge reliably)
    wanted = max((40 + 800 * noise) / density, MIN_WINDOW_CELLS * cell_size ** 2)
    half_width = float(np.clip(np.sqrt(wanted) / 2, cell_size, 1.5 * cell_size))
    half_length = float(np.clip(wanted / (4 * half_width), half_width, 6 * cell_size))
    if node_radius is None:
        node_radius = float(np.clip(np.sqrt(wanted / np.pi), cell_size, 3 * cell_size))
    return FitWindow(half_width, half_length, float(node_radius), density, noise)


def estimate_noise(points: np.ndarray, density: float, *, samples: int = 400,
                   seed: int = 0, index=None, progress=None, cancelled=None) -> float:
    """Vertical noise (m) of the points: the median RMS residual of least-squares planes fitted
    to about 30 points around ``samples`` places drawn at random in their bounding box (terrain
    curvature adds a little). The places depend on where the points lie, not on their order,
    so the same survey read in another order (a COPC file's octree, tiles merged) gives the
    same estimate; places with fewer than 10 points around (water, voids, beyond a diagonal
    reach) are drawn again, up to NOISE_DRAWS rounds. ``progress`` hears the share of the
    samples gathered (0–1), ``cancelled`` is polled between the fits' chunks of
    ``NOISE_CHUNK`` places."""
    rng = np.random.default_rng(seed)
    radius = np.sqrt(30 / density / np.pi)
    index = index if index is not None else point_index(points)
    lo, hi = index.box[:2], index.box[2:]
    wanted = min(samples, len(points))
    rms = []
    for _ in range(NOISE_DRAWS):
        centres = lo + (hi - lo) * rng.random((wanted, 2))
        for a, b in _chunks(wanted, NOISE_CHUNK):  # each place's fit its own: the same numbers
            _, fit_rms, count = _plane_fits(index, points, centres[a:b], np.full(b - a, radius))
            rms.extend(fit_rms[count >= 10])
            report(progress, cancelled, min(len(rms) / wanted, 1.0))
        if len(rms) >= wanted:
            break
    return float(np.median(rms[:wanted])) if rms else 0.0


def beyond_noise(mean_square: np.ndarray, noise: float, dof: np.ndarray) -> np.ndarray:
    """Whether each mean square residual (m²) of ``dof`` degrees of freedom exceeds the noise²
    (m) by more than three of its standard errors (χ²: noise²·√(2/dof)): a misfit, a fold."""
    return mean_square - noise ** 2 > 3 * noise ** 2 * np.sqrt(2 / np.maximum(dof, 1))


# Centres fitted at a time: their neighbour query holds some 36 B for each (centre, neighbour)
# pair (room for every point of the cells it reads, then the CSR), 140 MB for the 130,000 nodes
# of a 4 km² mesh at once; a chunk holds some 80 MB at most (the hinge fits' 110 points a
# vertex), whatever the mesh (each centre's fit is its own: the same numbers).
FIT_CHUNK = 20_000


def _chunks(n: int, size: int = FIT_CHUNK):
    return [(a, min(n, a + size)) for a in range(0, n, size)]


def _plane_fits(index, points, centres, radius, progress=None, cancelled=None):
    """Least-squares planes of the points within ``radius`` (one per centre) of each centre:
    (z at the centre, RMS residual, point count); NaN where fewer than 4 points. ``progress``
    hears the share fitted, chunk by chunk, ``cancelled`` is polled between them."""
    points = np.asarray(points, float)
    parts = [_plane_fits_chunk(index, points, centres[a:b], radius[a:b])
             for a, b in along(_chunks(len(centres)), progress, cancelled)]
    if not parts:
        return np.zeros(0), np.zeros(0), np.zeros(0, np.int64)
    return tuple(np.concatenate(column) for column in zip(*parts))


def _plane_fits_chunk(index, points, centres, radius):
    indptr, indices = index.neighbours(centres, radius)
    count = np.diff(indptr)
    z = np.full(len(centres), np.nan)
    rms = np.full(len(centres), np.nan)
    fit = count >= 4
    if not fit.any():
        return z, rms, count
    with threads_for(len(centres)):
        zmean, ata, atz = _plane_equations(points, indptr, indices, centres)
        ata[~fit] = np.eye(3)
        ata += np.eye(3) * 1e-9
        beta = np.linalg.solve(ata, atz[..., None])[..., 0]
        sse = _plane_residuals(points, indptr, indices, centres, zmean, beta)
    z[fit] = zmean[fit] + beta[fit, 0]
    rms[fit] = np.sqrt(sse[fit] / np.maximum(count[fit] - 3, 1))
    return z, rms, count


@njit(cache=True, nogil=True, parallel=True)
def _plane_equations(points, indptr, indices, centres):
    """Per centre (on all cores), of its points ``indices[indptr[i]:indptr[i + 1]]``: their
    mean z and the normal equations (AᵀA (3, 3), Aᵀdz (3,)) of the plane
    dz = a + b·dx + c·dy, with dx, dy from the centre and dz from that mean, summed point by
    point."""
    m = centres.shape[0]
    zmean, ata, atz = np.empty(m), np.empty((m, 3, 3)), np.empty((m, 3))
    for i in prange(m):
        total = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            total += points[indices[k], 2]
        zmean[i] = total / max(indptr[i + 1] - indptr[i], 1)
        s1 = sx = sy = sxx = sxy = syy = t1 = tx = ty = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            dx, dy, dz = _offsets(points, indices[k], centres[i], zmean[i])
            s1, sx, sy = s1 + 1.0, sx + dx, sy + dy
            sxx, sxy, syy = sxx + dx * dx, sxy + dx * dy, syy + dy * dy
            t1, tx, ty = t1 + dz, tx + dx * dz, ty + dy * dz
        ata[i, 0, 0], ata[i, 0, 1], ata[i, 0, 2] = s1, sx, sy
        ata[i, 1, 0], ata[i, 1, 1], ata[i, 1, 2] = sx, sxx, sxy
        ata[i, 2, 0], ata[i, 2, 1], ata[i, 2, 2] = sy, sxy, syy
        atz[i, 0], atz[i, 1], atz[i, 2] = t1, tx, ty
    return zmean, ata, atz


@njit(cache=True, nogil=True, parallel=True)
def _plane_residuals(points, indptr, indices, centres, zmean, beta):
    """Per centre (on all cores): the SSE of its points about its plane (``beta``: a, b, c of
    ``_plane_equations``' plane)."""
    m = centres.shape[0]
    sse = np.empty(m)
    for i in prange(m):
        total = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            dx, dy, dz = _offsets(points, indices[k], centres[i], zmean[i])
            r = dz - (beta[i, 0] + dx * beta[i, 1] + dy * beta[i, 2])
            total += r * r
        sse[i] = total
    return sse


@njit(cache=True, nogil=True)
def _offsets(points, q, centre, zmean):
    """Point q's x, y from ``centre`` and z from ``zmean``."""
    return points[q, 0] - centre[0], points[q, 1] - centre[1], points[q, 2] - zmean


@njit(cache=True, nogil=True)
def _solve4(a, b):
    """Gaussian elimination with partial pivoting of a 4x4 system (a, b are overwritten)."""
    n = 4
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(a[i, k]) > abs(a[p, k]):
                p = i
        if abs(a[p, k]) < 1e-12:
            return False
        if p != k:
            for j in range(n):
                a[k, j], a[p, j] = a[p, j], a[k, j]
            b[k], b[p] = b[p], b[k]
        for i in range(k + 1, n):
            f = a[i, k] / a[k, k]
            for j in range(k, n):
                a[i, j] -= f * a[k, j]
            b[i] -= f * b[k]
    for k in range(n - 1, -1, -1):
        s = b[k]
        for j in range(k + 1, n):
            s -= a[k, j] * b[j]
        b[k] = s / a[k, k]
    return True


@njit(cache=True, nogil=True)
def _hinge_sse(u, v, z, m, u0, fixed, beta, a, b):
    """SSE of the hinge z = a + b·v + c1·min(u-u0, 0) + c2·max(u-u0, 0) over the first m points,
    its coefficients into ``beta``; inf with fewer than 4 points on a side. ``fixed``: the sums
    that do not depend on u0 (``_hinge_fixed``); ``a`` (4, 4) and ``b`` (4,) are scratch for
    the normal equations, whose sums run in scalars (each the same additions in the same order
    as the products of a design row)."""
    s1, sv, svv, z1, zv = fixed
    slo = shi = svlo = svhi = slolo = shihi = zlo = zhi = 0.0
    left = 0
    for k in range(m):
        w = u[k] - u0
        lo, hi, vk, zk = min(w, 0.0), max(w, 0.0), v[k], z[k]
        if w < 0:
            left += 1
        slo, shi, svlo, svhi = slo + lo, shi + hi, svlo + vk * lo, svhi + vk * hi
        slolo, shihi, zlo, zhi = slolo + lo * lo, shihi + hi * hi, zlo + lo * zk, zhi + hi * zk
    # every min(w, 0)·max(w, 0) is ±0: their sum is 0.0
    if left < 4 or m - left < 4:
        return np.inf
    a[0, 0], a[0, 1], a[0, 2], a[0, 3] = s1, sv, slo, shi
    a[1, 0], a[1, 1], a[1, 2], a[1, 3] = sv, svv, svlo, svhi
    a[2, 0], a[2, 1], a[2, 2], a[2, 3] = slo, svlo, slolo, 0.0
    a[3, 0], a[3, 1], a[3, 2], a[3, 3] = shi, svhi, 0.0, shihi
    b[0], b[1], b[2], b[3] = z1, zv, zlo, zhi
    for i in range(4):
        a[i, i] += 1e-9
    if not _solve4(a, b):
        return np.inf
    sse = 0.0
    for k in range(m):
        w = u[k] - u0
        r = z[k] - (b[0] + b[1] * v[k] + b[2] * min(w, 0.0) + b[3] * max(w, 0.0))
        sse += r * r
    for i in range(4):
        beta[i] = b[i]
    return sse


@njit(cache=True, nogil=True)
def _hinge_fixed(v, z, m):
    """The hinge's sums over the first m points that no offset changes: (count, Σv, Σv²,
    Σz, Σv·z)."""
    s1 = sv = svv = z1 = zv = 0.0
    for k in range(m):
        s1, sv, svv, z1, zv = s1 + 1.0, sv + v[k], svv + v[k] * v[k], z1 + z[k], zv + v[k] * z[k]
    return s1, sv, svv, z1, zv


@njit(cache=True, nogil=True, parallel=True)
def _hinge_fits(points, indptr, indices, vx, vy, tx, ty, half_width, half_length):
    """Per vertex (on all cores): hinge offset across (m, + to the left of the tangent), z at
    the hinge, the hinge's RMS residual, slope change across it, the single plane's SSE over
    the hinge's SSE, the point count (NaN offsets where no fit)."""
    n = len(vx)
    out = np.full((n, 6), np.nan)
    for i in prange(n):
        _hinge_fit(points, indices[indptr[i]:indptr[i + 1]], vx[i], vy[i], tx[i], ty[i],
                   half_width, half_length, out[i])
    return out


@njit(cache=True, nogil=True)
def _hinge_fit(points, near, x, y, tx, ty, half_width, half_length, out):
    """``_hinge_fits`` of one vertex at (x, y), tangent (tx, ty), into ``out`` (6,) (left as
    it is where no fit)."""
    steps = 24
    u, v, z, m = _window_points(points, near, x, y, tx, ty, half_width, half_length)
    if m < 12:
        return
    zmean = 0.0
    for k in range(m):
        zmean += z[k]
    zmean /= m
    for k in range(m):
        z[k] -= zmean
    # one plane z = a + b·v + c·u: the hinge with c1 = c2, at any u0
    beta, a, b, fixed = np.zeros(4), np.empty((4, 4)), np.empty(4), _hinge_fixed(v, z, m)
    u0, best_j = _hinge_offset(u, v, z, m, half_width, steps, fixed, beta, a, b)
    if best_j < 0:
        return
    sse = _hinge_sse(u, v, z, m, u0, fixed, beta, a, b)
    if not np.isfinite(sse):
        return
    plane = _plane_sse(u, v, z, m)
    edge = best_j == 0 or best_j == steps
    out[0] = np.nan if edge else u0
    out[1] = zmean + beta[0]
    out[2] = np.sqrt(sse / max(m - 4, 1))
    out[3] = beta[3] - beta[2]
    out[4] = (plane - sse) / max(sse / max(m - 4, 1), 1e-12)
    out[5] = m


@njit(cache=True, nogil=True)
def _window_points(points, near, x, y, tx, ty, half_width, half_length):
    """The ``points`` (n, 3) ``near`` a vertex at (x, y) with unit tangent (tx, ty) that lie
    in its fit window: their offsets across (u, + to the left) and along (v) and their z, in
    the first m places of each; returns u, v, z and m."""
    u = np.empty(near.size)
    v = np.empty(near.size)
    z = np.empty(near.size)
    m = 0
    for k in range(near.size):
        q = near[k]
        dx, dy = points[q, 0] - x, points[q, 1] - y
        along = dx * tx + dy * ty
        across = -dx * ty + dy * tx
        if abs(along) <= half_length and abs(across) <= half_width:
            u[m], v[m], z[m] = across, along, points[q, 2]
            m += 1
    return u, v, z, m


@njit(cache=True, nogil=True)
def _hinge_offset(u, v, z, m, half_width, steps, fixed, beta, a, b):
    """The hinge's offset across the line: the least SSE of ``steps`` + 1 offsets evenly over
    ±0.7·``half_width``, refined by a parabola through its neighbours' SSE. Returns the offset
    and the best step's index (-1: no offset fits; 0 or ``steps``: at the window's edge).
    ``fixed``, ``beta``, ``a`` and ``b``: as ``_hinge_sse`` takes them.

    Each offset's sums come from the points binned between the offsets (those below an
    offset fill the bins before it), and its least SSE from the normal equations, the block of
    (a, b), which no offset changes, eliminated once (its Schur complement): a 2 x 2 solve an
    offset, not two passes over the points and a 4 x 4 solve. The near-least offsets and the
    best one's neighbours are then fitted point by point (``_hinge_sse``), so that the offset
    chosen and refined is the same to the bit as where every offset is (a near-tie, as on a
    DEM's lattice of cell centres, goes the same way)."""
    reach = 0.7 * half_width
    offsets = np.empty(steps + 1)
    for j in range(steps + 1):
        offsets[j] = -reach + 2 * reach * j / steps
    # sums over the points below each offset: Σu, Σu², Σv, Σu·v, Σz, Σu·z and their count,
    # binned first (bin k: offsets[k - 1] <= u < offsets[k]), then accumulated
    below = np.zeros((steps + 2, 7))
    zz = 0.0
    scale = steps / (2 * reach)
    for k in range(m):
        uk, vk, zk = u[k], v[k], z[k]
        zz += zk * zk
        f = (uk + reach) * scale
        i = 0 if f < 0.0 else (steps + 1 if f >= steps + 1 else int(f) + 1)
        while i <= steps and offsets[i] <= uk:  # exactly as u < offset decides
            i += 1
        while i > 0 and offsets[i - 1] > uk:
            i -= 1
        row = below[i]
        row[0] += uk
        row[1] += uk * uk
        row[2] += vk
        row[3] += uk * vk
        row[4] += zk
        row[5] += uk * zk
        row[6] += 1.0
    for i in range(1, steps + 2):
        for c in range(7):
            below[i, c] += below[i - 1, c]
    # (a, b)'s block [[n, Σv], [Σv, Σv²]] (with _hinge_sse's ridge), inverted once
    s1, sv, svv, z1, zv = fixed
    p00, p01, p11 = s1 + 1e-9, sv, svv + 1e-9
    det = p00 * p11 - p01 * p01
    if not det > 0.0:
        return 0.0, -1
    i00, i01, i11 = p11 / det, -p01 / det, p00 / det
    plane_part = z1 * (i00 * z1 + i01 * zv) + zv * (i01 * z1 + i11 * zv)
    best = np.inf
    sses = np.full(steps + 1, np.inf)
    total = below[steps + 1]
    for j in range(steps + 1):
        u0 = offsets[j]
        su, suu, svs, suv, sz, suz, nlo = below[j]  # u < u0: below the hinge
        nhi = m - nlo
        if nlo < 4 or nhi < 4:
            continue
        ru, ruu, rv = total[0] - su, total[1] - suu, total[2] - svs
        ruv, rz, ruz = total[3] - suv, total[4] - sz, total[5] - suz
        # the hinge's columns against (1, v), against each other, and against z
        c0, d0 = su - u0 * nlo, ru - u0 * nhi            # Σlo, Σhi
        c1, d1 = suv - u0 * svs, ruv - u0 * rv            # Σv·lo, Σv·hi
        slolo = suu - 2 * u0 * su + u0 * u0 * nlo + 1e-9
        shihi = ruu - 2 * u0 * ru + u0 * u0 * nhi + 1e-9
        zlo, zhi = suz - u0 * sz, ruz - u0 * rz
        # Schur complement of the (a, b) block, and the right-hand side with it eliminated
        g0, g1 = i00 * c0 + i01 * c1, i01 * c0 + i11 * c1  # P⁻¹·(Σlo, Σv·lo)
        h0, h1 = i00 * d0 + i01 * d1, i01 * d0 + i11 * d1  # P⁻¹·(Σhi, Σv·hi)
        s_ll = slolo - (c0 * g0 + c1 * g1)
        s_lh = -(c0 * h0 + c1 * h1)
        s_hh = shihi - (d0 * h0 + d1 * h1)
        e_l = zlo - (g0 * z1 + g1 * zv)
        e_h = zhi - (h0 * z1 + h1 * zv)
        det_s = s_ll * s_hh - s_lh * s_lh
        if not det_s > 0.0:
            continue
        explained = (s_hh * e_l * e_l - 2 * s_lh * e_l * e_h + s_ll * e_h * e_h) / det_s
        sses[j] = max(zz - plane_part - explained, 0.0)
        best = min(best, sses[j])
    near_least = best + 1e-6 * best + 1e-12 * zz
    best, best_j = np.inf, -1
    for j in range(steps + 1):
        if sses[j] <= near_least:
            sse = _hinge_sse(u, v, z, m, offsets[j], fixed, beta, a, b)
            if sse < best:
                best, best_j = sse, j
    h = 2 * reach / steps
    u0 = -reach + h * best_j
    if 0 < best_j < steps:
        left = _hinge_sse(u, v, z, m, offsets[best_j - 1], fixed, beta, a, b)
        right = _hinge_sse(u, v, z, m, offsets[best_j + 1], fixed, beta, a, b)
        if np.isfinite(left) and np.isfinite(right):
            curv = left - 2 * best + right
            if curv > 0:
                u0 += 0.5 * h * (left - right) / curv
    return u0, best_j


@njit(cache=True, nogil=True)
def _plane_sse(u, v, z, m):
    """SSE of the single plane z = a + b·v + c·u fitted by least squares to the first m points;
    inf where the fit is singular."""
    a = np.zeros((4, 4))
    b = np.zeros(4)
    for k in range(m):
        r0, r1, r2 = 1.0, v[k], u[k]
        b[0] += r0 * z[k]
        b[1] += r1 * z[k]
        b[2] += r2 * z[k]
        a[0, 0] += 1
        a[0, 1] += r1
        a[0, 2] += r2
        a[1, 1] += r1 * r1
        a[1, 2] += r1 * r2
        a[2, 2] += r2 * r2
    a[1, 0], a[2, 0], a[2, 1] = a[0, 1], a[0, 2], a[1, 2]
    a[3, 3] = 1.0
    plane = np.inf
    if _solve4(a, b):
        plane = 0.0
        for k in range(m):
            r = z[k] - (b[0] + b[1] * v[k] + b[2] * u[k])
            plane += r * r
    return plane


def _tangents(coords: np.ndarray) -> np.ndarray:
    """Unit tangents at a line's vertices (central differences, one-sided at the ends)."""
    d = np.empty((len(coords), 2))
    d[1:-1] = coords[2:, :2] - coords[:-2, :2]
    d[0] = coords[1, :2] - coords[0, :2]
    d[-1] = coords[-1, :2] - coords[-2, :2]
    length = np.hypot(*d.T)
    length[length == 0] = 1.0
    return d / length[:, None]


def localise_breaklines(lines: list[np.ndarray], points: np.ndarray, window: FitWindow, *,
                        s_crit: float = 10.0, iterations: int = 2, min_f_ratio: float = 10.0,
                        index=None, progress=None, cancelled=None
                        ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Break-line vertices moved onto the hinge of a two-plane fit to ``points`` (n, 3), z from
    the fit (see the module's docstring). ``lines`` are (k, 3) arrays. Returns the moved lines
    and, per line, each vertex's fit RMS residual (m) and the change of slope across the hinge
    (negative on a crest, positive at a toe, whichever way the line runs), both NaN where the
    vertex was not moved. ``progress`` hears the share fitted (0–1), ``cancelled`` is polled
    between the fits' chunks."""
    if not lines:
        report(progress, cancelled, 1.0)
        return [], [], []
    index = index if index is not None else point_index(points)
    points = np.asarray(points, float)  # its rows: a point's x, y, z in one cache line
    min_kink = 0.5 * np.tan(np.radians(s_crit))
    sizes = [len(c) for c in lines]
    coords = np.concatenate([np.asarray(c, float)[:, :3] for c in lines])
    starts = np.r_[0, np.cumsum(sizes)]
    confidence = np.full(len(coords), np.nan)
    kink = np.full(len(coords), np.nan)

    def hinge_fits(xy, tangents, half_length, progress):
        reach = float(np.hypot(window.half_width, half_length))
        with threads_for(len(xy)):
            # the fits' sums need no particular order of their points
            return np.concatenate([_hinge_fits(points, *index.neighbours(xy[a:b], reach,
                                                                         ascending=False),
                                               xy[a:b, 0].copy(), xy[a:b, 1].copy(),
                                               tangents[a:b, 0].copy(), tangents[a:b, 1].copy(),
                                               window.half_width, half_length)
                                   for a, b in along(_chunks(len(xy)), progress, cancelled)])

    for i in range(iterations):
        # each iteration its share of the bar: the full window's fits 0.6 of it, the lean rest
        told = part(progress, i / iterations, (i + 1) / iterations)
        tangents = np.concatenate([_tangents(coords[a:b]) for a, b in zip(starts[:-1], starts[1:])])
        fits = hinge_fits(coords[:, :2], tangents, window.half_length, part(told, 0.0, 0.6))
        half_length = window.half_length
        for r in range(LEAN_ROUNDS):  # where the ground bends along the line: a shorter window
            half_length /= 2
            if half_length < LEAN_LEAST * window.half_width:
                break
            bent = np.flatnonzero(np.isfinite(fits[:, 2]) & beyond_noise(
                fits[:, 2] ** 2, max(window.noise, LEAN_NOISE_FLOOR), fits[:, 5] - 4))
            if not len(bent):
                break
            closer = hinge_fits(coords[bent, :2], tangents[bent], half_length,
                                part(told, 0.6 + 0.4 * r / LEAN_ROUNDS,
                                     0.6 + 0.4 * (r + 1) / LEAN_ROUNDS))
            fitted = np.isfinite(closer[:, 2])
            fits[bent[fitted]] = closer[fitted]
        good = (np.isfinite(fits[:, 0]) & (np.abs(fits[:, 3]) >= min_kink)
                & (fits[:, 4] >= min_f_ratio))
        normal = np.column_stack([-tangents[:, 1], tangents[:, 0]])
        coords[good, :2] += fits[good, 0:1] * normal[good]
        coords[good, 2] = fits[good, 1]
        confidence[good] = fits[good, 2]
        kink[good] = fits[good, 3]
        report(told, cancelled, 1.0)
    bounds = list(zip(starts[:-1], starts[1:]))
    return ([coords[a:b] for a, b in bounds], [confidence[a:b] for a, b in bounds],
            [kink[a:b] for a, b in bounds])


def fit_node_elevations(nodes: np.ndarray, points: np.ndarray, lines: list[np.ndarray],
                        radius: float, *, on_line: float, own_lines: list = (), index=None,
                        noise: float | None = None, note=None, progress=None,
                        cancelled=None) -> tuple[np.ndarray, dict]:
    """Node elevations (n,) with the noise taken out: nodes within ``on_line`` m of a break line
    (k, 3 arrays) take z along it (``z_along_lines``; keep theirs where no line there has z: a
    modeller's 2-D line, read with NaN z, which leaves a line with z its z at a crossing; a
    node equally near two lines with z takes the one listed first), and those within it of one
    of ``own_lines`` (the modeller's, among ``lines``) its z where it has one, though another
    line be nearer (a crossing's node, snapped to a grid), as ``build_mesh`` gives them; the
    others z of a least-squares plane of ``points`` within ``radius`` m (at most 0.9 of their
    distance to the nearest line, at least ``on_line``·10), or keep theirs where fewer than 6
    points are there. Returns z and counts. Points without a
    finite x, y, z or with a z no ground has (-9999) are left out (``points.step_points``,
    ``note`` told; ``index`` then built anew). ``progress`` hears the share done (0–1) along
    the fits, ``cancelled`` is polled on the way."""
    nodes = xyz_array(nodes, "the mesh's nodes")
    points, index = _measured(points, index, note)
    z = nodes[:, 2].copy()
    xy = nodes[:, :2]
    distance, at, on_z = z_along_lines(xy, lines, within=on_line)
    z[at] = on_z
    _, at, on_z = z_along_lines(xy, own_lines, within=on_line)
    z[at] = on_z
    report(progress, cancelled, 0.1)
    on = distance <= on_line
    off = ~on
    r = np.clip(0.9 * distance[off], min(radius, 10 * on_line), radius)
    index = index if index is not None else point_index(points)
    plane, rms, count = _plane_fits(index, points, xy[off], r, part(progress, 0.2, 0.7),
                                    cancelled)
    if noise:  # lean planes (where they misfit beyond the noise, a fold inside): a closer fit
        for k in range(2):
            bent = (count >= 6) & beyond_noise(rms ** 2, noise, count - 3)
            if not bent.any():
                break
            closer = _plane_fits(index, points, xy[off][bent], r[bent] / 2,
                                 part(progress, 0.7 + 0.15 * k, 0.85 + 0.15 * k), cancelled)
            better = closer[2] >= 6
            pick = np.nonzero(bent)[0][better]
            plane[pick], rms[pick], count[pick] = (c[better] for c in closer)
            r[pick] = r[pick] / 2
    fitted = count >= 6
    idx = np.nonzero(off)[0][fitted]
    z[idx] = plane[fitted]
    report(progress, None, 1.0)
    return z, {"on_lines": int(on.sum()), "plane_fitted": int(fitted.sum()),
               "kept": int((~fitted).sum())}


def _measured(points, index, note) -> tuple[np.ndarray, object]:
    """The caller's measured ``points`` (n, 3) as a step takes them (``points.step_points``,
    ``note`` told of those left out) and their ``index``, None where some were left out."""
    usable = step_points(points, "the measured points", note)
    return usable, index if usable is points else None


def _failed_fits_left_out(coords, moved, max_gap, lateral, kink):
    """Which vertices to keep: the moved ones, the line's ends, runs of vertices the fit did
    not move where the moved vertices on either side are farther apart than ``max_gap`` m along
    the line (a stretch without a clear kink keeps its traced course), and, in shorter runs
    between two moved vertices on crests (``kink`` negative at both: not a toe, not a hop from
    crest to toe), those that Douglas–Peucker keeps within ``lateral`` m in plan (a crest's
    corner is not cut by a chord)."""
    keep = moved.copy()
    keep[0] = keep[-1] = True
    kept = np.nonzero(keep)[0]
    along = distance_along(coords)
    for a, b in zip(kept[:-1], kept[1:]):
        if b - a > 1 and along[b] - along[a] > max_gap:
            keep[a + 1:b] = True
        elif b - a > 1 and kink[a] < 0 and kink[b] < 0:
            keep[a:b + 1] |= douglas_peucker_mask(coords[a:b + 1, :2], lateral)  # in plan
    return keep


def _hops_cut(keep: np.ndarray, kink: np.ndarray) -> list[np.ndarray]:
    """The kept vertex indices split into pieces where the line hops from a crest to a toe
    (or back) across a band: between two moved vertices whose slope changes have opposite
    signs, the segment after the first goes."""
    signs = np.sign(kink[keep])
    moved = np.nonzero(np.isfinite(signs))[0]
    cuts = [i + 1 for i, j in zip(moved[:-1], moved[1:]) if signs[i] != signs[j]]
    return np.split(keep, cuts)


@njit(cache=True, nogil=True)
def _median(values: np.ndarray) -> float:
    """``np.median`` of a few ``values`` (the middle one, or the mean of the middle two; NaN
    where any is NaN or none) without its overhead (some 20 µs a call)."""
    ordered = np.sort(values)
    n = len(ordered)
    if not n or np.isnan(ordered[-1]):
        return np.nan
    return ordered[n // 2] if n % 2 else (ordered[n // 2 - 1] + ordered[n // 2]) / 2


def _ground_follows(points: np.ndarray, window: FitWindow, spacing: float = 0.5, index=None):
    """A check for ``join_pieces``: whether the measured points between two line ends (x, y, z)
    follow the straight line between them, i.e. the median z of the points near each of the
    gap's sample positions (every ``spacing`` m) lies on average within 0.05 m plus the noise
    of the line's z. Gaps under a metre pass unchecked."""
    index = index if index is not None else point_index(points)
    tolerance = 0.05 + window.noise

    def follows(a, b) -> bool:
        gap = float(np.hypot(*(b[:2] - a[:2])))
        if gap < 1.0 or len(a) < 3 or not (np.isfinite(a[2]) and np.isfinite(b[2])):
            return True
        t = np.linspace(0, 1, max(3, int(gap / spacing)) + 2)[1:-1, None]
        at = a[None, :3] * (1 - t) + b[None, :3] * t
        off = np.abs(_ground_z(points, window, at[:, :2], index, spacing) - at[:, 2])
        return not np.isfinite(off).any() or float(np.nanmean(off)) <= tolerance

    return follows


def _ground_z(points: np.ndarray, window: FitWindow, xy: np.ndarray, index,
              spacing: float = 0.5) -> np.ndarray:
    """The median z of the measured points within a ``spacing`` (m) of each of ``xy``, or of
    the 8 or so nearest where they are sparser; NaN where fewer than 3 lie that close."""
    radius = max(spacing, float(np.sqrt(8 / (np.pi * window.density))))
    indptr, indices = index.neighbours(np.asarray(xy, float), radius, ascending=False)
    return _medians_z(points, indptr, indices, 3)


@njit(cache=True, nogil=True)
def _medians_z(points, indptr, indices, least):
    """``_median`` of the z of each CSR row's points (``indptr``, ``indices`` into
    ``points``); NaN for a row of fewer than ``least``."""
    out = np.full(indptr.shape[0] - 1, np.nan)
    for i in range(out.shape[0]):
        if indptr[i + 1] - indptr[i] >= least:
            out[i] = _median(points[indices[indptr[i]:indptr[i + 1]], 2])
    return out


def _corners_cut(keep: np.ndarray, coords: np.ndarray, reach: float,
                 max_turn: float) -> list[np.ndarray]:
    """The kept vertex indices split where the line turns a corner: at the vertex where its
    chords to the points ``reach`` m before and after it (or its ends, if nearer) turn most, by
    more than ``max_turn`` degrees; then each part the same way (the vertex ends one part and
    starts the next). At a crossing or a junction the tracer runs round the corner from one
    feature's line onto the other's, or back onto its own; cut there, each arm can join the
    rest of its own line."""
    xy = coords[keep, :2]
    if len(xy) < 3:
        return [keep]
    along = distance_along(xy)

    def at(distance):  # the points ``distance`` m along the line (its ends beyond them)
        return np.column_stack([np.interp(distance, along, xy[:, 0]),
                                np.interp(distance, along, xy[:, 1])])

    u, v = xy - at(along - reach), at(along + reach) - xy
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = (u * v).sum(axis=1) / (np.hypot(*u.T) * np.hypot(*v.T))
    turn = np.degrees(np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1.0, 1.0)))
    turn[[0, -1]] = 0.0
    i = int(np.argmax(turn))
    if turn[i] <= max_turn:
        return [keep]
    return (_corners_cut(keep[:i + 1], coords, reach, max_turn)
            + _corners_cut(keep[i:], coords, reach, max_turn))


def _corners_left(pieces) -> list[tuple[int, int]]:
    """Links (``joining.chains_through``) of the pieces' ends that lie on one point: the two
    arms of a corner cut (``_corners_cut``) that are still free there."""
    free, links = {}, []
    for k, p in enumerate(pieces):
        for side, vertex in ((0, p[0][0]), (1, p[0][-1])):
            key = (float(vertex[0]), float(vertex[1]))
            if key in free:
                links.append((free.pop(key), 2 * k + side))
            else:
                free[key] = 2 * k + side
    return links


def _kinds(pieces) -> list[int]:
    """Per piece (coords, slopes, component, fit RMS, kink, ...): -1 a crest, +1 a toe (the median
    sign of its vertices' slope changes), 0 where no vertex was fitted."""
    return [int(np.sign(_median(p[4][~np.isnan(p[4])]))) if np.isfinite(p[4]).any() else 0
            for p in pieces]


def _second_traces_left_out(pieces, within: float, share: float) -> list:
    """The ``pieces`` (coords, slopes, component, fit RMS, kink, bridged) without those of
    which ``share`` of the vertices or more lie within ``within`` m of a longer piece of their
    kind (crest, toe; unknown goes with either): second traces of one kink."""
    if len(pieces) < 2:
        return pieces
    lines = np.array([shapely.LineString(p[0][:, :2]) for p in pieces], dtype=object)
    lengths = shapely.length(lines)
    kinds = np.array(_kinds(pieces))
    owner = np.repeat(np.arange(len(pieces)), [len(p[0]) for p in pieces])
    vertex, other = shapely.STRtree(lines).query(
        shapely.points(np.concatenate([p[0][:, :2] for p in pieces])), predicate="dwithin",
        distance=within)
    mine = owner[vertex]
    longer = (lengths[other] > lengths[mine]) | ((lengths[other] == lengths[mine])
                                                  & (other < mine))
    near = np.zeros(len(owner), bool)
    near[vertex[longer & (kinds[other] * kinds[mine] >= 0)]] = True
    second = np.bincount(owner, weights=near, minlength=len(pieces)) >= share * np.bincount(
        owner, minlength=len(pieces))
    return [p for p, drop in zip(pieces, second) if not drop]


def _fitted_span(coords: np.ndarray, fitted: np.ndarray, tail: float) -> tuple[int, int]:
    """(first, stop): a piece's vertices from its first fitted one to its last, where the
    unfitted run beyond either spans at most ``tail`` m (a longer one is the line's own traced
    course, and stays); the whole piece where fewer than two vertices would be left. The
    traced course beyond a piece's last kink found bends off the line with the noise (1-2 m at
    15 cm), so two pieces of one line, measured at their traced ends, lie too far apart across
    it to join."""
    n = len(coords)
    if not fitted.any():
        return 0, n
    along = distance_along(coords)
    first, last = np.flatnonzero(fitted)[[0, -1]]
    first = first if along[first] <= tail else 0
    stop = last + 1 if along[-1] - along[last] <= tail else n
    return (int(first), int(stop)) if stop - first >= 2 else (0, n)


def _tails_given_back(chains, spans, sizes) -> list:
    """``join_pieces``' ``chains`` of the pieces cut to their ``spans`` (``_fitted_span``), as
    chains of the whole pieces (``sizes`` vertices): each part shifted back onto its piece, and
    a chain's two free ends given back what was cut (an end that joined nothing keeps its
    traced course)."""
    out = []
    for chain in chains:
        parts = []
        for j, (k, reverse, first, stop) in enumerate(chain):
            shift = sizes[k] - spans[k][1] if reverse else spans[k][0]
            first, stop = (0 if j == 0 else first + shift,
                           sizes[k] if j == len(chain) - 1 else stop + shift)
            parts.append((k, reverse, first, stop))
        out.append(parts)
    return out


def _chained(pieces, chains) -> list[tuple]:
    """The ``pieces`` (coords, slopes, component, fit RMS, kink, bridged) joined as
    ``join_pieces``'s ``chains`` say: one piece per chain, its arrays the chain's parts end to
    end (a vertex that repeats the one before it, where a bridge meets its line, once)."""
    out = []
    for chain in chains:
        parts = [[(p[j][::-1] if reverse else p[j])[first:stop] for j in (0, 1, 3, 4, 5)]
                 for p, reverse, first, stop in ((pieces[k], *rest) for k, *rest in chain)]
        coords, slopes, fit, kink, bridged = (np.concatenate([part[j] for part in parts])
                                              for j in range(5))
        new = np.ones(len(coords), bool)  # False: a bridge's end
        new[1:] = (np.diff(coords[:, :2], axis=0) != 0).any(axis=1)
        repeated = np.flatnonzero(~new)
        bridged[repeated - 1] |= bridged[repeated]
        out.append((coords[new], slopes[new], min(pieces[k][2] for k, *_ in chain), fit[new],
                    kink[new], bridged[new]))
    return out


def _bridges_fitted(points: np.ndarray, window: FitWindow, s_crit: float, index,
                    tolerance: float, hold: float = BRIDGE_HOLD, progress=None, cancelled=None):
    """A ``make`` for ``joining.bridges``: each gap's chord, a vertex every half a hinge
    window along it, localised; a bridge where at least ``hold`` of those vertices find a kink
    of the line's kind (a crest across a channel's bed, a bank's toe across an embankment's
    slope), made of the ends and those vertices, thinned by Douglas–Peucker within
    ``tolerance`` m, else None (a channel cut through a levee: no crest on the bed).
    ``progress`` hears the share done (0–1) along the fits and the gaps, ``cancelled`` is
    polled on the way."""
    step = window.half_length

    def make(gaps):
        chords = []
        for a, b, _ in gaps:  # the ends too, for the chord's direction at every vertex
            n = max(1, int(np.hypot(*(b[:2] - a[:2])) / step))
            t = np.arange(n + 2)[:, None] / (n + 1)
            chords.append(a[None, :3] * (1 - t) + b[None, :3] * t)
        moved, fits, kinks = localise_breaklines(chords, points, window, s_crit=s_crit,
                                                 index=index, progress=part(progress, 0, 0.8),
                                                 cancelled=cancelled)
        out = []
        for (a, b, kind), coords, fit, kink in along(list(zip(gaps, moved, fits, kinks)),
                                                     part(progress, 0.8, 1.0), cancelled):
            coords, fit, kink = coords[1:-1], fit[1:-1], kink[1:-1]
            ok = np.isfinite(fit) & (np.sign(kink) == kind)
            if ok.mean() < hold:
                out.append(None)
                continue
            # where the fit failed (another feature's break crosses the window), the vertex
            # stays on the chord at the ground's height: a line left straight there would
            # carry the chord's z across the other feature
            coords[~ok, 2] = _ground_z(points, window, coords[~ok, :2], index)
            keep = ok | np.isfinite(coords[:, 2])
            fit[~ok] = kink[~ok] = np.nan
            nan = np.full(1, np.nan)
            coords = np.vstack([a[None, :3], coords[keep], b[None, :3]])
            fit, kink = (np.concatenate([nan, v[keep], nan]) for v in (fit, kink))
            # thinned as the traced lines are: a vertex every half window would hold the
            # mesh's smallest triangles where the bridge runs under water
            thin = douglas_peucker_mask(coords, tolerance)
            out.append((coords[thin], fit[thin], kink[thin]))
        return out

    return make


def _fitted_cut(pieces, tail: float) -> tuple[list, list]:
    """(each piece's ``_fitted_span`` within ``tail`` m, its coordinates cut to that span):
    the ends the joins and the bridges measure between."""
    spans = [_fitted_span(p[0], np.isfinite(p[3]), tail) for p in pieces]
    return spans, [p[0][first:stop] for p, (first, stop) in zip(pieces, spans)]


def _bridged(pieces, make, max_gap: float, lateral: float, tail: float) -> tuple[list, int]:
    """``pieces`` (as ``localise_traced`` keeps them) joined by ``joining.bridges`` across the
    gaps ``make`` (``_bridges_fitted``) bridges, measured between the pieces' ends cut to
    their fitted spans (``_fitted_span`` within ``tail`` m; 0: their traced ends), a chain's
    free ends given back what was cut; and how many bridges. A bridge's vertices are marked
    bridged (the mesh leaves them out on low ground) only where it crosses another feature:
    where it passes within ``lateral`` m of a piece other than the two it joins, or of another
    bridge of the pass (two features broken at their crossing, each bridged across the
    other). A bridge across a gap in a line's own run, where noise made the fits fail, is the
    line's."""
    spans, cut = _fitted_cut(pieces, tail)
    made = bridges(cut, _kinds(pieces), max_gap=max_gap, lateral=lateral, make=make)
    if not made:
        return pieces, 0
    # the pieces, then this pass's bridges in the order they are appended to them below
    others = shapely.STRtree([shapely.LineString(c[:, :2]) for c in
                              [p[0] for p in pieces] + [line[0] for line, _, _ in made]])
    pieces, links = list(pieces), []
    for (coords, fit, kink), start, stop in made:
        m = len(pieces)  # the bridge runs from the end ``start`` to the end ``stop``
        crossing = _crosses_another(others, coords, (start // 2, stop // 2, m), lateral)
        pieces.append((coords, np.full(len(coords), np.nan),
                       min(pieces[start // 2][2], pieces[stop // 2][2]), fit, kink,
                       np.full(len(coords), crossing)))
        spans.append((0, len(coords)))
        cut.append(coords)
        links += [(start, 2 * m), (2 * m + 1, stop)]
    return _chained(pieces, _tails_given_back(chains_through(cut, links), spans,
                                              [len(p[0]) for p in pieces])), len(made)


def _crosses_another(others, coords: np.ndarray, joined, within: float) -> bool:
    """Whether a bridge (``coords``) passes within ``within`` m of one of the lines in
    ``others`` (an STRtree of the pieces and bridges) but those in ``joined`` (its two pieces
    and itself, their indices)."""
    near = others.query(shapely.LineString(coords[:, :2]), predicate="dwithin", distance=within)
    return bool(np.isin(near, joined, invert=True).any())


def _resampled(coords: np.ndarray, step: float) -> np.ndarray:
    """x, y of a line every about ``step`` m along it, its ends included."""
    xy, along = coords[:, :2], distance_along(coords)
    at = np.linspace(0.0, along[-1], max(2, int(np.ceil(along[-1] / step)) + 1))
    return np.column_stack([np.interp(at, along, xy[:, 0]), np.interp(at, along, xy[:, 1])])


def _companions(pieces, points: np.ndarray, window: FitWindow, s_crit: float, index,
                tolerance: float, progress=None, cancelled=None) -> list[tuple]:
    """Pieces (as ``localise_traced`` keeps them) for the kinks that run beside a localised
    piece but that no line follows: the tracer follows one edge of a band of breakpoints, and
    where a crest and its toe (or a narrow embankment's two crests) lie a band's width apart
    the other kink goes untraced. Probes run parallel to each piece at ``COMPANION_PROBES``
    hinge-window half widths to each side (the window then holds none of the piece's own
    kink), a vertex every half a window length, and are localised; a run of at least
    ``COMPANION_RUN`` consecutive probe vertices that find a kink of one kind, each farther
    than ``COMPANION_APART`` half widths from every line and from the companions found before
    it, is a new piece, thinned by Douglas–Peucker within ``tolerance`` m. ``progress`` hears
    the share done (0–1) by stages and along the probes' fits, ``cancelled`` is polled on the
    way."""
    kinds = _kinds(pieces)
    hw = window.half_width
    apart = COMPANION_APART * hw
    lines = [p[0] for p in pieces]
    samples = [(k, _resampled(p[0], window.half_length)) for k, (p, kind)
               in enumerate(zip(pieces, kinds)) if kind]
    samples = [(k, xy, _tangents(xy)[:, ::-1] * (-1.0, 1.0)) for k, xy in samples
               if len(xy) >= COMPANION_RUN]
    if not samples:
        return []
    xy = np.concatenate([xy for _, xy, _ in samples])
    normal = np.concatenate([n for _, _, n in samples])

    # a side is probed only where no line runs 1.5 to 6.5 half widths from the piece (within
    # 2.5 of the point 4 out: the partner, a wide bank's other kink, is traced) and where the
    # ground between the probes lies above or below the line's by at least half of S_crit's
    # grade (a kink needs sloping ground beside it)
    free = [nearest_line(xy + side * 4.0 * hw * normal, lines)[1] > 2.5 * hw
            for side in (1.0, -1.0)]
    either = free[0] | free[1]
    base = _ground_z(points, window, xy[either], index)
    middle = float(np.mean(COMPANION_PROBES)) * hw
    for side, ok in zip((1.0, -1.0), free):
        rise = np.abs(_ground_z(points, window, xy[ok] + side * middle * normal[ok], index)
                      - base[ok[either]])
        ok[ok] = ~(rise <= 0.5 * np.tan(np.radians(s_crit)) * middle)
    report(progress, cancelled, 0.1)
    fitted, owners, start = [], [], 0
    for k, xy, normal in samples:
        stop = start + len(xy)
        for side, ok in zip((1.0, -1.0), free):
            for a, b in true_runs(ok[start:stop]):
                if b - a < COMPANION_RUN:
                    continue
                for reach in COMPANION_PROBES:
                    probe = xy[a:b] + side * reach * hw * normal[a:b]
                    fitted.append(np.column_stack([probe, np.full(b - a, np.nan)]))
                    owners.append(k)
        start = stop
    if not fitted:
        return []
    moved, fits, kinks = localise_breaklines(fitted, points, window, s_crit=s_crit,
                                             index=index, progress=part(progress, 0.1, 0.9),
                                             cancelled=cancelled)
    vertices = np.concatenate(moved)
    distance = nearest_line(vertices, lines)[1]
    runs, start = [], 0
    for k, coords, fit, kink in zip(owners, moved, fits, kinks):
        ok = np.isfinite(fit) & (distance[start:start + len(coords)] > apart)
        start += len(coords)
        sign = np.sign(np.nan_to_num(kink))
        for kind in (-1.0, 1.0):
            for a, b in true_runs(ok & (sign == kind)):
                if b - a >= COMPANION_RUN:
                    runs.append((k, coords[a:b], fit[a:b], kink[a:b]))
    out, found = [], []
    for k, coords, fit, kink in along(sorted(runs, key=lambda r: -len(r[1])),
                                      part(progress, 0.9, 1.0), cancelled):
        if found:
            d = shapely.distance(shapely.points(coords[:, :2]), shapely.multilinestrings(found))
            keep = d > apart
            if keep.sum() < COMPANION_RUN:
                continue
            first, stop = max(true_runs(keep), key=lambda r: r[1] - r[0])
            if stop - first < COMPANION_RUN:
                continue
            coords, fit, kink = coords[first:stop], fit[first:stop], kink[first:stop]
        thin = douglas_peucker_mask(coords, tolerance)
        found.append(shapely.LineString(coords[:, :2]))
        out.append((coords[thin], np.full(int(thin.sum()), np.nan), pieces[k][2], fit[thin],
                    kink[thin], np.zeros(int(thin.sum()), bool)))
    return out


def localise_traced(lines: list, points: np.ndarray, window: FitWindow, *,
                    s_crit: float = 10.0, tolerance: float = 0.1,
                    max_gap: float = 12.0, join_gap: float | None = None,
                    join_lateral: float = 1.0, bridge_gap: float | None = None,
                    cell_size: float = 1.0, index=None, note=None, progress=None,
                    cancelled=None) -> tuple[list, list[float], dict]:
    """``localise_breaklines`` on BreakLines, then each line thinned: vertices the fit did not
    move are dropped where that leaves no gap over ``max_gap`` m and, between crests, moves the
    line by no more than ``UNMOVED_LATERAL`` cells (``cell_size`` m) in plan
    (``_failed_fits_left_out``), and Douglas–Peucker within
    ``tolerance`` m (horizontal and vertical) keeps what the smooth, localised line needs; lines
    are cut where they hop across a band from crest to toe (``_hops_cut``) and where they turn
    a corner (``_corners_cut``), kinks beside the pieces that no line follows become pieces of
    their own (``_companions``), and pieces of one kind (crest or toe) whose ends face each
    other across at most ``join_gap`` m are joined (``joining.join_pieces``, lateral offset
    ``join_lateral`` m, measured between the pieces' fitted ends: ``_fitted_span``; None or 0:
    no joining); the gaps left of up to ``bridge_gap`` m where the terrain carries the line's
    kink across (a crossing, a junction: ``joining.bridges``, ``_bridges_fitted``) are
    bridged, between the traced ends and then between the fitted ends of those still free
    (``_bridged``, ``BRIDGE_TAIL_CELLS``; marked bridged where they cross another line); a
    second trace of a kink a longer line follows is left out (``_second_traces_left_out``);
    line ends that stop within ``join_lateral`` plus a tenth of ``join_gap`` m of another
    line's interior, pointing at it at its height (within ``tolerance`` m plus a rise at
    ``s_crit``), are snapped onto it
    (``joining.snap_t_junctions``). Returns the BreakLines, each line's confidence (the
    median fit RMS residual of its vertices, m; NaN where none moved) and counts. ``index``:
    ``nearest.point_index(points)`` if built. ``lines`` may be (k, 3) arrays
    (``as_breaklines``); points as for ``fit_node_elevations``. ``progress`` hears the share
    done (0–1) along the fits, then by stages, ``cancelled`` is polled on the way."""
    lines = as_breaklines(lines, "line")
    points, index = _measured(points, index, note)
    index = index if index is not None else point_index(points)  # one for both uses below
    lateral = UNMOVED_LATERAL * cell_size  # the grid's cell (m)
    moved, confidence, kinks = localise_breaklines([line.coords for line in lines], points,
                                                   window, s_crit=s_crit, index=index,
                                                   progress=part(progress, 0.0, 0.5),
                                                   cancelled=cancelled)
    pieces, hops = [], 0  # (coords, slopes, component, fit RMS, kink, bridged) per piece
    for line, coords, fit, kink in along(list(zip(lines, moved, confidence, kinks)),
                                         part(progress, 0.5, 0.6), cancelled):
        fitted = _failed_fits_left_out(coords, np.isfinite(fit), max_gap, lateral, kink)
        keep = np.nonzero(fitted)[0][douglas_peucker_mask(coords[fitted], tolerance)]
        for piece in (corner for hop in _hops_cut(keep, kink)
                      for corner in _corners_cut(hop, coords, CORNER_REACH * window.half_width,
                                                   CORNER_TURN)):
            hops += 1
            if len(piece) >= 2:
                pieces.append((coords[piece], line.slopes[piece], line.component, fit[piece],
                               kink[piece], np.zeros(len(piece), bool)))
        hops -= 1
    companions = _companions(pieces, points, window, s_crit, index, tolerance,
                             part(progress, 0.6, 0.75), cancelled)
    pieces += companions
    report(progress, cancelled, 0.75)
    joined = len(pieces)
    if join_gap:  # measured between the pieces' fitted ends
        spans, cut = _fitted_cut(pieces, JOIN_TAIL_CELLS * cell_size)
        pieces = _chained(pieces, _tails_given_back(join_pieces(
            cut, _kinds(pieces), max_gap=join_gap, lateral=join_lateral,
            ground=_ground_follows(points, window, index=index)), spans,
            [len(p[0]) for p in pieces]))
    joined -= len(pieces)
    report(progress, cancelled, 0.85)
    n_bridges = 0
    if join_gap and bridge_gap:  # between the traced ends, then the fitted ends of the rest
        for k, tail in enumerate((0.0, BRIDGE_TAIL_CELLS * cell_size)):
            make = _bridges_fitted(points, window, s_crit, index, tolerance,
                                   progress=part(progress, 0.85 + 0.05 * k, 0.9 + 0.05 * k),
                                   cancelled=cancelled)
            pieces, made = _bridged(pieces, make, bridge_gap, join_lateral, tail)
            n_bridges += made
    report(progress, cancelled, 0.95)
    # a corner where neither arm joined or bridged anything is no use cut: the line as traced
    corners = _corners_left(pieces)
    if corners:
        pieces = _chained(pieces, chains_through([p[0] for p in pieces], corners))
    traced = len(pieces)
    pieces = _second_traces_left_out(pieces, SECOND_TRACE_WITHIN * cell_size,
                                     SECOND_TRACE_SHARE)
    out = [BreakLine(coords, slopes, component, bridged if bridged.any() else None)
           for coords, slopes, component, _, _, bridged in pieces]
    per_line = [_median(p[3][~np.isnan(p[3])]) if np.isfinite(p[3]).any() else float("nan")
                for p in pieces]
    t_junctions = 0
    if join_gap and out:
        snapped, takes, t_junctions = snap_t_junctions(
            [line.coords for line in out], tolerance=join_lateral + 0.1 * join_gap,
            rise=tolerance, grade=float(np.tan(np.radians(s_crit))))
        out = [BreakLine(c, line.slopes[take], line.component,
                         None if line.bridged is None else line.bridged[take])
               for c, take, line in zip(snapped, takes, out)]
    every = np.concatenate(confidence) if confidence else np.zeros(0)
    done = np.isfinite(every)
    report(progress, None, 1.0)
    return out, per_line, {"vertices": int(every.size), "vertices_localised": int(done.sum()),
                           "vertices_kept": int(sum(len(line.coords) for line in out)),
                           "hop_segments_cut": hops,
                           "pieces_joined": joined,
                           "gaps_bridged": n_bridges,
                           "companions_found": len(companions),
                           "second_traces_left_out": traced - len(pieces),
                           "t_junctions_snapped": t_junctions,
                           "join_gap_m": join_gap or 0.0,
                           "thinning_tolerance_m": tolerance,
                           "median_fit_rms_m": float(np.median(every[done])) if done.any()
                           else None}
