"""Break-line simplification (floodmesh.core.steps.simplify): keep-every-n and Douglas–Peucker."""
import numpy as np
import pytest
import shapely

from floodmesh.core.steps.breaklines import BreakLine
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.steps.simplify import (douglas_peucker_mask, max_deviation,
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
    assert max_deviation([line], [out]) <= tolerance + 1e-9


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


def test_douglas_peucker_in_plan_alone():
    """Coordinates in plan (k, 2) are simplified as if their heights were all zero: the same
    mask as (k, 3) with z 0, a bump in plan kept, nothing read past the array."""
    from floodmesh.core.steps.simplify import douglas_peucker_mask

    rng = np.random.default_rng(4)
    xy = np.cumsum(rng.normal(0, 1, (200, 2)), axis=0)
    flat = np.column_stack([xy, np.zeros(len(xy))])
    for tolerance in (0.3, 1.0, 3.0):
        np.testing.assert_array_equal(douglas_peucker_mask(xy, tolerance),
                                      douglas_peucker_mask(flat, tolerance))
    bump = np.column_stack([np.arange(11.0), np.where(np.arange(11) == 5, 0.5, 0.0)])
    assert douglas_peucker_mask(bump, 0.1)[5] and not douglas_peucker_mask(bump, 1.0)[5]


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


# ---------------------------------------------------------------------------------------------
# cubic smoothing spline
@pytest.mark.parametrize("tolerance", [0.3, 0.9, 2.0])
@pytest.mark.parametrize("shape", ["walk", "noisy sine"])
def test_spline_stays_within_tolerance(shape, tolerance):
    """Every original vertex lies within the tolerance of the simplified segment that replaces
    it, in plan and in z at its foot on that segment; ends stay put; fewer vertices remain."""
    from floodmesh.core.steps.simplify import spline_plan

    if shape == "walk":
        coords = _random_walk(300, seed=4, step=0.7).coords
    else:
        rng = np.random.default_rng(1)
        coords = _sine().coords + np.column_stack([rng.normal(0, 0.15, (400, 2)),
                                                   rng.normal(0, 0.05, 400)])
    position, keep = spline_plan(coords, tolerance)
    kept = np.flatnonzero(keep)
    assert keep[0] and keep[-1] and keep.sum() < len(coords)
    np.testing.assert_array_equal(position[[0, -1]], coords[[0, -1]])
    for a, b in zip(kept[:-1], kept[1:]):
        pa, pb = position[a], position[b]
        ab = pb[:2] - pa[:2]
        for i in range(a, b + 1):
            t = np.clip((coords[i, :2] - pa[:2]) @ ab / (ab @ ab), 0, 1)
            foot = pa + t * (pb - pa)
            assert np.hypot(*(coords[i, :2] - foot[:2])) <= tolerance + 1e-9
            assert abs(coords[i, 2] - foot[2]) <= tolerance + 1e-9


def test_spline_is_smoother_than_the_staircase():
    """On a grid staircase (a line at 20° traced through cell centres) the spline's vertices lie
    closer to the true straight line than the staircase's own vertices do."""
    from floodmesh.core.steps.simplify import spline_plan

    x = np.arange(0, 60.0)
    y = np.round(np.tan(np.radians(20)) * x)
    coords = np.column_stack([x, y, np.zeros_like(x)])
    position, keep = spline_plan(coords, 1.0)
    true_line = shapely.LineString([(0, 0), (60, 60 * np.tan(np.radians(20)))])
    before = shapely.distance(true_line, shapely.points(coords[:, :2])).mean()
    after = shapely.distance(true_line, shapely.points(position[:, :2])).mean()
    assert after < 0.7 * before


# ---------------------------------------------------------------------------------------------
# the simplified set stays a valid PSLG
def _traced_rough_lines(seed=0):
    from affine import Affine
    from pyproj import CRS
    from scipy import ndimage

    from floodmesh.core.steps.breaklines import trace_breaklines
    from floodmesh.core.steps.breakpoints import classify_breakpoints
    from floodmesh.core.raster import Grid
    from floodmesh.core.steps.slope import slope

    rng = np.random.default_rng(seed)
    z = ndimage.gaussian_filter(rng.normal(0, 1, (120, 120)), 2) * 20
    dem = Grid(z, Affine(1, 0, 500_000, 0, -1, 6_000_120), CRS.from_epsg(25832))
    s = slope(dem)
    # the breakpoints' lines alone, which the tracer keeps from crossing: the crest lines of
    # narrow ridges, traced apart, may cross them (the mesh joins them there)
    return trace_breaklines(classify_breakpoints(s, 10.0), s, dem, 10.0, crests=False)


def _crossings(lines):
    geoms = [shapely.LineString(line.coords[:, :2]) for line in lines]
    tree = shapely.STRtree(geoms)
    n = 0
    for predicate in ("crosses", "overlaps"):
        a, b = tree.query(geoms, predicate=predicate)
        n += int((a < b).sum())
    return n + sum(not g.is_simple for g in geoms)


@pytest.mark.parametrize("method, amount", [("keep-every", 6), ("douglas-peucker", 1.5),
                                            ("spline", 1.5)])
def test_simplified_lines_do_not_cross(method, amount):
    """Dense traced lines on rough terrain do not cross; simplified one by one they do (so the
    case is a real one); simplify_breaklines gives back vertices until none cross."""
    from floodmesh.core.steps.simplify import simplify_breaklines, spline_plan

    lines = _traced_rough_lines(seed=1)
    assert _crossings(lines) == 0
    if method == "keep-every":
        naive = simplify_keep_every(lines, amount)
    elif method == "douglas-peucker":
        naive = simplify_douglas_peucker(lines, amount)
    else:
        naive = [_line(p[m]) for p, m in (spline_plan(line.coords, amount) for line in lines)]
    assert _crossings(naive) > 0
    out = simplify_breaklines(lines, method, amount)
    assert _crossings(out) == 0
    assert sum(len(o.coords) for o in out) < 0.7 * sum(len(line.coords) for line in lines)


def test_slivers_merge_into_the_longer_line():
    """A line running 0.3 m beside a longer one merges into it at min_distance 0.5 m (only the
    part beyond the longer line's end survives), and both stay at min_distance 0.2 m; no two
    consecutive vertices are closer than min_distance."""
    from floodmesh.core.steps.simplify import simplify_breaklines

    x = np.arange(0, 60.0)
    long_line = _line(np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]))
    x2 = np.arange(30, 70.0)
    short = _line(np.column_stack([x2, np.full_like(x2, 0.3), np.zeros_like(x2)]))
    merged = simplify_breaklines([long_line, short], "keep-every", 1, min_distance=0.5)
    assert len(merged) == 2
    np.testing.assert_array_equal(merged[0].coords, long_line.coords)
    assert merged[1].coords[:, 0].min() == 60.0  # only the part past the long line's end
    kept = simplify_breaklines([long_line, short], "keep-every", 1, min_distance=0.2)
    assert [len(k.coords) for k in kept] == [60, 40]
    dense = _line(np.column_stack([np.arange(0, 10, 0.25), np.zeros(40), np.zeros(40)]))
    (spaced,) = simplify_breaklines([dense], "keep-every", 1, min_distance=0.6)
    steps = np.hypot(*np.diff(spaced.coords[:, :2], axis=0).T)
    assert steps.min() >= 0.6 and spaced.coords[0, 0] == 0 and spaced.coords[-1, 0] == 9.75


