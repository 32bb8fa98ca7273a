"""Break-line tracing (core.steps.breaklines.trace_breaklines) on hand-made and synthetic DEMs."""
from collections import Counter

import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from scipy import ndimage

from floodmesh.core.frontends import demo
from floodmesh.core.steps.breaklines import narrow_crest_cells, trace_breaklines
from floodmesh.core.steps.breakpoints import classify_breakpoints
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.raster import Grid
from floodmesh.core.steps.slope import slope

ORIGIN = (412_000.0, 5_652_000.0)
S_CRIT = 10.0


def _grid(z, d=1.0, origin=ORIGIN):
    """A north-up grid in EPSG:25832 whose lower-left corner is ``origin``."""
    rows = z.shape[0]
    return Grid(z, Affine(d, 0.0, origin[0], 0.0, -d, origin[1] + rows * d), CRS.from_epsg(25832))


def _centres(rows, cols, d=1.0):
    """Local (x, y) of the cell centres, y up, lower-left corner at (0, 0)."""
    x = (np.arange(cols) + 0.5) * d
    y = rows * d - (np.arange(rows) + 0.5) * d
    return np.meshgrid(x, y)


def _trace(z, *, d=1.0, mode="auto", method="one-over-distance", join=True, crests=True):
    dem = _grid(z, d)
    s = slope(dem, method)
    bp = classify_breakpoints(s, S_CRIT)
    return dem, s, bp, trace_breaklines(bp, s, dem, S_CRIT, mode=mode, join=join,
                                        crests=crests)


def _local(line):
    return line.coords[:, :2] - ORIGIN


def _cells(grid, line):
    """(row, col) of the cells whose centres the line's points are; fails if a point is off-centre."""
    r, c = grid.fractional_index(line.coords[:, 0], line.coords[:, 1])
    ri, ci = np.rint(r).astype(int), np.rint(c).astype(int)
    np.testing.assert_allclose(r, ri, atol=1e-6)
    np.testing.assert_allclose(c, ci, atol=1e-6)
    return ri, ci


def _trend_rule_holds(xy, j):
    """The documented turn rule for a line opened at index ``j``: growing away from j in either
    direction, no step turns more than 90 degrees from the direction over the last (up to) three
    steps, and the two paths through j leave it in opposite half-planes."""
    def grows_ok(p):
        for m in range(1, len(p) - 1):
            if np.dot(p[m + 1] - p[m], p[m] - p[max(0, m - 3)]) < -1e-9:
                return False
        return True

    if 0 < j < len(xy) - 1 and np.dot(xy[j] - xy[j - 1], xy[j + 1] - xy[j]) < -1e-9:
        return False
    return grows_ok(xy[j:]) and grows_ok(xy[j::-1])


def _assert_tracing_rules(bp, s, lines, *, consecutive_turns=True, joined=False):
    """Check the tracing rules independently of the tracer on its output. Joined lines may jump
    in slope at their joints and were opened at more than one point, so those two checks are
    off for them (the joints are checked by test_joins_*)."""
    d = bp.cell_size
    assert lines, "no lines traced"
    in_lines, as_first = Counter(), Counter()
    for line in lines:
        assert len(line.coords) >= 3
        r, c = _cells(bp, line)
        assert (bp.values[r, c] == 1).all(), "a traced point is not a breakpoint"
        keys = list(zip(r.tolist(), c.tolist()))
        assert len(set(keys)) == len(keys), "a line visits a cell twice"
        in_lines.update(keys)
        as_first[keys[0]] += 1
        if joined and keys[-1] != keys[0]:  # a joined line may end at its opening point
            as_first[keys[-1]] += 1
        # points are the DEM's cell centres with its elevation and the slope grid's slope
        np.testing.assert_array_equal(line.slopes, s.values[r, c])
        steps = np.diff(line.coords[:, :2], axis=0)
        np.testing.assert_allclose(np.abs(steps).max(axis=1), d, rtol=0, atol=1e-9,
                                   err_msg="consecutive points are not grid neighbours")
        if not joined:
            assert (np.abs(np.diff(line.slopes)) < S_CRIT).all(), "slope jump of S_crit or more"
        xy = line.coords[:, :2]
        if not joined:  # joined lines keep it piece by piece: see test_joins_*
            assert any(_trend_rule_holds(xy, j) for j in range(len(xy))), \
                f"line turns more than 90 degrees from its trend: {(xy - ORIGIN).tolist()}"
        if consecutive_turns:
            assert ((steps[1:] * steps[:-1]).sum(axis=1) >= -1e-9).all(), \
                "consecutive steps turn more than 90 degrees"
    # a cell in several lines can only be an opening point shared by the lines that start there
    for key, n in in_lines.items():
        if n > 1:
            assert as_first[key] >= n - 1, f"cell {key} is in {n} lines"
    _assert_no_crossings(lines)


