"""Joining localised break-line pieces: a bank's crest broken mid-run joins into one line; a
crest and a toe, two parallel lines, and a crest cut by a channel stay apart."""
import numpy as np
import pytest

from floodmesh.core.steps.breaklines import BreakLine
from floodmesh.core.steps.joining import crossing_points, join_pieces
from floodmesh.core.steps.localise import _ground_follows, fit_window, localise_traced

ANGLE = np.radians(32.0)  # oblique to the grid
TANGENT = np.array([np.cos(ANGLE), np.sin(ANGLE)])
NORMAL = np.array([-np.sin(ANGLE), np.cos(ANGLE)])


def _piece(s0, s1, offset=0.0, step=1.0):
    s = np.arange(s0, s1 + 1e-9, step)
    xy = 50.0 + s[:, None] * TANGENT + offset * NORMAL
    return np.column_stack([xy, np.full(len(s), 10.0)])


def _joined(chains, n):
    assert sorted(k for chain in chains for k, *_ in chain) == list(range(n))
    return sorted(len(chain) for chain in chains)


def test_pieces_facing_each_other_across_a_gap_join():
    pieces = [_piece(-30, -2), _piece(2, 30)[::-1], _piece(33, 45)]  # one reversed
    chains = join_pieces(pieces, max_gap=6.0, lateral=1.0)
    assert _joined(chains, 3) == [3]
    [chain] = chains
    coords = np.concatenate([(pieces[k][::-1] if rev else pieces[k])[a:b]
                             for k, rev, a, b in chain])
    along = (coords[:, :2] - 50.0) @ TANGENT
    assert (np.diff(along) > 0).all() or (np.diff(along) < 0).all()  # one run, in order


def test_overlapping_ends_are_trimmed_at_the_midpoint():
    pieces = [_piece(-20, 1, 0.3), _piece(-1, 20, -0.3)]  # 2 m side by side
    [chain] = join_pieces(pieces, max_gap=6.0, lateral=1.0)
    coords = np.concatenate([(pieces[k][::-1] if rev else pieces[k])[a:b]
                             for k, rev, a, b in chain])
    along = (coords[:, :2] - 50.0) @ TANGENT
    assert (np.diff(along) > 0).all() or (np.diff(along) < 0).all()


@pytest.mark.parametrize("case", ["crest and toe", "parallel", "too far", "across"])
def test_pieces_that_are_not_one_line_stay_apart(case):
    a = _piece(-30, -2)
    kinds = None
    if case == "crest and toe":
        b, kinds = _piece(2, 30), [-1, 1]
    elif case == "parallel":  # a bank's top and toe, 3 m apart, ends side by side
        b = _piece(-1, 30, 3.0)
    elif case == "too far":
        b = _piece(8, 30)
    else:  # a line meeting the first's end at a right angle
        b = np.column_stack([50.0 + 1.0 * TANGENT + np.arange(2, 30)[:, None] * NORMAL,
                             np.full(28, 10.0)])
    assert _joined(join_pieces([a, b], kinds, max_gap=6.0, lateral=1.0), 2) == [1, 1]


def _bank(xy, channel=False):
    """A 1:2 bank whose crest runs through (50, 50) at 32°; optionally a 1.5 m deep channel
    4 m wide crossing it at s = 0."""
    u, s = (xy - 50.0) @ NORMAL, (xy - 50.0) @ TANGENT
    z = 10.0 + 0.5 * np.maximum(u, 0.0)
    return z - 1.5 * (np.abs(s) < 2.0) if channel else z


