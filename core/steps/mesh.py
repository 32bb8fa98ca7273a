"""Meshing: break lines and the domain boundary as a PSLG, refined by Triangle.

``triangulate_pslg`` is the only function that calls Triangle (Shewchuk's library is free for
non-commercial use only), so another backend can replace it in one place.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import shapely
from affine import Affine
from pyproj import CRS

from ..engine.arrays import boundary_edges, edge_nodes, spatial_order, unique_rows
from ..engine.limits import check_triangles
from ..engine.progress import part, report
from ..errors import FloodMeshError
from ..options import (DEFAULT_MAX_TRIANGLES, check_max_area, check_max_triangles, check_min_angle,
                       check_tolerance)
from ..points import line_list, step_points
from ..raster import Grid, bilinear, lines_near, nearest_value, usable_dem
from .hydraulic_lines import JOIN_RISE
from .joining import height_clashes
from .outline import smooth_outline

# Triangle leaves skinny triangles in the concentric shells it builds around input corners
# sharper than 60 degrees (Miller, Pav & Walkington 2003), so break lines may not form them.
SHARP_CORNER = 60.0
# Triangle's refinement passes over its own output that triangulate_pslg makes at most, to mend
# triangles below the angle bound that Triangle's first pass left (see there)
REPAIR_PASSES = 12
# passes of Triangle's refinement to the local areas and the size field, at most
REFINE_PASSES = 12


@dataclass(frozen=True)
class Mesh:
    """A triangular mesh: ``nodes`` (n, 3) x, y, z in metres, ``triangles`` (m, 3) node indices,
    counter-clockwise."""

    nodes: np.ndarray
    triangles: np.ndarray
    crs: CRS
    segments: np.ndarray = field(default_factory=lambda: np.empty((0, 2), np.int64))
    """Input (PSLG) segments as node index pairs."""


@dataclass(frozen=True)
class PSLG:
    """A planar straight line graph in Triangle's terms: ``vertices`` (n, 2), ``segments`` (s, 2)
    vertex index pairs, ``holes`` (h, 2) a point inside each hole."""

    vertices: np.ndarray
    segments: np.ndarray
    holes: np.ndarray


def domain_from_dem(dem: Grid, *, min_area: float = 0.0, tolerance: float | None = None):
    """The area of valid DEM cells as a (Multi)Polygon through the outer cell centres.

    Parts smaller than ``min_area`` (m²) are dropped. The staircase of cell edges the outline
    follows is straightened within ``tolerance`` m of it (the run's break-line tolerance α·Δ;
    default and at most Δ = d/2, d the cell size: farther out, a node on the edge could lie
    more than a cell from every valid cell centre); see ``outline``.
    """
    # lazy: GDAL loads only when this runs
    from rasterio.features import shapes

    valid = np.isfinite(dem.values).astype(np.uint8)
    d = dem.cell_size
    tolerance = d / 2 if tolerance is None else min(check_tolerance(tolerance), d / 2)
    # the outline in cells (column, -row: north up), where every corner is exact: in metres, a
    # strip of valid cells between cells with no data shrank to a sliver some 1e-13 m wide or to
    # nothing as the DEM's origin and cell size happened to round; straightening such a sliver
    # crossed rings, and smooth_outline's fallback then cut corners of 14° (the mesh fuzz test)
    cells = Affine.scale(1.0, -1.0)
    parts = [shapely.geometry.shape(geom) for geom, value in
             shapes(valid, mask=valid.astype(bool), transform=cells, connectivity=4)
             if value == 1]
    outline = shapely.unary_union(parts).buffer(-0.5, join_style="mitre")
    polygons = [p for p in getattr(outline, "geoms", [outline])
                if p.geom_type == "Polygon" and p.area > max(min_area / d ** 2, 4)]
    if not polygons:
        raise FloodMeshError("the DEM has no area of valid cells large enough to mesh; check its "
                             "nodata and the cell size")
    polygons = smooth_outline(polygons, tolerance / d, 1.0, sharpest=SHARP_CORNER)
    to_map = dem.transform * ~cells
    polygons = [shapely.transform(p, lambda uv: np.column_stack(to_map * uv.T)) for p in polygons]
    return shapely.MultiPolygon(polygons) if len(polygons) > 1 else polygons[0]


def _refuse_touching_parts(domain, name: str) -> None:
    """Refuse a domain whose rings touch at a point (two polygons meeting at a corner, a hole
    at the outer ring or at another hole): valid to GEOS, but the mesh boundary then passes a
    node twice, which no solver export takes."""
    rings = [ring for polygon in getattr(domain, "geoms", [domain])
             for ring in (polygon.exterior, *polygon.interiors)]
    pairs = shapely.STRtree(rings).query(rings, predicate="intersects")
    pairs = pairs[:, pairs[0] < pairs[1]]
    if pairs.shape[1]:
        touch = shapely.intersection(rings[pairs[0, 0]], rings[pairs[1, 0]])
        x, y = shapely.get_coordinates(touch)[0]
        more = f" and {pairs.shape[1] - 1} other place(s)" if pairs.shape[1] > 1 else ""
        raise FloodMeshError(
            f"{name}: the domain touches itself at one point, ({x:.2f}, {y:.2f}){more} "
            "(polygons meeting at a corner, or a hole at the outer ring or at another hole), "
            "which no solver's mesh boundary can; move the parts apart there, or join them "
            "along an edge")


def edge_tolerance(method: str, amount: float, cell_size: float) -> float:
    """The tolerance (m) a run straightens its domain edge within (``domain_from_dem``): its
    break lines' simplification tolerance α·Δ where it gives one ("douglas-peucker", "spline":
    ``amount`` m), else Δ = d/2 (α = 1; "keep-every" states none before it runs), d the
    ``cell_size`` in m."""
    return cell_size / 2 if method == "keep-every" else float(amount)


def user_domain(polygons, dem: Grid, *, name: str = "the boundary polygon",
                tolerance: float | None = None, note=None):
    """The mesh domain inside a user's boundary polygons (their union), holes (buildings,
    islands) included, clipped to the DEM's valid area (``domain_from_dem``, its edge
    straightened within ``tolerance`` m; the area clipped off said to ``note``); refuses
    invalid or non-overlapping ones."""
    # lazy: GEOS loads only when this runs
    from shapely.validation import explain_validity

    polygons = [polygons] if isinstance(polygons, shapely.Geometry) else list(polygons)
    polygons = [p for p in polygons if p is not None and not p.is_empty]
    if not polygons:
        raise FloodMeshError(f"{name} holds no polygon; draw the model domain as a polygon")
    for polygon in polygons:
        if not polygon.is_valid:
            raise FloodMeshError(f"{name} is not a valid polygon ({explain_validity(polygon)}); "
                                 "repair it (QGIS: Fix geometries; GDAL: ogr2ogr -makevalid) "
                                 "and check that its rings do not cross themselves")
    boundary = shapely.union_all(polygons)
    data = domain_from_dem(dem, tolerance=tolerance)
    domain = shapely.intersection(boundary, data)
    least = 4 * dem.cell_size ** 2  # domain_from_dem's least part: 4 cells
    polygons = [p for p in getattr(domain, "geoms", [domain])
                if p.geom_type == "Polygon" and p.area > least]
    if not polygons and domain.area > 0:
        raise FloodMeshError(
            f"{name} is too small to mesh: it covers {domain.area:.3g} m² of the DEM's data "
            f"({boundary.area:.3g} m² in all), and a part needs more than 4 cells, "
            f"{least:.3g} m² at the cell size of {dem.cell_size:g} m; draw a larger domain, "
            "or grid with smaller cells")
    if not polygons:
        raise FloodMeshError(f"{name} does not overlap the DEM's data (the data cover "
                             f"{data.bounds}); check that both are in the same CRS")
    clipped = boundary.area - sum(p.area for p in polygons)
    if note and clipped > max(0.01 * boundary.area, least):
        note(f"{clipped:,.0f} m² ({100 * clipped / boundary.area:.0f} %) of the model domain "
             f"{name} has no data (outside the survey, or in its gaps) and is left out of the "
             "mesh: extend the survey there, or draw the domain within the data")
    domain = shapely.MultiPolygon(polygons) if len(polygons) > 1 else polygons[0]
    _refuse_touching_parts(domain, name)
    if note:
        _note_narrow_parts(domain, dem.cell_size, name, note)
    return domain


# A stretch of the domain narrower than a cell is named where it covers this many cells' area
# or more: a corner sharper than 14 degrees does (its tip narrower than a cell), a square
# corner or the rounding of a cell's staircase does not
NARROW_CELLS = 2.0


def _note_narrow_parts(domain, cell_size: float, name: str, note) -> None:
    """Tell ``note`` where the ``domain`` is narrower than ``cell_size`` m (what an opening by
    half a cell takes away, in pieces of ``NARROW_CELLS`` cells' area or more): meshed as
    drawn, but the DEM holds one height a cell across it, and its triangles, smaller than a
    cell, would set a flood model's time step."""
    half = cell_size / 2
    opened = domain.buffer(-half, join_style="mitre").buffer(half, join_style="mitre")
    pieces = shapely.get_parts(shapely.difference(domain, opened))
    pieces = pieces[shapely.area(pieces) >= NARROW_CELLS * cell_size ** 2]
    if not len(pieces):
        return
    largest = pieces[np.argmax(shapely.area(pieces))]
    x, y = shapely.get_coordinates(shapely.point_on_surface(largest))[0]
    length = float(shapely.length(pieces).sum()) / 2  # a strip's outline runs along it twice
    more = f" and {len(pieces) - 1} other place(s)" if len(pieces) > 1 else ""
    note(f"{name}: the model domain is narrower than a cell ({cell_size:g} m) along some "
         f"{length:,.0f} m, around ({x:.2f}, {y:.2f}){more}; meshed as drawn, but the mesh "
         "there cannot follow the terrain across it (the DEM has one height a cell), and its "
         "triangles, smaller than a cell, would set a flood model's time step: widen the "
         "domain there, or grid with smaller cells")


def build_pslg(lines: list[np.ndarray], domain, *, snap: float,
               drop_sharp_corners: bool = True, corner_gap: float | None = None,
               note=None) -> PSLG:
    """PSLG of break lines (x, y[, z] arrays) inside ``domain`` plus its boundary.

    Lines are clipped to the domain shrunk by ``snap`` (m) so that none ends on or near the
    boundary; all lines are noded at their crossings and touches on a ``snap``/5 precision grid
    (snap rounding), which also merges vertices closer than that and dissolves duplicate or
    overlapping lines. With ``drop_sharp_corners``, break-line segments that meet another
    segment at less than ``SHARP_CORNER`` degrees are shortened near the meeting point (to end
    ``corner_gap`` m, default ``4·snap``, a cell at the chain's snap, off the other one; dropped
    only where that leaves too little): Triangle does not refine the triangles in such a
    corner, so they would break the angle bound; the gap is as wide as the smallest triangles
    there. ``note`` receives one line for each kind of repair made.
    """
    if not snap > 0 or not np.isfinite(snap):
        raise FloodMeshError(f"snapping distance must be positive metres, got {snap}")
    note = note or (lambda message: None)
    domain = _snapped_domain(domain, snap / 5)
    kept = _clipped_lines(lines, domain.buffer(-snap), snap, note)
    vertices, segments = _noded_segments(domain, kept, snap, note)
    # break lines lie at least snap inside the boundary, boundary segments within a grid step
    on_boundary = shapely.distance(
        shapely.points(vertices[segments].mean(axis=1)), domain.boundary) < snap / 2
    segments, on_boundary = _prune_dangles(segments, on_boundary)
    if not on_boundary.any():  # a sliver whose sides noding on the grid merged into one line
        raise _vanishes(domain, snap / 5)
    if drop_sharp_corners:
        vertices, segments = _clear_sharp_corners(vertices, segments, on_boundary,
                                                  4 * snap if corner_gap is None else corner_gap,
                                                  note)
    vertices, segments = _used_vertices(vertices, segments)
    return PSLG(vertices.astype(float), segments.astype(np.int32), _hole_points(domain, snap / 5))


def _usable(line: np.ndarray) -> bool:
    """A line the mesh can carry: (k, 2|3), at least 2 points, finite x and y."""
    return (line.ndim == 2 and line.shape[1] >= 2 and len(line) >= 2
            and bool(np.isfinite(line[:, :2]).all()))


def _clipped_lines(lines, inner, snap: float, note) -> list:
    """The break lines (x, y[, z] arrays) as LineStrings clipped to ``inner`` (the domain shrunk
    by ``snap`` m); those with fewer than 2 points or non-finite coordinates, and those wholly
    outside, are left out, each kind said to ``note``."""
    arrays = [np.asarray(c, float) for c in lines]
    usable = [c[:, :2] for c in arrays if _usable(c)]
    if len(usable) < len(arrays):
        note(f"{len(arrays) - len(usable)} break lines with fewer than 2 points or non-finite "
             "coordinates were left out")
    pieces = [shapely.LineString(c) for c in usable]
    clipped = list(shapely.intersection(pieces, inner)) if pieces else []
    kept = [g for g in clipped if not g.is_empty]
    if len(kept) < len(pieces):
        note(f"{len(pieces) - len(kept)} break lines lie wholly outside the meshed area (or within "
             f"{snap:g} m of its edge) and were left out")
    return kept


def _noded_segments(domain, kept: list, snap: float, note):
    """The ``domain``'s boundary and the ``kept`` break lines noded at their crossings and
    touches on the ``snap``/5 m precision grid: vertices (n, 2) in m and segments (s, 2); the
    lines merged (overlap) or joined there said to ``note``."""
    noded = shapely.unary_union([domain.boundary] + kept, grid_size=snap / 5)
    overlap = (shapely.length(domain.boundary) + sum(g.length for g in kept)
               - shapely.length(noded))
    if overlap > snap:
        note(f"{overlap:.1f} m of break lines duplicated or ran along another line (or the "
             "boundary) and were merged into one")
    parts = [g for g in getattr(noded, "geoms", [noded]) if g.geom_type == "LineString"]
    vertices, segments = _grid_segments([np.asarray(p.coords)[:, :2] for p in parts], snap / 5)
    degree = np.bincount(segments.ravel(), minlength=len(vertices))
    if kept and (degree >= 3).any():
        note(f"break lines were joined at {int((degree >= 3).sum())} nodes where they cross or "
             "touch one another or the boundary")
    return vertices, segments


def _grid_segments(coords: list[np.ndarray], grid: float):
    """The points of the lines ``coords`` ((k, 2) arrays, m) rounded to the ``grid`` m precision
    grid, each once, as vertices (n, 2) in m, and the lines' segments (s, 2) between them: each
    once, lower index first, none of zero length."""
    vertices, inverse = unique_rows(np.round(np.concatenate(coords) / grid).astype(np.int64),
                                    return_inverse=True)
    inverse = inverse.ravel()
    segments = []
    offset = 0
    for c in coords:
        idx = inverse[offset:offset + len(c)]
        segments.append(np.column_stack([idx[:-1], idx[1:]]))
        offset += len(c)
    segments = np.concatenate(segments)
    segments = segments[segments[:, 0] != segments[:, 1]]
    return vertices * grid, unique_rows(np.sort(segments, axis=1))


def _clear_sharp_corners(vertices, segments, on_boundary, gap: float, note):
    """Break-line segments meeting another at less than ``SHARP_CORNER`` degrees shortened to
    end ``gap`` m off it (``_shorten_small_angles``; boundary segments kept), said to
    ``note``: vertices (n, 2) and segments (s, 2)."""
    vertices, segments, shortened, dropped = _shorten_small_angles(
        vertices, segments, on_boundary, SHARP_CORNER, gap)
    if shortened or dropped:
        note(f"{shortened + dropped} break-line segments meeting another at less than "
             f"{SHARP_CORNER:g} degrees were shortened near the meeting point"
             f"{f' ({dropped} too short were left out)' if dropped else ''}, so that the "
             "angle bound holds there")
    return vertices, segments


def _used_vertices(vertices, segments):
    """Only the vertices that ``segments`` end at, in their order, and the segments renumbered
    to them."""
    used = np.unique(segments)
    renumber = np.full(len(vertices), -1)
    renumber[used] = np.arange(len(used))
    return vertices[used], renumber[segments]


def _hole_points(domain, grid: float) -> np.ndarray:
    """A point (h, 2; m) of each area inside the ``domain``'s hull that it leaves out and
    Triangle does not reach from the hull: its holes (not an island inside a hole), and areas
    that parts touching at corners enclose (a gap between cells at a diagonal); areas and
    stretches of hull under the ``grid`` m precision grid do not count."""
    hull = shapely.convex_hull(domain)
    gaps = shapely.get_parts(hull.difference(domain))
    gaps = gaps[(shapely.area(gaps) > grid ** 2) & (shapely.length(
        shapely.intersection(shapely.boundary(gaps), hull.exterior)) < grid)]
    holes = shapely.get_coordinates(shapely.point_on_surface(gaps))
    return np.asarray(holes, float).reshape(-1, 2)


def _prune_dangles(segments, on_boundary):
    """Drop boundary segments that end nowhere (a spike that noding on the precision grid
    collapsed to a line): no area lies beside them, so no triangle could hold them."""
    while True:
        degree = np.bincount(segments.ravel())
        dangling = on_boundary & ((degree[segments[:, 0]] == 1) | (degree[segments[:, 1]] == 1))
        if not dangling.any():
            return segments, on_boundary
        segments, on_boundary = segments[~dangling], on_boundary[~dangling]


def _snapped_domain(domain, grid: float):
    """The domain on the PSLG's precision grid, valid there: spikes and slivers thinner than
    the grid, which would leave boundary segments with no area beside them, are gone."""
    snapped = shapely.set_precision(domain, grid)
    polygons = [g for g in getattr(snapped, "geoms", [snapped])
                if g.geom_type == "Polygon" and g.area > 0]
    if not polygons:
        raise _vanishes(domain, grid)
    snapped = shapely.MultiPolygon(polygons) if len(polygons) > 1 else polygons[0]
    # the same coordinates, without the grid's precision model: GEOS would round what is made
    # from it (the buffer that clips the lines) to the grid, which can make it invalid and the
    # clipping raise a TopologyException ("side location conflict")
    return shapely.set_precision(snapped, 0)


def _vanishes(domain, grid: float) -> FloodMeshError:
    return FloodMeshError(
        f"the area to mesh ({domain.area:.3g} m²) vanishes on a {grid:.3g} m grid: it is "
        "thinner than the snapping distance; use a smaller cell size or a larger area")


def _shorten_small_angles(vertices, segments, fixed, limit, gap):
    """Shorten non-``fixed`` segments at vertices where two segments meet at less than
    ``limit`` degrees: the segment then starts where it lies ``gap`` from the other one (a new
    vertex on it), or is dropped where that would leave less than a fifth of it. Returns
    (vertices, segments, how many shortened, how many dropped)."""
    cos_limit = np.cos(np.radians(limit))
    candidates = _sharp_candidates(np.asarray(vertices, float), np.asarray(segments, np.int64),
                                   cos_limit)
    vertices = np.asarray(vertices, float).tolist()
    segments = np.asarray(segments, np.int64).reshape(-1, 2).tolist()
    keep = [True] * len(segments)
    incident = {}
    for k, (a, b) in enumerate(segments):
        incident.setdefault(a, []).append(k)
        incident.setdefault(b, []).append(k)
    shortened = dropped = 0

    def far_end(k, v):
        return segments[k][1] if segments[k][0] == v else segments[k][0]

    for v in candidates:
        changed = True
        while changed:
            changed = False
            live = [k for k in incident[v] if keep[k]]
            here = np.asarray(vertices[v])
            directions = {}
            for k in live:
                d = np.asarray(vertices[far_end(k, v)]) - here
                directions[k] = (d / np.hypot(*d), float(np.hypot(*d)))
            for i, ki in enumerate(live):
                for kj in live[i + 1:]:
                    cos = float(directions[ki][0] @ directions[kj][0])
                    if cos <= cos_limit:
                        continue
                    # shorten the break-line segment whose far end has fewer other segments
                    candidates = [k for k in (ki, kj) if not fixed[k]]
                    if not candidates:
                        continue
                    k = min(candidates, key=lambda k: len(incident[far_end(k, v)]))
                    unit, length = directions[k]
                    sine = np.sqrt(max(0.0, 1.0 - cos * cos))
                    cut = gap / sine if sine > 0 else np.inf
                    incident[v].remove(k)
                    if cut > 0.8 * length:
                        keep[k] = False
                        dropped += 1
                    else:
                        vertices.append((here + cut * unit).tolist())
                        new = len(vertices) - 1
                        segments[k] = [new, far_end(k, v)]
                        incident[new] = [k]
                        shortened += 1
                    changed = True
                    break
                if changed:
                    break
    segments = np.asarray(segments, np.int64).reshape(-1, 2)[np.asarray(keep, bool)]
    return np.asarray(vertices, float), segments, shortened, dropped


def _sharp_candidates(vertices: np.ndarray, segments: np.ndarray, cos_limit: float) -> list:
    """The vertices where ``_shorten_small_angles`` may act, in the order they first appear in
    ``segments``: those with three or more segments, and those with two that meet at less than
    the limit (the rest, most of a line's vertices, are passed by without a loop in Python;
    shortening a segment keeps its direction, so no other vertex becomes one)."""
    ends = segments.ravel()
    degree = np.bincount(ends, minlength=len(vertices))
    other = segments[:, ::-1].ravel()  # each segment end's far end
    direction = vertices[other] - vertices[ends]
    with np.errstate(invalid="ignore", divide="ignore"):  # a point segment: NaN, as there
        direction /= np.hypot(*direction.T)[:, None]
    order = np.argsort(ends, kind="stable")
    pair = degree[ends[order]] == 2
    first, second = order[pair][0::2], order[pair][1::2]
    sharp = np.zeros(len(vertices), bool)
    sharp[ends[first]] = ~((direction[first] * direction[second]).sum(axis=1) <= cos_limit)
    wanted = (degree >= 3) | sharp
    seen, at = np.unique(ends, return_index=True)
    return [int(v) for v in seen[np.argsort(at, kind="stable")] if wanted[v]]


def triangulate_pslg(pslg: PSLG, *, min_angle: float, max_area: float,
                     conforming: bool = True, points: np.ndarray | None = None,
                     local_areas: np.ndarray | None = None, size_field=None,
                     max_triangles: int = DEFAULT_MAX_TRIANGLES,
                     area: float | None = None, progress=None,
                     cancelled=None) -> tuple[np.ndarray, np.ndarray]:
    """Quality triangulation of a PSLG with Triangle (Shewchuk 1996, doi:10.1007/BFb0014497).

    No angle below ``min_angle`` degrees (except at small input angles), no triangle above
    ``max_area`` m²; ``conforming`` asks for a conforming Delaunay triangulation (switch D).
    ``points`` (k, 2) become mesh vertices too; ``local_areas`` (k, 3) rows of x, y, area (m²)
    then refine (switch r) the triangles holding such a point to at most that area, and
    ``size_field(x, y)`` (m², NaN: no limit) those whose centroid or corners lie where it asks
    for less than their area.
    A mesh estimated above ``max_triangles`` triangles (or the memory available) is refused
    before Triangle starts, from the meshed ``area`` (m², default the vertices' bounding box);
    one whose angle bound needs more (a sliver, features far closer than the area implies) is
    refused when Triangle reaches that many new vertices.
    Returns vertices (n, 2), the PSLG's vertices first, then ``points``, and triangles (m, 3).
    ``progress`` hears the share done after each call to Triangle, ``cancelled`` is polled there.

    The one function that calls Triangle: its helpers only prepare its input or check its output.
    """
    # lazy: Triangle loads only when this runs
    import triangle

    min_angle, max_area, max_triangles = _checked_bounds(pslg, min_angle, max_area,
                                                         max_triangles, area)
    origin, data = _triangle_input(pslg, points)
    # Triangle reads numbers in its switches without exponents ("a2e-05" is area 2, then
    # switch e): write them positional
    # at most max_triangles / 2 new vertices a call (switch S): a mesh has about two triangles
    # a vertex, and the estimate above, from the area, cannot see what the angle bound asks
    # (a 3-vertex sliver 6e-5 m wide and 667 m long took 14 M triangles and 32 s)
    steiner = max(max_triangles // 2, 1)
    quality = f"q{_positional(min_angle)}{'D' if conforming else ''}S{steiner}"
    switches = f"p{quality}a{_positional(max_area)}"
    result = _within_steiner_limit(triangle.triangulate(data, switches), data, steiner,
                                   max_triangles, min_angle)
    if "triangles" not in result or len(result["triangles"]) == 0:
        raise FloodMeshError("Triangle produced no triangles: the domain boundary is not closed "
                             "or a hole point lies outside its hole")
    report(progress, cancelled, 0.5)
    has_local = local_areas is not None and len(local_areas)
    for k in range(REFINE_PASSES if (has_local or size_field is not None) else 0):
        limit = _area_limits(result, origin, max_area, local_areas if has_local else None,
                             size_field)
        refine = _refinement(result, limit, data, max_triangles,
                             local="the size field" if size_field is not None else "refinement")
        if refine is None:  # every triangle keeps its limit
            break
        result = _within_steiner_limit(triangle.triangulate(refine, f"rp{quality}a"), refine,
                                       steiner, max_triangles, min_angle)
        report(progress, cancelled, 0.5 + 0.3 * (k + 1) / REFINE_PASSES)
    # Triangle leaves a triangle below the bound now and then where the angle rule
    # (below_angle_bound) allows none: it declines to split a skinny triangle whose shortest edge
    # joins two segments at equal distances from their common vertex (Miller, Pav & Walkington's
    # concentric shells), at corners of any angle, and the test of that rule is not exact either
    # (about one random PSLG in a thousand, found by tests/core/test_mesh_fuzz.py). Refining its
    # own output again (switch r) splits them: every vertex is an input vertex there, so that
    # rule no longer holds them back, though a pass may leave new ones where it splits a segment.
    # Go on while any are left, pass after pass, and deliver no mesh that breaks the rule.
    for k in range(REPAIR_PASSES):
        if not _angle_defects(result, pslg, min_angle):
            break
        report(progress, cancelled, 0.8 + 0.2 * k / REPAIR_PASSES)
        before = len(result["vertices"])
        repair = {key: result[key] for key in ("vertices", "triangles", "segments")}
        result = _within_steiner_limit(triangle.triangulate(repair, "r" + switches), repair,
                                       steiner, max_triangles, min_angle)
        if len(result["vertices"]) == before:  # Triangle added nothing: it will not again
            break
    _check_angle_rule(result, pslg, min_angle)
    report(progress, None, 1.0)
    return result["vertices"] + origin, result["triangles"].astype(np.int64)


def _within_steiner_limit(result: dict, data: dict, steiner: int, max_triangles: int,
                          min_angle: float) -> dict:
    """Triangle's ``result`` from ``data``, refused where it added ``steiner`` vertices, its
    limit (switch S): the angle bound then asks for more than ``max_triangles`` triangles."""
    if len(result.get("vertices", ())) - len(data["vertices"]) >= steiner:
        raise FloodMeshError(
            f"keeping every angle at {min_angle:g} degrees or more needs more than "
            f"{max_triangles:,} triangles here: the input has features far closer together than "
            "its size (a sliver between lines or boundary, lines almost touching); simplify or "
            "separate them, give a smaller minimum angle, or raise the limit (--max-triangles, "
            "'Maximum number of triangles' in QGIS) if the machine can take it")
    return result


def _checked_bounds(pslg: PSLG, min_angle: float, max_area: float, max_triangles: int,
                    area: float | None) -> tuple[float, float, int]:
    """The min angle (degrees), max area (m²) and max triangles checked; refuses a PSLG that
    Triangle cannot mesh (``_check_pslg``) and a mesh estimated above ``max_triangles``
    triangles from the meshed ``area`` (m², default the vertices' bounding box)."""
    min_angle = check_min_angle(min_angle)
    max_area = check_max_area(max_area)
    max_triangles = check_max_triangles(max_triangles)
    _check_pslg(pslg)
    if area is None:
        area = float(np.prod(np.ptp(pslg.vertices, axis=0)))
    check_triangles(area, max_area, max_triangles, len(pslg.vertices))
    return min_angle, max_area, max_triangles


def _triangle_input(pslg: PSLG, points: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """The origin (2,) in m, the PSLG's lowest x and y, and Triangle's input: the PSLG's
    vertices then ``points`` (k, 2+), its segments and holes, coordinates from that origin."""
    origin = pslg.vertices.min(axis=0)
    vertices = pslg.vertices if points is None else np.vstack([pslg.vertices, points[:, :2]])
    data = {"vertices": vertices - origin, "segments": pslg.segments}
    if len(pslg.holes):
        data["holes"] = pslg.holes - origin
    return origin, data


def _area_limits(result: dict, origin: np.ndarray, max_area: float,
                 local_areas: np.ndarray | None, size_field) -> np.ndarray:
    """Largest area (m²) each triangle of Triangle's ``result`` (coordinates from ``origin``)
    may keep: ``max_area``, less where a ``local_areas`` point (x, y, m²) lies in it or the
    ``size_field`` (m², NaN: no limit) asks for less at its centroid or corners."""
    xy, tris = result["vertices"], result["triangles"]
    limit = np.full(len(tris), float(max_area))
    if local_areas is not None:
        found = containing_triangle(xy, tris, local_areas[:, :2] - origin)
        inside = found >= 0
        np.minimum.at(limit, found[inside], local_areas[inside, 2])
    if size_field is not None:
        # each vertex asked once (it is the corner of some six triangles), then each centroid
        nodes = xy + origin
        centroids = nodes[tris].mean(axis=1)
        at = np.concatenate([nodes, centroids])
        wanted = np.asarray(size_field(at[:, 0], at[:, 1]), float)
        wanted = np.where(np.isfinite(wanted), wanted, np.inf)
        wanted = np.minimum(wanted[tris].min(axis=1), wanted[len(nodes):])
        if (wanted <= 0).any():
            raise FloodMeshError("the size field asks for triangles of 0 m² or less; give "
                                 "positive maximum areas (NaN where there is no limit)")
        limit = np.minimum(limit, wanted)
    return limit


def _refinement(result: dict, limit: np.ndarray, data: dict, max_triangles: int, *,
                local: str) -> dict | None:
    """Triangle's input to refine its ``result`` (switch r) to each triangle's ``limit`` (m²),
    the holes of its first input ``data`` kept; None where every triangle keeps its limit.
    Refuses a refined mesh estimated above ``max_triangles`` triangles (``local`` names what
    asks for it)."""
    xy, tris = result["vertices"], result["triangles"]
    areas = triangle_areas(xy, tris)
    if (areas <= limit * (1 + 1e-9)).all():
        return None
    # the refined mesh, as if every triangle were refined to its limit at once
    equivalent = float(areas.sum() / max(1, (areas / np.minimum(limit, areas)).sum()))
    check_triangles(float(areas.sum()), equivalent, max_triangles, local=local)
    refine = {"vertices": xy, "triangles": tris, "segments": result["segments"],
              "triangle_max_area": limit[:, None]}
    if "holes" in data:
        refine["holes"] = data["holes"]
    return refine


def _check_angle_rule(result: dict, pslg: PSLG, min_angle: float) -> None:
    """Refuse Triangle's ``result`` where triangles still break the angle rule
    (``below_angle_bound``) after the repair passes."""
    left = _angle_defects(result, pslg, min_angle)
    if left:
        raise FloodMeshError(
            f"Triangle left {left} triangles below the minimum angle of {min_angle:g} degrees "
            f"away from any input corner sharper than {SHARP_CORNER:g} degrees after "
            f"{REPAIR_PASSES} repair passes; a slightly different minimum angle or maximum area "
            "meshes this input")


def _angle_defects(result: dict, pslg: PSLG, min_angle: float) -> int:
    """Triangles of Triangle's ``result`` that break the angle rule (the PSLG's vertices keep
    their numbers in Triangle's output)."""
    defects, _ = below_angle_bound(result["vertices"], result["triangles"], pslg.segments,
                                   min_angle)
    return int(defects.sum())


# the least non-zero coordinate Triangle is handed: its exact predicates assume that products
# of coordinate differences do not underflow (Shewchuk 1997); the mesher's fuzz test found
# coordinates of 1e-159 to 1e-309 meshed in seconds in one session and timing out in another
TINY_COORDINATE = 1e-100


def _check_pslg(pslg: PSLG) -> None:
    """Refuse what Triangle's C code would read out of bounds, crash or loop on, or mesh in a
    way no check of ours can follow: too few vertices or segments, non-finite coordinates,
    segment ends that are no vertex, zero-length segments, duplicate vertices, segments that
    cross or overlap, hole points outside or on the boundary."""
    vertices = np.asarray(pslg.vertices, float)
    segments = np.asarray(pslg.segments)
    holes = np.asarray(pslg.holes, float).reshape(-1, 2)
    problem = None
    if vertices.ndim != 2 or vertices.shape[1:] != (2,) or len(vertices) < 3:
        problem = "it has fewer than 3 vertices"
    elif not np.isfinite(vertices).all() or not np.isfinite(holes).all():
        problem = "it has coordinates that are not finite numbers"
    elif ((vertices != 0) & (np.abs(vertices) < TINY_COORDINATE)).any():
        problem = (f"it has coordinates nearer 0 than {TINY_COORDINATE:g} but not 0, whose "
                   "products underflow in Triangle's exact arithmetic")
    elif segments.ndim != 2 or segments.shape[1:] != (2,) or len(segments) < 3:
        problem = "it has fewer than 3 segments, so no closed boundary"
    elif not np.issubdtype(segments.dtype, np.integer) or segments.min() < 0 \
            or segments.max() >= len(vertices):
        problem = "a segment ends at a vertex that does not exist"
    elif (segments[:, 0] == segments[:, 1]).any():
        problem = "a segment has zero length"
    elif len(unique_rows(vertices)) < len(vertices):
        problem = "two vertices coincide"
    elif _nearly_coincide(vertices):
        problem = ("two vertices are closer than a billionth of its extent, closer than its "
                   "coordinates can be meshed apart")
    elif _segments_cross(vertices, segments):
        problem = "segments cross or overlap"
    elif len(holes) and not _holes_inside(vertices, segments, holes):
        problem = "a hole point lies outside the vertices' hull or on a segment"
    if problem:
        raise FloodMeshError(f"the PSLG cannot be meshed: {problem} (build it with build_pslg, "
                             "which cleans break lines and the boundary)")


def _nearly_coincide(vertices: np.ndarray) -> bool:
    """Whether two distinct vertices lie within 1e-9 of the vertices' extent of each other:
    Triangle's mesh of such a pair (found by the mesher's fuzz test: vertices 2e-13 m apart
    in 800 m) left a segment unrecovered in some runs and not in others."""
    # lazy: SciPy loads only when this runs
    from scipy.spatial import cKDTree

    span = float(np.ptp(vertices, axis=0).max())
    return bool(cKDTree(vertices).query_pairs(1e-9 * span, output_type="ndarray").size)


def _segments_cross(vertices: np.ndarray, segments: np.ndarray) -> bool:
    """Whether any two segments meet other than at a shared end (crossing, touching inside,
    overlapping): Triangle would insert vertices there that no check of ours knows about."""
    lines = shapely.linestrings(vertices[segments])
    i, j = shapely.STRtree(lines).query(lines, predicate="intersects")
    pairs = i < j
    i, j = i[pairs], j[pairs]
    if not len(i):
        return False
    shared = (segments[i][:, :, None] == segments[j][:, None, :]).any(axis=(1, 2))
    if not shared.all():
        return True
    # lazy: numba loads only when this runs
    from .._kernels.mesh import overlap_beyond_shared_end

    # segments sharing an end may meet only there (an exact test: GEOS's overlay of each pair
    # took half of this check)
    ends = np.asarray(segments, np.int64)
    return bool(overlap_beyond_shared_end(np.ascontiguousarray(vertices, float), ends[i],
                                          ends[j]))


def _holes_inside(vertices: np.ndarray, segments: np.ndarray, holes: np.ndarray) -> bool:
    """Whether every hole point lies strictly inside the vertices' convex hull and off every
    segment: Triangle crashed (segmentation fault) on a hole point on its bounding box."""
    points = shapely.points(holes)
    hull = shapely.MultiPoint(vertices).convex_hull
    lines = shapely.MultiLineString(list(vertices[segments]))
    tolerance = 1e-9 * float(np.ptp(vertices, axis=0).max())
    return bool(shapely.contains(hull, points).all()
                and (shapely.distance(points, lines) > tolerance).all())


def _positional(value: float) -> str:
    """A number as Triangle's switch parser reads it: digits and a point, no exponent, and as
    many digits as give the same float back."""
    return np.format_float_positional(value, trim="-")


def size_from_slope(slope: Grid, *, max_area: float, min_area: float, s_crit: float) -> Grid:
    """A size field (local maximum triangle area, m²) from slope (degrees): ``max_area`` on
    flat ground, falling geometrically to ``min_area`` where the slope reaches ``s_crit``."""
    if not 0 < min_area <= max_area:
        raise FloodMeshError(f"the size field needs 0 < minimum area <= maximum area, got "
                             f"{min_area} and {max_area} m²")
    t = np.clip(slope.values / s_crit, 0.0, 1.0)
    return slope.with_values(max_area * (min_area / max_area) ** t)


def containing_triangle(xy: np.ndarray, triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index of the triangle holding each point, -1 outside the mesh (on an edge or a node: the
    lowest-index triangle holding it; see ``mesh_kernels``)."""
    # lazy: numba loads only when this runs
    from .._kernels.mesh import locate

    return locate(xy, triangles, points)[0]


class OwnLines(list):
    """The modeller's own lines as read from their file, checked there with the file's name and
    feature ids (``refuse_height_clashes``): ``build_mesh`` takes them without a second check."""


def refuse_height_clashes(lines, cell_size: float, *, name: str | None = None,
                          features=None) -> None:
    """Refuse own lines ((k, 3), z NaN where 2-D) that cross or touch at heights more than
    ``JOIN_RISE`` apart (a bridge deck's line over a road's): the mesh's node there takes one
    z, and the other line gets a spike. That rise is the one a detected line's end may take to
    join another line (``hydraulic_lines``): within it the heights of two surveys meeting agree;
    beyond it one is a wall's or a deck's. Lines closer than ``cell_size``/20 m, the grid
    ``build_mesh`` nodes lines on (its snap, d/4, over 5), share a node there. The message names
    the file ``name`` and its ``features`` (ids, one a line), or else own_lines[i]."""
    clashes = height_clashes(lines, near=cell_size / 20, rise=JOIN_RISE)
    if not len(clashes):
        return
    x, y, z1, z2, i, j = clashes[0]
    i, j = int(i), int(j)
    if features is None:
        which = (f"own_lines[{i}] crosses itself" if i == j
                 else f"own_lines[{i}] and own_lines[{j}] cross")
    else:
        which = (f"feature {features[i]} crosses itself" if features[i] == features[j]
                 else f"features {features[i]} and {features[j]} cross")
    places = len(np.unique(np.round(clashes[:, :2] / (cell_size / 20)), axis=0))
    more = f" (and at {places - 1} other place(s))" if places > 1 else ""
    raise FloodMeshError(
        f"{f'{name}: ' if name else ''}{which} at ({x:.2f}, {y:.2f}) at heights {z1:.2f} and "
        f"{z2:.2f} m, {abs(z1 - z2):.2f} m apart{more}; a mesh node has one height, so one line "
        "would get a spike there. Cut one line short of the crossing (a 2-D mesh holds no deck "
        "above a road), give both the same height there, or give the lines without Z so that "
        "the mesh takes the terrain's")


def build_mesh(dem: Grid, lines: list, *, own_lines: list = (), min_angle: float = 25.0,
               max_area: float = 100.0, conforming: bool = False, snap: float | None = None,
               domain=None, points: np.ndarray | None = None,
               local_areas: np.ndarray | None = None, size_field: Grid | None = None,
               max_triangles: int = DEFAULT_MAX_TRIANGLES, corner_gap: float | None = None,
               note=None, progress=None, cancelled=None) -> Mesh:
    """Mesh the DEM's valid area honouring the break lines (``BreakLine``s or (n, 2|3) arrays)
    and the modeller's ``own_lines`` ((k, 3) arrays, NaN z where 2-D; refused where two cross at
    heights apart, ``refuse_height_clashes``); node z along an own line
    where it has z there (linear along its segment, ``z_along_lines``: the surveyed crest
    between its vertices too, and at a crossing with a break line), else from the lines where a
    node is a break-line vertex, from ``points`` (k, 3: measurements put into the TIN) at
    theirs, else bilinear from the DEM. ``local_areas`` (x, y, m²) refine locally;
    ``size_field`` is a grid of local maximum areas (m², NaN: no limit; see
    ``size_from_slope``). A mesh estimated above ``max_triangles`` triangles is refused before
    any work; ``note`` receives the repairs made to the lines. Lines meeting at a sharp corner
    stop ``corner_gap`` m (default: 4 ``snap``, the cell size at the default snap: the spacing
    ``lines_for_hydraulics`` keeps lines apart by) short of each other (see ``build_pslg``).
    ``progress`` hears the share done by stages (PSLG built, meshed, node z fitted, numbered),
    ``cancelled`` is polled between them."""
    min_angle = check_min_angle(min_angle)
    max_area = check_max_area(max_area)
    max_triangles = check_max_triangles(max_triangles)
    checked = isinstance(own_lines, OwnLines)  # read from a file and checked there
    lines, own_lines = line_list(lines, "lines"), line_list(own_lines, "own_lines")
    dem = usable_dem(dem, "the DEM", note)  # -9999, inf: nodata, as in a DEM file
    if points is not None:  # (N, 3); as the readers leave them out
        points = step_points(points, "the points put into the mesh", note)
    # BreakLines as the tracer gives
    lines = [getattr(line, "coords", line) for line in lines]
    lines_near(lines, dem.bounds, "break line", "the DEM")
    lines_near(own_lines, dem.bounds, "own line", "the DEM")
    if not checked:
        refuse_height_clashes(own_lines, dem.cell_size)
    lines += own_lines
    snap = dem.cell_size / 4 if snap is None else snap
    domain = domain_from_dem(dem) if domain is None else domain
    check_triangles(domain.area, max_area, max_triangles)
    pslg = build_pslg(lines, domain, snap=snap, corner_gap=corner_gap, note=note)
    report(progress, cancelled, 0.1)
    if points is not None and len(points):
        points = _points_apart(points, pslg.vertices, domain, snap, segments=pslg.segments)
    vertices, triangles = triangulate_pslg(pslg, min_angle=min_angle, max_area=max_area,
                                           conforming=conforming, points=points,
                                           local_areas=local_areas,
                                           size_field=None if size_field is None else
                                           lambda x, y: nearest_value(size_field, x, y),
                                           max_triangles=max_triangles, area=domain.area,
                                           progress=part(progress, 0.1, 0.8),
                                           cancelled=cancelled)
    z = bilinear(dem, vertices[:, 0], vertices[:, 1])
    if points is not None and len(points):
        z[len(pslg.vertices):len(pslg.vertices) + len(points)] = points[:, 2]
    at, value = _line_vertex_z(lines, vertices, precision=snap / 5)
    z[at] = value
    # lazy: numba loads only when this runs
    from ..engine.nearest import z_along_lines

    # the own lines the PSLG kept, as _line_vertex_z takes them
    kept = [c for c in (np.asarray(c, float) for c in own_lines) if _usable(c)]
    _, at, value = z_along_lines(vertices, kept, within=snap / 5)
    z[at] = value
    if not np.isfinite(z).all():
        raise FloodMeshError(f"{int((~np.isfinite(z)).sum())} mesh nodes fall where the DEM has no "
                             "data; check the domain against the DEM's nodata")
    report(progress, cancelled, 0.9)
    mesh = in_spatial_order(Mesh(np.column_stack([vertices, z]),
                                 _counter_clockwise(vertices, triangles), dem.crs,
                                 pslg.segments.astype(np.int64)))
    report(progress, None, 1.0)
    return mesh


def honoured_lines(mesh: Mesh) -> list[np.ndarray]:
    """The break lines the mesh honours, as (k, 3) arrays of its nodes (x, y, z in m): its
    input segments off its boundary (``build_pslg`` keeps every line inside the domain), joined
    where two meet end to end. What a solver that builds its own mesh (HEC-RAS) is given."""
    on_edge = np.zeros(len(mesh.nodes), bool)
    on_edge[edge_nodes(mesh.triangles, boundary_edges(mesh.triangles)).ravel()] = True
    inner = mesh.segments[~on_edge[mesh.segments].any(axis=1)]
    if not len(inner):
        return []
    merged = shapely.line_merge(shapely.MultiLineString(list(mesh.nodes[inner])))
    return [np.asarray(part.coords) for part in shapely.get_parts(merged)]


def in_spatial_order(mesh: Mesh) -> Mesh:
    """The mesh numbered for a solver: triangles along a Z-order curve (Morton 1966), nodes as
    the triangles first use them (``arrays.spatial_order``), the input segments renumbered with
    them; every writer then writes that order. A Hilbert curve (Hilbert 1891; Skilling 2004)
    or reverse Cuthill-McKee (George 1971) were no faster in ANUGA: 2.48 and 2.46 ms per step
    against 2.42 (Triangle's numbering 2.62) on a Merewether mesh of 26,194 triangles."""
    order, triangles = spatial_order(mesh.nodes, mesh.triangles)
    number = np.full(len(mesh.nodes), -1, np.int64)
    number[order] = np.arange(len(order))
    segments = number[mesh.segments]
    return replace(mesh, nodes=mesh.nodes[order], triangles=triangles,
                   segments=segments[(segments >= 0).all(axis=1)])


def _points_apart(points: np.ndarray, vertices: np.ndarray, domain, snap: float, *,
                  segments: np.ndarray | None = None) -> np.ndarray:
    """The points inside ``domain`` (by more than ``snap``) that lie at least ``snap`` from the
    PSLG's vertices, its ``segments`` and each other (first come, first kept). A point a hair
    off a segment (a DEM cell centre on a traced line) would make Triangle refine towards it
    without end, leaving nodes on one spot and a triangulation no point can be located in."""
    # lazy: SciPy loads only when this runs
    from scipy.spatial import cKDTree

    inside = shapely.contains_xy(domain.buffer(-snap), points[:, 0], points[:, 1])
    points = points[inside]
    if not len(points):
        return points.reshape(0, 3)
    far = cKDTree(vertices).query(points[:, :2])[0] >= snap
    points = points[far]
    if segments is not None and len(segments) and len(points):
        tree = shapely.STRtree(shapely.linestrings(vertices[np.asarray(segments)]))
        hit = tree.query(shapely.points(points[:, :2]), predicate="dwithin", distance=snap)[0]
        points = np.delete(points, np.unique(hit), axis=0)
    keep = np.ones(len(points), bool)
    for i, j in sorted(cKDTree(points[:, :2]).query_pairs(snap)):
        if keep[i]:
            keep[j] = False
    return points[keep]


def _line_vertex_z(lines, vertices: np.ndarray, precision: float):
    """(indices of ``vertices``, their z): the mesh vertices that are a vertex of one of
    ``lines`` ((k, 3) arrays; (k, 2) ones carry no z) on the ``precision`` grid (m), with that
    vertex's z where finite; where lines share a vertex, the last line's."""
    # the lines the PSLG kept (_clipped_lines said which it left out)
    arrays = [np.asarray(c, float) for c in lines]
    with_z = [c for c in arrays if _usable(c) and c.shape[1] >= 3]
    if not with_z or not len(vertices):
        return np.zeros(0, np.int64), np.zeros(0)
    line_xyz = np.concatenate(with_z)
    pair = np.dtype([("x", np.int64), ("y", np.int64)])

    def keys(xy):
        return np.ascontiguousarray(np.round(xy[:, :2] / precision).astype(np.int64)).view(
            pair).ravel()

    line_keys = keys(line_xyz)
    order = np.argsort(line_keys, kind="stable")  # equal keys stay in line order ...
    ordered = line_keys[order]
    last = np.append(ordered[1:] != ordered[:-1], True)  # ... and the last of each wins
    known, known_z = ordered[last], line_xyz[order[last], 2]
    mesh_keys = keys(np.asarray(vertices, float))
    pos = np.minimum(np.searchsorted(known, mesh_keys), len(known) - 1)
    # field by field: == on structured arrays promotes their dtypes first, and a Ctrl-C landing
    # there comes out as numpy's TypeError ("Cannot compare structured arrays ...")
    found = known[pos]
    hit = ((found["x"] == mesh_keys["x"]) & (found["y"] == mesh_keys["y"])
           & np.isfinite(known_z[pos]))
    return np.flatnonzero(hit), known_z[pos[hit]]


def _counter_clockwise(xy, triangles):
    p = xy[triangles]
    cross = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
             - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    out = triangles.copy()
    out[cross < 0] = out[cross < 0][:, [0, 2, 1]]
    return out


def triangle_areas(nodes: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Plan areas (m²) of the triangles; negative for clockwise ones."""
    p = nodes[triangles][:, :, :2]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


def triangle_angles(nodes: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Interior plan angles (m, 3) in degrees at each triangle's three corners."""
    p = nodes[triangles][:, :, :2]
    angles = np.empty((len(triangles), 3))
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        cos = (u * v).sum(axis=1) / (np.hypot(*u.T) * np.hypot(*v.T))
        angles[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angles


def input_corner_angles(nodes: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Smallest angle (degrees) between the input segments meeting at each node; 180 where fewer
    than two segments meet."""
    smallest = np.full(len(nodes), 180.0)
    segments = np.asarray(segments, np.int64).reshape(-1, 2)
    if not len(segments):
        return smallest
    # every segment as two directions, one from each end; around a node the smallest angle
    # between any two is between two that follow each other by polar angle (the last and
    # the first included), so only those pairs are measured (a loop over nodes did them all)
    at = np.concatenate([segments[:, 0], segments[:, 1]])
    d = nodes[np.concatenate([segments[:, 1], segments[:, 0]]), :2] - nodes[at, :2]
    d = d / np.hypot(*d.T)[:, None]
    order = np.lexsort((np.arctan2(d[:, 1], d[:, 0]), at))
    at, d = at[order], d[order]
    first = np.r_[True, at[1:] != at[:-1]]
    last = np.r_[first[1:], True]
    following = np.arange(1, len(at) + 1)
    following[last] = np.flatnonzero(first)[np.cumsum(first)[last] - 1]
    pair = following != np.arange(len(at))  # a node with one segment has no angle
    cos = np.clip((d[pair] * d[following[pair]]).sum(axis=1), -1, 1)
    best = np.full(len(nodes), -np.inf)
    np.maximum.at(best, at[pair], cos)
    met = best > -np.inf
    smallest[met] = np.degrees(np.arccos(best[met]))
    return smallest


def below_angle_bound(nodes: np.ndarray, triangles: np.ndarray, segments: np.ndarray,
                      min_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The angle rule of the delivered mesh, the one place it is stated (the mesher's repair
    passes, report.json and the tests all ask it): every triangle keeps ``min_angle`` except at
    an input corner sharper than ``SHARP_CORNER`` (60°), where no mesher can (Miller, Pav &
    Walkington 2003). A triangle is at such a corner when the corner is one of its vertices or
    its centroid lies closer to the corner than the longest input segment at it.

    ``nodes`` are the mesh's (the PSLG's vertices first, as ``triangulate_pslg`` returns them),
    ``segments`` the PSLG's. Returns two boolean arrays over the triangles: below the bound and
    not excused (a defect), and below the bound at a sharp input corner (excused).
    """
    xy = np.asarray(nodes)[:, :2]
    xy = xy - xy.min(axis=0) if len(xy) else xy  # local coordinates keep the digits of UTM
    small = triangle_angles(xy, triangles).min(axis=1) < min_angle - 1e-6
    excused = np.zeros(len(triangles), bool)
    sharp = np.nonzero(input_corner_angles(xy, segments) < SHARP_CORNER)[0]
    candidates = np.nonzero(small)[0]
    if len(candidates) and len(sharp):
        seg_len = np.hypot(*(xy[segments[:, 0]] - xy[segments[:, 1]]).T)
        reach = np.zeros(len(xy))
        np.maximum.at(reach, segments[:, 0], seg_len)
        np.maximum.at(reach, segments[:, 1], seg_len)
        centroids = xy[triangles[candidates]].mean(axis=1)
        near = (np.hypot(centroids[:, None, 0] - xy[None, sharp, 0],
                         centroids[:, None, 1] - xy[None, sharp, 1])
                <= reach[sharp][None, :]).any(axis=1)
        excused[candidates] = near | np.isin(triangles[candidates], sharp).any(axis=1)
    return small & ~excused, small & excused


def mesh_quality(mesh: Mesh, *, min_angle: float, max_area: float) -> dict:
    """Smallest angle, largest area, and how many triangles break either bound (the angle bound
    as ``below_angle_bound`` states it: those at sharp input corners are counted apart)."""
    areas = triangle_areas(mesh.nodes, mesh.triangles)
    min_angles = triangle_angles(mesh.nodes, mesh.triangles).min(axis=1)
    corner = input_corner_angles(mesh.nodes, mesh.segments)
    below, at_input_corner = below_angle_bound(mesh.nodes, mesh.triangles, mesh.segments,
                                               min_angle)
    return {
        "nodes": int(len(mesh.nodes)),
        "triangles": int(len(mesh.triangles)),
        "min_angle_deg": float(min_angles.min()),
        "max_area_m2": float(areas.max()),
        "n_below_min_angle": int(below.sum()),
        "n_small_input_angles": int(at_input_corner.sum()),
        "smallest_input_angle_deg": float(corner.min()) if len(corner) else 180.0,
        "n_above_max_area": int((areas > max_area * (1 + 1e-9)).sum()),
        "all_counter_clockwise": bool((areas > 0).all()),
        "n_missing_segments": missing_segments(mesh.nodes, mesh.triangles, mesh.segments),
        "n_duplicate_nodes": int(len(mesh.nodes) - len(unique_rows(
            np.round(mesh.nodes[:, :2] / 1e-6).astype(np.int64)))),
    }


def missing_segments(nodes: np.ndarray, triangles: np.ndarray, segments: np.ndarray) -> int:
    """How many input segments are not a chain of mesh edges (nodes on the segment, in order,
    each consecutive pair an edge of a triangle)."""
    if not len(segments):
        return 0
    # the edges as sorted keys (a Python set of them took some 600 B a triangle)
    n = np.int64(len(nodes))
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1).astype(np.int64)
    keys = np.unique(edges[:, 0] * n + edges[:, 1])
    del edges

    def are_edges(pairs):  # (k, 2) node pairs, lower index first
        wanted = pairs[:, 0] * n + pairs[:, 1]
        at = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
        return keys[at] == wanted

    ordered = np.sort(np.asarray(segments, np.int64), axis=1)
    split = ordered[~are_edges(ordered)]  # segments that Triangle split with Steiner points
    if not len(split):
        return 0
    # lazy: numba loads only when a segment was split
    from ..engine.nearest import point_index

    # each split segment's chain: the nodes on it, in order along it, all at once
    xy = nodes[:, :2]
    a, b = split[:, 0], split[:, 1]
    d = xy[b] - xy[a]
    length = np.hypot(d[:, 0], d[:, 1])
    indptr, near = point_index(xy).neighbours((xy[a] + xy[b]) / 2,
                                              length / 2 * (1 + 1e-9) + 1e-9)
    owner = np.repeat(np.arange(len(split)), np.diff(indptr))
    rel, d, length = xy[near] - xy[a[owner]], d[owner], length[owner]
    t = (rel[:, 0] * d[:, 0] + rel[:, 1] * d[:, 1]) / length ** 2
    off = np.abs(rel[:, 0] * d[:, 1] - rel[:, 1] * d[:, 0]) / length
    on = np.flatnonzero((off <= 1e-6 * np.maximum(1.0, length)) & (t >= -1e-9)
                        & (t <= 1 + 1e-9))
    on = on[np.lexsort((t[on], owner[on]))]  # by segment, then along it (stable)
    owner, chain = owner[on], near[on]
    first = np.r_[True, owner[1:] != owner[:-1]]
    bad = first & (chain != a[owner]) & (chain != b[owner])
    within = ~first[1:]  # consecutive chain nodes of one segment
    pairs = np.sort(np.column_stack([chain[:-1], chain[1:]])[within], axis=1)
    bad[1:][within] |= ~are_edges(pairs)
    return int(len(np.unique(owner[bad])))


def boundary_loops(nodes: np.ndarray, triangles: np.ndarray) -> list[np.ndarray]:
    """The mesh boundary as closed loops of node indices (the first node not repeated).

    Boundary edges are those used by exactly one triangle. Each loop follows them with the mesh
    on its left: outer rings run counter-clockwise and come first (largest first), holes run
    clockwise and follow (largest first). Each loop starts at its lowest node index. Where the
    boundary touches itself at a node, the walk keeps to the wedge of mesh it is tracing.
    """
    tri = np.asarray(triangles, np.int64)
    xy = np.asarray(nodes, float)[:, :2]
    ccw = triangle_areas(xy, tri) >= 0
    tri = np.where(ccw[:, None], tri, tri[:, [0, 2, 1]])
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    n = len(xy)
    keys = directed[:, 0] * n + directed[:, 1]
    shared = np.unique(keys, return_counts=True)
    if (shared[1] > 1).any():
        raise FloodMeshError("the mesh has triangles that overlap or repeat an edge in the same "
                             "direction; fix the mesh (each edge may border at most two "
                             "triangles, on opposite sides)")
    edges = directed[~np.isin(keys, directed[:, 1] * n + directed[:, 0])]
    outgoing: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        outgoing.setdefault(a, []).append(b)
    loops = []
    for start in sorted(outgoing):
        while outgoing.get(start):
            loop, prev, node = [start], None, start
            while True:
                candidates = outgoing[node]
                if len(candidates) == 1 or prev is None:
                    nxt = candidates[0]
                else:  # a pinch node: the first edge clockwise from the way back
                    back = np.arctan2(*(xy[prev] - xy[node])[::-1])
                    turn = [(back - np.arctan2(*(xy[c] - xy[node])[::-1])) % (2 * np.pi)
                            for c in candidates]
                    nxt = candidates[int(np.argmin(turn))]
                candidates.remove(nxt)
                if nxt == start:
                    break
                loop.append(nxt)
                prev, node = node, nxt
            loops.append(np.array(loop, np.int64))
    areas = [_ring_area(xy[loop]) for loop in loops]
    order = sorted(range(len(loops)), key=lambda k: (areas[k] < 0, -abs(areas[k])))
    return [loops[k] for k in order]


def _ring_area(xy: np.ndarray) -> float:
    """Signed area (m²) of a closed ring of points, positive counter-clockwise."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
