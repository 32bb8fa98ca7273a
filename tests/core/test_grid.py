"""Gridding (``grid_points_linear``) and the holdout split (``split_holdout``).

Reference: linear interpolation on any triangulation of points lying on a plane reproduces
that plane exactly, so the DEM of plane points must equal the analytic plane at every cell
centre; the coverage is checked against scipy's convex hull of the points.
"""
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from pyproj import CRS
from scipy.spatial import Delaunay

from floodmesh.core.errors import FloodMeshError
from floodmesh.core.steps.grid import grid_points_linear
from floodmesh.core.points import (PointCloud, every_nth_by_place, held_out_by_place,
                                   holdout_candidates, least_hash, place_hashes, split_holdout)

from ..conftest import plane_points

CRS_M = CRS.from_epsg(25832)
ORIGIN = (500000.0, 6e6)
A, B, C = 0.1, -0.05, 12.0


def plane(x, y):
    """The plane of ``plane_points`` defaults, at map coordinates."""
    return A * (x - ORIGIN[0]) + B * (y - ORIGIN[1]) + C


def cloud(xyz):
    return PointCloud(np.asarray(xyz, dtype=np.float64), CRS_M)


def centres(grid):
    rows, cols = np.indices(grid.shape)
    return grid.cell_centres(rows, cols)


@pytest.fixture(scope="module")
def plane_xyz():
    return plane_points(a=A, b=B, c=C, size=40.0, density=4.0, seed=0, origin=ORIGIN)


@pytest.mark.parametrize("d", [1.0, 2.5])
def test_plane_is_reproduced_at_every_cell_centre(plane_xyz, d):
    """Every valid cell equals the plane at its centre (1e-9 m); most of the area is covered."""
    dem = grid_points_linear(cloud(plane_xyz), d)
    x, y = centres(dem)
    valid = np.isfinite(dem.values)
    assert valid.sum() > 0.8 * (40.0 / d) ** 2
    assert_allclose(dem.values[valid], plane(x, y)[valid], rtol=0, atol=1e-9)
    assert dem.cell_size == d
    assert dem.crs == CRS_M


@pytest.mark.parametrize("d", [1.0, 2.5])
def test_cell_edges_aligned_to_multiples_of_cell_size(plane_xyz, d):
    """The upper-left corner lies on whole multiples of d and the grid covers all points."""
    dem = grid_points_linear(cloud(plane_xyz), d)
    t = dem.transform
    assert (t.a, t.b, t.d, t.e) == (d, 0.0, 0.0, -d)
    assert math.fmod(t.c, d) == 0.0
    assert math.fmod(t.f, d) == 0.0
    xmin, ymin, xmax, ymax = dem.bounds
    assert xmin <= plane_xyz[:, 0].min() and plane_xyz[:, 0].max() <= xmax
    assert ymin <= plane_xyz[:, 1].min() and plane_xyz[:, 1].max() <= ymax
    # no spare row or column of cells beyond the data
    assert xmax - plane_xyz[:, 0].max() < d and plane_xyz[:, 1].min() - ymin < d


def test_cells_outside_convex_hull_are_nan(plane_xyz):
    """Cell centres outside the points' convex hull (scipy) are NaN; those inside are valid."""
    dem = grid_points_linear(cloud(plane_xyz), 1.0)
    x, y = centres(dem)
    inside = Delaunay(plane_xyz[:, :2]).find_simplex(np.column_stack([x.ravel(), y.ravel()]))
    inside = (inside >= 0).reshape(dem.shape)
    assert (~inside).sum() > 0, "the test needs cells outside the hull"
    assert np.isnan(dem.values[~inside]).all()
    assert np.isfinite(dem.values[inside]).all()


def gap_points():
    """Plane points with every point in the 10 m strip 15 <= local x < 25 removed."""
    xyz = plane_points(a=A, b=B, c=C, size=40.0, density=4.0, seed=0, origin=ORIGIN)
    local_x = xyz[:, 0] - ORIGIN[0]
    return xyz[(local_x < 15.0) | (local_x >= 25.0)]


