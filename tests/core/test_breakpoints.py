"""Breakpoints: the slope threshold and the thinning of completely surrounded breakpoints.

Reference: small hand-made arrays with the expected results written out cell by cell.
"""
import numpy as np
import pytest
from affine import Affine
from numpy.testing import assert_array_equal
from pyproj import CRS

from floodmesh.core.steps.breakpoints import classify_breakpoints, thin_breakpoints
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.raster import Grid

TRANSFORM = Affine(2.0, 0.0, 500000.0, 0.0, -2.0, 6001000.0)
CRS_M = CRS.from_epsg(25832)


def slope_grid(values):
    return Grid(np.asarray(values, dtype=np.float64), TRANSFORM, CRS_M)


def bits(text):
    """A boolean array from rows of 0/1 characters."""
    return np.array([[ch == "1" for ch in row.strip()] for row in text.strip().splitlines()])


def test_threshold_includes_equality_and_excludes_nan():
    slopes = slope_grid([[10.0, 14.999999, 15.0],
                         [15.000001, np.nan, 0.0],
                         [89.9, -np.inf, np.inf]])
    result = classify_breakpoints(slopes, 15.0, thin=False)
    assert result.values.dtype == np.uint8
    assert result.transform == TRANSFORM and result.crs == CRS_M
    assert_array_equal(result.values, [[0, 0, 1],
                                       [1, 0, 0],
                                       [1, 0, 1]])


def test_threshold_then_thinning():
    """classify_breakpoints thins by default: a steep 3x3 patch keeps its ring only."""
    slopes = np.full((5, 5), 2.0)
    slopes[1:4, 1:4] = 30.0
    result = classify_breakpoints(slope_grid(slopes), 20.0)
    assert_array_equal(result.values, bits("""
        00000
        01110
        01010
        01110
        00000
    """).astype(np.uint8))


@pytest.mark.parametrize("s_crit", [0.0, 90.0, -5.0, 95.0, float("nan")])
def test_s_crit_outside_open_interval_is_refused(s_crit):
    with pytest.raises(FloodMeshError, match="S_crit"):
        classify_breakpoints(slope_grid(np.zeros((3, 3))), s_crit)


def test_solid_block_keeps_its_outline():
    block = bits("""
        000000000
        000000000
        001111100
        001111100
        001111100
        001111100
        001111100
        000000000
        000000000
    """)
    expected = bits("""
        000000000
        000000000
        001111100
        001000100
        001000100
        001000100
        001111100
        000000000
        000000000
    """)
    thinned = thin_breakpoints(block)
    assert thinned.sum() == 16
    assert_array_equal(thinned, expected)


def test_one_cell_wide_lines_are_kept_whole():
    lines = bits("""
        000000000
        011111110
        000000000
        000010000
        000001000
        000000100
        000000010
        010000000
        010000000
    """)
    assert_array_equal(thin_breakpoints(lines), lines)


def test_three_cell_wide_band_keeps_both_sides():
    band = bits("""
        0000000
        1111111
        1111111
        1111111
        0000000
    """)
    expected = bits("""
        0000000
        1111111
        1000001
        1111111
        0000000
    """)
    assert_array_equal(thin_breakpoints(band), expected)


def test_block_touching_the_edge_keeps_its_edge_cells():
    block = bits("""
        1111000
        1111000
        1111000
        1111000
        0000000
        0000000
        0000000
    """)
    expected = bits("""
        1111000
        1001000
        1001000
        1111000
        0000000
        0000000
        0000000
    """)
    assert_array_equal(thin_breakpoints(block), expected)


def test_all_breakpoints_keeps_the_raster_border():
    everything = np.ones((4, 5), bool)
    expected = bits("""
        11111
        10001
        10001
        11111
    """)
    assert_array_equal(thin_breakpoints(everything), expected)
