"""Cheap hydraulic checks of a mesh, before any simulation: what an explicit finite-volume
solver (ANUGA, TUFLOW FV, BASEMENT, …) will make of it.

An explicit shallow-water solver's global time step is bounded by the CFL condition of its
smallest wet cell: dt ≤ C · r_in / (|u| + √(g·h)), with r_in a triangle's inradius (ANUGA
uses exactly this with C = 1). One tiny triangle therefore sets the cost of the whole run.
"""
from __future__ import annotations

import numpy as np

from ..engine.arrays import boundary_edges, edge_nodes
from ..raster import bilinear

G = 9.81
CHECK_DEPTH_M = 1.0        # the depth the time-step estimate is stated for
SMALL_INRADIUS_M = 0.15    # triangles under this inradius are counted (issue 16's figure)
EDGE_BAND_M = 2.0          # "at the domain edge": within this distance of the boundary


def inradii(nodes: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Inradius of each triangle (m): 2·area / perimeter."""
    # lazy: PROJ and GEOS load only when this runs
    from .mesh import triangle_areas

    p = nodes[triangles][:, :, :2]
    perimeter = np.hypot(*(p - np.roll(p, 1, axis=1)).transpose(2, 0, 1)).sum(axis=1)
    return 2 * np.abs(triangle_areas(nodes, triangles)) / np.maximum(perimeter, 1e-300)


def cfl_time_step(inradius: np.ndarray, depth: float = CHECK_DEPTH_M, speed: float = 0.0,
                  courant: float = 1.0) -> float:
    """The explicit time step (s) the smallest of ``inradius`` (m) allows at water ``depth``
    (m) and flow ``speed`` (m/s): C · r_in / (|u| + √(g·h))."""
    return float(courant * np.min(inradius) / (speed + np.sqrt(G * depth)))


def neighbours(triangles):
    """(m, 3): the neighbour across each triangle's edge e (opposite vertex e), -1 at the
    boundary."""
    m = len(triangles)
    a = np.concatenate([triangles[:, 1], triangles[:, 2], triangles[:, 0]])
    b = np.concatenate([triangles[:, 2], triangles[:, 0], triangles[:, 1]])
    key = np.minimum(a, b).astype(np.int64) * (triangles.max() + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = np.nonzero(ks[1:] == ks[:-1])[0]
    nb = np.full(3 * m, -1)
    nb[order[same]] = order[same + 1] % m
    nb[order[same + 1]] = order[same] % m
    return nb.reshape(3, m).T


def collinear_wall_stencils(nodes, triangles) -> np.ndarray:
    """Triangles with one edge on the boundary whose centroid and its two neighbours' centroids
    are collinear: a least-squares gradient from them is singular, and ANUGA's DE0 turns it
    into NaN as soon as water is there. A node fanning over three or more straight boundary
    segments makes one (Triangle's evenly split boundary segments make them often)."""
    nb = neighbours(triangles)
    c = nodes[triangles][:, :, :2].mean(axis=1)
    one = np.nonzero((nb < 0).sum(axis=1) == 1)[0]
    inner = nb[one]
    pairs = np.sort(inner, axis=1)[:, 1:]  # the two neighbours (the -1 sorts first)
    p0, p1, p2 = c[one], c[pairs[:, 0]], c[pairs[:, 1]]
    cross = ((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1])
             - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0]))
    scale = np.hypot(*(p1 - p0).T) * np.hypot(*(p2 - p0).T)
    return one[np.abs(cross) <= 1e-6 * scale]


def _edge_lengths(nodes, pairs):
    return np.hypot(*(nodes[pairs[:, 0], :2] - nodes[pairs[:, 1], :2]).T)


