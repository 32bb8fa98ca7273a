"""The domain edge of a DEM's valid cells without the staircase of cell edges (for
``mesh.domain_from_dem``). Lengths and tolerances in the coordinates' unit (cells there).

The outline through the outer cell centres runs along the grid: a straight or curved data edge
(a lake shore, a diagonal unsurveyed corner) comes out as steps of one cell, whose corners lie up
to half a cell off the edge they rasterise and whose edges' midpoints lie on it. Each ring is cut
into cell-long pieces, and Douglas–Peucker (``simplify.douglas_peucker_mask``) keeps the fewest of
their ends and midpoints such that every point of the ring stays within the tolerance of the
chords (and so the chords within it of the ring), splitting where it must at the midpoints of
the ring's edges or at its corners between edges of two cells or more (a real corner), else at
the pieces' ends and midpoints, the staircase's corners last. Then:

- where rings touch (cells meeting at a diagonal), both keep their corners within a cell of the
  point: a chord there would leave a sliver of a gap beside the other ring;
- where a chord makes a corner inside the domain sharper than ``sharpest`` degrees, the ring's
  corners around it come back (Triangle cannot keep its angle bound in such corners);
- edges shorter than a cell are merged into one vertex where the tolerance and the angles allow
  (short boundary edges make small triangles).

A polygon that comes out invalid (rings crossing) keeps its outline, simplified within the
tolerance as GEOS preserves topology.
"""
from __future__ import annotations

import numpy as np
import shapely

# rounds of Douglas–Peucker that give sharp corners the ring's corners back before a ring keeps
# its outline
SHARP_REPAIRS = 12


def smooth_outline(polygons: list, tolerance: float, cell: float, *,
                   sharpest: float = 60.0) -> list:
    """``polygons`` whose edges run along a grid of ``cell`` m (cell-centre outlines) with their
    staircases straightened within ``tolerance`` m (see the module docstring); corners inside
    stay at ``sharpest`` degrees or more."""
    # lazy: GEOS loads only when this runs
    from shapely.geometry.polygon import orient

    polygons = [orient(p, 1.0) for p in polygons]  # the domain left of every ring
    origin = np.min([p.bounds[:2] for p in polygons], axis=0)  # local metres keep the digits
    rings = [np.asarray(r.coords)[:-1, :2] - origin
             for p in polygons for r in (p.exterior, *p.interiors)]
    pieces = [_pieces(ring, cell) for ring in rings]
    touching, along = _contacts([p[0] for p in pieces], cell)
    done = [_straightened(*piece, touch, at, tolerance, cell, sharpest) + origin
            for piece, touch, at in zip(pieces, touching, along)]
    out, k = [], 0
    for polygon in polygons:
        holes = len(polygon.interiors)
        smooth = shapely.Polygon(done[k], done[k + 1:k + 1 + holes])
        k += 1 + holes
        out.append(smooth if smooth.is_valid and smooth.area > 0 else
                   polygon.simplify(tolerance, preserve_topology=True))
    if len(out) > 1 and not shapely.MultiPolygon(out).is_valid:
        return [p.simplify(tolerance, preserve_topology=True) for p in polygons]
    return out


def _pieces(ring: np.ndarray, cell: float):
    """An open ring (k, 2) as the ends and midpoints of its cell-long pieces (n, 2), each with
    its rank (0 best: see the module docstring) and whether it is a corner; starting at a point
    of rank 0."""
    corners = _corners(ring)
    if len(corners) < 4:
        return corners, np.zeros(len(corners), np.int64), np.ones(len(corners), bool)
    edge = np.roll(corners, -1, axis=0) - corners
    length = np.hypot(*edge.T)
    count = 2 * np.maximum(1, np.ceil(length / cell - 1e-6)).astype(np.int64)
    which = np.repeat(np.arange(len(corners)), count)
    step = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    points = corners[which] + (step / count[which])[:, None] * edge[which]
    short = length < 2 * cell * (1 - 1e-6)
    corner = step == 0
    rank = np.where(corner, np.where(short[which] | short[which - 1], 2, 0),
                    np.where(2 * step == count[which], 0, 1))
    start = int(np.argmin(rank))
    return tuple(np.roll(a, -start, axis=0) for a in (points, rank, corner))


def _contacts(rings: list, cell: float) -> tuple[list, list]:
    """Per point of each ring (a list of (n, 2)), whether it touches another ring or another
    stretch of its own (more than a cell along it), where rings pinch; and how far along its
    ring it lies (m)."""
    sizes = [len(r) for r in rings]
    xy = np.concatenate(rings)
    ring = np.repeat(np.arange(len(rings)), sizes)
    first = np.repeat(np.cumsum(sizes) - sizes, sizes)
    following = first + (np.arange(len(xy)) - first + 1) % np.repeat(sizes, sizes)
    step = np.hypot(*(xy[following] - xy).T)
    along = np.concatenate([np.cumsum(s) - s for s in np.split(step, np.cumsum(sizes)[:-1])])
    perimeter = np.bincount(ring, weights=step)[ring]
    segments = shapely.linestrings(np.stack([xy, xy[following]], axis=1))
    p, s = shapely.STRtree(segments).query(shapely.points(xy), predicate="dwithin",
                                           distance=1e-6 * cell)
    apart = np.abs(along[p] - along[s])
    apart = np.minimum(apart, perimeter[p] - apart)
    touching = np.zeros(len(xy), bool)
    touching[p[(ring[p] != ring[s]) | (apart > 1.5 * cell)]] = True
    return np.split(touching, np.cumsum(sizes)[:-1]), np.split(along, np.cumsum(sizes)[:-1])


