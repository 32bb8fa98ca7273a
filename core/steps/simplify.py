"""Break-line simplification within a tolerance α·Δ (Δ = d/2, the scale of detail).

Three methods per line: keep every n-th point, Douglas–Peucker, and a cubic smoothing spline.
``simplify_breaklines`` is what the chain uses: it simplifies each line, then keeps the set a
valid PSLG: a simplified segment that crosses another line (or its own) gets back the original
vertices it skipped until it no longer does, parts of a line closer than ``min_distance`` to a
longer line are merged into it (dropped; the segments reaching them get back the vertices
they skipped, so that only that part goes), and vertices closer than ``min_distance`` to the
previous one on their line are dropped. Those merges trade the tolerance for a valid mesh
input: an original vertex next to a merge may lie up to tolerance + ``min_distance`` from the
result (the chain reports the largest deviation it finds).
"""
from __future__ import annotations

import numpy as np
import shapely

from ..engine.arrays import distance_along
from ..engine.nearest import nearest_line
from ..engine.progress import along, part, poll, report
from ..options import (SIMPLIFY_METHODS, check_choice, check_min_distance, check_positive_int,
                       check_tolerance)
from .breaklines import BreakLine, as_breaklines


def simplify_keep_every(lines: list[BreakLine], n: int) -> list[BreakLine]:
    """Keep every ``n``-th point of each line, and always both ends."""
    n = check_positive_int(n, "keep-every")
    out = []
    for line in as_breaklines(lines, "line"):
        keep = _keep_every_mask(len(line.coords), int(n))
        out.append(BreakLine(line.coords[keep], line.slopes[keep], line.component))
    return out


def simplify_douglas_peucker(lines: list[BreakLine], tolerance: float) -> list[BreakLine]:
    """Douglas–Peucker: no dropped point lies farther than ``tolerance`` (m) from the simplified
    line, horizontally or vertically."""
    tolerance = check_tolerance(tolerance)
    out = []
    for line in as_breaklines(lines, "line"):
        keep = douglas_peucker_mask(line.coords, tolerance)
        out.append(BreakLine(line.coords[keep], line.slopes[keep], line.component))
    return out


def douglas_peucker_mask(coords: np.ndarray, tolerance: float,
                         rank: np.ndarray | None = None) -> np.ndarray:
    """Boolean mask of the vertices Douglas–Peucker keeps (horizontal and vertical deviation;
    ``coords`` (k, 3), or (k, 2): in plan alone).

    With ``rank`` (an integer per vertex, lower preferred), a stretch with a vertex farther
    than ``tolerance`` (m) from its chord is split at the farthest of its vertices of the lowest
    rank it holds rather than at its farthest vertex: the kept line bends at preferred vertices
    where it can, and every dropped vertex still lies within ``tolerance`` of it."""
    # lazy: numba loads only where lines are simplified
    from .._kernels.simplify import douglas_peucker_keep

    coords = np.ascontiguousarray(coords, dtype=np.float64)
    if coords.ndim == 2 and coords.shape[1] == 2:  # the kernel reads a height: none here
        coords = np.column_stack([coords, np.zeros(len(coords))])
    if len(coords) < 2:
        return np.ones(len(coords), bool)
    ranked = rank is not None
    rank = np.ascontiguousarray(rank, dtype=np.int64) if ranked else np.zeros(1, np.int64)
    return douglas_peucker_keep(coords, float(tolerance), rank, ranked)


def _deviation(a, b, pts):
    """Horizontal distance of ``pts`` to segment a–b and their z departure from it there."""
    ab = b[:2] - a[:2]
    length2 = float(ab @ ab)
    if length2 == 0:
        t = np.zeros(len(pts))
    else:
        t = np.clip(((pts[:, :2] - a[:2]) @ ab) / length2, 0.0, 1.0)
    foot = a[:2] + t[:, None] * ab
    horizontal = np.hypot(*(pts[:, :2] - foot).T)
    vertical = np.abs(pts[:, 2] - (a[2] + t * (b[2] - a[2])))
    vertical = np.where(np.isfinite(vertical), vertical, 0.0)
    return horizontal, vertical


def max_deviation(original: list[BreakLine], simplified: list[BreakLine]) -> float:
    """Largest horizontal distance (m) from an original vertex to the nearest simplified line."""
    kept = [line.coords for line in simplified if len(line.coords) > 1]
    if not original or not kept:
        return 0.0
    _, distance = nearest_line(np.concatenate([line.coords[:, :2] for line in original]), kept)
    return float(distance.max())