def _assert_no_crossings(lines):
    geoms = [shapely.LineString(line.coords[:, :2]) for line in lines]
    assert all(g.is_simple for g in geoms), "a line crosses itself"
    a, b = shapely.STRtree(geoms).query(geoms, predicate="crosses")
    pairs = [(int(i), int(j)) for i, j in zip(a, b) if i < j]
    assert pairs == [], f"lines cross: {pairs[:5]}"


def _staircase_factor(angle_deg):
    """Length of an 8-connected grid path per metre of a straight line at this angle to the grid."""
    t = np.radians(angle_deg % 90)
    t = min(t, np.pi / 2 - t)
    return np.cos(t) + (np.sqrt(2) - 1) * np.sin(t)


# ---------------------------------------------------------------------------------------------
# a straight north-south step
@pytest.mark.parametrize("mode", ["flat", "steep"])
@pytest.mark.parametrize("join", [False, True])
def test_straight_step(mode, join):
    """z = 0 west of column 10, rising over 3 columns to 2 m: two north-south lines along the two
    edges of the steep band (cell centres x = 10.5 and 13.5), each the full 40 rows long."""
    rows, cols = 40, 30
    z = np.tile(np.clip((np.arange(cols) - 10) / 3.0, 0, 1) * 2.0, (rows, 1))
    dem, s, bp, lines = _trace(z, mode=mode, join=join)
    _assert_tracing_rules(bp, s, lines, joined=join)
    xs = sorted(float(np.unique(_local(line)[:, 0])[0]) for line in lines)
    for line in lines:
        assert np.ptp(_local(line)[:, 0]) == 0, "line does not run north-south"
    assert xs == [10.5, 13.5]
    for line in lines:
        assert len(line.coords) == rows
    step_length = (rows - 1) * 1.0  # between the outer cell centres
    total = sum(line.length for line in lines)
    assert total == pytest.approx(2 * step_length, rel=0.05)
    # z of the points is the DEM's
    for line in lines:
        r, c = _cells(dem, line)
        np.testing.assert_array_equal(line.coords[:, 2], z[r, c])


# ---------------------------------------------------------------------------------------------
# a straight step at 30 degrees to the grid
@pytest.mark.parametrize("mode", ["flat", "steep"])
@pytest.mark.parametrize("join", [False, True])
def test_oblique_step(mode, join):
    """A 3 m wide ramp (2 m high) whose edges run 30 degrees east of north: every line runs along
    the step (chord within 30 degrees of it) inside the band, both edges are found, and the total
    length is that of two edges as 8-connected paths (+-10 %)."""
    n = 60
    x, y = _centres(n, n)
    theta = np.radians(30.0)
    u = (x - 30) * np.cos(theta) - (y - 30) * np.sin(theta)  # across the step, 0..3 m is the ramp
    z = np.clip(u / 3.0, 0, 1) * 2.0
    dem, s, bp, lines = _trace(z, mode=mode, join=join)
    _assert_tracing_rules(bp, s, lines, joined=join)

    along = np.array([np.sin(theta), np.cos(theta)])
    for line in lines:
        p = _local(line)
        pu = (p[:, 0] - 30) * np.cos(theta) - (p[:, 1] - 30) * np.sin(theta)
        assert pu.min() >= -1.5 and pu.max() <= 4.5, "a line leaves the steep band"
        chord = p[-1] - p[0]
        cos = abs(chord @ along) / np.hypot(*chord)
        assert cos >= np.cos(np.radians(30)), \
            f"line runs across the step, not along it: {p.tolist()}"

    box = shapely.box(0, 0, n, n)
    edges = [shapely.intersection(shapely.LineString([(30 + o / np.cos(theta) - 60 * np.tan(theta),
                                                       -30), (30 + o / np.cos(theta) + 60 *
                                                              np.tan(theta), 90)]), box)
             for o in (0.0, 3.0)]
    traced = shapely.MultiLineString([_local(line) for line in lines])
    for edge in edges:
        assert edge.intersection(traced.buffer(1.5)).length >= 0.9 * edge.length
    expected = sum(e.length for e in edges) * _staircase_factor(30.0)
    total = sum(line.length for line in lines)
    assert total == pytest.approx(expected, rel=0.10)


