"""Joining localised break-line pieces: a bank's crest broken mid-run joins into one line; a
crest and a toe, two parallel lines, and a crest cut by a channel stay apart."""
import numpy as np
import pytest

from floodmesh.core.breaklines import BreakLine
from floodmesh.core.joining import join_pieces
from floodmesh.core.localise import _ground_follows, fit_window, localise_traced

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
