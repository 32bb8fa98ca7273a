"""Meshing: break lines and the domain boundary as a PSLG, refined by Triangle.

``triangulate_pslg`` is the only function that calls Triangle (Shewchuk's library is free for
non-commercial use only), so another backend can replace it in one place.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from pyproj import CRS

from .errors import FloodMeshError
from .raster import Grid, bilinear

MAX_MIN_ANGLE = 34.0  # Triangle's refinement stops terminating reliably above about 33.8 degrees
# Triangle leaves skinny triangles in the concentric shells it builds around input corners
# sharper than 60 degrees (Miller, Pav & Walkington 2003), so break lines may not form them.
SHARP_CORNER = 60.0


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


def domain_from_dem(dem: Grid, *, min_area: float = 0.0):
    """The area of valid DEM cells as a (Multi)Polygon through the outer cell centres.

    Parts smaller than ``min_area`` (m²) are dropped; the staircase outline is simplified within
    half a cell.
    """
    from rasterio.features import shapes

    valid = np.isfinite(dem.values).astype(np.uint8)
    parts = [shapely.geometry.shape(geom) for geom, value in
             shapes(valid, mask=valid.astype(bool), transform=dem.transform, connectivity=4)
             if value == 1]
    d = dem.cell_size
    domain = shapely.unary_union(parts).buffer(-d / 2, join_style="mitre")
    domain = domain.simplify(d / 2, preserve_topology=True)
    polygons = [p for p in getattr(domain, "geoms", [domain])
                if p.geom_type == "Polygon" and p.area > max(min_area, 4 * d * d)]
    if not polygons:
        raise FloodMeshError("the DEM has no area of valid cells large enough to mesh; check its "
                             "nodata and the cell size")
    return shapely.MultiPolygon(polygons) if len(polygons) > 1 else polygons[0]


def user_domain(polygons, dem: Grid, *, name: str = "the boundary polygon"):
    """The mesh domain inside a user's boundary polygons (their union), holes (buildings,
    islands) included, clipped to the DEM's valid area; refuses invalid or non-overlapping
    ones."""
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
    data = domain_from_dem(dem)
    domain = shapely.intersection(boundary, data)
    polygons = [p for p in getattr(domain, "geoms", [domain])
                if p.geom_type == "Polygon" and p.area > 4 * dem.cell_size ** 2]
    if not polygons:
        raise FloodMeshError(f"{name} does not overlap the DEM's data (the data cover "
                             f"{data.bounds}); check that both are in the same CRS")
    return shapely.MultiPolygon(polygons) if len(polygons) > 1 else polygons[0]


def build_pslg(lines: list[np.ndarray], domain, *, snap: float,
               drop_sharp_corners: bool = True) -> PSLG:
    """PSLG of break lines (x, y[, z] arrays) inside ``domain`` plus its boundary.

    Lines are clipped to the domain shrunk by ``snap`` (m) so that none ends on or near the
    boundary; all lines are noded at their crossings on a ``snap``/5 precision grid, which also
    merges vertices closer than that. With ``drop_sharp_corners``, break-line segments that
    meet another segment at less than ``SHARP_CORNER`` degrees are dropped: Triangle does not
    refine the triangles in such a corner, so they would break the angle bound.
    """
    if not snap > 0:
        raise FloodMeshError(f"snapping distance must be positive metres, got {snap}")
    inner = domain.buffer(-snap)
    pieces = [shapely.LineString(np.asarray(c)[:, :2]) for c in lines if len(c) >= 2]
    clipped = shapely.intersection(pieces, inner) if pieces else []
    geoms = [domain.boundary] + [g for g in clipped if not g.is_empty]
    noded = shapely.unary_union(geoms, grid_size=snap / 5)
    parts = [g for g in getattr(noded, "geoms", [noded]) if g.geom_type == "LineString"]
    coords = [np.asarray(p.coords)[:, :2] for p in parts]
    allpts = np.concatenate(coords)
    vertices, inverse = np.unique(np.round(allpts / (snap / 5)).astype(np.int64), axis=0,
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
    segments = np.unique(np.sort(segments, axis=1), axis=0)
    vertices = vertices * (snap / 5)
    if drop_sharp_corners:
        on_boundary = shapely.distance(
            shapely.points(vertices[segments].mean(axis=1)), domain.boundary) < snap / 10
        segments = _drop_small_angles(vertices, segments, on_boundary, SHARP_CORNER)
        used = np.unique(segments)
        renumber = np.full(len(vertices), -1)
        renumber[used] = np.arange(len(used))
        vertices, segments = vertices[used], renumber[segments]
    holes = [shapely.Polygon(ring).representative_point().coords[0]
             for poly in getattr(domain, "geoms", [domain]) for ring in poly.interiors]
    return PSLG(vertices.astype(float), segments.astype(np.int32),
                np.asarray(holes, float).reshape(-1, 2))


def _drop_small_angles(vertices, segments, fixed, limit):
    """Remove non-``fixed`` segments until no two segments meet at less than ``limit`` degrees."""
    keep = np.ones(len(segments), bool)
    incident = {}
    for k, (a, b) in enumerate(segments):
        incident.setdefault(a, []).append(k)
        incident.setdefault(b, []).append(k)
    cos_limit = np.cos(np.radians(limit))
    for v, ks in incident.items():
        changed = True
        while changed:
            changed = False
            live = [k for k in ks if keep[k]]
            directions = {}
            for k in live:
                other = segments[k, 1] if segments[k, 0] == v else segments[k, 0]
                d = vertices[other] - vertices[v]
                directions[k] = d / np.hypot(*d)
            for i, ki in enumerate(live):
                for kj in live[i + 1:]:
                    if directions[ki] @ directions[kj] > cos_limit:
                        # drop the break-line segment whose far end has fewer other segments
                        candidates = [k for k in (ki, kj) if not fixed[k]]
                        if not candidates:
                            continue
                        drop = min(candidates, key=lambda k: len(
                            incident[segments[k, 1] if segments[k, 0] == v else segments[k, 0]]))
                        keep[drop] = False
                        changed = True
                        break
                if changed:
                    break
    return segments[keep]


def triangulate_pslg(pslg: PSLG, *, min_angle: float, max_area: float,
                     conforming: bool = True, points: np.ndarray | None = None,
                     local_areas: np.ndarray | None = None,
                     size_field=None) -> tuple[np.ndarray, np.ndarray]:
    """Quality triangulation of a PSLG with Triangle (Shewchuk 1996, doi:10.1007/BFb0014497).

    No angle below ``min_angle`` degrees (except at small input angles), no triangle above
    ``max_area`` m²; ``conforming`` asks for a conforming Delaunay triangulation (switch D).
    ``points`` (k, 2) become mesh vertices too; ``local_areas`` (k, 3) rows of x, y, area (m²)
    then refine (switch r) the triangles holding such a point to at most that area, and
    ``size_field(x, y)`` (m², NaN: no limit) those whose centroid or corners lie where it asks
    for less than their area.
    Returns vertices (n, 2), the PSLG's vertices first, then ``points``, and triangles (m, 3).
    """
    import triangle

    if not 0 < min_angle <= MAX_MIN_ANGLE:
        raise FloodMeshError(
            f"minimum angle must be above 0 and at most {MAX_MIN_ANGLE} degrees, got {min_angle}: "
            "above that Delaunay refinement may never finish (25 to 30 is usual)")
    if not max_area > 0:
        raise FloodMeshError(f"maximum triangle area must be positive m², got {max_area}")
    origin = pslg.vertices.min(axis=0)
    vertices = pslg.vertices if points is None else np.vstack([pslg.vertices, points[:, :2]])
    data = {"vertices": vertices - origin, "segments": pslg.segments}
    if len(pslg.holes):
        data["holes"] = pslg.holes - origin
    quality = f"q{min_angle:.6g}{'D' if conforming else ''}"
    result = triangle.triangulate(data, f"p{quality}a{max_area:.6g}")
    if "triangles" not in result or len(result["triangles"]) == 0:
        raise FloodMeshError("Triangle produced no triangles: the domain boundary is not closed "
                             "or a hole point lies outside its hole")
    has_local = local_areas is not None and len(local_areas)
    for _ in range(12 if (has_local or size_field is not None) else 0):
        xy, tris = result["vertices"], result["triangles"]
        limit = np.full(len(tris), float(max_area))
        if has_local:
            found = _containing_triangle(xy, tris, local_areas[:, :2] - origin)
            inside = found >= 0
            np.minimum.at(limit, found[inside], local_areas[inside, 2])
        if size_field is not None:
            corners = xy[tris] + origin
            at = np.concatenate([corners, corners.mean(axis=1, keepdims=True)], axis=1)
            wanted = np.asarray(size_field(at[..., 0].ravel(), at[..., 1].ravel()), float)
            wanted = np.where(np.isfinite(wanted), wanted, np.inf).reshape(-1, 4).min(axis=1)
            if (wanted <= 0).any():
                raise FloodMeshError("the size field asks for triangles of 0 m² or less; give "
                                     "positive maximum areas (NaN where there is no limit)")
            limit = np.minimum(limit, wanted)
        if (triangle_areas(xy, tris) <= limit * (1 + 1e-9)).all():
            break
        refine = {"vertices": xy, "triangles": tris, "segments": result["segments"],
                  "triangle_max_area": limit[:, None]}
        if len(pslg.holes):
            refine["holes"] = data["holes"]
        result = triangle.triangulate(refine, f"rp{quality}a")
    return result["vertices"] + origin, result["triangles"].astype(np.int64)


def size_from_slope(slope: Grid, *, max_area: float, min_area: float, s_crit: float) -> Grid:
    """A size field (local maximum triangle area, m²) from slope (degrees): ``max_area`` on
    flat ground, falling geometrically to ``min_area`` where the slope reaches ``s_crit``."""
    if not 0 < min_area <= max_area:
        raise FloodMeshError(f"the size field needs 0 < minimum area <= maximum area, got "
                             f"{min_area} and {max_area} m²")
    t = np.clip(slope.values / s_crit, 0.0, 1.0)
    return slope.with_values(max_area * (min_area / max_area) ** t)


def _containing_triangle(xy: np.ndarray, triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index of the triangle holding each point, -1 outside the mesh."""
    from matplotlib.tri import Triangulation

    return Triangulation(xy[:, 0], xy[:, 1], triangles).get_trifinder()(points[:, 0],
                                                                        points[:, 1])