# ---------------------------------------------------------------------------------------------
# a cone: the break line at its foot closes
@pytest.mark.parametrize("mode", ["flat", "steep"])
@pytest.mark.parametrize("join", [False, True])
def test_cone_foot_closes(mode, join):
    """A cone of radius 15 m (slope 16.7 degrees): the longest line runs round the foot within 2 m
    of the circle, covers at least 90 % of it and its two ends are at most 4 cells apart."""
    n, radius = 50, 15.0
    x, y = _centres(n, n)
    r = np.hypot(x - 25, y - 25)
    z = np.clip((radius - r) / 10.0, 0, None) * 3.0
    dem, s, bp, lines = _trace(z, mode=mode, join=join)
    _assert_tracing_rules(bp, s, lines, joined=join)
    main = max(lines, key=lambda line: line.length)
    p = _local(main)
    pr = np.hypot(p[:, 0] - 25, p[:, 1] - 25)
    assert np.abs(pr - radius).max() <= 2.0
    circle = shapely.Point(25, 25).buffer(radius, quad_segs=64).exterior
    covered = circle.intersection(shapely.LineString(p).buffer(2.0)).length / circle.length
    assert covered >= 0.9
    assert np.hypot(*(p[0] - p[-1])) <= 4 * dem.cell_size, "the foot line does not close"


# ---------------------------------------------------------------------------------------------
# rough terrain: the rules and no crossings, however many breakpoints
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("mode", ["flat", "steep"])
@pytest.mark.parametrize("roughness", ["smooth", "white"])
@pytest.mark.parametrize("join", [False, True])
def test_rules_hold_on_rough_terrain(seed, mode, roughness, join):
    """Random terrain with hundreds of breakpoints: every line obeys the tracing rules (breakpoints
    only, neighbours, slope change below S_crit, no turn beyond 90 degrees from the trend) and no
    two lines cross. Consecutive single steps may turn by 135 degrees here (the rule is on the
    three-step trend), so that stricter check is off."""
    rng = np.random.default_rng(seed)
    if roughness == "smooth":
        z = ndimage.gaussian_filter(rng.normal(0, 1, (80, 90)), 2) * 20
    else:
        z = rng.normal(0, 0.3, (60, 70))
    dem, s, bp, lines = _trace(z, mode=mode, join=join, crests=False)
    assert int(bp.values.sum()) > 300
    _assert_tracing_rules(bp, s, lines, consecutive_turns=False, joined=join)
    # the lines of narrow crests and troughs come after, traced by the same rules through
    # their own cells
    both = trace_breaklines(bp, s, dem, S_CRIT, mode=mode, join=join)
    assert [line.coords.tolist() for line in both[:len(lines)]] == \
        [line.coords.tolist() for line in lines]
    crests = bp.with_values(narrow_crest_cells(dem, S_CRIT))
    _assert_tracing_rules(crests, s, both[len(lines):], consecutive_turns=False, joined=join)