def _surveyed(height, seed, noise):
    """(points, their fit window): 9 points/m² over 100 x 100 m on ``height(xy)``, with
    ``noise`` m of Gaussian noise."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 100, (90_000, 2))
    points = np.column_stack([xy, height(xy) + rng.normal(0, noise, len(xy))])
    return points, fit_window(points, 1e4, 1.0)


def _crest_pieces(*spans):
    """Traced pieces of the bank's crest, one per (s0, s1, offset), at the crest's height."""
    return [BreakLine(np.column_stack([p[:, :2], _bank(p[:, :2])]), np.full(len(p), 20.0))
            for p in (_piece(*span) for span in spans)]


@pytest.mark.parametrize("channel", [False, True])
def test_localised_crest_broken_mid_run_joins_unless_a_channel_cuts_it(channel):
    points, window = _surveyed(lambda xy: _bank(xy, channel), seed=3, noise=0.15)
    lines = _crest_pieces((-35, -3, 0.4), (3, 35, -0.4))
    out, confidence, counts = localise_traced(lines, points, window, join_gap=6.0,
                                              join_lateral=1.0)
    assert len(out) == len(confidence) == (2 if channel else 1)
    assert counts["pieces_joined"] == (0 if channel else 1)
    follows = _ground_follows(points, window)
    assert follows(lines[0].coords[-1], lines[1].coords[0]) is (not channel)


def test_a_negative_join_gap_is_refused():
    from floodmesh.core.errors import FloodMeshError
    from floodmesh.core.options import RunOptions

    with pytest.raises(FloodMeshError, match="join gap must be 0"):
        RunOptions(join_gap=-1.0)
    assert RunOptions(join_gap=0.0).join_gap == 0.0


def _branch(u0, u1, s=0.5):
    """A line leaving the ``_piece`` line at right angles, from ``u0`` to ``u1`` m off it, at
    ``s`` m along it (between two of its vertices): its start is the end that meets it."""
    u = np.arange(u0, u1 + 1e-9, 1.0)
    xy = 50.0 + s * TANGENT + u[:, None] * NORMAL
    return np.column_stack([xy, np.full(len(u), 10.0)])


def test_an_end_short_of_a_line_becomes_a_shared_vertex_of_it():
    from floodmesh.core.steps.joining import snap_t_junctions

    main, branch = _piece(-30, 30), _branch(0.6, 20.6)  # 0.6 cells short of the middle
    main[:, 2] = 10.0 + 0.002 * np.arange(len(main))
    (new_main, new_branch), takes, snapped = snap_t_junctions([main, branch], tolerance=1.6)
    assert snapped == 1
    node = new_branch[0]
    assert np.allclose(node[:2], 50.0 + 0.5 * TANGENT)  # the foot on the main line
    assert len(new_main) == len(main) + 1 and (np.hypot(*(new_main[:, :2] - node[:2]).T)
                                               < 1e-9).sum() == 1
    assert node[2] == pytest.approx(10.0 + 0.002 * 30.5)  # the main line's z there
    assert len(new_branch) == len(branch) + 1 and np.array_equal(new_branch[1:], branch)
    assert list(takes[1]) == [0] + list(range(len(branch)))
    # aimed 0.2 m beside a vertex of the line: that vertex is the node, no short edge
    (near_main, near), _, snapped = snap_t_junctions([main, _branch(0.6, 20.6, 1.2)],
                                                     tolerance=1.6)
    assert snapped == 1 and len(near_main) == len(main) and np.allclose(near[0], main[31])
    # an end that ran 0.6 m past the line is trimmed to it: no stub beyond the node
    (_, crossing), _, snapped = snap_t_junctions([main, _branch(-0.6, 20.4)], tolerance=1.6)
    assert snapped == 1 and np.allclose(crossing[0, :2], node[:2])
    assert ((crossing[:, :2] - 50.0) @ NORMAL >= -1e-9).all()


@pytest.mark.parametrize("case", ["parallel", "far", "higher"])
def test_ends_alongside_far_from_or_above_a_line_are_not_snapped(case):
    from floodmesh.core.steps.joining import snap_t_junctions

    main = _piece(-30, 30)
    other = (_piece(1.5, 30, 0.6) if case == "parallel" else _branch(3.0, 23.0)
             if case == "far" else _branch(0.6, 20.6) + [0, 0, 0.5])  # a crest 0.5 m up
    lines, _, snapped = snap_t_junctions([main, other], tolerance=1.6)
    assert snapped == 0
    assert np.array_equal(lines[0], main) and np.array_equal(lines[1], other)


def test_a_snapped_t_junction_meshes_at_25_degrees_with_a_node_of_degree_3():
    import shapely

    from floodmesh.core.steps.joining import snap_t_junctions
    from floodmesh.core.steps.mesh import build_pslg, triangulate_pslg

    lines, _, snapped = snap_t_junctions([_piece(-30, 30), _branch(0.6, 20.6)], tolerance=1.6)
    assert snapped == 1
    pslg = build_pslg(lines, shapely.box(0, 0, 120, 110), snap=0.5)
    degree = np.bincount(pslg.segments.ravel(), minlength=len(pslg.vertices))
    node = np.argmin(np.hypot(*(pslg.vertices - lines[1][0, :2]).T))
    assert degree[node] == 3 and np.hypot(*(pslg.vertices[node] - lines[1][0, :2])) < 0.1
    vertices, triangles = triangulate_pslg(pslg, min_angle=25.0, max_area=100.0)
    corners = vertices[triangles]
    sides = np.hypot(*(np.roll(corners, -1, axis=1) - corners).transpose(2, 0, 1))
    a, b, c = sides.T
    cos = np.clip([(b * b + c * c - a * a) / (2 * b * c), (a * a + c * c - b * b) / (2 * a * c),
                   (a * a + b * b - c * c) / (2 * a * b)], -1, 1)
    assert np.degrees(np.arccos(cos)).min() >= 25.0 - 1e-6
    # the same lines left 0.6 m apart: no node joins them, the network has a gap there
    apart = build_pslg([_piece(-30, 30), _branch(0.6, 20.6)], shapely.box(0, 0, 120, 110),
                       snap=0.5)
    assert (np.bincount(apart.segments.ravel()) == 3).sum() == 0


def test_two_ends_crossing_at_a_corner_meet_in_one_node():
    from floodmesh.core.steps.joining import snap_t_junctions

    a = np.vstack([_piece(-30, 0), _piece(0.8, 0.8)])  # runs 0.8 m past the other line
    b = _branch(-0.5, 20, s=0.0)  # starts 0.5 m past the first
    (a2, b2), _, snapped = snap_t_junctions([a, b], tolerance=1.6)
    assert snapped == 1
    assert np.allclose(a2[-1, :2], 50.0) and np.allclose(b2[0, :2], 50.0)  # an L, no stubs
    assert len(a2) == len(a) - 1 and len(b2) == len(b)


def _crossed_bank(xy, across):
    """``_bank`` crossed at s = 0 (at 70°) by ``across``: "embankment", a 1.2 m embankment
    (crest 3 m, 1:2 sides) added to the ground, so the bank's crest runs on over it; or
    "cut", a flat-bottomed channel 10 m wide at the bank's foot level, which cuts the crest
    away."""
    z = _bank(xy)
    angle = ANGLE + np.radians(70.0)
    r = np.abs((xy - 50.0) @ np.array([-np.sin(angle), np.cos(angle)]))
    if across == "embankment":
        return z + 1.2 * np.clip((7.5 - r) / 6.0, 0.0, 1.0)
    return np.where(r < 5.0, 9.0, z)


@pytest.mark.parametrize("across", ["embankment", "cut"])
def test_a_crest_broken_at_a_crossing_is_bridged_only_where_the_crest_runs_on(across):
    """The tracer stops a line where another feature crosses it; the gap (here 20 m, twice the
    join gap) is bridged where the terrain still has the line's crest along it (a bank's crest
    over a road embankment), the bridge's vertices on the crest at its height, and not where
    the crossing cuts the crest away (a channel through it). The bridge is marked as one (the
    mesh leaves it out on low ground) only where it crosses another line."""
    points, window = _surveyed(lambda xy: _crossed_bank(xy, across), seed=5, noise=0.05)
    lines = _crest_pieces((-40, -10, 0.4), (10, 40, -0.4))
    out, _, counts = localise_traced(lines, points, window, join_gap=6.0, join_lateral=1.0,
                                     bridge_gap=30.0)
    if across == "cut":
        assert len(out) == 2 and counts["gaps_bridged"] == 0
        assert all(line.bridged is None for line in out)
        return
    assert len(out) == 1 and counts["gaps_bridged"] == 1
    coords = out[0].coords
    along = (coords[:, :2] - 50.0) @ TANGENT
    assert (np.diff(along) > 0).all() or (np.diff(along) < 0).all()  # one run, in order
    inner = np.abs(along) < 9.0
    assert inner.sum() >= 4  # the bridge has vertices of its own across the embankment
    assert np.abs((coords[inner, :2] - 50.0) @ NORMAL).max() < 0.3  # on the crest
    truth = _crossed_bank(coords[inner, :2], across)
    assert np.abs(coords[inner, 2] - truth).max() < 0.1  # at its height over the embankment
    assert coords[inner, 2].max() > 10.9  # up and over, not the straight chord at 10 m
    # with no other line across it, the bridge is the crest's own run: nothing is marked
    assert out[0].bridged is None
    # with the embankment's crest edge traced across it, the bridge's vertices are marked
    # (the mesh leaves them out on low ground), no others
    angle = ANGLE + np.radians(70.0)
    s = np.arange(-30.0, 30.5, 1.0)
    xy = (50.0 + s[:, None] * np.array([np.cos(angle), np.sin(angle)])
          + 1.5 * np.array([-np.sin(angle), np.cos(angle)]))
    edge = BreakLine(np.column_stack([xy, _crossed_bank(xy, across)]), np.full(len(s), 20.0))
    out, _, counts = localise_traced(lines + [edge], points, window, join_gap=6.0,
                                     join_lateral=1.0, bridge_gap=30.0)
    [bank] = [line for line in out if np.ptp((line.coords[:, :2] - 50.0) @ TANGENT) > 70]
    along = (bank.coords[:, :2] - 50.0) @ TANGENT
    inner = np.abs(along) < 9.0
    assert counts["gaps_bridged"] == 1 and inner.sum() >= 4
    assert bank.bridged[inner].all() and not bank.bridged[np.abs(along) > 10.5].any()


def test_a_crossing_is_bridged_between_the_pieces_fitted_ends(monkeypatch):
    """The bank's crest broken where an embankment crosses it, each piece's traced run beyond
    its last kink found bending off the crest on the embankment's slope (2.1 m to either side
    at the gap, where the fits fail): measured between the traced ends the two ends lie 4 m
    apart across the line and stay two lines; measured between the fitted ends, a second pass
    after the first, the crest is bridged into one line."""
    from floodmesh.core.steps import localise

    points, window = _surveyed(lambda xy: _crossed_bank(xy, "embankment"), seed=5, noise=0.05)

    def bent(s0, s1, side):  # off the crest by 0.3 m per m inside |s| = 10
        s = np.arange(s0, s1 + 1e-9, 1.0)
        xy = (50.0 + s[:, None] * TANGENT
              + (side * 0.3 * np.maximum(10.0 - np.abs(s), 0.0))[:, None] * NORMAL)
        return BreakLine(np.column_stack([xy, _bank(xy)]), np.full(len(s), 20.0))

    lines = [bent(-40, -3, 1.0), bent(3, 40, -1.0)]
    out, _, counts = localise_traced(lines, points, window, join_gap=6.0, join_lateral=1.0,
                                     bridge_gap=30.0)
    assert len(out) == 1 and counts["gaps_bridged"] == 1
    along = (out[0].coords[:, :2] - 50.0) @ TANGENT
    assert along.min() <= -39.9 and along.max() >= 39.9  # the free ends keep their runs
    assert np.abs((out[0].coords[:, :2] - 50.0) @ NORMAL).max() < 0.3  # on the crest
    first = localise._bridged  # the first pass alone: between the traced ends
    monkeypatch.setattr(localise, "_bridged", lambda pieces, make, gap, lateral, tail: first(
        pieces, make, gap, lateral, tail) if tail == 0 else (pieces, 0))
    out, _, counts = localise_traced(lines, points, window, join_gap=6.0, join_lateral=1.0,
                                     bridge_gap=30.0)
    assert len(out) == 2 and counts["gaps_bridged"] == 0


def test_a_line_is_cut_at_a_corner_and_not_at_a_bend():
    from floodmesh.core.steps.localise import _corners_cut

    s = np.arange(0.0, 30.0, 0.7)
    corner = np.vstack([np.column_stack([s, 0 * s]), np.column_stack([30 + 0 * s, s])[1:]])
    cut = _corners_cut(np.arange(len(corner)), corner, 2.0, 45.0)
    assert len(cut) == 2 and cut[0][-1] == cut[1][0]  # two arms sharing the corner vertex
    assert np.allclose(corner[cut[0][-1]], [30.0, 0.0], atol=0.8)
    theta = np.arange(0.0, np.pi / 2, 0.7 / 40.0)  # a quarter of a 40 m radius bend
    bend = np.column_stack([40 * np.cos(theta), 40 * np.sin(theta)])
    assert len(_corners_cut(np.arange(len(bend)), bend, 2.0, 45.0)) == 1


def test_a_run_keeps_a_channels_banks_and_a_roads_sides_whole_through_their_crossing(
        tmp_path, monkeypatch):
    """From the user's side: LiDAR of a floodplain where a road embankment crosses a channel at
    70°. In the break-line layer each bank line and each side of the road is one line through
    the crossing (pieces per true line, as the corpus counts them); without the corners cut
    and the gaps bridged they stopped at the crossing, two or three pieces each."""
    import shapely

    from floodmesh.core import io
    from floodmesh.core.chain import pipeline
    from floodmesh.core.frontends import demo
    from floodmesh.core.options import RunOptions
    from floodmesh.core.steps import localise
    from floodmesh.core.steps.validation import score_breaklines

    channel = shapely.LineString([(-20, 100), (320, 130)])
    across = 170 * np.array([np.cos(np.radians(70)), np.sin(np.radians(70))])
    road = shapely.LineString([(150, 120) - across, (150, 120) + across])
    plain = demo.Floodplain({"river": (channel, demo.Profile(-2.0, 4.0, 8.0)),
                             "road": (road, demo.Profile(1.5, 3.0, 6.0))}, terrace=None)
    points, classes = demo.synthetic_floodplain(density=9.0, seed=9, floodplain=plain)
    io.write_points_las(tmp_path / "points.laz", points, classes=classes)
    truth = [shapely.affinity.translate(g, *demo.DEMO_ORIGIN)
             for g in demo.true_breaklines(plain)]

    def pieces(out):
        pipeline.run_pipeline(tmp_path / "points.laz", tmp_path / out, RunOptions())
        score = score_breaklines(io.read_lines_gpkg(tmp_path / out / "breaklines.gpkg"),
                                 truth, 2.0)
        return score["pieces"], score["recall"]

    whole, recall = pieces("with")
    monkeypatch.setattr(pipeline, "BRIDGE_GAP_CELLS", 0.0)
    monkeypatch.setattr(localise, "CORNER_TURN", 180.0)
    broken, recall_before = pieces("without")
    # when written: 1.25 pieces a line (at most 2), recall 0.995; before, 2.9 (2 to 4), 0.967;
    # since joins are measured between the pieces' fitted ends, 2.4 before (2 to 3)
    assert np.mean(whole) <= 1.5 and max(whole) <= 2 and recall >= 0.98
    assert np.mean(broken) >= 2.25 and min(broken) >= 2 and recall_before < recall


def test_crossing_points_are_where_two_lines_cross_or_meet_at_an_angle():
    road = np.array([[0.0, -50.0], [0.0, 50.0]])
    bank = np.array([[-50.0, 10.0], [50.0, 10.0]])                  # crosses the road at 90°
    spur = np.array([[20.0, 10.0], [20.0 + 30 * np.cos(0.6), 10.0 + 30 * np.sin(0.6)]])  # 34°
    graze = np.array([[-40.0, 10.0], [-10.0, 10.0 + 30 * np.tan(np.radians(20))]])  # 20°
    piece = np.array([[50.0, 10.0], [90.0, 10.0]])                  # the bank's next piece
    beside = np.array([[-50.0, 11.0], [10.0, 11.0]])                # a metre beside it
    found = crossing_points([road, bank, spur, graze, piece, beside])
    assert sorted(map(tuple, np.round(found, 6))) == [(0.0, 10.0), (0.0, 11.0), (20.0, 10.0)]
    assert crossing_points([road]).shape == (0, 2)
