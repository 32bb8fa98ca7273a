"""The shared nearest-neighbour look-ups against the definitions they replace."""
import numpy as np
import shapely
from scipy.spatial import cKDTree

from floodmesh.core.nearest import nearest_line, point_tree


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
    geoms = [shapely.LineString(c[:, :2]) for c in lines]
    (point, line), distance = shapely.STRtree(geoms).query_nearest(
        shapely.points(xy), return_distance=True, all_matches=True)
    least = np.full(len(xy), np.inf)
    np.minimum.at(least, point, distance)
    lowest = np.full(len(xy), len(lines))
    np.minimum.at(lowest, point, line)

    nearest, found = nearest_line(xy, lines)

    assert np.array_equal(found, least)
    assert np.array_equal(nearest, lowest)
    assert (nearest != len(lines) - 1).all()  # the copy of line 0 never wins over line 0


def test_point_tree_finds_the_same_neighbours_as_the_default_tree():
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(0, 100, (20000, 2)), rng.normal(0, 1, 20000)])
    centres = rng.uniform(0, 100, (500, 2))
    ours = point_tree(points).query_ball_point(centres, 1.7)
    default = cKDTree(points[:, :2]).query_ball_point(centres, 1.7)
    assert all(list(a) == list(b) for a, b in zip(ours, default))
