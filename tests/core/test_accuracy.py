"""Accuracy assessment (floodmesh.core.steps.accuracy): TIN residuals and their statistics."""
import json
import math

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS
from scipy.spatial import Delaunay

from floodmesh.core.steps.accuracy import (CLASS_NAMES, accuracy_statistics, nssda_threshold_m,
                                           residual_class, residuals, tin_elevation)
from floodmesh.core.steps.mesh import Mesh, build_mesh
from floodmesh.core.raster import Grid

from ..conftest import plane_points

ORIGIN = np.array([500_000.0, 6_000_000.0])
UTM = CRS.from_epsg(25832)


def _delaunay_mesh(xy_local, z):
    tri = Delaunay(xy_local)
    return Mesh(np.column_stack([xy_local + ORIGIN, z]), tri.simplices.astype(np.int64), UTM)


def _brute_force_tin(nodes, triangles, x, y):
    """z at (x, y) by barycentric interpolation in the triangle found by looping over all of them;
    NaN where no triangle holds the point."""
    out = np.full(len(x), np.nan)
    for k, (px, py) in enumerate(zip(x, y)):
        for t in triangles:
            (x1, y1, z1), (x2, y2, z2), (x3, y3, z3) = nodes[t]
            det = (y2 - y3) * (x1 - x3) + (x3 - x2) * (y1 - y3)
            l1 = ((y2 - y3) * (px - x3) + (x3 - x2) * (py - y3)) / det
            l2 = ((y3 - y1) * (px - x3) + (x1 - x3) * (py - y3)) / det
            l3 = 1.0 - l1 - l2
            if min(l1, l2, l3) >= -1e-12:
                out[k] = l1 * z1 + l2 * z2 + l3 * z3
                break
    return out


# ---------------------------------------------------------------------------------------------
def test_residuals_on_a_plane_are_zero():
    """Points on the plane of the mesh nodes have residual 0 (to 1e-9 m)."""
    nodes = plane_points(size=40.0, density=0.1, seed=1, origin=(0.0, 0.0))
    mesh = _delaunay_mesh(nodes[:, :2], nodes[:, 2])
    rng = np.random.default_rng(2)
    inside = rng.uniform(10, 30, (500, 2))
    z = 0.1 * inside[:, 0] - 0.05 * inside[:, 1] + 12.0
    res = residuals(mesh, np.column_stack([inside + ORIGIN, z]))
    assert np.isfinite(res).all()
    np.testing.assert_allclose(res, 0.0, rtol=0, atol=1e-9)