@pytest.mark.parametrize("method, amount", [("--tolerance", 0.5), ("--spline", 0.5),
                                            ("--keep-every", 8)])
def test_a_line_ending_at_a_longer_one_keeps_all_but_the_part_beside_it(tmp_path, method,
                                                                          amount):
    """``floodmesh simplify`` of a straight bank 30 m long whose end comes 0.3 m from a longer
    line (a T-junction), at --min-distance 0.5: every traced vertex lies within the tolerance
    plus the minimum distance of the lines written (method.md's bound; measured with shapely),
    and the bank keeps all of its length but the half metre beside the longer line. The whole
    last segment to the merged end went, for Douglas–Peucker the whole bank (its two ends)."""
    from pyproj import CRS

    from floodmesh.core import io
    from floodmesh.core.frontends.cli import main

    x0, y0 = 412_000.0, 5_652_000.0
    x = np.arange(0.0, 101.0)
    long_line = np.column_stack([x0 + x, y0 + 0.1 * np.sin(x / 7), 12 + 0.01 * x])
    y = np.arange(30.0, -0.5, -1.0) + 0.3  # 30.3 ... 0.3 m north of the longer line
    bank = np.column_stack([np.full_like(y, x0 + 50.5), y0 + y, 13 - 0.02 * y])
    io.write_lines_gpkg(tmp_path / "lines.gpkg", [long_line, bank], CRS.from_epsg(25832))
    out = tmp_path / "simple.gpkg"
    assert main(["simplify", str(tmp_path / "lines.gpkg"), method, str(amount),
                 "--min-distance", "0.5", "--out", str(out)]) == 0
    written = io.read_lines_gpkg(out)
    result = shapely.MultiLineString([line[:, :2] for line in written])
    bound = (amount if method != "--keep-every" else 8 * np.sqrt(2)) + 0.5
    for traced in (long_line, bank):
        assert shapely.distance(result, shapely.points(traced[:, :2])).max() <= bound + 1e-9
    # the bank: from its far end to within a metre of the longer line
    bank_part = [line for line in written if np.ptp(line[:, 0]) < 1.0 and np.ptp(line[:, 1]) > 1]
    assert len(bank_part) == 1
    assert bank_part[0][:, 1].max() - y0 == pytest.approx(30.3, abs=amount)
    assert bank_part[0][:, 1].min() - y0 <= 1.31