def strip_cells(dem):
    """Cells whose centres lie well inside the strip (local x in [17, 23], y in [2, 38])."""
    x, y = centres(dem)
    lx, ly = x - ORIGIN[0], y - ORIGIN[1]
    return (lx >= 17) & (lx <= 23) & (ly >= 2) & (ly <= 38)


def test_gap_wider_than_max_gap_stays_nodata():
    dem = grid_points_linear(cloud(gap_points()), 1.0, max_gap=3.0)
    strip = strip_cells(dem)
    assert strip.sum() == 6 * 36  # centres at x = 17.5 .. 22.5, y = 2.5 .. 37.5
    assert np.isnan(dem.values[strip]).all()
    # the data either side of the strip is still gridded
    x, _ = centres(dem)
    lx = x - ORIGIN[0]
    assert np.isfinite(dem.values[(lx > 3) & (lx < 12)]).mean() > 0.8
    assert np.isfinite(dem.values[(lx > 28) & (lx < 37)]).mean() > 0.8


def test_gap_narrower_than_max_gap_is_bridged_on_the_plane():
    dem = grid_points_linear(cloud(gap_points()), 1.0, max_gap=50.0)
    strip = strip_cells(dem)
    assert np.isfinite(dem.values[strip]).all()
    x, y = centres(dem)
    assert_allclose(dem.values[strip], plane(x, y)[strip], rtol=0, atol=1e-9)


def curved_points():
    """Points on a curved surface, so a different triangulation would change the DEM."""
    xyz = plane_points(a=A, b=B, c=C, size=40.0, density=2.0, seed=3, origin=ORIGIN)
    lx, ly = xyz[:, 0] - ORIGIN[0], xyz[:, 1] - ORIGIN[1]
    xyz[:, 2] = 3.0 * np.sin(lx / 5.0) * np.cos(ly / 7.0) + 0.02 * lx * ly
    return xyz


def test_exact_duplicate_points_give_the_same_dem():
    xyz = curved_points()
    reference = grid_points_linear(cloud(xyz), 1.0)
    doubled = grid_points_linear(cloud(np.vstack([xyz, xyz[::-1]])), 1.0)
    assert doubled.transform == reference.transform
    assert_array_equal(np.isnan(doubled.values), np.isnan(reference.values))
    assert_allclose(doubled.values, reference.values, rtol=0, atol=1e-9, equal_nan=True)


def test_points_repeated_with_another_z_grid_to_their_mean():
    """Every point again 0.2 m higher (tiles merged twice after a reprocessing): each place's
    two heights averaged, so the DEM is the surface 0.1 m up, whatever order the copies come
    in (the sweep kept the first of each, so the DEM followed the file's order)."""
    xyz = curved_points()
    reference = grid_points_linear(cloud(xyz), 1.0)
    higher = xyz + [0.0, 0.0, 0.2]
    for both in (np.vstack([xyz, higher]), np.vstack([higher, xyz[::-1]])):
        doubled = grid_points_linear(cloud(both), 1.0)
        assert_array_equal(np.isnan(doubled.values), np.isnan(reference.values))
        assert_allclose(doubled.values, reference.values + 0.1, rtol=0, atol=1e-9,
                        equal_nan=True)


def test_the_same_points_in_any_order_grid_to_the_same_dem():
    """A survey with some places measured two and three times, in three orders: the DEM the
    same to the bit (kept by the order of the file, 574 of 1,600 cells differed)."""
    xyz = curved_points()
    survey = np.vstack([xyz, xyz[:800] + [0.0, 0.0, 0.3], xyz[:200] - [0.0, 0.0, 0.1]])
    first = grid_points_linear(cloud(survey), 1.0).values
    for seed in (1, 2):
        order = np.random.default_rng(seed).permutation(len(survey))
        assert_array_equal(grid_points_linear(cloud(survey[order]), 1.0).values, first)


