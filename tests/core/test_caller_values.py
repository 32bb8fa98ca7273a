"""Values the library's caller hands the steps (``floodmesh.core``, as docs/library.md uses
it) meet the readers' rule: non-finite values and elevations no ground has (below -1000 m or
above 9000 m, such as -9999) are no-data, left out with a note, never gridded or meshed."""
import numpy as np
import pytest
from affine import Affine

from floodmesh import core

CRS = "EPSG:25832"


def _cloud_xyz():
    rng = np.random.default_rng(0)
    return np.column_stack([rng.uniform(0, 80, 12000) + 500000,
                            rng.uniform(0, 60, 12000) + 5700000, rng.normal(10, 0.1, 12000)])


@pytest.mark.parametrize("column, value", [(0, np.nan), (0, np.inf), (1, -np.inf),
                                           (2, np.nan), (2, np.inf), (2, -9999.0)])
def test_grid_points_leaves_out_unusable_points_with_a_note(column, value):
    xyz = _cloud_xyz()
    clean = core.grid_points(core.PointCloud(xyz, CRS), 1.0)
    bad = xyz.copy()
    bad[5, column] = value
    given = bad.copy()
    notes = []
    dem = core.grid_points(core.PointCloud(bad, CRS), 1.0, note=notes.append)
    assert np.array_equal(bad, given, equal_nan=True)  # the caller's array untouched
    assert np.nanmin(dem.values) > 9 and np.nanmax(dem.values) < 11
    assert dem.shape == clean.shape
    assert len(notes) == 1 and "1 points" in notes[0] and "left out" in notes[0]


def test_grid_points_refuses_a_cloud_with_no_usable_point():
    for xyz in (np.empty((0, 3)), np.full((10, 3), np.nan)):
        with pytest.raises(core.FloodMeshError, match="usable"):
            core.grid_points(core.PointCloud(xyz, CRS), 1.0)
