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
Where a feature crosses a line (a road over a channel's banks, a levee meeting an embankment),
the tracer stops the line on either side, where the breakpoints of both run together; the
terrain there does not follow the straight line between the ends, but the line's kink runs on
across the other feature. ``bridges`` offers such gaps, up to a longer ``max_gap``, to a
terrain check of the caller's (localisation's hinge fits along the gap) that makes the line
across them.
After that, ``snap_t_junctions`` snaps an end that stops within about a cell of another line's
interior, pointing at it at its height, onto it as a shared node (a T-junction); crossings are
noded by ``mesh.build_pslg``.
"""
from __future__ import annotations

import numpy as np

from ..engine.arrays import distance_along


def _end_frame(coords: np.ndarray, at_start: bool, reach: float):
    """(end point, outward unit direction) of a line's end: the chord over ``reach`` m."""
    xy = coords[:, :2] if not at_start else coords[::-1, :2]
    back = distance_along(xy[::-1])  # distance back from the end
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
    n = len(lines)
    kinds = np.zeros(n, int) if kinds is None else np.asarray(kinds, int)
    reach = 2 * max_gap if reach is None else reach
    points, directions, owners, ends = _line_ends(lines, reach)
    if len(points) < 2:
        return [[(i, False, 0, len(c))] for i, c in enumerate(lines)]
    points, directions, owners = np.array(points), np.array(directions), np.array(owners)
    candidates = _facing_ends(points, directions, owners, ends, kinds, max_gap=max_gap,
                              lateral=lateral, max_turn=max_turn, ground=ground)
    partner, joint = _chosen_joins(candidates, points, owners, n)
    return _joined_chains(lines, partner, joint)