def test_min_points_drops_short_lines():
    """min_points=6 returns exactly the lines of the min_points=3 run that have 6 points or more."""
    rng = np.random.default_rng(2)
    z = ndimage.gaussian_filter(rng.normal(0, 1, (80, 90)), 2) * 20
    dem = _grid(z)
    s = slope(dem)
    bp = classify_breakpoints(s, S_CRIT)
    all_lines = trace_breaklines(bp, s, dem, S_CRIT, min_points=3)
    long_lines = trace_breaklines(bp, s, dem, S_CRIT, min_points=6)
    expected = [line for line in all_lines if len(line.coords) >= 6]
    assert 0 < len(long_lines) < len(all_lines)
    assert len(long_lines) == len(expected)
    for a, b in zip(long_lines, expected):
        np.testing.assert_array_equal(a.coords, b.coords)


# ---------------------------------------------------------------------------------------------
# arguments
def test_modes_and_argument_errors():
    """'flat' and 'steep' both trace the step; an unknown mode, an S_crit outside (0, 90) and grids
    of different shapes raise FloodMeshError."""
    z = np.tile(np.clip((np.arange(30) - 10) / 3.0, 0, 1) * 2.0, (20, 1))
    dem = _grid(z)
    s = slope(dem)
    bp = classify_breakpoints(s, S_CRIT)
    for mode in ("flat", "steep", "auto"):
        assert len(trace_breaklines(bp, s, dem, S_CRIT, mode=mode)) == 2
    with pytest.raises(FloodMeshError, match="mode"):
        trace_breaklines(bp, s, dem, S_CRIT, mode="sideways")
    with pytest.raises(FloodMeshError, match="S_crit"):
        trace_breaklines(bp, s, dem, 0.0)
    with pytest.raises(FloodMeshError, match="S_crit"):
        trace_breaklines(bp, s, dem, 90.0)
    small = _grid(z[:, :-1])
    with pytest.raises(FloodMeshError, match="same shape"):
        trace_breaklines(bp, s, small, S_CRIT)
    with pytest.raises(FloodMeshError, match="same shape"):
        trace_breaklines(classify_breakpoints(slope(small), S_CRIT), s, dem, S_CRIT)


# ---------------------------------------------------------------------------------------------
# the synthetic floodplain
@pytest.fixture(scope="module")
def floodplain():
    """The noise-free demo terrain on a 1 m grid of cell centres over 0..300 x 0..240 m."""
    x, y = _centres(int(demo.HEIGHT), int(demo.WIDTH))
    z = demo.ground_elevation(x, y)
    dem = _grid(z, origin=demo.DEMO_ORIGIN)
    s = slope(dem, "one-over-distance")
    bp = classify_breakpoints(s, S_CRIT)
    return dem, s, bp


def _floodplain_figures(lines):
    truth = shapely.union_all(demo.true_breaklines())
    traced = shapely.MultiLineString([line.coords[:, :2] - demo.DEMO_ORIGIN for line in lines])
    precision = traced.intersection(truth.buffer(2.0)).length / traced.length
    recall = truth.intersection(traced.buffer(2.0)).length / truth.length
    return precision, recall, traced.length, truth.length


@pytest.mark.parametrize("mode", ["auto", "steep"])
def test_floodplain_lines_match_true_breaklines(floodplain, mode):
    """On the noise-free demo terrain more than 80 % of the traced length lies within 2 m of a true
    break line, and more than 80 % of the true break-line length within 2 m of a traced line."""
    dem, s, bp = floodplain
    lines = trace_breaklines(bp, s, dem, S_CRIT, mode=mode)
    precision, recall, traced_len, true_len = _floodplain_figures(lines)
    print(f"floodplain {mode}: {len(lines)} lines, traced {traced_len:.1f} m, true {true_len:.1f} m,"
          f" precision {precision:.4f}, recall {recall:.4f}")
    assert precision > 0.8
    assert recall > 0.8
    _assert_tracing_rules(bp, s, lines, consecutive_turns=False, joined=True)


def test_floodplain_tracing_is_deterministic(floodplain):
    """The same input traced twice gives identical lines (coordinates and slopes)."""
    dem, s, bp = floodplain
    first = trace_breaklines(bp, s, dem, S_CRIT)
    second = trace_breaklines(bp.with_values(bp.values.copy()), s.with_values(s.values.copy()),
                              dem, S_CRIT)
    assert len(first) == len(second) > 10
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a.coords, b.coords)
        np.testing.assert_array_equal(a.slopes, b.slopes)