def simplify_breaklines(lines: list[BreakLine], method: str, amount: float, *,
                        min_distance: float = 0.0, progress=None,
                        cancelled=None) -> list[BreakLine]:
    """Simplify ``lines`` (BreakLines, or (k, 3) arrays: ``as_breaklines``) by ``method``
    ("keep-every": every ``amount``-th point;
    "douglas-peucker" or "spline": within ``amount`` metres), then repair crossings and merge
    slivers and near-duplicate vertices closer than ``min_distance`` metres (see the module
    docstring). ``progress`` hears the share done line by line, then by stages (crossings
    repaired, slivers merged); ``cancelled`` is polled on the way."""
    check_choice(method, SIMPLIFY_METHODS, "simplification")
    min_distance = check_min_distance(min_distance)
    lines = as_breaklines(lines, "line")
    if method == "keep-every":
        amount = check_positive_int(amount, "keep-every")
    else:
        amount = check_tolerance(amount)
    plan = {"keep-every": lambda c: (c, _keep_every_mask(len(c), amount)),
            "douglas-peucker": lambda c: (c, douglas_peucker_mask(c, amount)),
            "spline": lambda c: spline_plan(c, amount)}[method]
    plans = [plan(line.coords) for line in along(lines, part(progress, 0.0, 0.7), cancelled)]
    positions = [p.copy() for p, _ in plans]
    masks = [m.copy() for _, m in plans]
    _repair_crossings(lines, positions, masks, cancelled=cancelled)
    merged = _restore_beside_merges(lines, positions, masks, min_distance, cancelled)
    report(progress, cancelled, 0.9)
    separate = _separate(lines, positions, masks, merged, min_distance)
    report(progress, None, 1.0)
    return separate