def _straightened(points, rank, corner, touching, along, tolerance, cell, sharpest):
    """One ring's pieces (see ``_pieces``) straightened within ``tolerance`` (m): the ring's
    coordinates (k, 2), closed. Where it is ``touching`` another stretch of the boundary, it
    keeps its corners within a cell (``along`` it, m) as they are."""
    # lazy: numba loads only when this runs
    from .simplify import douglas_peucker_mask

    n = len(points)
    if n < 8:  # fewer than 4 corners: not a ring of the grid
        return np.vstack([points, points[:1]])
    coords = np.column_stack([np.vstack([points, points[:1]]), np.zeros(n + 1)])
    ranks = np.append(rank, rank[0])
    pinned = frozenset()
    if touching.any():
        apart = np.abs(along[corner][:, None] - along[touching][None, :])
        apart = np.minimum(apart, along[-1] + np.hypot(*(points[0] - points[-1])) - apart)
        near = np.flatnonzero(corner)[(apart <= cell * (1 + 1e-6)).any(axis=1)]
        pinned = frozenset(np.flatnonzero(touching).tolist()) | frozenset(near.tolist())
    fixed = {0, n} | pinned
    for _ in range(SHARP_REPAIRS):
        ordered = sorted(fixed)
        keep = np.zeros(n + 1, bool)
        for a, b in zip(ordered[:-1], ordered[1:]):
            keep[a:b + 1] |= douglas_peucker_mask(coords[a:b + 1], tolerance, ranks[a:b + 1])
        kept = np.flatnonzero(keep[:-1])
        kept = kept[~_straight(points[kept])]
        if len(kept) < 3:
            break
        sharp = np.flatnonzero(_inner_angles(points[kept]) < sharpest)
        if not len(sharp):
            kept, position = _without_short_edges(coords[:-1], rank, kept, pinned, tolerance,
                                                  cell, sharpest)
            return np.vstack([position[kept, :2], position[kept[:1], :2]])
        # the ring's corners come back between the kept neighbours of each sharp corner
        grown = set(fixed)
        for a, b in zip(kept[sharp - 1].tolist(), kept[(sharp + 1) % len(kept)].tolist()):
            span = (a + np.arange((b - a) % n + 1)) % n
            grown.update(span[corner[span]].tolist() + [a, b])
        grown |= {n} if 0 in grown else set()
        if grown == fixed:
            break
        fixed = grown
    return np.vstack([points[corner], points[corner][:1]])


def _without_short_edges(coords, rank, kept, pinned, tolerance, cell, sharpest):
    """The vertices ``kept`` (indices into a ring's pieces ``coords``, (n, 3), in order) with
    each edge shorter than ``cell`` merged into one vertex where it can be: one of its ends, a
    piece between them, or where the edges before and after it meet (none of them ``pinned``).
    The ring from the vertex before to the one after is simplified again through it (as the
    ranks prefer, else plainly); the merge is taken where every piece there stays within
    ``tolerance`` of the new edges, the new vertex within it of the ring, and no new edge is
    shorter than ``cell`` nor corner sharper than ``sharpest``. Returns the kept indices and
    the pieces' positions (a vertex where edges meet moved off the ring)."""
    n = len(coords)
    position = coords.copy()
    failed = set()
    while len(kept) > 5:
        ring = position[kept, :2]
        length = np.hypot(*(np.roll(ring, -1, axis=0) - ring).T)
        short = [e for e in np.argsort(length, kind="stable")
                 if length[e] < cell * (1 - 1e-6)
                 and tuple(np.roll(kept, -e)[[-1, 0, 1, 2]]) not in failed]
        if not short:
            break
        order = np.roll(kept, -short[0])
        a, b = order[0], order[1]
        candidates = [(w, coords[w], False)
                      for w in (a, b, *((a + np.arange(1, (b - a) % n)) % n))
                      if not ({a, b} - {w}) & pinned]
        meet = _meeting_point(position[order[[-1, 0, 1, 2]], :2])
        if meet is not None and not {a, b} & pinned:
            candidates.append((a, np.append(meet, 0.0), True))
        for w, xyz, moved in candidates:
            merged = _merged(coords, position, rank, order, w, xyz, moved, tolerance, cell,
                             sharpest)
            if merged is not None:
                position[w], kept = xyz, merged
                break
        else:
            failed.add(tuple(order[[-1, 0, 1, 2]]))
    return kept, position


