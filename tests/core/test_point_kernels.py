"""The compiled area check of the points read against the numpy definition it replaced."""
import numpy as np
import pytest

from floodmesh.core._kernels.points import spread


def _numpy_spread(xy):
    """The definition (points.check_spread before it was compiled)."""
    centred = xy - xy.mean(axis=0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    across, along = np.ptp(centred @ axes, axis=0)
    return np.ptp(xy, axis=0).max(), across, along


@pytest.mark.parametrize("case", ["cloud", "tilted strip", "line", "one place"])
def test_spread_is_the_numpy_definition(case):
    rng = np.random.default_rng(4)
    t = rng.uniform(0, 800, 5000)
    across = {"cloud": rng.uniform(0, 300, 5000), "tilted strip": rng.normal(0, 0.5, 5000),
              "line": np.zeros(5000), "one place": np.zeros(5000)}[case]
    if case == "one place":
        t = np.zeros(5000)
    angle = np.radians(33.0)
    xy = np.column_stack([400_000 + t * np.cos(angle) - across * np.sin(angle),
                          5_600_000 + t * np.sin(angle) + across * np.cos(angle)])
    expected = _numpy_spread(xy)
    for blocks in (1, 3, 64):  # a block a thread, one, or more blocks than threads
        ours = spread(xy[:, 0], xy[:, 1], blocks)
        assert ours[0] == pytest.approx(expected[0], abs=1e-9)
        assert ours[1] == pytest.approx(expected[1], abs=1e-6)  # the minor axis: across
        assert ours[2] == pytest.approx(expected[2], abs=1e-6)


def _numpy_repeats(xyz, step):
    """The definition (the check of repeated positions before it was compiled): one key per rounded
    position, a stable sort, the z of consecutive points at one position compared."""
    cell = np.round((xyz[:, :2] - xyz[:, :2].min(axis=0)) / step).astype(np.int64)
    key = cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1]
    order = np.argsort(key, kind="stable")
    dz = np.abs(np.diff(xyz[order, 2]))[key[order][1:] == key[order][:-1]]
    return int((dz > 0).sum()), float(dz.max()) if dz.size else 0.0