def build_mesh(dem: Grid, lines: list[np.ndarray], *, min_angle: float = 25.0,
               max_area: float = 100.0, conforming: bool = True, snap: float | None = None,
               domain=None, points: np.ndarray | None = None,
               local_areas: np.ndarray | None = None, size_field: Grid | None = None) -> Mesh:
    """Mesh the DEM's valid area honouring the break lines; node z from the lines where a node is
    a break-line vertex, from ``points`` (k, 3: measurements put into the TIN) at theirs, else
    bilinear from the DEM. ``local_areas`` (x, y, m²) refine locally; ``size_field`` is a grid of
    local maximum areas (m², NaN: no limit; see ``size_from_slope``)."""
    snap = dem.cell_size / 4 if snap is None else snap
    domain = domain_from_dem(dem) if domain is None else domain
    pslg = build_pslg(lines, domain, snap=snap)
    if points is not None and len(points):
        points = _points_apart(np.asarray(points, float), pslg.vertices, domain, snap)
    vertices, triangles = triangulate_pslg(pslg, min_angle=min_angle, max_area=max_area,
                                           conforming=conforming, points=points,
                                           local_areas=local_areas,
                                           size_field=None if size_field is None else
                                           lambda x, y: _nearest_value(size_field, x, y))
    z = bilinear(dem, vertices[:, 0], vertices[:, 1])
    if points is not None and len(points):
        z[len(pslg.vertices):len(pslg.vertices) + len(points)] = points[:, 2]
    known = _line_vertex_z(lines, precision=snap / 5)
    if known:
        keys = map(tuple, np.round(vertices / (snap / 5)).astype(np.int64).tolist())
        for i, key in enumerate(keys):
            value = known.get(key)
            if value is not None and np.isfinite(value):
                z[i] = value
    if not np.isfinite(z).all():
        raise FloodMeshError(f"{int((~np.isfinite(z)).sum())} mesh nodes fall where the DEM has no "
                             "data; check the domain against the DEM's nodata")
    return Mesh(np.column_stack([vertices, z]), _counter_clockwise(vertices, triangles), dem.crs,
                pslg.segments.astype(np.int64))