def test_residuals_on_a_paraboloid_match_brute_force_barycentric():
    """Nodes on z = x² + y²: residuals at random points equal point z minus the z found here by
    brute-force barycentric interpolation; points outside the mesh give NaN."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 20, (150, 2))
    mesh = _delaunay_mesh(xy, (xy ** 2).sum(axis=1))
    pts = rng.uniform(-2, 22, (300, 2))  # some outside the hull of the nodes
    z_true = (pts ** 2).sum(axis=1)
    pts_map = pts + ORIGIN
    res = residuals(mesh, np.column_stack([pts_map, z_true]))
    expected_tin = _brute_force_tin(np.column_stack([xy, mesh.nodes[:, 2]]), mesh.triangles,
                                    pts[:, 0], pts[:, 1])
    outside = np.isnan(expected_tin)
    assert 10 < outside.sum() < 200
    assert np.array_equal(np.isnan(res), outside)
    # z reaches 800 m here; matplotlib's per-triangle plane coefficients are exact to about 4e-11
    # relative (3e-8 m measured against exact rational arithmetic), hence 1e-6 m
    np.testing.assert_allclose(res[~outside], z_true[~outside] - expected_tin[~outside],
                               rtol=0, atol=1e-6)
    # a curved surface under a linear TIN: the TIN lies above it inside, residuals are negative
    assert (res[~outside] <= 1e-9).all() and res[~outside].min() < -0.1
    stats = accuracy_statistics(res)
    assert stats["n_outside_mesh"] == int(outside.sum())
    assert stats["n_assessed"] == int((~outside).sum())
    assert stats["n_holdout"] == len(pts)


def test_points_on_edges_and_nodes_are_never_lost_and_match_matplotlib():
    """The compiled locator against matplotlib's trapezoid map (the independent reference) on
    random Delaunay meshes in map coordinates: every node, every inner edge's midpoint and random
    points inside are found (no point falls between two triangles sharing an edge), the same
    points are outside, and the TIN elevations agree to round-off."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation

    from floodmesh.core.steps.mesh import containing_triangle

    rng = np.random.default_rng(7)
    for _ in range(6):
        xy = rng.uniform(0, 100, (int(rng.integers(50, 2000)), 2))
        z = rng.normal(20.0, 1.0, len(xy))
        mesh = _delaunay_mesh(xy, z)
        tri = mesh.triangles
        pairs = np.sort(np.stack([tri, np.roll(tri, 1, axis=1)], axis=2).reshape(-1, 2), axis=1)
        shared, count = np.unique(pairs, axis=0, return_counts=True)
        inner = shared[count == 2]  # a hull edge's midpoint may round to just outside
        edges = 0.5 * (xy[inner[:, 0]] + xy[inner[:, 1]])
        pts = np.vstack([xy, edges, rng.uniform(-10, 110, (3000, 2))])
        found = containing_triangle(mesh.nodes[:, :2], tri, pts + ORIGIN)
        assert (found[:len(xy) + len(edges)] >= 0).all()
        # both in the same local coordinates: pts + ORIGIN has already rounded the points by
        # some 1e-10 m, which the steep random surface turns into 1e-8 m of z
        low = mesh.nodes[:, :2].min(axis=0)
        local, at = mesh.nodes[:, :2] - low, pts + ORIGIN - low
        reference = Triangulation(local[:, 0], local[:, 1], tri)
        expected = np.ma.filled(LinearTriInterpolator(reference, z)(at[:, 0], at[:, 1])
                                .astype(float), np.nan)
        got = tin_elevation(mesh, *(pts + ORIGIN).T)
        assert np.array_equal(np.isnan(got), np.isnan(expected))
        assert np.array_equal(found < 0, np.isnan(expected))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
        # a point strictly inside one triangle is found in that one
        centroids = xy[tri].mean(axis=1)
        assert np.array_equal(containing_triangle(mesh.nodes[:, :2], tri, centroids + ORIGIN),
                              np.arange(len(tri)))


def test_located_points_do_not_depend_on_their_order_or_the_threads():
    """The locator sorts the points into its buckets, a share per thread: shuffled, or on one
    thread, the same points get the same triangles and the same TIN elevations to the bit,
    nodes and edge midpoints (held by several triangles: the lowest-index one) included; points
    far off the mesh or with a coordinate not a number are outside."""
    import numba

    from floodmesh.core._kernels.mesh import Locator

    rng = np.random.default_rng(11)
    xy = rng.uniform(0, 100, (400, 2))
    mesh = _delaunay_mesh(xy, rng.normal(20.0, 1.0, len(xy)))
    tri = mesh.triangles
    edges = 0.5 * (xy[tri[:, 0]] + xy[tri[:, 1]])
    pts = np.vstack([xy, edges, rng.uniform(-10, 110, (20_000, 2))]) + ORIGIN
    off = [[np.nan, 50.0], [50.0, np.nan], [np.inf, 50.0], [-1e12, 50.0], [50.0, 1e12]]
    pts[-len(off):] = ORIGIN + off
    locator = Locator(mesh.nodes[:, :2], tri)
    assert len(pts) > 2 * locator.rows * locator.cols  # each thread sorts a share
    found, z = locator(pts, mesh.nodes[:, 2])
    assert (found[:len(xy)] >= 0).all() and (found < 0).any()
    assert (found[-len(off):] == -1).all() and np.isnan(z[-len(off):]).all()
    for t, c in zip(tri[found[:len(xy)]], range(len(xy))):  # a node: its lowest triangle
        assert found[c] == np.flatnonzero((tri == c).any(axis=1)).min() and c in t
    shuffle = rng.permutation(len(pts))
    found_shuffled, z_shuffled = locator(pts[shuffle], mesh.nodes[:, 2])
    assert np.array_equal(found_shuffled, found[shuffle])
    assert np.array_equal(z_shuffled, z[shuffle], equal_nan=True)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        found_one, z_one = locator(pts, mesh.nodes[:, 2])
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(found_one, found) and np.array_equal(z_one, z, equal_nan=True)