def hydraulic_checks(nodes: np.ndarray, triangles: np.ndarray, *, own_lines=(),
                     detected_lines=(), dem=None, depth: float = CHECK_DEPTH_M,
                     small_inradius: float = SMALL_INRADIUS_M,
                     edge_band: float = EDGE_BAND_M) -> dict:
    """The report's ``hydraulics`` section: the smallest inradius, the CFL time step it allows
    at ``depth`` (and a uniform mesh's of the same node count, for comparison), how many
    triangles have an inradius under ``small_inradius`` and how many of those lie within
    ``edge_band`` of the domain edge, the smallest inradius there (where a flood flows in and
    out, a small triangle costs every step), the shortest edge at the domain edge and the
    closest node to it, and the shortest
    edge at the points where the modeller's ``own_lines`` cross ``detected_lines`` (lists of
    (k, 2+) coordinate arrays); with the ``dem`` (a Grid), how far the mesh's surface along
    the own lines (crests the modeller chose) falls below the DEM's."""
    # lazy: SciPy loads only when this runs
    from scipy.spatial import cKDTree

    # lazy: PROJ and GEOS load only when this runs
    from .mesh import triangle_areas
    from ..io.report import mesh_edges

    nodes = np.asarray(nodes, float)
    triangles = np.asarray(triangles)
    r = inradii(nodes, triangles)
    edges = mesh_edges(triangles)
    lengths = _edge_lengths(nodes, edges)
    bnodes = edge_nodes(triangles, boundary_edges(triangles))
    on_edge = np.unique(bnodes)
    centroids = nodes[triangles][:, :, :2].mean(axis=1)
    small = np.nonzero(r < small_inradius)[0]
    near_edge, edge_r = 0, None
    if on_edge.size:
        dist, _ = cKDTree(nodes[on_edge, :2]).query(centroids)
        near_edge = int((dist[small] <= edge_band).sum())
        if (dist <= edge_band).any():
            edge_r = float(r[dist <= edge_band].min())
    touches_edge = np.isin(edges, on_edge).any(axis=1)
    # a uniform mesh of equilateral triangles with the same node count over the same area
    uniform_area = np.abs(triangle_areas(nodes, triangles)).sum() / max(len(triangles), 1)
    uniform_r = np.sqrt(uniform_area / (3 * np.sqrt(3)))  # equilateral: A = 3√3 r²
    smallest = int(np.argmin(r))
    report = {
        "check_depth_m": depth,
        "min_inradius_m": float(r[smallest]),
        "min_inradius_at": [float(v) for v in centroids[smallest]],
        "median_inradius_m": float(np.median(r)),
        "cfl_time_step_s": cfl_time_step(r, depth),
        "uniform_mesh_cfl_time_step_s": cfl_time_step(np.array([uniform_r]), depth),
        "small_inradius_threshold_m": small_inradius,
        "n_small_inradius": int(small.size),
        "n_small_inradius_near_edge": near_edge,
        "edge_band_m": edge_band,
        "min_inradius_near_edge_m": edge_r,
        "n_collinear_wall_stencils": int(len(collinear_wall_stencils(nodes, triangles))),
        "min_edge_m": float(lengths.min()),
        "min_edge_at_domain_edge_m": float(lengths[touches_edge].min()) if touches_edge.any()
        else None,
        "min_node_distance_to_edge_m": _inner_node_distance(nodes, bnodes),
    }
    crossings = _crossings(own_lines, detected_lines)
    report["n_own_detected_crossings"] = len(crossings)
    report["min_edge_at_crossings_m"] = None
    if len(crossings):
        _, nearest = cKDTree(nodes[:, :2]).query(crossings)
        at = np.isin(edges, nearest).any(axis=1)
        report["min_edge_at_crossings_m"] = float(lengths[at].min()) if at.any() else None
    report.update(crest_lowering(nodes, triangles, own_lines, dem) if dem is not None
                  else {})
    report["cfl_slowdown_vs_uniform"] = (report["uniform_mesh_cfl_time_step_s"]
                                         / max(report["cfl_time_step_s"], 1e-300))
    return report


def _inner_node_distance(nodes, bnodes) -> float | None:
    """The smallest distance (m) from a node off the boundary to the boundary's edges (each
    node's nearest edge from a tree of them: the distance to one multi-line of all edges took
    time in proportion to nodes × edges)."""
    # lazy: numba loads only when this runs
    from ..engine.nearest import nearest_line

    inner = np.setdiff1d(np.arange(len(nodes)), bnodes)
    if not inner.size or not len(bnodes):
        return None
    return float(nearest_line(nodes[inner, :2], list(nodes[bnodes][:, :, :2]))[1].min())


def crest_lowering(nodes, triangles, lines, dem, step: float = 0.5) -> dict:
    """The mesh's surface (linear on each triangle) against the DEM (bilinear) every ``step``
    m along ``lines``: the largest and the mean lowering (DEM − mesh, m); None without lines."""
    # lazy: GEOS loads only when this runs
    import shapely

    # lazy: numba loads only when this runs
    from .._kernels.mesh import locate

    points = [np.asarray(shapely.segmentize(shapely.LineString(np.asarray(c)[:, :2]),
                                            step).coords) for c in lines if len(c) >= 2]
    if not points:
        return {"crest_max_lowering_m": None, "crest_mean_lowering_m": None}
    xy = np.vstack(points)
    surface = locate(nodes, triangles, xy, nodes[:, 2])[1]
    lowering = bilinear(dem, xy[:, 0], xy[:, 1]) - surface
    lowering = lowering[np.isfinite(lowering)]
    return {"crest_max_lowering_m": float(lowering.max()) if lowering.size else None,
            "crest_mean_lowering_m": float(lowering.mean()) if lowering.size else None}


def _crossings(own_lines, detected_lines) -> np.ndarray:
    """(k, 2) points where any own line meets any detected line."""
    # lazy: GEOS loads only when this runs
    import shapely

    own = [shapely.LineString(np.asarray(c)[:, :2]) for c in own_lines if len(c) >= 2]
    detected = [shapely.LineString(np.asarray(c)[:, :2]) for c in detected_lines if len(c) >= 2]
    if not own or not detected:
        return np.empty((0, 2))
    meet = shapely.intersection(shapely.union_all(own), shapely.union_all(detected))
    points = shapely.get_coordinates(meet)
    return points[:, :2]