def test_simplify_breaklines_refuses_bad_arguments():
    from floodmesh.core.steps.simplify import simplify_breaklines

    lines = [_random_walk(10, 0)]
    with pytest.raises(FloodMeshError, match="unknown simplification"):
        simplify_breaklines(lines, "bezier", 1.0)
    with pytest.raises(FloodMeshError, match="tolerance"):
        simplify_breaklines(lines, "spline", 0)
    with pytest.raises(FloodMeshError, match="keep-every"):
        simplify_breaklines(lines, "keep-every", 0)
    with pytest.raises(FloodMeshError, match="minimum distance"):
        simplify_breaklines(lines, "keep-every", 2, min_distance=-1)


def _numpy_douglas_peucker(coords, tolerance, rank=None):
    """The definition (simplify.douglas_peucker_mask before it was compiled)."""
    keep = np.zeros(len(coords), bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(coords) - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b, pts = coords[i], coords[j], coords[i + 1:j]
        ab = b[:2] - a[:2]
        length2 = float(ab @ ab)
        t = (np.zeros(len(pts)) if length2 == 0
             else np.clip(((pts[:, :2] - a[:2]) @ ab) / length2, 0.0, 1.0))
        horizontal = np.hypot(*(pts[:, :2] - (a[:2] + t[:, None] * ab)).T)
        vertical = np.abs(pts[:, 2] - (a[2] + t * (b[2] - a[2])))
        worst = np.maximum(horizontal, np.where(np.isfinite(vertical), vertical, 0.0))
        k = int(np.argmax(worst))
        if worst[k] > tolerance:
            if rank is not None:
                inner = rank[i + 1:j]
                k = int(np.argmax(np.where(inner == inner.min(), worst, -1.0)))
            keep[i + 1 + k] = True
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return keep


def test_compiled_douglas_peucker_is_the_numpy_definition():
    """The same vertices kept as the NumPy version on random walks, lines at UTM magnitudes,
    rounded grids (ties), lines with missing z, with and without ranks."""
    rng = np.random.default_rng(0)
    for trial in range(3000):
        n = int(rng.integers(2, 200))
        coords = np.cumsum(rng.normal(0, 1, (n, 3)), axis=0)
        if trial % 4 == 1:
            coords[:, :2] = coords[:, :2].round(1) + [400_000, 5_600_000]
        elif trial % 4 == 2:
            coords = np.column_stack([rng.uniform(0, 20, (n, 2)).round(1), rng.normal(0, 1, n)])
        elif trial % 4 == 3:
            coords[rng.integers(0, n, 3), 2] = np.nan
        tolerance = float(rng.choice([0.1, 0.25, 0.5, 1.0]))
        rank = rng.integers(0, 3, n) if trial % 2 else None
        assert np.array_equal(douglas_peucker_mask(coords, tolerance, rank),
                              _numpy_douglas_peucker(coords, tolerance, rank)), trial
