"""The shared nearest-neighbour look-ups against the definitions they replace."""
import numpy as np
import shapely
from scipy.spatial import cKDTree

from floodmesh.core.engine.nearest import nearest_line, point_index


def _random_lines(rng, n=40):
    lines = []
    for _ in range(n):
        start = rng.uniform(0, 200, 2)
        steps = rng.normal(0, 3, (int(rng.integers(2, 30)), 2))
        xy = start + np.cumsum(steps, axis=0)
        lines.append(np.column_stack([xy, rng.uniform(0, 5, len(xy))]))
    return lines


def test_nearest_line_is_the_whole_line_tree_answer():
    """Distances equal those of an STR tree of whole lines (GEOS's point–line distance) to the
    last bit; the line is the same wherever one line alone is nearest, the lower index at a
    tie (a point at a vertex two lines share)."""
    rng = np.random.default_rng(3)
    lines = _random_lines(rng)
    lines.append(lines[0].copy())  # the same line twice: a tie wherever line 0 is nearest
    xy = np.vstack([rng.uniform(-20, 220, (3000, 2)), lines[5][:, :2]])
    lowest, least = _whole_line_tree(xy, lines)

    nearest, found = nearest_line(xy, lines)

    assert np.array_equal(found, least)
    assert np.array_equal(nearest, lowest)
    assert (nearest != len(lines) - 1).all()  # the copy of line 0 never wins over line 0


def _whole_line_tree(xy, lines):
    """(lowest index of the nearest lines, distance) by an STR tree of whole lines."""
    geoms = [shapely.LineString(c[:, :2]) for c in lines]
    (point, line), distance = shapely.STRtree(geoms).query_nearest(
        shapely.points(xy), return_distance=True, all_matches=True)
    least = np.full(len(xy), np.inf)
    np.minimum.at(least, point, distance)
    lowest = np.full(len(xy), len(lines))
    np.minimum.at(lowest, point, line)
    return lowest, least


def test_nearest_line_far_off_and_long_segments_at_utm_magnitudes():
    """Points far off the lines (10 km), long diagonal segments among short ones, a line of
    one repeated vertex and coordinates of UTM magnitude: the tree's answer to the last bit."""
    rng = np.random.default_rng(7)
    origin = np.array([400_000.0, 5_600_000.0])
    lines = [origin + np.cumsum(rng.normal(0, 0.5, (int(rng.integers(2, 20)), 2)), axis=0)
             + rng.uniform(0, 300, 2) for _ in range(30)]
    lines += [origin + np.array([[0.0, 0.0], [900.0, 700.0]]),
              origin + np.array([[50.0, 800.0], [850.0, -20.0], [851.0, -20.5]]),
              np.repeat(origin[None] + 5.0, 2, axis=0)]
    xy = np.vstack([origin + rng.uniform(-100, 1000, (3000, 2)),
                    origin + rng.uniform(-1e4, 1e4, (200, 2)), lines[31]])

    nearest, found = nearest_line(xy, lines)

    lowest, least = _whole_line_tree(xy, lines)
    assert np.array_equal(found, least)
    assert np.array_equal(nearest, lowest)


def _same_as_ckdtree(points, centres, radius):
    """The index's query as cKDTree's, sorted; unsorted (``ascending=False``), the same
    points and counts."""
    index = point_index(points)
    indptr, indices = index.neighbours(centres, radius)
    loose_indptr, loose = index.neighbours(centres, radius, ascending=False)
    assert np.array_equal(loose_indptr, indptr)
    tree = cKDTree(points[:, :2])
    radii = np.broadcast_to(radius, (len(centres),))
    for k, (c, r) in enumerate(zip(centres, radii)):
        assert list(indices[indptr[k]:indptr[k + 1]]) == sorted(tree.query_ball_point(c, r))
        assert sorted(loose[indptr[k]:indptr[k + 1]]) == sorted(tree.query_ball_point(c, r))


def test_point_index_finds_the_points_cKDTree_finds():
    """The same points, sorted by index, as scipy's ball query: random points with one radius
    and one radius per centre, centres off the points, and points on a whole-metre lattice
    where many lie at exactly the radius (distance ≤ r counts)."""
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(0, 100, (20000, 2)), rng.normal(0, 1, 20000)])
    centres = np.vstack([rng.uniform(-5, 105, (400, 2)), [[-50.0, 50.0], [500.0, 500.0]]])
    _same_as_ckdtree(points, centres, 1.7)
    _same_as_ckdtree(points, centres, rng.uniform(0.1, 6.0, len(centres)))
    yy, xx = np.mgrid[0:40, 0:30].astype(float)
    lattice = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    _same_as_ckdtree(lattice, lattice[::7, :2], 2.0)
    _same_as_ckdtree(lattice, lattice[::5, :2] + 0.5, np.sqrt(2.0) / 2)


def test_point_index_of_points_on_one_line():
    x = np.linspace(0, 1000, 5000)
    points = np.column_stack([x, np.full_like(x, 7.0), x])
    _same_as_ckdtree(points, points[::50, :2], 3.0)


def test_cell_index_finds_the_points_the_point_index_finds_on_a_dem():
    """A DEM's cell centres as the fits' points (a seeded order, nodata cells left out) are
    found from the grid as the point index finds them in a copy of their coordinates: the same
    points, in the same order, at radii that put many centres exactly on the circle (whole
    and half cells), with centres off the grid and on odd origins and cell sizes."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.engine.nearest import CellIndex
    from floodmesh.core.chain.pipeline import _cell_points, _dem_cells
    from floodmesh.core.raster import Grid

    rng = np.random.default_rng(7)
    for cell, x0, y0 in ((1.0, 600_000.0, 5_700_040.0), (0.37, 512_345.678, 5_432_109.87)):
        values = rng.normal(10, 1, (40, 55))
        values[rng.random(values.shape) < 0.2] = np.nan  # nodata cells hold no point
        values[:5, :9] = np.nan
        dem = Grid(values, Affine(cell, 0, x0, 0, -cell, y0), CRS.from_epsg(25832))
        cells = _dem_cells(dem, seed=3)
        points = _cell_points(dem, cells)
        by_cells = CellIndex(dem.transform, dem.shape, cells)
        by_points = point_index(points)
        corner = np.array([x0, y0 - 40 * cell])
        centres = np.vstack([corner + rng.uniform(-3, 58, (300, 2)) * cell,  # some off the grid
                             points[rng.choice(len(points), 100), :2]])  # some on a centre
        for radius in (cell, 1.5 * cell, 2.5 * cell, 3 * cell,
                       rng.uniform(0.2, 4, len(centres)) * cell):
            a, b = by_cells.neighbours(centres, radius), by_points.neighbours(centres, radius)
            assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
            loose = by_cells.neighbours(centres, radius, ascending=False)  # sorted all the same
            assert np.array_equal(loose[0], a[0]) and np.array_equal(loose[1], a[1])
        assert by_cells.neighbours(centres, 1.0 * cell)[1].size > len(centres)
        assert by_cells.rank.itemsize == 4  # 4 B a cell
