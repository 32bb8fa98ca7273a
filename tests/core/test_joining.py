"""Joining localised break-line pieces: a bank's crest broken mid-run joins into one line; a
crest and a toe, two parallel lines, and a crest cut by a channel stay apart."""
import numpy as np
import pytest

from floodmesh.core.steps.breaklines import BreakLine
from floodmesh.core.steps.joining import join_pieces
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


@pytest.mark.parametrize("channel", [False, True])
def test_localised_crest_broken_mid_run_joins_unless_a_channel_cuts_it(channel):
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 100, (90_000, 2))
    points = np.column_stack([xy, _bank(xy, channel) + rng.normal(0, 0.15, len(xy))])
    window = fit_window(points, 1e4, 1.0)
    lines = [BreakLine(np.column_stack([p[:, :2], _bank(p[:, :2])]), np.full(len(p), 20.0))
             for p in (_piece(-35, -3, 0.4), _piece(3, 35, -0.4))]
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