def test_touching_lines_share_a_component_and_it_survives_simplification(tmp_path):
    """Two separate steep bands give two break-line systems; a line's component id is written
    to the GeoPackage, read back, and kept by simplification."""
    from floodmesh.core import io
    from floodmesh.core.steps.simplify import simplify_keep_every

    x, y = _centres(60, 60)
    z = np.clip((x - 10) / 3, 0, 1) * 2 + np.clip((x - 40) / 3, 0, 1) * 2
    dem, s, bp, lines = _trace(z, mode="flat")
    by_band = {}
    for line in lines:
        band = "west" if _local(line)[:, 0].mean() < 30 else "east"
        by_band.setdefault(band, set()).add(line.component)
    assert len(by_band["west"]) >= 1 and len(by_band["east"]) >= 1
    assert not by_band["west"] & by_band["east"]
    assert all(line.component > 0 for line in lines)
    simple = simplify_keep_every(lines, 4)
    assert [line.component for line in simple] == [line.component for line in lines]
    io.write_breaklines(tmp_path / "l.gpkg", simple, dem.crs)
    assert [line.component for line in io.read_breaklines(tmp_path / "l.gpkg")] == \
        [line.component for line in lines]


# ---------------------------------------------------------------------------------------------
# scored against known break lines, with LiDAR-like noise (the bars)
def _noisy_dem(ground, width, seed, noise=0.05, density=9.0):
    """A 1 m DEM gridded from points scattered at ``density`` per m² over a ``width`` square,
    z = ground(x, y) plus Gaussian noise (m)."""
    from floodmesh.core.steps.grid import grid_points_linear
    from floodmesh.core.points import PointCloud

    rng = np.random.default_rng(seed)
    n = int(density * width * width)
    x, y = rng.uniform(0, width, n) + ORIGIN[0], rng.uniform(0, width, n) + ORIGIN[1]
    z = ground(x - ORIGIN[0], y - ORIGIN[1]) + rng.normal(0, noise, n)
    return grid_points_linear(PointCloud(np.column_stack([x, y, z]), CRS.from_epsg(25832)), 1.0)


def _reference_case(dem, **kwargs):
    s = slope(dem, "one-over-distance")
    return trace_breaklines(classify_breakpoints(s, S_CRIT), s, dem, S_CRIT, **kwargs)


@pytest.mark.parametrize("course", ["straight", "curved"])
@pytest.mark.parametrize("angle", [3.0, 22.5, 45.0, 70.0])
def test_levee_with_noise_scores(course, angle):
    """A levee (1.8 m high, 4 m crest, 1:3 sides) at an angle to the grid, straight or
    meandering, from 9 points/m² with 5 cm noise on a 1 m grid: recall and precision within
    2 cells at least 0.9, and fewer than 3 traced pieces for each of its four break lines."""
    from floodmesh.core.frontends.demo import Profile
    from floodmesh.core.steps.validation import score_breaklines

    width, t = 120.0, np.radians(angle)
    if course == "straight":
        centre = shapely.LineString([(60 - 100 * np.cos(t), 60 - 100 * np.sin(t)),
                                     (60 + 100 * np.cos(t), 60 + 100 * np.sin(t))])
    else:
        u = np.linspace(-100, 100, 400)
        v = 15 * np.sin(2 * np.pi * u / 90)
        centre = shapely.LineString(np.column_stack([60 + u * np.cos(t) - v * np.sin(t),
                                                     60 + u * np.sin(t) + v * np.cos(t)]))
    levee = Profile(1.8, 2.0, 7.4)
    dem = _noisy_dem(lambda x, y: 10 + levee(shapely.distance(centre, shapely.points(x, y))),
                     width, seed=int(angle))
    lines = _reference_case(dem)
    box = shapely.box(0, 0, width, width)
    truth = [shapely.affinity.translate(shapely.intersection(centre.offset_curve(o), box), *ORIGIN)
             for o in (2.0, -2.0, 7.4, -7.4)]
    score = score_breaklines([line.coords for line in lines], truth, 2.0)
    print(f"levee {course} {angle}°: recall {score['recall']:.3f}, precision "
          f"{score['precision']:.3f}, pieces {score['pieces']}")
    assert score["recall"] >= 0.9
    assert score["precision"] >= 0.9
    assert score["max_pieces"] < 3


