"""Meshing with break lines (floodmesh.core.mesh): quality bounds, honoured break lines, holes."""
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from scipy.spatial import cKDTree

from floodmesh.core.errors import FloodMeshError
from floodmesh.core.mesh import (PSLG, build_mesh, build_pslg, domain_from_dem, mesh_quality,
                                 triangle_angles, triangulate_pslg)
from floodmesh.core.raster import Grid

ORIGIN = np.array([500_000.0, 6_000_000.0])
N = 60  # cells each way, d = 1 m: the domain runs through the outer cell centres, 0.5..59.5


def _plane(x, y):
    """z of the test plane at local coordinates."""
    return 0.1 * x - 0.05 * y + 12.0


def _plane_dem(hole=None):
    x = np.arange(N) + 0.5
    y = N - (np.arange(N) + 0.5)
    xx, yy = np.meshgrid(x, y)
    z = _plane(xx, yy)
    if hole is not None:
        z[hole] = np.nan
    transform = Affine(1.0, 0.0, ORIGIN[0], 0.0, -1.0, ORIGIN[1] + N)
    return Grid(z, transform, CRS.from_epsg(25832))


def _line(local_xy):
    """A break line (k, 3) in map coordinates with z on the plane."""
    xy = np.asarray(local_xy, float)
    return np.column_stack([xy + ORIGIN, _plane(xy[:, 0], xy[:, 1])])


DIAGONAL = _line([(10, 12), (18, 20), (26, 28), (34, 36), (42, 44), (48, 50)])
L_SHAPE = _line([(8, 52), (16, 52), (28, 52), (28, 44), (28, 36)])
OUTWARD = _line([(45, 20), (52, 20), (70, 20)])  # leaves the domain at x = 59.5: clipped