@pytest.mark.parametrize("case", ["scattered", "clustered", "one place", "a line"])
def test_repeated_positions_are_the_numpy_definition(case):
    """Points repeating an earlier point's x, y (to 0.1 mm) with another z: counted as the
    sort of one key per point counted them, in cells of a few points and in crowded ones."""
    from floodmesh.core._kernels.points import repeated_positions

    rng = np.random.default_rng(7)
    n = 30_000
    xy = rng.uniform(0, 500, (n, 2))
    if case == "clustered":  # thousands of points within a few cells
        xy[: n // 2] = rng.uniform(0, 0.01, (n // 2, 2)).round(3)
    elif case == "one place":
        xy[:] = 0.25
    elif case == "a line":
        xy[:, 1] = 3.0
    xy += [400_000, 5_600_000]
    repeat = rng.integers(0, n, 3000)
    xy[rng.integers(0, n, 3000)] = xy[repeat] + rng.uniform(-4e-5, 4e-5, (3000, 2))
    z = rng.choice([10.0, 10.0, 10.25, 11.5], n)
    xyz = np.column_stack([xy, z])
    expected = _numpy_repeats(xyz, 1e-4)
    assert expected[0] > 0
    count, largest = repeated_positions(xyz[:, 0], xyz[:, 1], xyz[:, 2], 1e-4)
    assert (count, largest) == expected


@pytest.mark.parametrize("case", ["uniform", "rounded normal", "circle at UTM", "small lattice"])
def test_convex_hull_is_geos_hull(case):
    """The candidates outside the octagon of extremes, then Andrew's monotone chain, give the
    hull GEOS gives of all the points: the same area, anticlockwise, valid; lattices and points
    on a circle (every point a hull vertex) included."""
    import shapely

    from floodmesh.core._kernels.points import hull_candidates, monotone_chain

    rng = np.random.default_rng(9)
    for trial in range(25):
        n = int(rng.integers(3, 3000))
        if case == "uniform":
            x, y = rng.uniform(0, 100, n), rng.uniform(0, 50, n)
        elif case == "rounded normal":
            x, y = np.round(rng.normal(0, 10, n)), np.round(rng.normal(0, 10, n))
        elif case == "circle at UTM":
            angle = rng.uniform(0, 2 * np.pi, n)
            x, y = 500_000 + 300 * np.cos(angle), 6e6 + 300 * np.sin(angle)
        else:
            x, y = rng.integers(0, 4, n).astype(float), rng.integers(0, 3, n).astype(float)
        keep = hull_candidates(x, y, 3)
        # the first point of each extreme, whatever the blocks: the same candidates
        assert all(np.array_equal(hull_candidates(x, y, blocks), keep) for blocks in (1, 2, 64))
        order = np.lexsort((y[keep], x[keep]))
        hull = shapely.Polygon(monotone_chain(x[keep][order], y[keep][order]))
        expected = shapely.convex_hull(shapely.multipoints(np.column_stack([x, y])))
        assert hull.is_valid and hull.exterior.is_ccw
        assert hull.area == pytest.approx(expected.area, rel=1e-9)


@pytest.mark.parametrize("blocks", [1, 2, 3, 16])
@pytest.mark.parametrize("n", [0, 1, 5, 10_007])
def test_split_and_scaled_rows_are_numpy_indexing_in_any_blocks(n, blocks):
    """The holdout split and the scaling of a LAS file's stored integers, counted and copied
    block by block on threads, give numpy's boolean indexing of the rows: the same rows, in
    the file's order, whatever the number of blocks (more blocks than points included)."""
    from floodmesh.core._kernels.points import scaled_points, split_rows

    rng = np.random.default_rng(n + blocks)
    xyz = rng.normal(size=(n, 3))
    taken = rng.random(n) < 0.1
    left, held = split_rows(xyz, taken, blocks)
    assert np.array_equal(left, xyz[~taken]) and np.array_equal(held, xyz[taken])
    assert left.shape == (n - taken.sum(), 3) and held.shape == (taken.sum(), 3)
    stored = [rng.integers(-10**6, 10**6, n).astype(np.int32) for _ in range(3)]
    classes = rng.integers(0, 8, n).astype(np.uint8)
    keep = np.zeros(256, bool)
    keep[[2, 9]] = True
    scales, offsets = np.array([0.001, 0.01, 0.001]), np.array([4e5, 5.6e6, 17.0])
    mine = keep[classes]
    expected = np.column_stack([s[mine] * scales[k] + offsets[k] for k, s in enumerate(stored)])
    assert np.array_equal(scaled_points(*stored, classes, keep, scales, offsets, blocks),
                          expected.reshape(-1, 3))


@pytest.mark.parametrize("blocks", [1, 2, 3, 16])
@pytest.mark.parametrize("n", [1, 5, 10_007])
def test_extent_bins_and_usable_rows_are_numpy_in_any_blocks(n, blocks):
    """The bounding box, the occupied bins of the footprint and the usable rows (finite, z in
    range), each block of points on a thread, give numpy's: a non-finite value or a z out of
    range in the first, a middle or the last row, or in none."""
    from floodmesh.core._kernels.points import (extent, extent_on_threads, occupied_bins,
                                                usable_rows)

    rng = np.random.default_rng(n * blocks)
    xyz = rng.uniform(0.0, 50.0, (n, 3)) + [600_000.0, 5_700_000.0, 0.0]
    x, y = xyz[:, 0].copy(), xyz[:, 1].copy()
    box = (x.min(), y.min(), x.max(), y.max())
    assert extent_on_threads(x, y, blocks) == box == extent(x, y)
    size = 2.5
    cols, rows = int((x.max() - x.min()) / size) + 1, int((y.max() - y.min()) / size) + 1
    bins = np.unique(((y - y.min()) / size).astype(np.int64) * cols
                     + ((x - x.min()) / size).astype(np.int64))
    assert occupied_bins(x, y, x.min(), y.min(), size, cols, rows, blocks) == len(bins)
    assert usable_rows(xyz, -1000.0, 9000.0, blocks) is None
    for row, column, value in ((0, 2, np.nan), (n // 2, 0, np.inf), (n - 1, 1, -np.inf),
                               (n // 3, 2, -9999.0), (n - 1, 2, 9000.5)):
        broken = xyz.copy()
        broken[row, column] = value
        want = np.isfinite(broken).all(axis=1) & (np.abs(broken[:, 2] - 4000) <= 5000)
        assert np.array_equal(usable_rows(broken, -1000.0, 9000.0, blocks), want)