def test_points_in_a_mesh_hole_are_outside():
    """A mesh built around a NaN hole: points in the hole are NaN, points on the plane elsewhere 0."""
    n = 40
    x = np.arange(n) + 0.5
    xx, yy = np.meshgrid(x, n - x)
    z = 0.2 * xx + 0.1 * yy + 5.0
    z[15:25, 15:25] = np.nan  # hole: local x and y 15..25
    dem = Grid(z, Affine(1.0, 0.0, ORIGIN[0], 0.0, -1.0, ORIGIN[1] + n), UTM)
    mesh = build_mesh(dem, [], min_angle=25, max_area=10)
    pts = np.array([[20.0, 20.0], [17.0, 22.5], [5.0, 5.0], [30.0, 12.0], [35.5, 35.5]])
    res = residuals(mesh, np.column_stack([pts + ORIGIN, 0.2 * pts[:, 0] + 0.1 * pts[:, 1] + 5]))
    assert np.isnan(res[:2]).all()
    np.testing.assert_allclose(res[2:], 0.0, atol=1e-9)
    np.testing.assert_allclose(tin_elevation(mesh, *(pts[2:] + ORIGIN).T),
                               0.2 * pts[2:, 0] + 0.1 * pts[2:, 1] + 5, atol=1e-9)


# ---------------------------------------------------------------------------------------------
def test_statistics_of_a_known_vector():
    """rmse, mean, std (ddof=1), skew, 1.96·rmse and max |r| equal the values computed here; NaN
    residuals are counted as outside the mesh and left out."""
    r = np.array([0.05, -0.12, 0.30, 0.0, 0.08, -0.02, 0.15, -0.26, 0.11, 0.04, np.nan, np.nan])
    v = r[np.isfinite(r)]
    stats = accuracy_statistics(r)
    rmse = math.sqrt(sum(x * x for x in v) / len(v))
    mean = sum(v) / len(v)
    std1 = math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1))
    std0 = math.sqrt(sum((x - mean) ** 2 for x in v) / len(v))
    skew = sum((x - mean) ** 3 for x in v) / len(v) / std0 ** 3
    assert stats["n_holdout"] == 12 and stats["n_assessed"] == 10 and stats["n_outside_mesh"] == 2
    assert stats["rmse_m"] == pytest.approx(rmse, rel=1e-12)
    assert stats["mean_m"] == pytest.approx(mean, rel=1e-12)
    assert stats["std_m"] == pytest.approx(std1, rel=1e-12)
    assert stats["skew"] == pytest.approx(skew, rel=1e-10)
    assert stats["accuracy_95_m"] == pytest.approx(1.96 * rmse, rel=1e-12)
    assert stats["max_abs_residual_m"] == pytest.approx(0.30, abs=1e-15)
    # n = 10 assessed points: the NSSDA bound exists, but the test needs 20 points
    assert stats["nssda_threshold_m"] == pytest.approx(nssda_threshold_m(10), rel=1e-15)
    assert stats["nssda_pass"] is None
    assert "vertex_error_bound_m" not in stats


def test_residual_classes_at_the_limits():
    """|r| < 0.10 is class 0, 0.10 <= |r| < 0.25 class 1, |r| >= 0.25 class 2 (np.digitize);
    shares are fractions of the assessed residuals."""
    r = np.array([0.0, 0.0999, 0.10, -0.10, 0.2499, -0.2499, 0.25, -0.25, 1.0, np.nan])
    np.testing.assert_array_equal(residual_class(r), [0, 0, 1, 1, 1, 1, 2, 2, 2, -1])
    classes = accuracy_statistics(r)["classes"]
    assert list(classes) == list(CLASS_NAMES)
    assert classes["<10 cm"] == pytest.approx(2 / 9)
    assert classes["10-25 cm"] == pytest.approx(4 / 9)
    assert classes[">25 cm"] == pytest.approx(3 / 9)
    assert sum(classes.values()) == pytest.approx(1.0)


