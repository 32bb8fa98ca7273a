"""Break-line simplification (floodmesh.core.simplify): keep-every-n and Douglas–Peucker."""
import numpy as np
import pytest
import shapely

from floodmesh.core.breaklines import BreakLine
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.simplify import (douglas_peucker_mask, max_deviation,
                                     simplify_douglas_peucker, simplify_keep_every)


def _line(coords):
    coords = np.asarray(coords, float)
    return BreakLine(coords, np.arange(len(coords), dtype=float) + 10.0)


def _random_walk(n, seed, step=1.0):
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(0, step, (n, 2)), axis=0) + [412_000.0, 5_652_000.0]
    z = 20 + np.cumsum(rng.normal(0, 0.3, n))
    return _line(np.column_stack([xy, z]))


def _sine(n=400):
    x = np.linspace(0, 100, n)
    return _line(np.column_stack([x + 5e5, 3 * np.sin(x / 7) + 6e6, 10 + 2 * np.cos(x / 5)]))


# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n_points, every", [(10, 3), (13, 3), (7, 1), (5, 10), (2, 4), (21, 4)])
def test_keep_every(n_points, every):
    """Indices 0, n, 2n, ... and the last are kept, with their slopes."""
    line = _random_walk(n_points, seed=n_points)
    (out,) = simplify_keep_every([line], every)
    expected = sorted(set(range(0, n_points, every)) | {n_points - 1})
    np.testing.assert_array_equal(out.coords, line.coords[expected])
    np.testing.assert_array_equal(out.slopes, line.slopes[expected])


@pytest.mark.parametrize("every", [0, -2, 1.5])
def test_keep_every_refuses_bad_n(every):
    """n below 1 or not whole is a FloodMeshError."""
    with pytest.raises(FloodMeshError, match="keep-every"):
        simplify_keep_every([_random_walk(10, 0)], every)


# ---------------------------------------------------------------------------------------------
def _assert_within_tolerance(original, simplified, tolerance):
    """Every original vertex lies within ``tolerance`` of the simplified polyline horizontally
    (shapely distance), and, projected onto the simplified segment that replaced it (the one between
    the kept vertices around it), within ``tolerance`` of it in plan and of its interpolated z."""
    s = simplified.coords
    pts = shapely.points(original.coords[:, :2])
    assert shapely.distance(shapely.LineString(s[:, :2]), pts).max() <= tolerance + 1e-9
    # the kept vertices are a subsequence of the original ones: find their indices in order
    kept, k = [], 0
    for vertex in s:
        while not np.array_equal(original.coords[k], vertex):
            k += 1
        kept.append(k)
    assert kept[0] == 0 and kept[-1] == len(original.coords) - 1
    for i, j in zip(kept[:-1], kept[1:]):
        a, b = original.coords[i], original.coords[j]
        segment = shapely.LineString([a[:2], b[:2]])
        between = original.coords[i:j + 1]
        within = shapely.points(between[:, :2])
        assert shapely.distance(segment, within).max() <= tolerance + 1e-9
        t = shapely.line_locate_point(segment, within, normalized=True)
        z_simplified = a[2] + t * (b[2] - a[2])
        assert np.abs(between[:, 2] - z_simplified).max() <= tolerance + 1e-9


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("tolerance", [0.25, 1.0, 3.0])
def test_douglas_peucker_random_walk(seed, tolerance):
    """Random-walk lines stay within the tolerance, keep both ends and a subset of the vertices."""
    line = _random_walk(200, seed)
    (out,) = simplify_douglas_peucker([line], tolerance)
    np.testing.assert_array_equal(out.coords[0], line.coords[0])
    np.testing.assert_array_equal(out.coords[-1], line.coords[-1])
    keep = douglas_peucker_mask(line.coords, tolerance)
    np.testing.assert_array_equal(out.coords, line.coords[keep])
    np.testing.assert_array_equal(out.slopes, line.slopes[keep])
    assert len(out.coords) < len(line.coords)
    _assert_within_tolerance(line, out, tolerance)
    assert max_deviation(line, out) <= tolerance + 1e-9


@pytest.mark.parametrize("tolerance", [0.05, 0.2, 1.0])
def test_douglas_peucker_sine(tolerance):
    """A sine curve (with a cosine z) stays within the tolerance in plan and in z."""
    line = _sine()
    (out,) = simplify_douglas_peucker([line], tolerance)
    assert 2 < len(out.coords) < len(line.coords)
    np.testing.assert_array_equal(out.coords[[0, -1]], line.coords[[0, -1]])
    _assert_within_tolerance(line, out, tolerance)


def test_douglas_peucker_vertical_deviation_alone_keeps_a_vertex():
    """A straight line in plan with a 0.5 m bump in z keeps the bump at tolerance 0.1 and drops it
    at tolerance 1.0."""
    x = np.arange(11, dtype=float)
    z = np.where(x == 5, 10.5, 10.0)
    line = _line(np.column_stack([x, np.zeros(11), z]))
    (fine,) = simplify_douglas_peucker([line], 0.1)
    assert 5.0 in fine.coords[:, 0]
    _assert_within_tolerance(line, fine, 0.1)
    (coarse,) = simplify_douglas_peucker([line], 1.0)
    np.testing.assert_array_equal(coarse.coords, line.coords[[0, -1]])


def test_straight_line_collapses_to_two_points():
    """Collinear points with linear z reduce to the two ends."""
    t = np.linspace(0, 1, 50)
    line = _line(np.column_stack([5e5 + 40 * t, 6e6 + 30 * t, 12 + 3 * t]))
    (out,) = simplify_douglas_peucker([line], 0.01)
    np.testing.assert_array_equal(out.coords, line.coords[[0, -1]])
    np.testing.assert_array_equal(out.slopes, line.slopes[[0, -1]])


@pytest.mark.parametrize("tolerance", [0.0, -1.0, float("nan")])
def test_douglas_peucker_refuses_non_positive_tolerance(tolerance):
    """A tolerance that is not a positive number is a FloodMeshError."""
    with pytest.raises(FloodMeshError, match="tolerance"):
        simplify_douglas_peucker([_random_walk(10, 0)], tolerance)
