"""Break lines a flood model can afford, applied to the lines before the PSLG is built.

An explicit solver's time step is set by its smallest triangle (see ``hydraulics``). Detected
break lines make tiny triangles in three places: where they run within a fraction of a metre
of the domain edge, where they cross or nearly touch the modeller's own lines or each other,
and where simplification left vertices closer together than the mesh can resolve. With a
smallest spacing s (default: the cell size d):

- a bridge that localisation laid across a crossing (``without_wet_bridges``) is left out
  where it lies on low ground;
- a detected line that folds back (segments meeting at less than ``FOLD_ANGLE``) is cut there
  into two lines, and one that climbs a wall (a segment steeper than ``JOIN_GRADE``, higher
  than ``JOIN_RISE``) loses that segment (``split_at_walls``);
- detected lines are clipped back ``clearance`` (default 2 s) from the domain edge; where the
  clip's end falls within the clearance of the line's last vertex, the line ends at that
  vertex (a short stub beside the edge's nodes made a flood's smallest wet triangle);
- the parts of a detected line within s of an own line, or of a longer detected line, are cut
  away (near-parallel lines merge into the longer one; crossings keep one line through them);
- an end left within s of a line it meets at ``JOIN_ANGLE`` or more is moved onto that line
  (a junction; both pieces of a line cut at a crossing meet it at one point), so no gap of s
  between an end and a line holds the mesh's smallest triangles; not where that line lies
  higher or lower than the end by a wall's height (``JOIN_RISE``, ``JOIN_GRADE``);
- vertices closer than s to the previous kept vertex are dropped (the end points stay);
- what is left shorter than 2 s is dropped.

Where the mesh gets a flow size (``flow_spacing``: the side of the flow zone's triangles, see
``drainage``), vertices are thinned to that spacing and shorter pieces dropped, so no break-line
segment there is shorter than the triangles around it (a short segment in the wet zone would
make the smallest wet triangle, which sets the flood model's time step), and a vertex where the
thinned line turns sharply (an angle under 60°, where Triangle splits the segments into small triangles) is dropped there too.
A vertex closer than the flow spacing gives way only where the chord from the previous kept
vertex to the next one passes within ``FLOW_PLAN_TOLERANCE`` cells in plan and
``FLOW_HEIGHT_TOLERANCE`` m in height of it: where the line runs straight and even or bends
smoothly, it thins; where it steps or turns at the vertex (a kerb, a corner), the vertex is
terrain the mesh needs and stays, no closer than the spacing s.

The modeller's own lines are kept as given.
"""
from __future__ import annotations

import numpy as np

from ..engine.arrays import distance_along, true_runs

FLOW_PLAN_TOLERANCE = 0.25   # cells: a vertex this close to the chord past it may give way
FLOW_HEIGHT_TOLERANCE = 0.05  # m: ... if its height is this close too (a flood's wet depth)
FOLD_ANGLE = 60.0  # degrees: a line whose segments meet at less folds back (the PSLG's corner)
JOIN_ANGLE = 60.0  # degrees: a line ending a spacing off another at this or more joins it
# ... unless the other line's z there lies farther from the end's than this rise (m) plus this
# grade times the move: a climb steeper than 1:1 is a wall between them, no junction (the
# corpus's and the real samples' joins climb at most 0.64 m in 1 m; a toe line ending at a
# 10 m wall's top edge took its z and gave a 40 m segment a 10 m ramp)
JOIN_RISE, JOIN_GRADE = 0.2, 1.0


def thin_vertices(coords: np.ndarray, spacing, *, firm: float | None = None,
                  tolerance: tuple[float, float] | None = None) -> np.ndarray:
    """``coords`` (k, 2+) without vertices closer than ``spacing`` (m, one value or one per
    vertex) to the previous kept one; both ends stay (the last kept inner vertex closer than
    its spacing to the end gives way to it). With ``firm`` (m) and ``tolerance`` (plan m,
    height m), a vertex closer than its spacing but not than ``firm`` gives way, to the next
    one or to the end, only where the chord from the previous kept vertex to the next one
    passes within ``tolerance`` of it."""
    # lazy: numba loads only when this runs (the flood command imports this module)
    from .._kernels.lines import thinned

    coords = np.asarray(coords, float)
    if len(coords) <= 2:
        return coords
    spacing = np.ascontiguousarray(np.broadcast_to(np.asarray(spacing, float), (len(coords),)))
    plan, height = tolerance if tolerance is not None else (0.0, 0.0)
    return coords[thinned(np.ascontiguousarray(coords), spacing, tolerance is not None,
                          float(firm or 0.0), float(plan), float(height))]