def _edges(triangles):
    e = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                triangles[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def _angles_and_areas(nodes, triangles):
    """Interior angles (degrees) by atan2(|cross|, dot) and signed areas, computed here."""
    p = nodes[triangles][:, :, :2]
    angles = []
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        dot = (u * v).sum(axis=1)
        angles.append(np.degrees(np.arctan2(np.abs(cross), dot)))
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    signed = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                    - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    return np.column_stack(angles), signed


def _covered_length(nodes, edges, a, b, tol=1e-6):
    """Total length of the mesh edges lying on the straight segment a-b."""
    ab = b - a
    length = np.hypot(*ab)
    rel = nodes[:, :2] - a
    t = rel @ ab / length ** 2
    off = np.abs(rel[:, 0] * ab[1] - rel[:, 1] * ab[0]) / length
    on = (off < tol) & (t > -tol / length) & (t < 1 + tol / length)
    both = on[edges[:, 0]] & on[edges[:, 1]]
    e = edges[both]
    return np.hypot(*(nodes[e[:, 1], :2] - nodes[e[:, 0], :2]).T).sum()


@pytest.fixture(scope="module")
def plane_mesh():
    dem = _plane_dem()
    lines = [DIAGONAL, L_SHAPE, OUTWARD]
    return dem, lines, build_mesh(dem, lines, min_angle=25, max_area=20)


def test_quality_bounds(plane_mesh):
    """mesh_quality and an independent computation agree: no angle below 25 degrees, no area above
    20 m², every triangle counter-clockwise, and the triangles tile the 59 x 59 m domain."""
    dem, _, mesh = plane_mesh
    q = mesh_quality(mesh, min_angle=25, max_area=20)
    assert q["min_angle_deg"] >= 25 - 1e-6
    assert q["max_area_m2"] <= 20
    assert q["n_below_min_angle"] == 0 and q["n_above_max_area"] == 0
    assert q["all_counter_clockwise"] is True
    assert q["nodes"] == len(mesh.nodes) and q["triangles"] == len(mesh.triangles)

    angles, areas = _angles_and_areas(mesh.nodes, mesh.triangles)
    np.testing.assert_allclose(angles.sum(axis=1), 180.0, atol=1e-9)
    assert angles.min() >= 25 - 1e-6
    assert (areas > 0).all()
    assert areas.max() <= 20 * (1 + 1e-9)
    assert areas.sum() == pytest.approx(59.0 * 59.0, rel=1e-9)
    assert q["min_angle_deg"] == pytest.approx(angles.min(), abs=1e-9)
    assert q["max_area_m2"] == pytest.approx(areas.max(), rel=1e-12)
    assert mesh.crs == dem.crs


def test_break_lines_are_chains_of_mesh_edges(plane_mesh):
    """Every surviving break-line vertex is a mesh node, and every PSLG segment (break lines after
    clipping, and the boundary) is covered end to end by mesh edges lying on it."""
    dem, lines, mesh = plane_mesh
    nodes = mesh.nodes
    tree = cKDTree(nodes[:, :2])
    snap = dem.cell_size / 4
    inner = shapely.Polygon([(0.5, 0.5), (59.5, 0.5), (59.5, 59.5), (0.5, 59.5)]).buffer(-snap)
    for line in lines:
        local = line[:, :2] - ORIGIN
        inside = shapely.contains_xy(inner, local[:, 0], local[:, 1])
        dist, _ = tree.query(line[inside, :2])
        assert dist.max() < 1e-6
    assert (~shapely.contains_xy(inner, *(OUTWARD[:, :2] - ORIGIN).T)).sum() == 1

    pslg = build_pslg([c for c in lines], domain_from_dem(dem), snap=snap)
    edges = _edges(mesh.triangles)
    # 4 boundary sides + 5 diagonal + 4 L-shape + 2 clipped outward segments
    assert len(pslg.segments) == 15
    for i, j in pslg.segments:
        a, b = pslg.vertices[i], pslg.vertices[j]
        expected = np.hypot(*(b - a))
        assert _covered_length(nodes, edges, a, b) == pytest.approx(expected, rel=1e-9, abs=1e-6)
    # the clipped outward line ends just inside the boundary (snap from it) and is a segment chain
    end = np.array([59.5 - snap, 20.0]) + ORIGIN
    assert tree.query(end)[0] < 1e-6
    assert _covered_length(nodes, edges, OUTWARD[0, :2], end) == pytest.approx(59.5 - snap - 45)


def test_nodes_are_unique_and_on_the_plane(plane_mesh):
    """No two nodes coincide and every node's z is the plane's (bilinear is exact on a plane)."""
    _, _, mesh = plane_mesh
    nodes = mesh.nodes
    assert cKDTree(nodes[:, :2]).query_pairs(1e-6) == set()
    local = nodes[:, :2] - ORIGIN
    np.testing.assert_allclose(nodes[:, 2], _plane(local[:, 0], local[:, 1]), rtol=0, atol=1e-6)
    assert np.unique(mesh.triangles).size == len(nodes), "a node belongs to no triangle"


def test_nan_hole_is_not_meshed():
    """A 20 x 20 cell NaN hole: no triangle centroid inside it, all node z finite, and the mesh area
    is the domain's (59² minus the hole through the valid cell centres around it, 21²). The L-shaped
    line reaches into the hole and is clipped there."""
    dem = _plane_dem(hole=(slice(20, 40), slice(20, 40)))
    mesh = build_mesh(dem, [DIAGONAL[:2], L_SHAPE], min_angle=25, max_area=20)
    assert np.isfinite(mesh.nodes[:, 2]).all()
    centroids = mesh.nodes[mesh.triangles][:, :, :2].mean(axis=1) - ORIGIN
    in_hole = ((centroids > 20) & (centroids < 40)).all(axis=1)
    assert not in_hole.any()
    _, areas = _angles_and_areas(mesh.nodes, mesh.triangles)
    assert areas.sum() == pytest.approx(59.0 ** 2 - 21.0 ** 2, rel=1e-9)
    local = mesh.nodes[:, :2] - ORIGIN
    np.testing.assert_allclose(mesh.nodes[:, 2], _plane(local[:, 0], local[:, 1]), atol=1e-6)


@pytest.mark.parametrize("min_angle", [40.0, 0.0, -5.0])
def test_min_angle_out_of_range(min_angle):
    """A minimum angle of 0 or above 34 degrees is refused, the message naming 34."""
    with pytest.raises(FloodMeshError, match="34"):
        build_mesh(_plane_dem(), [DIAGONAL], min_angle=min_angle, max_area=20)


@pytest.mark.parametrize("max_area", [0.0, -10.0])
def test_max_area_not_positive(max_area):
    """A maximum area of 0 or less is refused."""
    with pytest.raises(FloodMeshError, match="area"):
        build_mesh(_plane_dem(), [DIAGONAL], min_angle=25, max_area=max_area)


def test_crossing_break_lines_are_noded():
    """Two break lines crossing in an X: the crossing point (30, 30) is a mesh node with the plane's
    z, and both lines are chains of mesh edges through it."""
    a = _line([(10, 10), (50, 50)])
    b = _line([(10, 50), (50, 10)])
    mesh = build_mesh(_plane_dem(), [a, b], min_angle=25, max_area=20)
    crossing = ORIGIN + [30.0, 30.0]
    dist, idx = cKDTree(mesh.nodes[:, :2]).query(crossing)
    assert dist < 1e-6
    assert mesh.nodes[idx, 2] == pytest.approx(_plane(30.0, 30.0), abs=1e-6)
    edges = _edges(mesh.triangles)
    for line in (a, b):
        for p, q in ((line[0, :2], crossing), (crossing, line[1, :2])):
            assert _covered_length(mesh.nodes, edges, p, q) == pytest.approx(np.hypot(*(q - p)))


# ---------------------------------------------------------------------------------------------
# regressions found by tests/core/test_mesh_fuzz.py
def test_tiny_max_area_reaches_triangle_unchanged():
    """Triangle reads its switches without exponents: 2e-05 m² was read as 2 m² (then switch
    e). A 0.1 m square at 2e-05 m² has every triangle within the bound."""
    square = PSLG(np.array([[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]]) + ORIGIN,
                  np.array([[0, 1], [1, 2], [2, 3], [3, 0]], np.int32), np.empty((0, 2)))
    vertices, triangles = triangulate_pslg(square, min_angle=25, max_area=2e-5)
    _, areas = _angles_and_areas(np.column_stack([vertices, np.zeros(len(vertices))]), triangles)
    assert areas.max() <= 2e-5 * (1 + 1e-9) and len(triangles) > 500


FUZZ_PSLG_31 = PSLG(
    np.array([[0.0, 2.242], [3.448, 6.044], [3.998, 4.4], [5.822, 6.282], [7.236, 2.202],
              [7.444, 0.0], [7.916, 2.202], [13.64, 2.234], [16.398, 5.276], [16.84, 3.96],
              [18.298, 5.466], [19.428, 2.202], [19.596, 0.44], [19.972, 2.202]]),
    np.array([[0, 1], [0, 5], [1, 2], [2, 3], [3, 6], [4, 5], [4, 6], [7, 8], [7, 12], [8, 9],
              [9, 10], [10, 13], [11, 12], [11, 13]], np.int32), np.empty((0, 2)))


def test_conforming_refinement_leaves_no_triangle_below_the_bound():
    """Two quadrilaterals, no input angle below 71 degrees: Triangle with q31 and D leaves one
    24.7-degree triangle; triangulate_pslg refines its output again until none is left."""
    import triangle

    raw = triangle.triangulate({"vertices": FUZZ_PSLG_31.vertices,
                                "segments": FUZZ_PSLG_31.segments},
                               "pq31.008265836121716a15.871787322642925D")
    assert triangle_angles(raw["vertices"], raw["triangles"]).min() < 25  # Triangle's own result
    vertices, triangles = triangulate_pslg(FUZZ_PSLG_31, min_angle=31.008265836121716,
                                           max_area=15.871787322642925)
    assert triangle_angles(vertices, triangles).min() >= 31.008265836121716
    np.testing.assert_array_equal(vertices[:len(FUZZ_PSLG_31.vertices)], FUZZ_PSLG_31.vertices)


def test_hole_point_on_the_bounding_box_is_refused_not_a_crash():
    """Triangle crashed with a segmentation fault on this hexagon with a hole point outside it
    at the bounding box's edge (found by the fuzz test): it is refused before Triangle runs."""
    pslg = PSLG(np.array([[58.28367861, 24.12484253], [90.85922587, 0.0],
                          [25.36434167, 94.79197394], [28.98888217, 28.5714], [0.0, 0.0],
                          [14.76912979, 0.37040256]]) + [500_000.0, 5_700_000.0],
                np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 0]], np.int32),
                np.array([[0.0, 50.92378231]]) + [500_000.0, 5_700_000.0])
    with pytest.raises(FloodMeshError, match="hole point lies outside"):
        triangulate_pslg(pslg, min_angle=31.44310859687332, max_area=0.029743290100072917)