def _nearest_value(grid: Grid, x, y) -> np.ndarray:
    """The grid's value in the cell holding each point (NaN outside the grid)."""
    r, c = grid.fractional_index(x, y)
    r, c = np.rint(r).astype(np.int64), np.rint(c).astype(np.int64)
    inside = (r >= 0) & (r < grid.shape[0]) & (c >= 0) & (c < grid.shape[1])
    out = np.full(np.shape(r), np.nan)
    out[inside] = grid.values[r[inside], c[inside]]
    return out


def _points_apart(points: np.ndarray, vertices: np.ndarray, domain, snap: float) -> np.ndarray:
    """The points inside ``domain`` (by more than ``snap``) that lie at least ``snap`` from the
    PSLG's vertices and from each other (first come, first kept)."""
    from scipy.spatial import cKDTree

    inside = shapely.contains_xy(domain.buffer(-snap), points[:, 0], points[:, 1])
    points = points[inside]
    if not len(points):
        return points.reshape(0, 3)
    far = cKDTree(vertices).query(points[:, :2])[0] >= snap
    points = points[far]
    keep = np.ones(len(points), bool)
    for i, j in sorted(cKDTree(points[:, :2]).query_pairs(snap)):
        if keep[i]:
            keep[j] = False
    return points[keep]