def test_jittered_duplicate_points_give_the_same_dem():
    """Each point again, moved by 1e-9 m in x and y (same z)."""
    xyz = curved_points()
    rng = np.random.default_rng(7)
    jittered = xyz.copy()
    jittered[:, :2] += rng.choice([-1e-9, 1e-9], size=(len(xyz), 2))
    reference = grid_points_linear(cloud(xyz), 1.0)
    doubled = grid_points_linear(cloud(np.vstack([xyz, jittered])), 1.0)
    assert doubled.transform == reference.transform
    assert_array_equal(np.isnan(doubled.values), np.isnan(reference.values))
    assert_allclose(doubled.values, reference.values, rtol=0, atol=1e-6, equal_nan=True)


@pytest.mark.parametrize("cell_size", [0.0, -1.0, float("nan"), float("inf")])
def test_non_positive_cell_size_is_refused(plane_xyz, cell_size):
    with pytest.raises(FloodMeshError, match="cell size"):
        grid_points_linear(cloud(plane_xyz), cell_size)


@pytest.mark.parametrize("cell_size", [20.0, 100.0])
def test_cell_size_larger_than_the_data_is_refused(plane_xyz, cell_size):
    """40 m of data at 20 m or 100 m cells is fewer than 4 cells each way, as a DEM needs to be
    meshed."""
    with pytest.raises(FloodMeshError, match="fewer than 4 cells"):
        grid_points_linear(cloud(plane_xyz), cell_size)


def test_too_many_cells_is_refused(plane_xyz):
    """40 m at 1 mm cells would be 1.6e9 cells, over the limit."""
    with pytest.raises(FloodMeshError, match="cells"):
        grid_points_linear(cloud(plane_xyz), 0.001)


# ---------------------------------------------------------------------------------------------
# holdout split
@pytest.fixture(scope="module")
def thousand():
    xyz = plane_points(size=10.0, density=10.0, seed=5, origin=ORIGIN)
    assert len(xyz) == 1000
    return cloud(xyz)


def rows_as_set(xyz):
    return {tuple(row) for row in xyz.tolist()}


def test_holdout_fraction_and_partition(thousand):
    kept, held = split_holdout(thousand, 0.1, seed=42)
    assert len(held) == 100
    assert len(kept) == 900
    assert kept.crs == thousand.crs and held.crs == thousand.crs
    assert rows_as_set(kept.xyz).isdisjoint(rows_as_set(held.xyz))
    assert rows_as_set(kept.xyz) | rows_as_set(held.xyz) == rows_as_set(thousand.xyz)
    together = np.vstack([kept.xyz, held.xyz])
    assert_array_equal(together[np.lexsort(together.T)],
                       thousand.xyz[np.lexsort(thousand.xyz.T)])


def test_the_same_points_in_another_order_hold_out_the_same_points(thousand):
    order = np.random.default_rng(3).permutation(len(thousand))
    shuffled = PointCloud(thousand.xyz[order], thousand.crs)
    for fraction, seed in ((0.1, 42), (0.001, 0)):
        kept, held = split_holdout(thousand, fraction, seed=seed)
        kept_again, held_again = split_holdout(shuffled, fraction, seed=seed)
        assert rows_as_set(held_again.xyz) == rows_as_set(held.xyz)
        assert rows_as_set(kept_again.xyz) == rows_as_set(kept.xyz)
    # another seed, another draw
    draws = [rows_as_set(split_holdout(thousand, 0.1, seed=seed)[1].xyz) for seed in (42, 43)]
    assert draws[0] != draws[1]


def test_points_given_twice_still_hold_out_the_count_asked(thousand):
    twice = np.vstack([thousand.xyz, thousand.xyz[:500]])
    for n_out, seed in ((1, 0), (20, 1), (150, 2), (1499, 3)):
        assert held_out_by_place(twice, n_out, seed).sum() == n_out
    assert not held_out_by_place(twice, 0, 0).any() and held_out_by_place(twice, 1500, 0).all()