def drop_spikes(coords: np.ndarray, where=None, min_angle: float = FOLD_ANGLE) -> np.ndarray:
    """``coords`` (k, 2+) without the inner vertices (of those ``where`` is true) at which the
    line folds back, its two segments meeting at less than ``min_angle`` degrees."""
    # lazy: numba loads only when this runs (the flood command imports this module)
    from .._kernels.lines import unspiked

    coords = np.asarray(coords, float)
    where = np.ones(len(coords), bool) if where is None else np.asarray(where, bool)
    return coords[unspiked(np.ascontiguousarray(coords), np.ascontiguousarray(where),
                           float(np.cos(np.radians(min_angle))))]


def split_at_folds(coords: np.ndarray, min_angle: float = FOLD_ANGLE) -> list[np.ndarray]:
    """``coords`` (k, 2+) cut into pieces at the inner vertices where the line folds back, its
    two segments meeting at less than ``min_angle`` degrees (the vertex ends one piece and
    starts the next)."""
    coords = np.asarray(coords, float)
    if len(coords) < 3:
        return [coords]
    back = coords[:-2, :2] - coords[1:-1, :2]
    ahead = coords[2:, :2] - coords[1:-1, :2]
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = (back * ahead).sum(axis=1) / (np.hypot(*back.T) * np.hypot(*ahead.T))
    folds = 1 + np.flatnonzero(cos > np.cos(np.radians(min_angle)))
    cuts = folds.tolist()  # np.r_ cost 40 µs a call
    return [coords[a:b + 1] for a, b in zip([0, *cuts], [*cuts, len(coords) - 1])]


def _wall(rise, run):
    """Whether a climb of ``rise`` m over ``run`` m in plan is a wall's: more than
    ``JOIN_RISE`` plus ``JOIN_GRADE`` times the run."""
    return np.abs(rise) > JOIN_RISE + JOIN_GRADE * run


def split_at_walls(coords: np.ndarray) -> list[np.ndarray]:
    """``coords`` (k, 3) cut into the pieces between its wall segments, which climb more than
    ``JOIN_RISE`` plus ``JOIN_GRADE`` times their length: a crest or toe does not run up a
    wall, and a mesh edge along one would give the nodes on it heights between its foot and
    its top. Pieces of one vertex are left out."""
    coords = np.asarray(coords, float)
    if coords.shape[1] < 3 or len(coords) < 2:
        return [coords]
    step = np.diff(coords, axis=0)
    walls = np.flatnonzero(_wall(step[:, 2], np.hypot(step[:, 0], step[:, 1])))
    if not len(walls):
        return [coords]
    starts, stops = [0, *(walls + 1).tolist()], [*(walls + 1).tolist(), len(coords)]
    return [coords[a:b] for a, b in zip(starts, stops) if b - a >= 2]