def _line_vertex_z(lines, precision):
    known = {}
    for c in lines:
        c = np.asarray(c)
        if c.shape[1] < 3:
            continue
        for key, zval in zip(map(tuple, np.round(c[:, :2] / precision).astype(np.int64).tolist()),
                             c[:, 2]):
            known[key] = zval
    return known


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
    incident = {}
    for a, b in segments:
        incident.setdefault(a, []).append(b)
        incident.setdefault(b, []).append(a)
    for v, others in incident.items():
        d = nodes[others, :2] - nodes[v, :2]
        d /= np.hypot(*d.T)[:, None]
        cos = np.clip(d @ d.T, -1, 1)
        np.fill_diagonal(cos, -1)
        smallest[v] = np.degrees(np.arccos(cos.max())) if len(others) > 1 else 180.0
    return smallest


def mesh_quality(mesh: Mesh, *, min_angle: float, max_area: float) -> dict:
    """Smallest angle, largest area, and how many triangles break either bound.

    Triangles below the angle bound within reach of an input corner sharper than 60° (the
    shortest segment at that corner) are input-bound, not refinable, and counted apart.
    """
    from scipy.spatial import cKDTree

    areas = triangle_areas(mesh.nodes, mesh.triangles)
    min_angles = triangle_angles(mesh.nodes, mesh.triangles).min(axis=1)
    corner = input_corner_angles(mesh.nodes, mesh.segments)
    small = min_angles < min_angle - 1e-6
    at_input_corner = np.zeros_like(small)
    sharp = np.nonzero(corner < SHARP_CORNER)[0]
    if small.any() and sharp.size:
        reach = np.full(len(mesh.nodes), 0.0)
        seg_len = np.hypot(*(mesh.nodes[mesh.segments[:, 0], :2]
                             - mesh.nodes[mesh.segments[:, 1], :2]).T)
        for k, (a, b) in enumerate(mesh.segments):
            for v in (a, b):
                reach[v] = seg_len[k] if reach[v] == 0 else min(reach[v], seg_len[k])
        centroids = mesh.nodes[mesh.triangles[small]][:, :, :2].mean(axis=1)
        dist, nearest = cKDTree(mesh.nodes[sharp, :2]).query(centroids)
        at_input_corner[np.nonzero(small)[0]] = dist <= reach[sharp[nearest]]
    return {
        "nodes": int(len(mesh.nodes)),
        "triangles": int(len(mesh.triangles)),
        "min_angle_deg": float(min_angles.min()),
        "max_area_m2": float(areas.max()),
        "n_below_min_angle": int((small & ~at_input_corner).sum()),
        "n_small_input_angles": int(at_input_corner.sum()),
        "smallest_input_angle_deg": float(corner.min()) if len(corner) else 180.0,
        "n_above_max_area": int((areas > max_area * (1 + 1e-9)).sum()),
        "all_counter_clockwise": bool((areas > 0).all()),
        "n_missing_segments": missing_segments(mesh.nodes, mesh.triangles, mesh.segments),
        "n_duplicate_nodes": int(len(mesh.nodes) - len(np.unique(
            np.round(mesh.nodes[:, :2] / 1e-6).astype(np.int64), axis=0))),
    }


def missing_segments(nodes: np.ndarray, triangles: np.ndarray, segments: np.ndarray) -> int:
    """How many input segments are not a chain of mesh edges (nodes on the segment, in order,
    each consecutive pair an edge of a triangle)."""
    from scipy.spatial import cKDTree

    if not len(segments):
        return 0
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    edge_set = set(map(tuple, edges.tolist()))
    split = [seg for seg in np.sort(segments, axis=1).tolist() if tuple(seg) not in edge_set]
    xy = nodes[:, :2]
    tree = cKDTree(xy) if split else None
    missing = 0
    for a, b in split:  # segments that Triangle split with Steiner points
        d = xy[b] - xy[a]
        length = float(np.hypot(*d))
        near = np.array(tree.query_ball_point((xy[a] + xy[b]) / 2, length / 2 * (1 + 1e-9)
                                              + 1e-9))
        rel = xy[near] - xy[a]
        t = rel @ d / length ** 2
        off = np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]) / length
        on = near[(off <= 1e-6 * max(1.0, length)) & (t >= -1e-9) & (t <= 1 + 1e-9)]
        chain = on[np.argsort(t[np.isin(near, on)], kind="stable")]
        pairs = np.sort(np.column_stack([chain[:-1], chain[1:]]), axis=1)
        if chain[0] != a and chain[0] != b or not all(map(edge_set.__contains__,
                                                          map(tuple, pairs.tolist()))):
            missing += 1
    return missing


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