def test_noisy_floodplain_scores():
    """The demo floodplain (river with 1:2 banks, tributary, levee, road embankment, terrace;
    straight and curved courses at many angles) from 9 points/m² with 5 cm noise, reference
    case (1 m grid, one-over-distance, S_crit 10°): recall and precision within 2 cells at least
    0.9, fewer than 3 traced pieces per true line on average; without joining, the lines along
    the road (6° to the grid) would be cut at every step of its staircase."""
    from floodmesh.core.steps.grid import grid_points_linear
    from floodmesh.core.steps.validation import score_breaklines

    points, classes = demo.synthetic_floodplain(noise=0.05, vegetation=0.0, seed=3)
    dem = grid_points_linear(points, 1.0)
    truth = [shapely.affinity.translate(g, *demo.DEMO_ORIGIN) for g in demo.true_breaklines()]
    joined = score_breaklines([line.coords for line in _reference_case(dem)], truth, 2.0)
    pieces = score_breaklines([line.coords for line in _reference_case(dem, join=False)], truth,
                              2.0)
    print(f"noisy floodplain: recall {joined['recall']:.3f}, precision {joined['precision']:.3f},"
          f" pieces {joined['pieces']} (mean {joined['mean_pieces']:.2f}); without joining mean "
          f"{pieces['mean_pieces']:.2f}")
    assert joined["recall"] >= 0.9
    assert joined["precision"] >= 0.9
    assert joined["mean_pieces"] < 3
    assert pieces["mean_pieces"] > 2 * joined["mean_pieces"]


# ---------------------------------------------------------------------------------------------
# joining pieces across staircase corners
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_joins_are_concatenations_of_traced_pieces(seed):
    """Every joined line is a chain of whole traced paths (each used once, forward or reversed);
    at each joint the two end cells are grid neighbours and the chords over the six steps before
    and after the joint point the same way within 45°."""
    from floodmesh.core.steps import breaklines as bl

    rng = np.random.default_rng(seed)
    x, y = _centres(90, 90)
    u = (x - 45) * np.sin(0.1) - (y - 30) * np.cos(0.1)  # a step at 6° to the rows
    z = np.clip(u / 3, 0, 1) * 2 + ndimage.gaussian_filter(rng.normal(0, 1, x.shape), 2) * 3
    s = slope(_grid(z))
    bp = classify_breakpoints(s, S_CRIT).values.astype(bool)
    order = bl._opening_order(bp, s.values)
    cells, starts = bl._trace(bp, s.values, order, S_CRIT, False, np.uint64(0))
    joined, jstarts = bl._join_fragments(cells, starts, *bp.shape)
    raw = {}
    for k in range(len(starts) - 1):
        path = tuple(cells[starts[k]:starts[k + 1]].tolist())
        raw.setdefault(path, []).append(k)
    used = Counter()
    n_joints = 0
    for k in range(len(jstarts) - 1):
        line = joined[jstarts[k]:jstarts[k + 1]].tolist()
        i = 0
        pieces = []
        while i < len(line):
            for j in range(len(line), i, -1):  # the longest whole path that starts here
                piece = tuple(line[i:j])
                if piece in raw or piece[::-1] in raw:
                    pieces.append(piece)
                    used[piece if piece in raw else piece[::-1]] += 1
                    i = j
                    break
            else:
                pytest.fail(f"joined line {k} is not a chain of traced paths")
        for a, b in zip(pieces[:-1], pieces[1:]):
            n_joints += 1
            ra, ca = divmod(a[-1], bp.shape[1])
            rb, cb = divmod(b[0], bp.shape[1])
            assert max(abs(ra - rb), abs(ca - cb)) == 1, "joint ends are not grid neighbours"
            pa = np.array(divmod(a[-1], bp.shape[1])) - np.array(divmod(a[max(0, len(a) - 7)],
                                                                       bp.shape[1]))
            pb = np.array(divmod(b[min(6, len(b) - 1)], bp.shape[1])) - np.array((rb, cb))
            cos = pa @ pb / (np.hypot(*pa) * np.hypot(*pb))
            assert cos >= np.cos(np.radians(45)) - 1e-9, "joined pieces do not point the same way"
    assert sum(used.values()) == len(starts) - 1, "a traced path was lost or used twice"
    assert all(used[p] == len(ks) for p, ks in raw.items())
    assert n_joints > 5, "the oblique step gave nothing to join"


