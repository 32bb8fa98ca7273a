"""The break-line score on lines whose answer is known by hand: a narrow embankment's crest
and toe 1 m apart, a trace that runs along one of them, collinear duplicates, a line that
crosses, and one that hops between the two."""
import numpy as np
import pytest
import shapely

from floodmesh.core.steps.validation import score_breaklines

CREST = shapely.LineString([(0, 0), (100, 0)])
TOE = shapely.LineString([(0, 1), (100, 1)])  # 1 m from the crest: within the 2 m tolerance


def test_a_trace_of_the_crest_is_not_also_the_toe():
    """With the buffer of each line alone, a trace of the crest also recalled the toe 1 m away
    and counted as a piece of it: recall 1.0, pieces [1, 1]. It belongs to the crest only."""
    score = score_breaklines([[(0, 0.1), (100, 0.1)]], [CREST, TOE], 2.0)
    assert score["pieces"] == [1, 0]
    assert score["recall"] == pytest.approx(0.5, abs=1e-9)
    assert score["recalled_m"] == pytest.approx([100.0, 0.0], abs=1e-9)
    assert score["precision"] == pytest.approx(1.0)
    assert score["spans_m"][0] == [pytest.approx((0.0, 100.0))]


def test_collinear_duplicates_are_pieces_and_a_crossing_line_is_not():
    duplicates = [[(0, 0.2), (60, 0.2)], [(40, -0.3), (100, -0.3)], [(50, -20), (50, 20)]]
    score = score_breaklines(duplicates, [CREST], 2.0)
    assert score["pieces"] == [2]
    assert score["spans_m"][0] == [pytest.approx((0.0, 60.0)), pytest.approx((40.0, 100.0))]
    assert score["recall"] == pytest.approx(1.0)
    # the crossing line's 4 m near the crest are within the tolerance; the rest is not
    assert score["precision"] == pytest.approx(124 / 160)


def test_a_trace_that_hops_between_crest_and_toe_is_a_piece_of_each_where_it_runs():
    hop = [(0, 0), (30, 0), (32, 1), (70, 1), (72, 0), (100, 0)]
    score = score_breaklines([hop], [CREST, TOE], 2.0)
    assert score["pieces"] == [1, 1]
    # the toe owns the hop from 31 to 71 m (where it is nearer the toe); within 2 m of that
    # stretch, 0.5 m from the toe at its ends, the toe runs 1.94 m further each way: 43.9 m
    assert score["recalled_m"][1] == pytest.approx(40 + 2 * np.sqrt(4 - 0.25), abs=0.6)
    assert score["recalled_m"][0] == pytest.approx(60 + 2 * np.sqrt(4 - 0.25), abs=0.6)
    assert score["recall"] == pytest.approx(sum(score["recalled_m"]) / 200)


def test_no_lines():
    empty = score_breaklines([], [CREST], 2.0)
    assert empty["recall"] == 0 and empty["pieces"] == [0] and np.isnan(empty["precision"])