def lines_for_hydraulics(lines, domain, *, spacing: float, clearance: float | None = None,
                         own_lines=(), within=None,
                         flow_spacing=None) -> tuple[list[np.ndarray], dict]:
    """Detected ``lines`` ((k, 3) arrays) made affordable for a flood model inside ``domain``
    (a shapely (Multi)Polygon), as the module says, and only ``within`` a polygon if given
    (e.g. ``wet_zone`` of a first flood); ``flow_spacing`` (a Grid of spacings in m, NaN
    outside the flow zone) widens the spacing where it is larger; returns (lines, counts of
    what was done)."""
    # lazy: GEOS loads only when this runs
    import shapely

    clearance = 2 * spacing if clearance is None else clearance
    keep_terrain = (None if flow_spacing is None else dict(firm=spacing, tolerance=(
        FLOW_PLAN_TOLERANCE * flow_spacing.cell_size, FLOW_HEIGHT_TOLERANCE)))
    inner = domain.buffer(-clearance) if domain is not None else None
    if within is not None:
        inner = within if inner is None else shapely.intersection(inner, within)
    if inner is not None:  # most lines lie well inside: a prepared test spares their overlay
        shapely.prepare(inner)
    edge = inner.boundary if inner is not None else None  # where the clip leaves line ends
    # a line folding back on itself is two lines: the shorter's part within the spacing of
    # the longer goes, as for any two lines (a fold's arms a fraction of a metre apart made
    # the mesh's smallest triangles)
    pieces = [piece for c in lines for fold in split_at_folds(c) for piece in
              split_at_walls(fold)]
    taken_xyz = [np.asarray(c, float) for c in own_lines if len(c) >= 2]
    taken = [shapely.LineString(c[:, :2]) for c in taken_xyz]
    taken_bounds = shapely.bounds(taken).reshape(-1, 4)  # grown as lines are taken: an array
    # made from a list of boxes at each look-up was a pass over all of them in Python
    junctions = []  # where line ends were snapped onto other lines: later ends meet them there
    order = sorted(range(len(pieces)), key=lambda k: -_length(pieces[k]))
    out, stats = [], {"lines_in": len(lines), "vertices_in": int(sum(len(c) for c in lines)),
                      "clipped_at_edge": 0, "cut_near_other_lines": 0, "ends_joined": 0}
    for k in order:
        coords = np.asarray(pieces[k], float)
        if flow_spacing is not None:  # thinned first, so the cuts below see the final chords
            coords = thin_vertices(coords, _spacing_at(flow_spacing, coords, spacing),
                                   **keep_terrain)
            coords = drop_spikes(coords, _spacing_at(flow_spacing, coords, spacing) > spacing)
        line = shapely.LineString(coords)
        # (the overlay also splits a line where it crosses itself: such a line is taken to it)
        if inner is not None and not (shapely.contains_properly(inner, line)
                                      and shapely.is_simple(line)):
            clipped = shapely.intersection(line, inner)
            stats["clipped_at_edge"] += clipped.length < line.length - 1e-9
            line = clipped
        if taken and not line.is_empty:
            # only the lines whose buffer can reach this one: the union of all of them for
            # every line made the step quadratic in the number of lines
            near = _near(taken, taken_bounds, line, spacing)
            if near is not None:
                cut = shapely.difference(line, near)
                stats["cut_near_other_lines"] += cut.length < line.length - 1e-9
                line = cut
        own_pieces = []  # a cut leaves pieces that may end a hair apart: keep them s apart too
        for part in _parts(line):
            if own_pieces:
                part = shapely.difference(part, shapely.union_all(
                    [shapely.LineString(c[:, :2]) for c in own_pieces]).buffer(spacing))
            for piece in _parts(part):
                coords = shapely.get_coordinates(piece, include_z=True)
                local = _spacing_at(flow_spacing, coords, spacing)
                coords = thin_vertices(coords, local, **(keep_terrain or {}))
                if edge is not None:
                    coords = without_edge_stubs(coords, np.maximum(local, clearance), edge)
                if _length(coords) >= max(2 * spacing, local.max()) and len(coords) >= 2:
                    own_pieces.append(coords)
        joined = []  # ends a spacing off a line they meet, onto it (not onto each other)
        for coords in own_pieces:
            coords, count = _joined_ends(coords, taken, taken_xyz, taken_bounds, spacing,
                                         junctions)
            stats["ends_joined"] += count
            joined.append(coords)
        out.extend(joined)
        taken_xyz.extend(joined)
        taken.extend(shapely.LineString(c[:, :2]) for c in joined)
        taken_bounds = np.concatenate([taken_bounds, shapely.bounds(
            taken[len(taken) - len(joined):]).reshape(-1, 4)])
    stats.update(lines_out=len(out), vertices_out=int(sum(len(c) for c in out)),
                 spacing_m=spacing, clearance_m=clearance)
    return out, stats


def without_wet_bridges(lines, bridged, low_ground) -> list[np.ndarray]:
    """``lines`` ((k, 3) arrays) without the segments of their bridges (``bridged``: per line,
    per vertex whether it is a bridge's, or None; see ``localise.localise_traced``) that lie on
    low ground (``low_ground``: a Grid, finite there, e.g. ``drainage.flow_spacing``; None:
    none). A bridge so marked carries a line across another feature's (a crossing); under
    water it adds little that a flood feels, and its crossings with the other feature's lines
    hold the wet zone's smallest triangles, which set the flood model's time step (RESULTS.md,
    "Crossings and junctions")."""
    if low_ground is None:
        return list(lines)
    out = []
    for coords, flags in zip(lines, bridged):
        if flags is None or len(coords) < 2:
            out.append(coords)
            continue
        middle = 0.5 * (coords[:-1, :2] + coords[1:, :2])
        drop = flags[:-1] & flags[1:] & (_spacing_at(low_ground, middle, 0.0) > 0)
        if not drop.any():
            out.append(coords)
            continue
        out += [coords[a:b + 1] for a, b in true_runs(~drop)]
    return out


