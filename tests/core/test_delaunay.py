"""The numba Delaunay triangulation (``core._kernels.delaunay``) against scipy (Qhull) and brute force."""
from fractions import Fraction

import numpy as np
import pytest
from scipy.spatial import ConvexHull, Delaunay

from floodmesh.core._kernels import delaunay as dl
from floodmesh.core._kernels.delaunay import delaunay

pytestmark = pytest.mark.filterwarnings("error")  # no point may be left out


def _canonical(tri):
    """Triangles as a set-like array: each row sorted, rows sorted."""
    t = np.sort(np.asarray(tri), axis=1)
    return t[np.lexsort(t.T[::-1])]


def _areas(xy, tri):
    """Signed areas (positive = counter-clockwise)."""
    p = xy[tri]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


def _check_valid(xy, tri):
    """A proper triangulation of the hull of xy: CCW, no zero areas, areas add up to the hull's."""
    assert tri.dtype == np.int64 and tri.ndim == 2 and tri.shape[1] == 3
    a = _areas(xy, tri)
    assert (a > 0).all()
    hull = ConvexHull(xy).volume
    assert abs(a.sum() - hull) <= 1e-9 * hull
    # every interior edge is shared by exactly two triangles, hull edges by one
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert counts.max() == 2
    # Euler: T = 2V - 2 - H for a triangulated convex region
    v = np.unique(tri).size
    h = (counts == 1).sum()
    assert len(tri) == 2 * v - 2 - h


@pytest.mark.parametrize("n", [10, 1000, 100_000])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_points_match_scipy(n, seed):
    xy = np.random.default_rng(seed).random((n, 2)) * 1000.0
    tri = delaunay(xy)
    assert np.array_equal(_canonical(tri), _canonical(Delaunay(xy).simplices))
    assert (_areas(xy, tri) > 0).all()


@pytest.mark.parametrize("seed", range(20))
def test_small_random_sets_match_scipy(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(3, 60))
    xy = rng.normal(size=(n, 2)) * rng.uniform(1e-3, 1e3) + rng.uniform(-1e6, 1e6, 2)
    assert np.array_equal(_canonical(delaunay(xy)), _canonical(Delaunay(xy).simplices))


def _incircle_fraction(a, b, c, d):
    """Exact incircle determinant (> 0: d inside the circle of counter-clockwise a, b, c)."""
    a, b, c, d = ([Fraction(v) for v in p] for p in (a, b, c, d))
    adx, ady, bdx, bdy = a[0] - d[0], a[1] - d[1], b[0] - d[0], b[1] - d[1]
    cdx, cdy = c[0] - d[0], c[1] - d[1]
    return ((adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
            + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
            + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady))


def test_circumcircles_are_empty():
    """Brute force: no point lies strictly inside any triangle's circumcircle (doubtful cases in
    exact rational arithmetic)."""
    xy = np.random.default_rng(7).random((400, 2))
    tri = delaunay(xy)
    assert len(tri) > 0
    a, b, c = (xy[tri[:, k]][:, None, :] - xy[None, :, :] for k in range(3))  # (T, N, 2)
    lift = [(v ** 2).sum(-1) for v in (a, b, c)]
    det = (lift[0] * (b[..., 0] * c[..., 1] - c[..., 0] * b[..., 1])
           + lift[1] * (c[..., 0] * a[..., 1] - a[..., 0] * c[..., 1])
           + lift[2] * (a[..., 0] * b[..., 1] - b[..., 0] * a[..., 1]))
    det[np.arange(len(tri))[:, None], tri] = -1.0  # a triangle's own corners
    assert (det < 1e-12).all()
    for t, i in zip(*np.nonzero(det > -1e-12)):
        assert _incircle_fraction(*xy[tri[t]], xy[i]) <= 0


def test_jittered_grid():
    """A regular 0.5 m grid at UTM magnitudes plus tiny noise: nearly cocircular everywhere."""
    rng = np.random.default_rng(3)
    g = np.stack(np.meshgrid(np.arange(200.0), np.arange(150.0)), -1).reshape(-1, 2) * 0.5
    for noise in (1e-3, 1e-6, 1e-9):
        xy = g + rng.normal(0.0, noise, g.shape) + [500000.0, 6000000.0]
        tri = delaunay(xy)
        assert np.unique(tri).size == len(xy)
        _check_valid(xy - [500000.0, 6000000.0], tri)
    # the exact grid: every cell's four corners are cocircular
    xy = g + [500000.0, 6000000.0]
    tri = delaunay(xy)
    assert len(tri) == 2 * 199 * 149
    _check_valid(g, tri)


def test_duplicated_points():
    rng = np.random.default_rng(4)
    xy = rng.random((2000, 2)) * 100.0
    twice = np.concatenate([xy, xy])
    for pts in (twice, rng.permutation(twice), np.repeat(xy, 3, axis=0)):
        tri = delaunay(pts)
        _check_valid(pts, tri)
        # one copy of each point is used, the same triangles as without the copies
        assert np.unique(tri).size == len(xy)
        u, inverse = np.unique(pts, axis=0, return_inverse=True)
        same = _canonical(inverse.ravel()[tri])
        assert np.array_equal(same, _canonical(Delaunay(u).simplices))