@pytest.mark.parametrize("vertices, segments, problem", [
    ([[0, 0], [1, 0]], [[0, 1], [1, 0], [0, 1]], "fewer than 3 vertices"),
    ([[0, 0], [1, 0], [np.nan, 1]], [[0, 1], [1, 2], [2, 0]], "not finite"),
    ([[0, 0], [1, 0], [0, 1]], [[0, 1], [1, 2]], "fewer than 3 segments"),
    ([[0, 0], [1, 0], [0, 1]], [[0, 1], [1, 2], [2, 3]], "does not exist"),
    ([[0, 0], [1, 0], [0, 1]], [[0, 1], [1, 2], [2, 2]], "zero length"),
    ([[0, 0], [1, 0], [0, 1], [1, 0]], [[0, 1], [1, 2], [2, 0]], "coincide"),
    ([[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 2], [1, 3], [0, 1], [2, 3]], "cross"),
    ([[0, 0], [2, 0], [1, 0], [1, 1]], [[0, 1], [0, 2], [1, 3], [3, 0]], "overlap"),
])
def test_triangle_is_handed_only_sound_pslgs(vertices, segments, problem):
    pslg = PSLG(np.array(vertices, float) + ORIGIN, np.array(segments, np.int32),
                np.empty((0, 2)))
    with pytest.raises(FloodMeshError, match=problem):
        triangulate_pslg(pslg, min_angle=25, max_area=1)
