"""Meshing with break lines (core.steps.mesh): quality bounds, honoured break lines, holes."""
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from scipy.spatial import cKDTree

from floodmesh.core.errors import FloodMeshError
from floodmesh.core.steps.mesh import (PSLG, build_mesh, build_pslg, domain_from_dem, mesh_quality,
                                       triangle_angles, triangle_areas, triangulate_pslg)
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
    assert q["n_missing_segments"] == 0 and q["n_duplicate_nodes"] == 0

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


def test_missing_segments_and_duplicate_nodes_are_counted(plane_mesh):
    """The segment check finds a segment whose chain of edges is broken (the triangles along it
    removed), and the duplicate count finds a node repeated."""
    from floodmesh.core.steps.mesh import Mesh, missing_segments

    dem, _, mesh = plane_mesh
    assert missing_segments(mesh.nodes, mesh.triangles, mesh.segments) == 0
    # a segment split by Triangle (not itself an edge) and one that is an edge
    edges = {tuple(sorted(e)) for t in mesh.triangles.tolist()
             for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    split = [s for s in mesh.segments.tolist() if tuple(sorted(s)) not in edges]
    whole = [s for s in mesh.segments.tolist() if tuple(sorted(s)) in edges]
    assert split and whole
    for a, b in (split[0], whole[0]):
        on_line = np.isin(mesh.triangles, [a, b]).any(axis=1)
        assert missing_segments(mesh.nodes, mesh.triangles[~on_line], np.array([[a, b]])) == 1
    doubled = Mesh(np.vstack([mesh.nodes, mesh.nodes[:1]]), mesh.triangles, mesh.crs,
                   mesh.segments)
    assert mesh_quality(doubled, min_angle=25, max_area=20)["n_duplicate_nodes"] == 1


# ---------------------------------------------------------------------------------------------
# a user's domain polygon (with holes) and their own lines
def _write_polygons(path, polygons, crs="EPSG:25832"):
    import fiona

    schema = {"geometry": "Polygon", "properties": {"name": "str"}}
    with fiona.open(path, "w", driver="GPKG", schema=schema, crs=crs) as dst:
        for k, poly in enumerate(polygons):
            dst.write({"geometry": shapely.geometry.mapping(poly), "properties": {"name": str(k)}})


def test_user_boundary_with_a_hole_and_2d_user_lines(plane_mesh, tmp_path):
    """The mesh covers exactly the user's polygon minus its hole (clipped to the data), every
    segment of the 2-D user line is a chain of mesh edges, and the line's nodes take z from the
    DEM."""
    from floodmesh.core import io
    from floodmesh.core.chain.pipeline import mesh_constraints
    from floodmesh.core.raster import bilinear

    dem, _, _ = plane_mesh
    x0, y0 = dem.transform.c, dem.transform.f - dem.shape[0] * dem.cell_size
    outer = shapely.box(x0 + 5, y0 + 5, x0 + 45, y0 + 40)
    hole = shapely.box(x0 + 20, y0 + 15, x0 + 28, y0 + 22)
    boundary = shapely.Polygon(outer.exterior.coords, [hole.exterior.coords])
    _write_polygons(tmp_path / "domain.gpkg", [boundary])
    user_line = np.array([[x0 + 8, y0 + 30], [x0 + 40, y0 + 33]])
    io.write_lines_gpkg(tmp_path / "own.gpkg", [user_line], dem.crs, layer="lines")
    domain, own = mesh_constraints(dem, tmp_path / "domain.gpkg", tmp_path / "own.gpkg")
    mesh = build_mesh(dem, own, min_angle=25, max_area=10, domain=domain)
    covered = triangle_areas(mesh.nodes, mesh.triangles).sum()
    assert covered == pytest.approx(boundary.area, rel=1e-9)
    centroids = shapely.points(mesh.nodes[mesh.triangles][:, :, :2].mean(axis=1))
    assert not shapely.contains(hole, centroids).any()
    assert shapely.contains(outer, centroids).all()
    q = mesh_quality(mesh, min_angle=25, max_area=10)
    assert q["n_missing_segments"] == 0 and q["n_below_min_angle"] == 0
    on_line = shapely.distance(shapely.LineString(user_line), shapely.points(mesh.nodes[:, :2]))
    line_nodes = mesh.nodes[on_line < 1e-6]
    assert len(line_nodes) >= 4
    np.testing.assert_allclose(line_nodes[:, 2], bilinear(dem, line_nodes[:, 0],
                                                          line_nodes[:, 1]), atol=1e-9)


@pytest.mark.parametrize("polygon, words", [
    (shapely.Polygon([(0, 0), (30, 30), (30, 0), (0, 30)]), "not a valid polygon"),
    (shapely.box(1e4, 1e4, 1e4 + 50, 1e4 + 50), "does not overlap"),
])
def test_bad_boundaries_are_refused(plane_mesh, tmp_path, polygon, words):
    """A self-intersecting (bow-tie) boundary and one away from the data get a message naming
    the problem and the fix; a boundary in another CRS is refused too."""
    from floodmesh.core.errors import FloodMeshError
    from floodmesh.core.chain.pipeline import mesh_constraints

    dem, _, _ = plane_mesh
    x0, y0 = dem.transform.c, dem.transform.f - dem.shape[0] * dem.cell_size
    moved = shapely.affinity.translate(polygon, x0, y0)
    _write_polygons(tmp_path / "b.gpkg", [moved])
    with pytest.raises(FloodMeshError, match=words):
        mesh_constraints(dem, tmp_path / "b.gpkg")
    _write_polygons(tmp_path / "other.gpkg", [shapely.box(0, 0, 1, 1)], crs="EPSG:32633")
    with pytest.raises(FloodMeshError, match="reproject it"):
        mesh_constraints(dem, tmp_path / "other.gpkg")


def test_size_field_sets_the_local_maximum_area(plane_mesh):
    """A size raster asking for 2 m² on the western half and nothing (NaN) on the eastern: every
    triangle meets the field at its centroid and corners, the west is refined and the east keeps
    the global maximum; a slope-driven field is smallest where the slope is steepest."""
    from floodmesh.core.steps.mesh import size_from_slope
    from floodmesh.core.raster import nearest_value
    from floodmesh.core.steps.slope import slope

    dem, lines, coarse = plane_mesh
    field = np.full(dem.shape, np.nan)
    field[:, : dem.shape[1] // 2] = 2.0
    size = dem.with_values(field)
    mesh = build_mesh(dem, lines, min_angle=25, max_area=20, size_field=size)
    areas = triangle_areas(mesh.nodes, mesh.triangles)
    corners = mesh.nodes[mesh.triangles][:, :, :2]
    at = np.concatenate([corners, corners.mean(axis=1, keepdims=True)], axis=1)
    wanted = np.nanmin(np.where(np.isnan(v := nearest_value(size, at[..., 0].ravel(),
                                                            at[..., 1].ravel())), np.inf, v)
                       .reshape(-1, 4), axis=1)
    assert (areas <= np.minimum(wanted, 20) * (1 + 1e-9)).all()
    centre_x = mesh.nodes[mesh.triangles][:, :, 0].mean(axis=1)
    west = centre_x < dem.transform.c + dem.shape[1] / 2 * dem.cell_size - 3
    assert areas[west].max() <= 2 + 1e-9 and areas[~west].max() > 10
    assert len(mesh.nodes) > 3 * len(coarse.nodes)
    assert mesh_quality(mesh, min_angle=25, max_area=20)["n_below_min_angle"] == 0

    # z = x²/100: slope rises from 0 at the west edge past 10° at x = 8.8 m
    x = np.arange(dem.shape[1]) * dem.cell_size
    bowl = dem.with_values(np.tile(x ** 2 / 100, (dem.shape[0], 1)))
    by_slope = size_from_slope(slope(bowl), max_area=100, min_area=4, s_crit=10)
    row = by_slope.values[dem.shape[0] // 2, 1:-1]
    assert (np.diff(row) <= 1e-9).all(), "the size does not fall as the slope rises"
    assert row[0] > 50 and row[-1] == pytest.approx(4)
    from floodmesh.core.errors import FloodMeshError
    with pytest.raises(FloodMeshError, match="size field"):
        build_mesh(dem, lines, max_area=20, size_field=dem.with_values(np.zeros(dem.shape)))


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


def test_a_sliver_the_angle_bound_cannot_mesh_in_bounds_is_refused_at_once():
    """A triangle 667 m long and 6e-5 m wide (found by the mesher's fuzz test): its area asks
    for a few triangles, its angle bound for millions (14 M and 32 s, unbounded, before the
    Steiner-point limit); refused with what to do, before Triangle goes past the limit."""
    pslg = PSLG(np.array([[0.0, 0.0], [667.48525793348745, 6.0469950227570735e-05],
                          [500.70174752380990, 0.0]]) + [-3000.0, 250.0],
                np.array([[0, 1], [1, 2], [2, 0]], np.int32), np.empty((0, 2)))
    with pytest.raises(FloodMeshError, match="needs more than 60,000 triangles.*--max-triangles"):
        triangulate_pslg(pslg, min_angle=17.3, max_area=946448.9, max_triangles=60_000)


@pytest.mark.parametrize("vertices, segments, meet", [
    ([[0, 0], [2, 0], [1, 0]], [[0, 1], [0, 2]], True),           # one along the other
    ([[0, 0], [2, 0], [1, 0]], [[1, 0], [2, 0]], True),           # ... either way round
    ([[0, 0], [1, 0], [-1, 0]], [[0, 1], [0, 2]], False),         # straight on, apart
    ([[0, 0], [2, 0], [1, 1e-8]], [[0, 1], [0, 2]], False),       # all but collinear
    ([[0, 0], [2, 0]], [[0, 1], [1, 0]], True),                   # the same segment twice
    ([[0, 0], [2, 0], [2, 2], [0, 2]], [[0, 1], [1, 2], [2, 3], [3, 0]], False),
    ([[0, 0], [2, 0], [2, 2], [0, 2]], [[0, 2], [1, 3]], True),   # crossing
    ([[0, 0], [2, 0], [1, 0], [1, 1]], [[0, 1], [2, 3]], True),   # touching inside
])
def test_segments_meeting_other_than_at_a_shared_end_are_found(vertices, segments, meet):
    """The PSLG check's crossing test, at shared ends exactly: collinear arms on one side of
    their common end overlap, on opposite sides or a hair off collinear they do not."""
    from floodmesh.core.steps.mesh import _segments_cross

    xy = np.array(vertices, float) + ORIGIN
    assert _segments_cross(xy, np.array(segments, np.int32)) is meet


def test_lines_meeting_at_a_sharp_corner_stop_a_cell_apart():
    """Two break lines meeting at 20°: one is shortened to end a cell (the spacing the lines
    are kept apart by elsewhere) off the other, not half a cell, so the smallest triangle in
    the corner, which sets a flood model's time step, is twice as large."""
    from floodmesh.core.steps.hydraulics import inradii

    dem = Grid(np.zeros((60, 80)), Affine(1, 0, 0, 0, -1, 60), CRS.from_epsg(32633))
    a = np.array([[40, 30, 1], [10, 30, 1]])
    b = np.array([[40, 30, 1], [10, 30 + 30 * np.tan(np.radians(20)), 1]])
    default, half = (build_mesh(dem, [a, b], corner_gap=gap) for gap in (None, 0.5))
    assert inradii(default.nodes, default.triangles).min() > 0.4
    assert inradii(half.nodes, half.triangles).min() < 0.25
    assert mesh_quality(default, min_angle=25, max_area=100)["n_below_min_angle"] == 0


def test_one_line_array_instead_of_a_list_of_lines_is_refused_naming_the_fix():
    from floodmesh import core  # as docs/library.md calls it

    # a (k, 3) array iterated as lines of one point each used to end in an IndexError
    with pytest.raises(FloodMeshError, match=r"lines must be a list of lines.*give \[line\]"):
        core.build_mesh(_plane_dem(), DIAGONAL, max_area=50)
    with pytest.raises(FloodMeshError, match=r"own_lines must be a list of lines"):
        core.build_mesh(_plane_dem(), [], own_lines=L_SHAPE, max_area=50)


@pytest.mark.parametrize("bad", [np.empty((0, 3)), np.empty((0, 2)), DIAGONAL[0],
                                 DIAGONAL[:1]])
@pytest.mark.parametrize("others", [[], [DIAGONAL]], ids=["alone", "with a line"])
def test_an_empty_or_one_point_line_is_left_out_with_a_note(bad, others):
    from floodmesh import core

    # alone, an empty line used to end in an IndexError, a 1-D one in either case
    notes = []
    mesh = core.build_mesh(_plane_dem(), [*others, bad], max_area=50, note=notes.append)
    without = core.build_mesh(_plane_dem(), others, max_area=50)
    assert notes == ["1 break lines with fewer than 2 points or non-finite coordinates were "
                     "left out"]
    np.testing.assert_array_equal(mesh.nodes, without.nodes)
    np.testing.assert_array_equal(mesh.segments, without.segments)
