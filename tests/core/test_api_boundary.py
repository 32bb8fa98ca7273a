"""Arrays of the wrong shape given to the public steps, as docs/library.md calls them: a
FloodMeshError naming the fix, not an IndexError (or a reshape that reads x, y as x, y, z)."""
import numpy as np
import pytest
from affine import Affine

from floodmesh import core

CRS = "EPSG:25832"


@pytest.fixture(scope="module")
def case():
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, 40, 2000) + 5e5, rng.uniform(0, 30, 2000) + 5.7e6,
                           rng.normal(10, .05, 2000)])
    y, x = np.mgrid[0:30, 0:40]
    dem = core.Grid(10 + np.clip((x - 20) / 2, 0, 1) * 2.0,
                    Affine(1, 0, 500000, 0, -1, 5700030), CRS)
    return dem, xyz, core.build_mesh(dem, [], max_area=50)


SHAPES = ["N x 2", "PointCloud", "1-D"]


def _given(shape, xyz):
    return {"N x 2": xyz[:, :2], "PointCloud": core.PointCloud(xyz, CRS), "1-D": xyz.ravel()}[shape]


def _fix(shape):
    return "give its .xyz" if shape == "PointCloud" else "third column"


@pytest.mark.parametrize("shape", SHAPES)
def test_assess_refuses_points_without_z(case, shape):
    dem, xyz, mesh = case
    with pytest.raises(core.FloodMeshError,
                       match=f"check points must be an \\(N, 3\\).*{_fix(shape)}"):
        core.assess(mesh, _given(shape, xyz))


@pytest.mark.parametrize("shape", SHAPES)
def test_refine_mesh_refuses_points_without_z(case, shape):
    dem, xyz, mesh = case
    with pytest.raises(core.FloodMeshError, match=f"refinement's points must be .*{_fix(shape)}"):
        core.refine_mesh(dem, [], _given(shape, xyz), max_area=50, max_rounds=1)


@pytest.mark.parametrize("shape", SHAPES)
def test_export_mesh_refuses_nodes_without_z(case, shape, tmp_path):
    mesh = case[2]
    with pytest.raises(core.FloodMeshError, match=f"mesh's nodes must be .*{_fix(shape)}"):
        core.export_mesh(tmp_path / "m.2dm", _given(shape, mesh.nodes), mesh.triangles,
                         crs=mesh.crs)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("shape", SHAPES)
def test_build_mesh_refuses_points_without_z(case, shape):
    dem, xyz, _ = case
    with pytest.raises(core.FloodMeshError,
                       match=f"points put into the mesh must be .*{_fix(shape)}"):
        core.build_mesh(dem, [], max_area=50, points=_given(shape, xyz[:20]))


def test_x_y_nodes_whose_count_fits_three_columns_are_not_read_as_x_y_z(case, tmp_path):
    # 6 nodes' x, y are 12 numbers: reshaped to (4, 3) they made a mesh of the wrong nodes
    nodes = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1]], float) + 5e5
    with pytest.raises(core.FloodMeshError, match=r"mesh's nodes must be an \(N, 3\)"):
        core.export_mesh(tmp_path / "m.2dm", nodes, [[0, 1, 2], [0, 2, 3]], crs=CRS)


def test_no_check_points_is_still_no_accuracy_test(case):
    res, stats = core.assess(case[2], np.empty((0, 3)))
    assert res.shape == (0,)


def test_a_cancelled_step_says_so(case):
    with pytest.raises(core.Cancelled, match="cancelled"):
        core.grid_points(core.PointCloud(case[1], CRS), 1.0, cancelled=lambda: True)