def _merged(coords, position, rank, kept, w, xyz, moved, tolerance, cell, sharpest):
    """``kept`` with its first two vertices merged into piece ``w`` placed at ``xyz`` (off the
    ring where ``moved``; see ``_without_short_edges``), or None where that is not allowed."""
    n = len(coords)
    span = (kept[-1] + np.arange((kept[2] - kept[-1]) % n + 1)) % n
    if moved:  # the ring from the vertex before to the one after, near the two new edges
        chain = np.vstack([position[kept[-1], :2], xyz[:2], position[kept[2], :2]])
        if (_distances(coords[span, :2], chain) > tolerance).any() or \
                _distances(xyz[None, :2], coords[span, :2])[0] > tolerance:
            return None
        return _fits([w], chain, position, kept, cell, sharpest)
    for preferred in (rank, None):
        stretch, chain = _through(coords, position, preferred, kept, w, tolerance)
        merged = _fits(stretch, chain, position, kept, cell, sharpest)
        if merged is not None:
            return merged
    return None


def _through(coords, position, rank, kept, w, tolerance):
    """Douglas–Peucker's vertices within ``tolerance`` (by ``rank``, None: plain) from the
    vertex before the first two of ``kept`` through piece ``w`` to the one after them: the new
    vertices between those two, and the positions of all."""
    # lazy: numba loads only when this runs
    from .simplify import douglas_peucker_mask

    n = len(coords)
    stretch, chain = [], [position[kept[-1], :2]]
    for a, b in ((kept[-1], w), (w, kept[2])):
        part = (a + np.arange((b - a) % n + 1)) % n
        points = coords[part]
        points[0] = position[a] if a != w else coords[w]
        points[-1] = position[b] if b != w else coords[w]
        keep = douglas_peucker_mask(points, tolerance, None if rank is None else rank[part])
        stretch.extend(part[keep][1:])
        chain.extend(points[keep][1:, :2])
    return stretch[:-1], np.asarray(chain)


def _fits(stretch, chain, position, kept, cell, sharpest):
    """``kept`` with its first two vertices replaced by ``stretch`` (``chain``: their positions
    between those of the vertices before and after), or None where that leaves an edge shorter
    than ``cell`` or a corner sharper than ``sharpest``."""
    if (np.hypot(*np.diff(chain, axis=0).T) < cell * (1 - 1e-6)).any():
        return None
    merged = np.concatenate([stretch, kept[2:]]).astype(np.int64)
    after = merged[(len(stretch) + 1) % len(merged)]
    around = np.vstack([position[merged[-2], :2], chain, position[after, :2]])
    return merged if (_inner_angles(around)[1:-1] >= sharpest).all() else None


def _meeting_point(quad: np.ndarray):
    """Where the line from the first of four points (4, 2) through the second meets the line
    from the fourth through the third, ahead of both; None where it does not."""
    u, v = quad[1] - quad[0], quad[3] - quad[2]
    cross = u[0] * v[1] - u[1] * v[0]
    if abs(cross) <= 1e-9 * np.hypot(*u) * np.hypot(*v):
        return None
    w = quad[2] - quad[0]
    t, s = (w[0] * v[1] - w[1] * v[0]) / cross, (w[0] * u[1] - w[1] * u[0]) / cross
    return quad[0] + t * u if t > 0 and s < 1 else None


def _distances(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distances (m) from points (k, 2) to a polyline (m, 2)."""
    a, ab = line[:-1], np.diff(line, axis=0)
    rel = points[:, None, :] - a[None, :, :]
    t = np.clip((rel * ab).sum(axis=2) / np.maximum((ab * ab).sum(axis=1), 1e-300), 0.0, 1.0)
    return np.hypot(*np.moveaxis(rel - t[..., None] * ab, 2, 0)).min(axis=1)


def _corners(xy: np.ndarray) -> np.ndarray:
    """The vertices of an open ring (k, 2) where it turns (repeats and vertices it runs
    straight through dropped)."""
    xy = xy[np.any(xy != np.roll(xy, 1, axis=0), axis=1)]
    return xy[~_straight(xy)] if len(xy) >= 3 else xy


def _straight(xy: np.ndarray) -> np.ndarray:
    """Which vertices of an open ring (k, 2) its edges run straight through."""
    u = xy - np.roll(xy, 1, axis=0)
    w = np.roll(xy, -1, axis=0) - xy
    cross = u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]
    return (np.abs(cross) <= 1e-9 * np.hypot(*u.T) * np.hypot(*w.T)) & ((u * w).sum(axis=1) > 0)


def _inner_angles(xy: np.ndarray) -> np.ndarray:
    """Angles (degrees) of an open ring (k, 2) at its vertices on its left, the domain's side
    for a ring that runs with the domain on its left; 0 where it turns back on itself."""
    u = xy - np.roll(xy, 1, axis=0)
    w = np.roll(xy, -1, axis=0) - xy
    turn = np.arctan2(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0], (u * w).sum(axis=1))
    return np.where(np.abs(turn) > np.pi * (1 - 1e-9), 0.0, 180.0 - np.degrees(turn))
