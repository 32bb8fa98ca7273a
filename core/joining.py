"""Break-line pieces joined end to end into continuous lines, after localisation.

The tracer ends a line wherever the slope's continuity rule fails, and with noisy points it
fails mid-run: at 15 cm noise on the benchmark floodplains most breaks between the pieces of one
true line are gaps of 0–5 m (or short overlaps) along a straight run, not junctions (see
``benchmarks/fidelity.py --breaks``). Two ends are joined where they face each other: each end's
direction (its chord over the last ``reach`` m) within ``max_turn`` of the other's reversed, the
gap at most ``max_gap`` m along their mean direction (an overlap of up to ``max_gap``/2 is
trimmed at the midpoint), the lateral offset at most ``lateral`` m plus a tenth of the gap, and
both of one kind (a crest joins no toe), and, if ``ground`` is given, the ground along the gap
following the straight line between the two ends' z (a channel cut through an embankment, a
tributary's mouth in a river bank, breaks the line: there the terrain has no break to join).
Cheapest joins (short, straight) first; no end joins twice and no chain closes on itself.
"""
from __future__ import annotations

import numpy as np


def _end_frame(coords: np.ndarray, at_start: bool, reach: float):
    """(end point, outward unit direction) of a line's end: the chord over ``reach`` m."""
    xy = coords[:, :2] if not at_start else coords[::-1, :2]
    step = np.hypot(*np.diff(xy, axis=0).T)
    back = np.r_[0.0, np.cumsum(step[::-1])]  # distance back from the end
    k = min(int(np.searchsorted(back, reach)), len(xy) - 1)
    chord = xy[-1] - xy[len(xy) - 1 - k]
    norm = np.hypot(*chord)
    return xy[-1], (chord / norm if norm > 0 else None)


def join_pieces(lines, kinds=None, *, max_gap: float, lateral: float, max_turn: float = 30.0,
                reach: float | None = None, ground=None
                ) -> list[list[tuple[int, bool, int, int]]]:
    """Chains of ``lines`` ((k, 2+) arrays) joined as the module says; ``kinds`` per line
    (-1 crest, +1 toe, 0 unknown; None: all unknown); ``ground(a, b)``, for two end points
    (x, y, z), says whether the terrain between them follows the line (None: not checked).
    Returns one chain per output line: a list
    of (line index, reversed, first, stop), i.e. ``lines[i][::-1 if reversed][first:stop]`` in
    order; every line appears in exactly one chain."""
    from scipy.spatial import cKDTree

    n = len(lines)
    kinds = np.zeros(n, int) if kinds is None else np.asarray(kinds, int)
    reach = 2 * max_gap if reach is None else reach
    points, directions, owners, ends = [], [], [], []
    for i, c in enumerate(lines):
        c = np.asarray(c, float)
        for side in (0, 1):  # 0: the line's start, 1: its end
            p, d = _end_frame(c, side == 0, reach) if len(c) >= 2 else (None, None)
            if d is not None:
                ends.append(c[0 if side == 0 else -1])
                points.append(p)
                directions.append(d)
                owners.append(2 * i + side)
    if len(points) < 2:
        return [[(i, False, 0, len(c))] for i, c in enumerate(lines)]
    points, directions, owners = np.array(points), np.array(directions), np.array(owners)
    cos_turn = np.cos(np.radians(max_turn))
    candidates = []
    for a, b in cKDTree(points).query_pairs(max_gap + lateral):
        ea, eb = owners[a], owners[b]
        if ea // 2 == eb // 2 or kinds[ea // 2] * kinds[eb // 2] < 0:
            continue
        da, db = directions[a], directions[b]
        if -(da @ db) < cos_turn:
            continue
        mean = da - db
        mean /= np.hypot(*mean)
        chord = points[b] - points[a]
        along, across = chord @ mean, abs(chord[0] * mean[1] - chord[1] * mean[0])
        if along > max_gap or along < -max_gap / 2 or across > lateral + 0.1 * max(along, 0.0):
            continue
        if ground is not None and not ground(ends[a], ends[b]):
            continue
        candidates.append((max(along, 0.0) + 2 * across + (1 + da @ db) * max_gap, a, b, mean))
    candidates.sort(key=lambda t: t[0])
    partner = {}
    joint = {}  # end -> (midpoint, direction from the end's line into the partner's)
    root = list(range(n))

    def find(i):
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    for _, a, b, mean in candidates:
        ea, eb = owners[a], owners[b]
        if ea in partner or eb in partner:
            continue
        ra, rb = find(ea // 2), find(eb // 2)
        if ra == rb:
            continue
        root[max(ra, rb)] = min(ra, rb)
        partner[ea], partner[eb] = eb, ea
        mid = 0.5 * (points[a] + points[b])
        joint[ea], joint[eb] = (mid, mean), (mid, -mean)
    chains, done = [], np.zeros(n, bool)
    for i in range(n):
        if done[i] or (2 * i in partner and 2 * i + 1 in partner):
            continue
        end = 2 * i if 2 * i not in partner else 2 * i + 1  # start the chain at a free end
        chain = []
        while True:
            k = end // 2
            done[k] = True
            c = np.asarray(lines[k], float)
            reverse = end % 2 == 1  # entered at its end: walk it backwards
            ordered = c[::-1] if reverse else c
            first, stop = 0, len(c)
            far = end + 1 if end % 2 == 0 else end - 1
            if end in joint:  # trim what lies beyond the joint's midpoint
                mid, into = joint[end]
                while stop - first > 2 and (ordered[first, :2] - mid) @ into > 0:
                    first += 1
            if far in joint:
                mid, into = joint[far]
                while stop - first > 2 and (ordered[stop - 1, :2] - mid) @ into > 0:
                    stop -= 1
            chain.append((k, bool(reverse), first, stop))
            if far not in partner:
                break
            end = partner[far]
        chains.append(chain)
    for i in np.nonzero(~done)[0]:  # closed loops cannot occur (no cycles), but be safe
        chains.append([(int(i), False, 0, len(lines[i]))])
    return chains