def test_duplicates_of_the_seed_and_a_grid():
    g = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    xy = np.concatenate([g, g[::-1], g[200:210]])
    tri = delaunay(xy)
    _check_valid(xy, tri)
    assert np.unique(xy[np.unique(tri)], axis=0).shape[0] == len(g)


@pytest.mark.parametrize("xy", [
    np.c_[np.arange(10.0), 2.0 * np.arange(10.0) + 1.0],
    np.c_[np.full(5, 3.0), np.arange(5.0)],
    np.c_[np.arange(5.0), np.zeros(5)][[3, 1, 4, 1, 0, 2]],
    np.zeros((4, 2)),
    np.array([[0.0, 0.0], [1.0, 1.0]]),
    np.zeros((0, 2)),
    # nearly but exactly collinear: on a line of slope 1 at UTM magnitudes
    np.c_[500000.0 + np.arange(50.0), 6000000.0 + np.arange(50.0)],
])
def test_collinear_or_too_few_points_give_no_triangles(xy):
    tri = delaunay(xy)
    assert tri.shape == (0, 3) and tri.dtype == np.int64


def test_small_cases_and_errors():
    assert _canonical(delaunay([[0, 0], [1, 0], [0, 1]])).tolist() == [[0, 1, 2]]
    tri = delaunay(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))
    assert len(tri) == 2 and (_areas(np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]]), tri) > 0).all()
    with pytest.raises(ValueError):
        delaunay(np.zeros((5, 3)))
    with pytest.raises(ValueError):
        delaunay(np.array([[0.0, 0.0], [1.0, 0.0], [np.nan, 1.0]]))


@pytest.mark.parametrize("seed", [0, 1])
def test_area_equals_hull_area(seed):
    rng = np.random.default_rng(seed)
    # clustered points, like LiDAR strips with gaps
    centres = rng.random((30, 2)) * 1000.0
    xy = (centres[rng.integers(0, 30, 50_000)] + rng.normal(0, 20.0, (50_000, 2)))
    tri = delaunay(xy)
    _check_valid(xy, tri)
    assert np.unique(tri).size == len(xy)


def test_exact_predicates():
    """The filtered predicates give the exact sign where plain floating point does not
    (Kettner et al.'s near-collinear points; rounded points on a circle), checked against
    rational arithmetic."""
    def orient_fraction(a, b, c):
        a, b, c = ([Fraction(v) for v in p] for p in (a, b, c))
        return (a[0] - c[0]) * (b[1] - c[1]) - (a[1] - c[1]) * (b[0] - c[0])

    ws = np.empty(dl.WORKSPACE)  # the exact arithmetic's workspace
    u = np.spacing(0.5)
    b, c = np.array([12.0, 12.0]), np.array([24.0, 24.0])
    for i in range(0, 64, 2):
        for j in range(0, 64, 2):
            a = np.array([0.5 + i * u, 0.5 + j * u])
            for p in ((a, b, c), (b, c, a), (c, a, b)):
                s = dl.orient2d(*p[0], *p[1], *p[2], ws)
                assert np.sign(s) == np.sign(orient_fraction(*p))

    # on a circle (the determinant rounding noise) and anywhere in a tile (most decided by
    # the static bound alone: the points' own, as the sweep takes it, or a wider set's)
    rng = np.random.default_rng(5)
    decided = 0
    for k in range(1000):
        r = rng.uniform(0.1, 100.0)
        p = ([r * np.array([np.cos(t), np.sin(t)]) for t in rng.uniform(0, 2 * np.pi, 4)]
             if k % 2 else list(rng.uniform(0.0, 130.0, (4, 2)) + rng.uniform(-1e6, 1e6, 2)))
        exact = np.sign(_incircle_fraction(*p))
        assert np.sign(dl._incircle(*p[0], *p[1], *p[2], *p[3], np.inf, ws)) == exact
        for static in (dl._incircle_static_bound(np.array(p)),
                       dl._incircle_static_bound(np.array(p + [p[0] + 100.0]))):
            s = dl._incircle(*p[0], *p[1], *p[2], *p[3], static, ws)
            assert np.sign(s) == exact
            decided += abs(s) > static
    assert decided > 900


@pytest.mark.parametrize("n", [3, 50, 5000])
def test_the_sweep_order_form_is_the_same_triangulation(n):
    """``delaunay_in_sweep_order`` (what the gridding rasterises) gives delaunay's triangles:
    its points are xy's in another order, its triangles clockwise over them."""
    xy = np.random.default_rng(n).random((n, 2)) * 100
    swept, ids, tri = dl.delaunay_in_sweep_order(xy)
    np.testing.assert_array_equal(swept, xy[ids])
    assert tri.dtype == np.int32 and np.all(_areas(swept, tri) < 0)
    np.testing.assert_array_equal(_canonical(ids[tri]), _canonical(delaunay(xy)))
    np.testing.assert_array_equal(_canonical(ids[tri]), _canonical(Delaunay(xy).simplices))
