"""The compiled area check of the points read against the numpy definition it replaced."""
import numpy as np
import pytest

from floodmesh.core._kernels.points import spread


def _numpy_spread(xy):
    """The definition (points._check_area before it was compiled)."""
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
    ours, expected = spread(xy[:, 0], xy[:, 1]), _numpy_spread(xy)
    assert ours[0] == pytest.approx(expected[0], abs=1e-9)
    assert ours[1] == pytest.approx(expected[1], abs=1e-6)  # the minor axis: across
    assert ours[2] == pytest.approx(expected[2], abs=1e-6)


def test_position_keys_are_the_numpy_keys():
    """The keys of the duplicate check equal the numpy expression they replaced."""
    from floodmesh.core._kernels.points import position_keys

    rng = np.random.default_rng(2)
    xy = np.column_stack([400_000 + rng.uniform(0, 900, 20000),
                          5_600_000 + rng.uniform(0, 700, 20000)])
    xy[:2000:2] = xy[1:2000:2].round(4)  # some at 0.1 mm positions and repeated
    cell = np.round((xy - xy.min(axis=0)) / 1e-4).astype(np.int64)
    expected = cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1]
    assert np.array_equal(position_keys(xy[:, 0], xy[:, 1], 1e-4), expected)
    far = np.array([[0.0, 0.0], [1e9, 1e9], [5.0, 5.0]])
    assert len(position_keys(far[:, 0], far[:, 1], 1e-4)) == 0