@pytest.mark.parametrize("n", [20, 100, 1000])
def test_nssda_threshold(n):
    """The FEMA/NSSDA bound is 0.15·sqrt(((n-1) - 2.326·sqrt(n-1))/n) m."""
    expected = 0.15 * math.sqrt(((n - 1) - 2.326 * math.sqrt(n - 1)) / n)
    assert nssda_threshold_m(n) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("n", [0, 1, 2, 5, 6])
def test_nssda_threshold_undefined_for_small_samples(n):
    """Below 7 points the bound does not exist (NaN); at 7 it does."""
    assert math.isnan(nssda_threshold_m(n))
    assert nssda_threshold_m(7) > 0


def test_small_sample_reports_no_nssda_test():
    """With 5 assessed residuals the NSSDA threshold and pass are None, not NaN or a verdict."""
    stats = accuracy_statistics(np.array([0.01, -0.02, 0.03, 0.0, 0.05]))
    assert stats["nssda_threshold_m"] is None and stats["nssda_pass"] is None


def test_vertex_error_bound():
    """With alpha and delta the bound is rmse + alpha·delta."""
    r = np.array([0.1, -0.2, 0.05, 0.0, 0.3, -0.1, 0.02])
    stats = accuracy_statistics(r, alpha=0.8, delta=0.5)
    rmse = float(np.sqrt(np.mean(r ** 2)))
    assert stats["vertex_error_bound_m"] == pytest.approx(rmse + 0.8 * 0.5, rel=1e-12)
    assert stats["alpha"] == 0.8 and stats["delta_m"] == 0.5


def test_all_outside_gives_no_figures():
    """When every point is outside the mesh the figures and the classes' shares are None (null
    in JSON): there is no share of no residuals."""
    stats = accuracy_statistics(np.array([np.nan, np.nan, np.nan]))
    assert stats["n_outside_mesh"] == 3 and stats["n_assessed"] == 0
    assert stats["rmse_m"] is None and stats["max_abs_residual_m"] is None
    assert set(stats["classes"].values()) == {None}


def test_a_run_says_how_many_check_points_lie_outside_its_mesh(tmp_path):
    """Coarse cells on a 120 m square survey: the mesh spans the DEM's valid cell centres, half
    a cell (5 m) inside the survey's edge, so the check points in that rim are not assessed.
    The run says how many and why, in its notes and on the terminal (before, only the
    summary's 'on n points' showed that a sixth of them were left out)."""
    from floodmesh.core import io
    from floodmesh.core.points import PointCloud
    from tests.core.test_cli import floodmesh

    points = plane_points(size=120.0, density=2.0, origin=tuple(ORIGIN))
    io.write_points_las(tmp_path / "plane.laz", PointCloud(points, UTM))
    run = floodmesh("run", tmp_path / "plane.laz", "--out", tmp_path / "run", "--cell-size", 10,
                    "--holdout", 0.05)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    n_out = report["n_outside_mesh"]
    assert 0.1 * report["n_holdout"] < n_out < 0.25 * report["n_holdout"]  # 1 − (110/120)²
    said = (f"{n_out:,} of the {report['n_holdout']:,} check points lie outside the mesh and "
            "were not assessed: the DEM's valid cell centres bound the mesh, half a cell (5 m) "
            "inside the survey's edge")
    assert [note for note in report["notes"] if note.startswith(said)] and said in run.stderr


def test_nssda_verdict_needs_its_20_check_points():
    """19 check points (a domain that leaves few): the FEMA/NSSDA test needs 20, so no verdict
    (it was true), and a note says why; 20 give one."""
    notes = []
    few = accuracy_statistics(np.full(19, 0.01), note=notes.append)
    assert few["nssda_pass"] is None and few["nssda_threshold_m"] is not None
    assert len(notes) == 1 and "fewer than the 20" in notes[0]
    assert accuracy_statistics(np.full(20, 0.01))["nssda_pass"] is True