def _joined_ends(coords: np.ndarray, lines: list, lines_xyz: list, bounds: np.ndarray,
                 spacing: float, junctions: list) -> tuple[np.ndarray, int]:
    """(``coords`` with each end that lies within a ``spacing`` (m) of one of ``lines`` (shapely
    lines; ``lines_xyz`` their (k, 2|3) coordinates, ``bounds`` their boxes) and meets it at
    ``JOIN_ANGLE`` or more moved onto it, how many were). Cutting a line a spacing short of
    the line it runs into leaves its end, the other line and the next line's end a spacing
    apart, the triangles there the mesh's smallest; joined, the lines meet in one vertex: a
    junction (``junctions``, points already made, taken within a spacing), else the other
    line's vertex within a spacing, else the nearest point on it (z along it); not where that
    z differs from the end's by more than ``JOIN_RISE`` plus ``JOIN_GRADE`` times the move."""
    # lazy: GEOS loads only when this runs
    import shapely

    coords = coords.copy()
    if not lines or len(coords) < 2:
        return coords, 0
    joined = 0
    for end, inner in ((0, 1), (-1, -2)):
        e = coords[end, :2]
        close = _boxes_near(bounds, (*e, *e), spacing)
        if not close.size:
            continue
        point = shapely.points(e)
        gaps = shapely.distance(np.asarray([lines[k] for k in close], object), point)
        k = close[int(np.argmin(gaps))]
        if not 1e-9 < gaps.min() <= spacing * (1 + 1e-6):
            continue
        along = shapely.line_locate_point(lines[k], point)
        target = np.asarray(shapely.get_coordinates(shapely.line_interpolate_point(
            lines[k], along)))[0]
        bar = lines_xyz[k]
        lengths = distance_along(bar)
        seg = int(np.clip(np.searchsorted(lengths, along) - 1, 0, len(bar) - 2))
        tangent = bar[seg + 1, :2] - bar[seg, :2]
        stem = e - coords[inner, :2]
        cross = tangent[0] * stem[1] - tangent[1] * stem[0]  # (np.cross of 2-vectors: deprecated)
        sine = abs(cross) / max(np.hypot(*tangent) * np.hypot(*stem), 1e-12)
        if sine < np.sin(np.radians(JOIN_ANGLE)):
            continue  # a glancing meeting: the corner rule of the PSLG takes it
        z = (float(np.interp(along, lengths, bar[:, 2])) if bar.shape[1] > 2
             else coords[end, 2] if coords.shape[1] > 2 else None)
        vertex = int(np.argmin(np.hypot(*(bar[:, :2] - target).T)))
        made = [j for j in junctions if np.hypot(*(j[:2] - target)) <= spacing]
        if made:
            target, z = made[0][:2], made[0][2]
        elif np.hypot(*(bar[vertex, :2] - target)) <= spacing:
            target = bar[vertex, :2]
            z = bar[vertex, 2] if bar.shape[1] > 2 else z
        if coords.shape[1] > 2 and z is not None and _wall(z - coords[end, 2],
                                                           np.hypot(*(target - e))):
            continue  # the other line passes above or below: a wall, no junction
        if np.hypot(*(coords[inner, :2] - target)) < spacing and len(coords) > 2:
            coords = np.delete(coords, inner % len(coords), axis=0)  # no segment under it
        coords[end, :2] = target
        if coords.shape[1] > 2 and z is not None:
            coords[end, 2] = z
        junctions.append(np.array([*target, np.nan if z is None else z]))
        joined += 1
    return coords, joined


def _near(lines: list, bounds: np.ndarray, line, spacing: float):
    """The union of those ``lines`` (with their ``bounds``) within ``spacing`` of ``line``,
    grown by ``spacing``; None where none is that close (most lines: no union, buffer and
    difference for them)."""
    # lazy: GEOS loads only when this runs
    import shapely

    close = [lines[k] for k in _boxes_near(bounds, shapely.bounds(line), spacing)]
    if not close or shapely.distance(line, close).min() > spacing:
        return None
    return shapely.union_all(close).buffer(spacing)