@pytest.mark.parametrize("fraction, n_out", [(0.1, 100), (0.001, 20), (0.5, 500)])
def test_parts_of_a_survey_draw_the_check_points_of_the_whole(thousand, fraction, n_out):
    """Cut into parts of any size (tiles, an empty one, one of a single point), each part's
    candidates hold the check points the whole survey draws at once."""
    xyz = thousand.xyz
    whole = rows_as_set(xyz[held_out_by_place(xyz, n_out, 7)])
    cuts = [0, 0, 1, 37, 400, 401, 999, 1000]  # parts of 0, 1, 36, 363, 0, 1, 598, 1 points
    parts = [xyz[a:b] for a, b in zip(cuts[:-1], cuts[1:])]
    drawn = [holdout_candidates(place_hashes(p, 7), fraction) for p in parts]
    below = least_hash([place_hashes(p, 7)[rows] for p, (rows, _) in zip(parts, drawn)],
                       [bound for _, bound in drawn], n_out)
    held = set()
    for p in parts:
        held |= rows_as_set(p[place_hashes(p, 7) <= np.uint64(below)])
    assert held == whole and len(held) == n_out
    # a part's candidates are few: its share, 8 standard deviations and 64 more
    rows, _ = holdout_candidates(place_hashes(xyz, 7), 0.001)
    assert len(rows) < 1 + 8 + 64 + 4 * np.sqrt(73)
    assert least_hash([], [], 5) is None and least_hash([np.zeros(3, np.uint64)], [9], 0) is None


def test_every_nth_point_by_place_is_the_same_in_any_order():
    xyz = plane_points(size=100.0, density=9.0, seed=5, origin=ORIGIN)
    some = every_nth_by_place(xyz, 9)
    assert abs(len(some) - len(xyz) / 9) < 4 * np.sqrt(len(xyz) / 9)
    assert rows_as_set(some) <= rows_as_set(xyz)
    shuffled = every_nth_by_place(xyz[np.random.default_rng(0).permutation(len(xyz))], 9)
    assert rows_as_set(shuffled) == rows_as_set(some)
    # spread over the area as the points are: each quarter holds its share
    quarter = (some[:, :2] - some[:, :2].min(axis=0)) // 50
    counts = np.unique(quarter[:, 0] * 2 + quarter[:, 1], return_counts=True)[1]
    assert len(counts) == 4 and counts.min() > 0.8 * len(some) / 4
    assert every_nth_by_place(xyz, 1) is xyz


def test_a_small_survey_holds_out_the_20_points_the_nssda_test_needs(thousand):
    """The reference share (0.001) keeps 1 of 1,000 points: raised to 20, with a note, instead
    of a refusal (Topography.laz's 8,159 points kept 8 and the default run stopped)."""
    notes = []
    kept, held = split_holdout(thousand, 0.001, seed=0, note=notes.append)
    assert (len(held), len(kept)) == (20, 980)
    assert len(notes) == 1 and "keeps 1 of 1,000" in notes[0] and "raised to 20" in notes[0]
    notes.clear()
    split_holdout(thousand, 0.05, seed=0, note=notes.append)  # 50 points: nothing to say
    assert notes == []


def test_too_few_points_to_spare_20_are_refused_with_the_fix():
    with pytest.raises(FloodMeshError, match="too few points to hold 20 back; give holdout 0"):
        split_holdout(cloud(plane_points(size=2.0, density=5.0)), 0.001, seed=0)


def test_holdout_same_seed_same_split_other_seed_other_split(thousand):
    kept1, held1 = split_holdout(thousand, 0.1, seed=42)
    kept2, held2 = split_holdout(thousand, 0.1, seed=42)
    assert_array_equal(held1.xyz, held2.xyz)
    assert_array_equal(kept1.xyz, kept2.xyz)
    _, held3 = split_holdout(thousand, 0.1, seed=43)
    assert rows_as_set(held3.xyz) != rows_as_set(held1.xyz)


def test_holdout_fraction_zero_holds_nothing_out(thousand):
    kept, held = split_holdout(thousand, 0.0, seed=1)
    assert len(held) == 0
    assert_array_equal(kept.xyz, thousand.xyz)


@pytest.mark.parametrize("fraction", [-0.1, 1.0, 1.5])
def test_holdout_fraction_outside_range_is_refused(thousand, fraction):
    with pytest.raises(FloodMeshError, match="holdout fraction"):
        split_holdout(thousand, fraction, seed=0)