def spline_plan(coords: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Cubic smoothing spline through x(s), y(s), z(s) (s: distance along the line), as smooth
    as keeps every vertex within ``tolerance``/2 of its own position in plan and in z, ends
    fixed; then Douglas–Peucker within ``tolerance``/2 on the smoothed vertices. Returns the
    smoothed positions and the mask of vertices kept: every original vertex lies within
    ``tolerance`` of the simplified line, horizontally and vertically."""
    # lazy: SciPy loads only when this runs
    from scipy.interpolate import make_smoothing_spline

    coords = np.asarray(coords, float)
    half = tolerance / 2
    if len(coords) < 5 or not np.isfinite(coords).all():
        return coords, douglas_peucker_mask(coords, tolerance)
    s = distance_along(coords)
    scale = (s[-1] / len(s)) ** 3  # lam is in units of spacing³

    def smoothed(lam):
        out = np.column_stack([make_smoothing_spline(s, coords[:, k], lam=lam)(s)
                               for k in range(3)])
        out[0], out[-1] = coords[0], coords[-1]
        return out

    def within(p):
        return (np.hypot(*(p[:, :2] - coords[:, :2]).T).max() <= half
                and np.abs(p[:, 2] - coords[:, 2]).max() <= half)

    best = coords
    lo, hi = np.log(1e-4 * scale), np.log(1e4 * scale)
    for _ in range(14):  # bisection on log(lam) for the smoothest spline within the bound
        mid = (lo + hi) / 2
        candidate = smoothed(np.exp(mid))
        if within(candidate):
            best, lo = candidate, mid
        else:
            hi = mid
    return best, douglas_peucker_mask(best, half)


def _keep_every_mask(n_points: int, n: int) -> np.ndarray:
    keep = np.zeros(n_points, bool)
    keep[::n] = True
    keep[-1] = True
    return keep


def _kept_lines(positions, masks) -> np.ndarray:
    lines = [shapely.LineString(p[m][:, :2]) if m.sum() >= 2 else shapely.LineString()
             for p, m in zip(positions, masks)]
    return np.array(lines + [None], dtype=object)[:-1]  # an object array even when empty


def _repair_crossings(lines, positions, masks, max_rounds=1000, cancelled=None):
    """Give simplified segments that cross another line (or their own) back the original
    vertex they skipped that lies farthest from them, or, on a segment between neighbouring
    vertices, the original positions, until nothing crosses that the originals did not;
    ``cancelled`` polled each round."""
    for _ in range(max_rounds):
        poll(cancelled)
        geoms = _kept_lines(positions, masks)
        # the pairs that touch, then those that cross, overlap or contain (collinear, inside)
        # among them: one query instead of one per predicate
        a, b = shapely.STRtree(geoms).query(geoms, predicate="intersects")
        a, b = a[a != b], b[a != b]
        ga, gb = geoms[a], geoms[b]
        hit = shapely.crosses(ga, gb) | shapely.overlaps(ga, gb) | shapely.contains(ga, gb)
        pairs = {(int(i), int(j)) for i, j in zip(a[hit], b[hit])}
        pairs |= {(j, i) for i, j in pairs}
        pairs |= {(int(i), int(i)) for i in np.flatnonzero(~shapely.is_empty(geoms)
                                                           & ~shapely.is_simple(geoms))}
        changed = False
        for i, j in sorted(pairs):
            changed |= _refine_where(lines[i].coords, positions[i], masks[i],
                                     geoms[j] if i != j else None)
        if not changed:
            return


def _refine_where(original, position, mask, other) -> bool:
    """Refine the kept segments of one line that cross ``other`` (None: the line itself)."""
    kept = np.flatnonzero(mask)
    segments = shapely.linestrings(np.stack([position[kept[:-1], :2], position[kept[1:], :2]],
                                            axis=1))
    if other is None:  # segments meeting non-adjacent segments, or folding back on the next
        tree = shapely.STRtree(segments)
        u, v = tree.query(segments, predicate="intersects")
        apart = np.abs(u - v)
        folded = (apart == 1) & (shapely.length(shapely.intersection(segments[u],
                                                                     segments[v])) > 0)
        hit = np.unique(u[(apart > 1) | folded])
    else:
        shared = shapely.length(shapely.intersection(segments, other)) > 0  # collinear parts
        hit = np.flatnonzero(shapely.crosses(segments, other) | shared)
    changed = False
    for k in hit:
        a, b = kept[k], kept[k + 1]
        if b - a > 1:
            horizontal, vertical = _deviation(position[a], position[b], position[a + 1:b])
            mask[a + 1 + int(np.argmax(np.maximum(horizontal, vertical)))] = True
            changed = True
        elif not np.array_equal(position[a:b + 1], original[a:b + 1]):
            position[a:b + 1] = original[a:b + 1]
            changed = True
    return changed


def _restore_beside_merges(lines, positions, masks, min_distance,
                           cancelled=None) -> list[np.ndarray]:
    """Give a simplified segment from a kept vertex to one merged into a longer line
    (``_merged``) back the original vertices it skipped, so that only the part of the line
    within ``min_distance`` of the longer one merges, not the whole segment (a line's last
    segment to a T-junction was dropped, its far end metres from any line); crossings that
    brings are repaired as the simplification's (``_repair_crossings``). Returns ``_merged``
    of the vertices then kept."""
    for _ in range(10):
        changed = False
        merged = _merged(positions, masks, min_distance)
        for mask, near in zip(masks, merged):
            kept = np.flatnonzero(mask)
            edge = near[:-1] != near[1:]
            for a, b in zip(kept[:-1][edge], kept[1:][edge]):
                if b - a > 1:
                    mask[a + 1:b] = True
                    changed = True
        if not changed:
            return merged
        _repair_crossings(lines, positions, masks, cancelled=cancelled)
    return _merged(positions, masks, min_distance)


def _merged(positions, masks, min_distance) -> list[np.ndarray]:
    """Per line, which of its kept vertices lie within ``min_distance`` of a longer line (they
    merge into it)."""
    geoms = _kept_lines(positions, masks)
    near = [np.zeros(int(m.sum()), bool) for m in masks]
    if min_distance > 0 and len(geoms):
        rank = np.empty(len(geoms), int)
        rank[np.argsort(-shapely.length(geoms), kind="stable")] = \
            np.arange(len(geoms))
        # every line's kept vertices in one query (one per line was 0.2 s on 500 lines),
        # against the lines' segments, each its own geometry: a point's distance to a segment
        # is one formula, to a whole line a pass over all its vertices (0.24 s on 500 lines)
        counts = [len(n) for n in near]
        owner = np.repeat(np.arange(len(near)), counts)
        kept = np.concatenate([p[m][:, :2] for p, m in zip(positions, masks)])
        first = np.flatnonzero(owner[:-1] == owner[1:])  # segment starts
        segments = shapely.linestrings(np.stack([kept[first], kept[first + 1]], axis=1))
        v, s = shapely.STRtree(segments).query(shapely.points(kept), predicate="dwithin",
                                               distance=min_distance)
        merged = np.zeros(len(kept), bool)
        merged[v[rank[owner[first[s]]] < rank[owner[v]]]] = True
        near = np.split(merged, np.cumsum(counts)[:-1])
    return near


def _separate(lines, positions, masks, merged, min_distance) -> list[BreakLine]:
    """Split off the kept vertices that lie within ``min_distance`` of a longer line (merged
    into it: ``merged``, as ``_merged`` gives it), drop vertices within ``min_distance`` of the
    previous one, and build the lines."""
    out = []
    for line, p, m, drop in zip(lines, positions, masks, merged):
        idx = np.flatnonzero(m)
        # runs of consecutive kept vertices that are not merged into a longer line
        breaks = np.flatnonzero(drop)
        for run in np.split(np.arange(len(idx)), breaks):
            run = run[~drop[run]]
            if len(run) < 2:
                continue
            keep = _spaced(p[idx[run]], min_distance)
            coords = p[idx[run]][keep]
            out.append(BreakLine(coords, line.slopes[idx[run]][keep], line.component))
    return out


def _spaced(coords: np.ndarray, min_distance: float) -> np.ndarray:
    """The indices of the vertices kept when interior vertices closer than ``min_distance``
    (plan) to the previous kept one are dropped; both ends stay (the last kept inner vertex
    closer than that to the end gives way to it)."""
    # lazy: numba loads only when this runs
    from .._kernels.lines import thinned

    coords = np.ascontiguousarray(coords, float)
    if min_distance <= 0 or len(coords) <= 2:
        return np.arange(len(coords))
    return thinned(coords, np.full(len(coords), float(min_distance)), False, 0.0, 0.0, 0.0)