def _boxes_near(b: np.ndarray, box, spacing: float) -> np.ndarray:
    """The indices of the boxes ``b`` ((n, 4): xmin, ymin, xmax, ymax) within ``spacing`` of
    ``box``."""
    return np.flatnonzero((b[:, 0] <= box[2] + spacing) & (b[:, 2] >= box[0] - spacing)
                          & (b[:, 1] <= box[3] + spacing) & (b[:, 3] >= box[1] - spacing))


def without_edge_stubs(coords: np.ndarray, spacing: np.ndarray, edge) -> np.ndarray:
    """``coords`` without an end the clip at the domain edge (``edge``, the clipped area's
    boundary) made closer than its ``spacing`` (m, per vertex) to the next vertex: the line
    ends at that vertex instead. The clip's end is no terrain (a point interpolated on a
    segment), and the short segment it leaves beside the edge's nodes held the smallest
    triangle of a flood's outflow (87 % of its time steps)."""
    # lazy: GEOS loads only when this runs
    import shapely

    for end, inner in ((0, 1), (-1, -2)):
        if len(coords) < 3:
            break
        gap = np.hypot(*(coords[end, :2] - coords[inner, :2]))
        if gap < spacing[end] and shapely.distance(shapely.Point(coords[end, :2]), edge) < 1e-6:
            coords = coords[1:] if end == 0 else coords[:-1]
            spacing = spacing[1:] if end == 0 else spacing[:-1]
    return coords


def _spacing_at(flow_spacing, coords, spacing: float) -> np.ndarray:
    """The spacing at each vertex: ``spacing``, or the flow spacing of its cell if larger."""
    local = np.full(len(coords), float(spacing))
    if flow_spacing is None or not len(coords):
        return local
    row, col = flow_spacing.fractional_index(coords[:, 0], coords[:, 1])
    ny, nx = flow_spacing.shape
    # minimum and maximum, not np.clip: 20 µs less a call, of some 1,500 calls a run
    row = np.minimum(np.maximum(np.rint(row).astype(int), 0), ny - 1)
    col = np.minimum(np.maximum(np.rint(col).astype(int), 0), nx - 1)
    # the vertices' cells only: converting the whole grid per line made the step quadratic
    return np.fmax(local, np.asarray(flow_spacing.values[row, col], float))


def _length(coords) -> float:
    c = np.asarray(coords, float)
    return float(np.hypot(*np.diff(c[:, :2], axis=0).T).sum()) if len(c) > 1 else 0.0


def _parts(geometry):
    if geometry.is_empty:
        return []
    if geometry.geom_type == "LineString":
        return [geometry]
    return [g for g in getattr(geometry, "geoms", []) if g.geom_type == "LineString"]


def _wet_mask(max_depth, wet_depth: float, margin: float) -> np.ndarray:
    # lazy: SciPy loads only when this runs
    from scipy.ndimage import binary_dilation

    wet = np.nan_to_num(np.asarray(max_depth.values, float), nan=0.0) > wet_depth
    steps = int(np.ceil(margin / max_depth.cell_size))
    if steps:
        disk = np.hypot(*np.mgrid[-steps:steps + 1, -steps:steps + 1]) <= steps
        wet = binary_dilation(wet, structure=disk)
    return wet


def flood_size_field(max_depth, *, wet_area: float, wet_depth: float = 0.05,
                     margin: float = 5.0):
    """A size field (a Grid of local maximum triangle areas, m²; NaN: no limit) from a first
    flood's maximum depth (a Grid, m): ``wet_area`` where the water was deeper than
    ``wet_depth`` and within ``margin`` m of there, so that a second mesh puts its resolution
    where the water flows."""
    wet = _wet_mask(max_depth, wet_depth, margin)
    return max_depth.with_values(np.where(wet, float(wet_area), np.nan).astype(np.float32))


def wet_zone(max_depth, *, wet_depth: float = 0.05, margin: float = 10.0):
    """The (Multi)Polygon where a first flood was deeper than ``wet_depth``, grown by
    ``margin`` m: detected lines outside it shape no flow (``lines_for_hydraulics(within=)``)."""
    # lazy: GEOS and GDAL load only when this runs
    import shapely
    from rasterio.features import shapes

    wet = _wet_mask(max_depth, wet_depth, margin).astype(np.uint8)
    return shapely.union_all([shapely.geometry.shape(g) for g, v in
                              shapes(wet, mask=wet.astype(bool), transform=max_depth.transform)
                              if v == 1])