def test_tiles_equal_one_global_tin():
    """A grid spanning several tiles (with halos) equals linear interpolation on one global
    Delaunay TIN (scipy's griddata, Qhull), cell for cell. The reference works in local
    coordinates: at UTM magnitudes Qhull's interpolation is off by centimetres."""
    from scipy.interpolate import griddata

    from floodmesh.core.steps import grid as grid_module

    rng = np.random.default_rng(5)
    n = 120_000
    x, y = rng.uniform(0, 700, n), rng.uniform(0, 330, n)
    z = 5 * np.sin(x / 37) * np.cos(y / 23) + 0.01 * x
    xyz = np.column_stack([x + 500_000, y + 6e6, z])
    dem = grid_module.grid_points_linear(PointCloud(xyz, CRS_M), 1.0, max_gap=50.0)
    assert min(dem.shape) > grid_module.near_tile_side(*dem.shape, 1.0, n, 2)  # tiles each way
    rows, cols = np.indices(dem.shape)
    gx, gy = dem.cell_centres(rows, cols)
    reference = griddata(np.column_stack([x, y]), z, (gx - 500_000, gy - 6e6), method="linear")
    assert_array_equal(np.isfinite(dem.values), np.isfinite(reference))
    both = np.isfinite(reference)
    assert_allclose(dem.values[both], reference[both], atol=1e-9)


def test_voids_and_a_ragged_edge_across_tiles_equal_one_global_tin():
    """Dense points (tiles then take a near halo, checked) with a lake, a channel and ponds
    across tile edges and a ragged survey boundary: every cell equals linear interpolation on
    Qhull's Delaunay TIN of all the points, NaN where the triangle has an edge over the max gap
    or no triangle covers the cell. A near halo taken on trust would bridge the voids with
    triangles that the whole TIN does not have."""
    from floodmesh.core.steps import grid as grid_module

    rng = np.random.default_rng(11)
    n = 500_000
    x, y = rng.uniform(0, 400, n), rng.uniform(0, 300, n)
    void = (((x - 128) ** 2 + (y - 150) ** 2 < 25 ** 2) | (np.abs(x - 256 + 0.1 * y) < 4)
            | ((x - 60) ** 2 + (y - 60) ** 2 < 9))
    for px, py in ((384.5, 100), (200, 161.5), (320, 34.5)):  # ponds on tile edges
        void |= (x - px) ** 2 + (y - py) ** 2 < 4.5 ** 2
    void |= y > 290 - 12 * np.abs(np.sin(x / 17))  # a ragged, concave edge
    x, y = x[~void], y[~void]
    z = 4 * np.sin(x / 23) * np.cos(y / 31) + 0.01 * x
    xyz = np.column_stack([x + ORIGIN[0], y + ORIGIN[1], z])
    dem = grid_module.grid_points_linear(cloud(xyz), 1.0, max_gap=10.0)
    assert min(dem.shape) > 2 * grid_module.near_tile_side(*dem.shape, 1.0, len(x), 2)
    gx, gy = centres(dem)
    tin = Delaunay(np.column_stack([x, y]))
    cells = np.column_stack([gx.ravel() - ORIGIN[0], gy.ravel() - ORIGIN[1]])
    simplex = tin.find_simplex(cells)
    corners = tin.points[tin.simplices[simplex]]
    longest = np.max([np.hypot(*(corners[:, k] - corners[:, (k + 1) % 3]).T) for k in range(3)],
                     axis=0)
    reference = np.full(len(cells), np.nan)
    inside = (simplex >= 0) & (longest <= 10.0)
    weights = np.einsum("nij,nj->ni", tin.transform[simplex[inside], :2],
                        cells[inside] - tin.transform[simplex[inside], 2])
    weights = np.column_stack([weights, 1 - weights.sum(axis=1)])
    reference[inside] = (weights * z[tin.simplices[simplex[inside]]]).sum(axis=1)
    reference = reference.reshape(dem.shape)
    assert np.isnan(reference).sum() > 3000  # the voids are there
    assert_array_equal(np.isfinite(dem.values), np.isfinite(reference))
    both = np.isfinite(reference)
    assert_allclose(dem.values[both], reference[both], atol=1e-9)