def bridges(lines, kinds, *, max_gap: float, lateral: float, make, max_turn: float = 20.0,
            reach: float | None = None) -> list[tuple]:
    """Lines across the gaps where a crossing or a junction broke a line: for two ends of one
    kind (crest or toe, not unknown) of different ``lines`` that face each other across at
    most ``max_gap`` m (as ``join_pieces`` rules, with ``lateral`` and ``max_turn``),
    ``make(gaps)`` gets every such gap as (a, b, kind) (the two end vertices (x, y, z), -1
    crest or +1 toe) and gives for each the line from ``a`` to ``b`` where the terrain carries
    the break across, else None. Cheapest gaps first, no end twice, no chain closed on itself.
    Returns per bridge (what ``make`` gave, the end it starts at, the end it stops at), ends
    numbered 2·line (a line's start) and 2·line + 1 (its end): ``chains_through``'s links."""
    kinds = np.asarray(kinds, int)
    reach = 2 * max_gap if reach is None else reach
    points, directions, owners, ends = _line_ends(lines, reach)
    if len(points) < 2:
        return []
    points, directions, owners = np.array(points), np.array(directions), np.array(owners)
    gaps = [(c, kinds[owners[c[1]] // 2] or kinds[owners[c[2]] // 2])
            for c in _facing_ends(points, directions, owners, ends, kinds, max_gap=max_gap,
                                  lateral=lateral, max_turn=max_turn, ground=None)]
    gaps = [(c, kind) for c, kind in gaps if kind]
    made = make([(ends[c[1]], ends[c[2]], kind) for c, kind in gaps]) if gaps else []
    found = [(c, line) for (c, _), line in zip(gaps, made) if line is not None]
    # the joins' own choice among the gaps the terrain bridges: cheapest first, no end twice,
    # no chain closed on itself
    partner, _ = _chosen_joins([c for c, _ in found], points, owners, len(lines))
    return [(line, int(owners[a]), int(owners[b])) for (_, a, b, _), line in found
            if partner.get(owners[a]) == owners[b]]


def chains_through(lines, links) -> list[list[tuple[int, bool, int, int]]]:
    """Chains of ``lines`` joined end to end where ``links`` say: pairs of ends that lie on one
    vertex (ends numbered 2·line for a line's start, 2·line + 1 for its end), nothing trimmed.
    Returns chains as ``join_pieces`` does."""
    partner, joint = {}, {}
    for a, b in links:
        partner[a], partner[b] = b, a
        joint[a] = joint[b] = (np.zeros(2), np.zeros(2))  # no direction: nothing beyond it
    return _joined_chains(lines, partner, joint)


def _line_ends(lines, reach: float):
    """The ends of ``lines`` that have a direction: per end, its point and outward direction
    (``_end_frame``), its owner (2·line for a line's start, 2·line + 1 for its end) and its
    vertex (x, y, z)."""
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
    return points, directions, owners, ends


def _facing_ends(points, directions, owners, ends, kinds, *, max_gap: float, lateral: float,
                 max_turn: float, ground):
    """The possible joins, cheapest first: (cost, end a, end b, their mean direction from a
    towards b) for every two ends of different lines, not a crest and a toe, that face each
    other across a gap (or overlap) the module allows, over ground that follows the line."""
    # lazy: SciPy loads only when this runs
    from scipy.spatial import cKDTree

    pairs = cKDTree(points).query_pairs(max_gap + lateral, output_type="ndarray")
    a, b = pairs.T if len(pairs) else (np.zeros(0, int), np.zeros(0, int))
    line_a, line_b = owners[a] // 2, owners[b] // 2
    da, db = directions[a], directions[b]
    facing = -(da * db).sum(axis=1)
    ok = (line_a != line_b) & (kinds[line_a] * kinds[line_b] >= 0)
    ok &= facing >= np.cos(np.radians(max_turn))
    mean = da - db
    mean /= np.maximum(np.hypot(*mean.T), 1e-12)[:, None]
    chord = points[b] - points[a]
    along = (chord * mean).sum(axis=1)
    across = np.abs(chord[:, 0] * mean[:, 1] - chord[:, 1] * mean[:, 0])
    ok &= (along <= max_gap) & (along >= -max_gap / 2)
    ok &= across <= lateral + 0.1 * np.maximum(along, 0.0)
    cost = np.maximum(along, 0.0) + 2 * across + (1 - facing) * max_gap
    candidates = [(cost[k], a[k], b[k], mean[k]) for k in np.flatnonzero(ok)
                  if ground is None or ground(ends[a[k]], ends[b[k]])]
    candidates.sort(key=lambda t: t[0])
    return candidates


def _chosen_joins(candidates, points, owners, n: int):
    """The joins made, in the order of ``candidates``: no end joins twice and no chain of the
    ``n`` lines closes on itself. Returns per joined end (owner number) its partner, and its
    joint: (midpoint, direction from the end's line into the partner's)."""
    partner = {}
    joint = {}
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
    return partner, joint


def _joined_chains(lines, partner, joint):
    """The chains of joined lines, each walked from a free end, as ``join_pieces`` returns them;
    an overlap at a joint trimmed at its midpoint."""
    n = len(lines)
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
            far = end + 1 if end % 2 == 0 else end - 1
            first, stop = _span_within_joints(c[::-1] if reverse else c, joint.get(end),
                                              joint.get(far))
            chain.append((k, bool(reverse), first, stop))
            if far not in partner:
                break
            end = partner[far]
        chains.append(chain)
    for i in np.nonzero(~done)[0]:  # closed loops cannot occur (no cycles), but be safe
        chains.append([(int(i), False, 0, len(lines[i]))])
    return chains


def _span_within_joints(ordered, entry_joint, exit_joint):
    """(first, stop): the vertices of a line (in walking order) short of the midpoints of its
    joints at entry and exit ((midpoint, direction into the partner), or None), at least two."""
    first, stop = 0, len(ordered)
    if entry_joint is not None:  # trim what lies beyond the joint's midpoint
        mid, into = entry_joint
        while stop - first > 2 and (ordered[first, :2] - mid) @ into > 0:
            first += 1
    if exit_joint is not None:
        mid, into = exit_joint
        while stop - first > 2 and (ordered[stop - 1, :2] - mid) @ into > 0:
            stop -= 1
    return first, stop


def snap_t_junctions(lines, *, tolerance: float, min_angle: float = 30.0,
                     rise: float = 0.1, grade: float = 0.18, reach: float | None = None
                     ) -> tuple[list, list, int]:
    """Line ends that stop short of (or run just past) another line's interior, snapped onto it:
    where an end's direction (its chord over ``reach`` m, default 2·``tolerance``) meets another
    line's segment at ``min_angle`` degrees or more and within ``tolerance`` m ahead of (or
    behind) the end, the end is extended (or trimmed) to the meeting point and that point
    becomes a vertex of the other line too, with the other line's z there (its nearest vertex,
    where one lies within a quarter of ``tolerance``: no short edge): one shared node, a
    T-junction. Not where the other line's z there differs from the end's by more than
    ``rise`` m plus ``grade`` times the distance (it passes above or below: a levee's crest
    ending beside a channel's toe is no junction on the ground, and a node there would tie the
    two heights together across the slope), nor where the end runs alongside a line (under
    ``min_angle``) or lies farther off. Lines of any kind meet (x, y, z arrays; z is what
    decides): a bank's crest ending on a road embankment's toe at the same height is a network
    node, and to the mesh either near-miss is a gap narrower than a cell that Triangle fills
    with small triangles. Closest ends first; where two lines' ends would each snap onto the
    other at one corner, the second line's stub beyond the node is trimmed instead (an L).
    Returns the lines, per line the index of the input vertex each output vertex comes from
    (an inserted vertex: its segment's first), and how many ends were snapped."""
    lines = [np.asarray(c, float) for c in lines]
    takes = [np.arange(len(c)) for c in lines]
    reach = 2 * tolerance if reach is None else reach
    segments = _segment_index(lines) if tolerance > 0 else None
    if segments is None:
        return lines, takes, 0
    sin_min = np.sin(np.radians(min_angle))
    best = []  # (|ahead|, line, side, hit row, direction, target line)
    for i, c in enumerate(lines):
        for side in (0, 1) if len(c) >= 2 else ():
            snap = _end_snap(c, i, side, segments, tolerance=tolerance, reach=reach,
                             sin_min=sin_min, rise=rise, grade=grade)
            if snap is not None:
                best.append(snap)
    best.sort(key=lambda t: t[0])
    nodes = {}  # (line, target line) -> node of an applied snap
    snapped = 0
    for _, i, side, hit, d, j in best:
        if (j, i) in nodes:  # j's end already met i here: trim i's stub beyond that node
            _trim_stub(lines, takes, i, side, nodes[(j, i)], 2 * tolerance)
            continue
        _end_at_node(lines, takes, i, side, hit, d, tolerance)
        _insert_vertex(lines, takes, j, hit)
        nodes[(i, j)] = hit
        snapped += 1
    return lines, takes, snapped


def _segment_index(lines):
    """The segments of ``lines``: first and second vertices, the line each is on, their xy
    spans, half lengths and a KD-tree of their midpoints; None with fewer than two lines of two
    or more vertices."""
    # lazy: SciPy loads only when this runs
    from scipy.spatial import cKDTree

    seg_a, seg_b, seg_line = [], [], []
    for i, c in enumerate(lines):
        if len(c) >= 2:
            seg_a.append(c[:-1])
            seg_b.append(c[1:])
            seg_line.append(np.full(len(c) - 1, i))
    if len(seg_a) < 2:
        return None
    seg_a, seg_b, seg_line = np.concatenate(seg_a), np.concatenate(seg_b), np.concatenate(seg_line)
    span = seg_b[:, :2] - seg_a[:, :2]
    half = 0.5 * np.hypot(*span.T)
    tree = cKDTree(0.5 * (seg_a[:, :2] + seg_b[:, :2]))
    return seg_a, seg_b, seg_line, span, half, tree


def _end_snap(c, i, side, segments, *, tolerance: float, reach: float, sin_min: float,
              rise: float, grade: float):
    """Where the end at ``side`` (0: start, 1: end) of line ``i`` (``c``) meets another line's
    segment as ``snap_t_junctions`` says: (|distance ahead|, i, side, the node, the end's
    direction, the other line), or None."""
    seg_a, seg_b, seg_line, span, half, tree = segments
    p, d = _end_frame(c, side == 0, reach)
    if d is None:
        return None
    k = np.asarray(tree.query_ball_point(p, tolerance + half.max()), int)
    k = k[seg_line[k] != i]
    if not k.size:
        return None
    cross = d[0] * span[k, 1] - d[1] * span[k, 0]  # d × (b - a)
    rel = seg_a[k, :2] - p
    with np.errstate(divide="ignore", invalid="ignore"):
        ahead = (rel[:, 0] * span[k, 1] - rel[:, 1] * span[k, 0]) / cross
        at = (rel[:, 0] * d[1] - rel[:, 1] * d[0]) / cross
    ok = ((np.abs(cross) >= sin_min * 2 * half[k]) & (np.abs(ahead) <= tolerance)
          & (at >= 0) & (at <= 1))
    if not ok.any():
        return None
    m = np.nonzero(ok)[0][np.argmin(np.abs(ahead[ok]))]
    hit = seg_a[k[m]] + at[m] * (seg_b[k[m]] - seg_a[k[m]])
    for vertex in (seg_a[k[m]], seg_b[k[m]]):  # near a vertex: that one, no short edge
        if np.hypot(*(vertex[:2] - hit[:2])) < 0.25 * tolerance:
            hit = vertex
    end = c[-1 if side == 1 else 0]
    if c.shape[1] > 2 and abs(hit[2] - end[2]) > rise + grade * abs(ahead[m]):
        return None  # the other line lies higher or lower: no junction on the ground
    return abs(ahead[m]), i, side, hit, d, int(seg_line[k[m]])


def _end_at_node(lines, takes, i, side, hit, d, tolerance):
    """Line ``i``'s end at ``side`` ended at the node ``hit``: its vertices past the node (along
    ``d``, the end's direction) cut off, and one within a quarter of ``tolerance`` of it."""
    c, take = (lines[i], takes[i]) if side == 1 else (lines[i][::-1], takes[i][::-1])
    past = (c[:, :2] - hit[:2]) @ d >= 0
    stop = len(c)
    while stop > 1 and past[stop - 1]:
        stop -= 1
    c, take = c[:stop], take[:stop]
    if stop > 1 and np.hypot(*(c[-1, :2] - hit[:2])) < 0.25 * tolerance:
        c, take = c[:-1], take[:-1]
    c, take = np.vstack([c, hit[None, :c.shape[1]]]), np.r_[take, take[-1]]
    lines[i], takes[i] = (c, take) if side == 1 else (c[::-1], take[::-1])


def _insert_vertex(lines, takes, j, point):
    """``point`` made a vertex of line ``j`` on its nearest segment (unless it is one)."""
    c = lines[j]
    a, span = c[:-1, :2], np.diff(c[:, :2], axis=0)
    length2 = np.maximum((span ** 2).sum(axis=1), 1e-18)
    t = np.clip(((point[:2] - a) * span).sum(axis=1) / length2, 0, 1)
    k = int(np.argmin(np.hypot(*(a + t[:, None] * span - point[:2]).T)))
    if min(np.hypot(*(c[k, :2] - point[:2])), np.hypot(*(c[k + 1, :2] - point[:2]))) < 1e-6:
        return
    lines[j] = np.vstack([c[:k + 1], point[None, :c.shape[1]], c[k + 1:]])
    takes[j] = np.r_[takes[j][:k + 1], takes[j][k], takes[j][k + 1:]]


def _trim_stub(lines, takes, i, side, node, longest):
    """Line ``i``'s vertices beyond ``node`` (one of its vertices) at its ``side`` end cut off,
    where that stub is at most ``longest`` m long."""
    c = lines[i] if side == 1 else lines[i][::-1]
    at = np.nonzero(np.hypot(*(c[:, :2] - node[:2]).T) < 1e-6)[0]
    if not at.size or at[-1] < 1:
        return
    k = int(at[-1])
    if np.hypot(*np.diff(c[k:, :2], axis=0).T).sum() > longest:
        return
    take = takes[i] if side == 1 else takes[i][::-1]
    c, take = c[:k + 1], take[:k + 1]
    lines[i], takes[i] = (c, take) if side == 1 else (c[::-1], take[::-1])


def crossing_points(lines, *, min_angle: float = 30.0, reach: float = 2.0) -> np.ndarray:
    """x, y (k, 2) of the points where two of ``lines`` ((n, 2+) arrays) cross or meet at more
    than ``min_angle`` degrees (a road over a channel, a tributary's banks at the river's),
    each line's direction taken over ``reach`` m either side; not where one line's pieces meet
    end to end nor where two run side by side."""
    # lazy: GEOS loads only when this runs
    import shapely

    if len(lines) < 2:
        return np.zeros((0, 2))
    shapes = np.array([shapely.LineString(np.asarray(c, float)[:, :2]) for c in lines],
                      dtype=object)
    first, second = shapely.STRtree(shapes).query(shapes, predicate="intersects")
    pair = first < second
    first, second = first[pair], second[pair]
    points, which = shapely.get_coordinates(shapely.intersection(shapes[first], shapes[second]),
                                            return_index=True)
    if not len(points):
        return np.zeros((0, 2))
    at = shapely.points(points)

    def direction(owner):
        line = shapes[owner]
        along = shapely.line_locate_point(line, at)
        ends = [shapely.get_coordinates(shapely.line_interpolate_point(
            line, np.clip(along + step, 0.0, shapely.length(line)))) for step in (-reach, reach)]
        d = ends[1] - ends[0]
        return d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]

    cos = np.abs((direction(first[which]) * direction(second[which])).sum(axis=1))
    return points[cos < np.cos(np.radians(min_angle))]


def height_clashes(lines, *, near: float, rise: float) -> np.ndarray:
    """Where two of ``lines`` ((k, 3) arrays, m; a line with NaN z, 2-D, is passed over), or two
    segments of one line that do not follow each other, cross or come within ``near`` m in
    plan at heights (each along its own line) more than ``rise`` m apart: one mesh node there
    can take one z only. Rows (c, 6) of x, y, the one line's z, the other's, and the two
    lines' indices, the largest height difference first."""
    # lazy: GEOS loads only when this runs
    import shapely

    segments, owner, order = [], [], []
    for i, c in enumerate(lines):
        c = np.asarray(c, float)
        if c.ndim != 2 or c.shape[1] < 3 or len(c) < 2 or not np.isfinite(c[:, 2]).all():
            continue
        segments.append(np.stack([c[:-1, :3], c[1:, :3]], axis=1))
        owner.append(np.full(len(c) - 1, i))
        order.append(np.arange(len(c) - 1))
    if not segments:
        return np.zeros((0, 6))
    seg, owner, order = np.concatenate(segments), np.concatenate(owner), np.concatenate(order)
    plan = shapely.linestrings(seg[:, :, :2])
    a, b = shapely.STRtree(plan).query(plan, predicate="dwithin", distance=near)
    keep = (a < b) & ~((owner[a] == owner[b]) & (np.abs(order[a] - order[b]) == 1))
    a, b = a[keep], b[keep]
    if not len(a):
        return np.zeros((0, 6))
    # the two segments' nearest points lie where they cross or at an end of one of them; over
    # a stretch where they run within ``near``, the heights part most at such an end too
    found = [_where_crossing(seg[a], seg[b])]
    for one, other, swap in ((seg[a], seg[b], False), (seg[b], seg[a], True)):
        for end in (0, 1):
            at, on = one[:, end], _nearest_on(one[:, end], other)
            found.append((on, at) if swap else (at, on))
    first = np.stack([f[0] for f in found])   # (5, pairs, 3): the point on a's segment
    second = np.stack([f[1] for f in found])  # ... and on b's
    apart = np.hypot(*(first[..., :2] - second[..., :2]).transpose(2, 0, 1))
    difference = np.where(apart <= near, np.abs(first[..., 2] - second[..., 2]), -np.inf)
    pick = np.argmax(difference, axis=0)
    pairs = np.arange(len(a))
    worst = difference[pick, pairs]
    clash = np.flatnonzero(worst > rise)
    clash = clash[np.argsort(-worst[clash], kind="stable")]
    p, q = first[pick[clash], clash], second[pick[clash], clash]
    return np.column_stack([(p[:, :2] + q[:, :2]) / 2, p[:, 2], q[:, 2], owner[a[clash]],
                            owner[b[clash]]])


def _nearest_on(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """The point (k, 3) of each segment ((k, 2, 3), m) nearest in plan to each of ``points``
    (k, 2+), its z along the segment."""
    start, step = segments[:, 0], segments[:, 1] - segments[:, 0]
    length2 = (step[:, :2] ** 2).sum(axis=1)
    t = ((points[:, :2] - start[:, :2]) * step[:, :2]).sum(axis=1) / np.where(length2 > 0,
                                                                               length2, 1.0)
    return start + np.clip(t, 0.0, 1.0)[:, None] * step


def _where_crossing(one: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each segment of ``one`` ((k, 2, 3), m) crosses the one of ``other`` in plan: the
    point on each (k, 3), z along it; NaN where they do not cross (parallel ones included)."""
    d1, d2 = one[:, 1] - one[:, 0], other[:, 1] - other[:, 0]
    gap = other[:, 0] - one[:, 0]
    denominator = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (gap[:, 0] * d2[:, 1] - gap[:, 1] * d2[:, 0]) / denominator
        u = (gap[:, 0] * d1[:, 1] - gap[:, 1] * d1[:, 0]) / denominator
    crossing = (denominator != 0) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    t, u = np.where(crossing, t, np.nan), np.where(crossing, u, np.nan)
    return one[:, 0] + t[:, None] * d1, other[:, 0] + u[:, None] * d2