# ---------------------------------------------------------------------------------------------
# ties: the kernel widens to 5x5 and 7x7, then a seeded random choice
def _fork(ring_slopes):
    """A breakpoint line running east along row 5 to column 5, then forking north-east and
    south-east for three cells each. All slopes 20° except ``ring_slopes`` {(row, col): slope}."""
    bp = np.zeros((11, 12), np.uint8)
    bp[5, 0:6] = 1
    for i in range(1, 4):
        bp[5 - i, 5 + i] = bp[5 + i, 5 + i] = 1
    s = np.where(bp == 1, 20.0, 0.0)
    s[5, 0] = 21.0  # the west end opens the line
    for (r, c), v in ring_slopes.items():
        s[r, c] = v
    return _grid(bp), _grid(s), _grid(np.zeros(bp.shape))


def _branch(lines):
    main = max(lines, key=lambda line: len(line.coords))
    r, _ = _cells(_grid(np.zeros((11, 12))), main)
    return "north-east" if r.min() < 5 else "south-east"


@pytest.mark.parametrize("ring,branch", [(2, "north-east"), (2, "south-east"),
                                         (3, "north-east"), (3, "south-east")])
def test_ties_widen_the_kernel(ring, branch):
    """Both branches tie in the 3x3 kernel (same slope, same 45° turn); a lower slope (flat mode)
    on the branch's cell on the 5x5 (or, with the 5x5 ring tied too, the 7x7) ring decides."""
    row = 5 - ring if branch == "north-east" else 5 + ring
    bp, s, dem = _fork({(row, 5 + ring): 15.0})
    lines = trace_breaklines(bp, s, dem, S_CRIT, mode="flat", join=False, min_points=2)
    assert _branch(lines) == branch


def test_ties_beyond_7x7_go_to_a_seeded_random_choice():
    """A fork symmetric out to the 7x7 ring: the choice depends on the seed alone, is the same
    for the same seed, and both branches occur over a few seeds."""
    bp, s, dem = _fork({})
    picks = {}
    for seed in range(12):
        a = trace_breaklines(bp, s, dem, S_CRIT, mode="flat", join=False, seed=seed, min_points=2)
        b = trace_breaklines(bp, s, dem, S_CRIT, mode="flat", join=False, seed=seed, min_points=2)
        assert [line.coords.tolist() for line in a] == [line.coords.tolist() for line in b]
        picks[seed] = _branch(a)
    assert set(picks.values()) == {"north-east", "south-east"}


def test_min_length_drops_short_lines():
    """min_length (m) returns exactly the lines of the unfiltered run that are at least that
    long."""
    rng = np.random.default_rng(2)
    z = ndimage.gaussian_filter(rng.normal(0, 1, (80, 90)), 2) * 20
    dem = _grid(z, d=2.0)
    s = slope(dem)
    bp = classify_breakpoints(s, S_CRIT)
    every = trace_breaklines(bp, s, dem, S_CRIT)
    long_lines = trace_breaklines(bp, s, dem, S_CRIT, min_length=15.0)
    expected = [line for line in every if line.length >= 15.0]
    assert 0 < len(long_lines) < len(every)
    assert [line.coords.tolist() for line in long_lines] == \
        [line.coords.tolist() for line in expected]
    with pytest.raises(FloodMeshError, match="minimum break-line length"):
        trace_breaklines(bp, s, dem, S_CRIT, min_length=-1)
