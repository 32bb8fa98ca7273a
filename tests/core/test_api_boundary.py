"""Arrays of the wrong shape given to the public steps, as docs/library.md calls them: a
FloodMeshError naming the fix, not an IndexError (or a reshape that reads x, y as x, y, z)."""
import numpy as np
import pytest
from affine import Affine

from floodmesh import core
from floodmesh.core.io import write_points_las

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


# Grids and point clouds built in memory meet the readers' rule on CRS, place and quantity
def _on(dem, crs=CRS, transform=None):
    return core.Grid(dem.values, dem.transform if transform is None else transform, crs)


REFUSED_CRS = [(None, "has no coordinate reference system"),
               ("EPSG:4326", "is in a geographic CRS"), ("EPSG:2227", "units of 'US survey foot'")]


@pytest.mark.parametrize("crs, said", REFUSED_CRS)
def test_the_steps_refuse_a_crs_the_readers_refuse(case, crs, said):
    dem, xyz, mesh = case
    grid, slope = _on(dem, crs), core.terrain_slope(dem)
    runs = {"grid_points": lambda: core.grid_points(core.PointCloud(xyz, crs), 1.0),
            "terrain_slope": lambda: core.terrain_slope(grid),
            "laplacian_of_gaussian": lambda: core.laplacian_of_gaussian(grid, 1.0),
            "classify_breakpoints": lambda: core.classify_breakpoints(
                core.Grid(slope.values, slope.transform, crs), 10.0),
            "trace_breaklines": lambda: core.trace_breaklines(
                core.classify_breakpoints(slope, 10.0), slope, grid, 10.0),
            "build_mesh": lambda: core.build_mesh(grid, [], max_area=50),
            "refine_mesh": lambda: core.refine_mesh(grid, [], xyz, max_area=50, max_rounds=1),
            "assess": lambda: core.assess(core.Mesh(mesh.nodes, mesh.triangles, crs), xyz)}
    for step, run in runs.items():
        with pytest.raises(core.FloodMeshError, match=said):
            run()


def test_a_missing_crs_is_asked_for_as_the_library_gives_it(case):
    # the library user was told "--crs EPSG:XXXX, or the CRS parameter in QGIS", neither of
    # which they have
    dem, xyz, mesh = case
    runs = {'Grid(values, transform, crs="EPSG:XXXX")': lambda: core.terrain_slope(_on(dem, None)),
            'PointCloud(xyz, crs="EPSG:XXXX")': lambda: core.grid_points(
                core.PointCloud(xyz, None), 1.0),
            'Mesh(nodes, triangles, crs="EPSG:XXXX")': lambda: core.assess(
                core.Mesh(mesh.nodes, mesh.triangles, None), xyz)}
    for how, run in runs.items():
        with pytest.raises(core.FloodMeshError) as error:
            run()
        message = str(error.value)
        assert f"has no coordinate reference system: give one ({how})" in message, message
        assert "--crs" not in message and "QGIS" not in message, message


def test_a_file_without_a_crs_is_still_asked_for_as_the_command_line_and_qgis_give_it(tmp_path):
    from ..bad_inputs import slope_dem, write_tif

    with pytest.raises(core.FloodMeshError, match=r"has no coordinate reference system: give "
                       r"one \(--crs EPSG:XXXX, or the CRS parameter in QGIS\)"):
        core.io.read_dem(write_tif(tmp_path / "dem.tif", slope_dem(), crs=None))


def test_a_grid_far_outside_its_crs_area_is_refused_naming_the_zone(case):
    dem = case[0]
    prefixed = _on(dem, transform=Affine(1, 0, 32_500_000, 0, -1, 5_700_030))
    with pytest.raises(core.FloodMeshError, match="far outside the area.*UTM zone number"):
        core.terrain_slope(prefixed)


def test_a_slope_grid_is_refused_where_a_dem_belongs(case):
    dem = case[0]
    slope = core.terrain_slope(dem)
    assert slope.quantity == "slope"
    for run in (lambda: core.terrain_slope(slope), lambda: core.build_mesh(slope, [], max_area=50),
                lambda: core.trace_breaklines(core.classify_breakpoints(slope, 10.0), slope,
                                              slope, 10.0)):
        with pytest.raises(core.FloodMeshError, match="the DEM holds a slope in degrees.*not "
                                                      "elevations: give the DEM"):
            run()
    with pytest.raises(core.FloodMeshError, match="breakpoints grid holds a slope in degrees"):
        core.trace_breaklines(slope, slope, dem, 10.0)
    log = core.laplacian_of_gaussian(dem, 1.0)
    with pytest.raises(core.FloodMeshError, match="slope holds a Laplacian-of-Gaussian"):
        core.classify_breakpoints(log, 10.0)


def test_a_breakpoints_grid_is_refused_where_a_dem_belongs(case, tmp_path):
    # classify_breakpoints' 0/1 grid was untagged: build_mesh meshed it as a DEM 0-1 m high,
    # though its file (breakpoints.tif, tagged) is refused there
    dem = case[0]
    slope = core.terrain_slope(dem)
    for breakpoints in (core.classify_breakpoints(slope, 10.0),
                        core.log_breakpoints(core.laplacian_of_gaussian(dem, 1.0), 0.02)):
        assert breakpoints.quantity == "breakpoints"
        for run in (lambda: core.terrain_slope(breakpoints),
                    lambda: core.build_mesh(breakpoints, [], max_area=50)):
            with pytest.raises(core.FloodMeshError, match=r"the DEM holds breakpoints \(1\) and "
                               r"other cells \(0\).*not elevations: give the DEM \(what "
                               r"grid_points returns\), not its breakpoints$"):
                run()
        core.trace_breaklines(breakpoints, slope, dem, 10.0)  # where breakpoints belong
    core.write_raster(tmp_path / "bp.tif", breakpoints)
    assert core.read_raster(tmp_path / "bp.tif", elevations=False).quantity == "breakpoints"


def test_the_quantity_travels_with_the_file(case, tmp_path):
    slope = core.terrain_slope(case[0])
    core.write_raster(tmp_path / "slope.tif", slope)
    assert core.read_raster(tmp_path / "slope.tif", elevations=False).quantity == "slope"


def test_breakpoints_must_be_zeros_and_ones(case):
    dem = case[0]
    slope = core.terrain_slope(dem)
    untagged = core.Grid(slope.values, slope.transform, slope.crs)
    with pytest.raises(core.FloodMeshError, match="breakpoints grid holds 0 to .*not 0 and 1"):
        core.trace_breaklines(untagged, slope, dem, 10.0)


def test_grids_of_another_place_are_not_combined_by_their_shape(case):
    dem = case[0]
    slope = core.terrain_slope(dem)
    breakpoints = core.classify_breakpoints(slope, 10.0)
    elsewhere = Affine(1, 0, 600_000, 0, -1, 5_800_030)
    with pytest.raises(core.FloodMeshError,
                       match=r"breakpoints grid lies at x 600,000 to 600,040, y 5,800,000 to "
                             r"5,800,030 m, the DEM at x 500,000 to 500,040, y 5,700,000 to "
                             r"5,700,030 m, not on the same cells"):
        core.trace_breaklines(_on(breakpoints, transform=elsewhere), slope, dem, 10.0)
    with pytest.raises(core.FloodMeshError, match="slope lies at .* in ETRS89 / UTM zone 33N"):
        core.trace_breaklines(breakpoints, _on(slope, "EPSG:25833"), dem, 10.0)


def test_lines_far_from_the_dem_are_refused_naming_both_places(case):
    dem = case[0]
    far = np.array([[10.0, 20.0, 11.0], [30.0, 20.0, 11.0]])  # x, y without the easting
    with pytest.raises(core.FloodMeshError, match=r"break line 1 lies at x 10 to 30, y 20 to 20 m,"
                                                  r" far from the DEM at x 500,000 to 500,040"):
        core.build_mesh(dem, [far], max_area=50)
    with pytest.raises(core.FloodMeshError, match="own line 1 lies at"):
        core.build_mesh(dem, [], own_lines=[far * [1, 1, np.nan]], max_area=50)
    with pytest.raises(core.FloodMeshError, match="break line 2 must be an array of numbers"):
        core.build_mesh(dem, [far + [5e5, 5.7e6, 0], [["a", "b"], ["c", "d"]]], max_area=50)
    near = far + [500_045, 5_700_000, 0]  # just past the DEM's edge: left out with a note
    notes = []
    core.build_mesh(dem, [near], max_area=50, note=notes.append)
    assert any("wholly outside" in n for n in notes)


@pytest.mark.parametrize("make, said", [
    (lambda dem, xyz: core.PointCloud(xyz.astype(object), CRS), "xyz must be a numpy array of "
                                                                "numbers.*got ndarray of object"),
    (lambda dem, xyz: core.PointCloud(xyz.tolist(), CRS), "xyz must be a numpy array.*got list"),
    (lambda dem, xyz: core.Grid(dem.values, dem.transform.to_gdal(), CRS),
     r"transform must be an affine.Affine.*Affine.from_gdal"),
    (lambda dem, xyz: core.terrain_slope(core.Grid(np.zeros((0, 0)), dem.transform, CRS)),
     r"the DEM has no cells \(shape \(0, 0\)\)"),
    (lambda dem, xyz: core.grid_points(xyz, 1.0), "the point cloud must be a PointCloud"),
])
def test_types_built_wrong_are_named(case, make, said):
    with pytest.raises(core.FloodMeshError, match=said):
        make(case[0], case[1])


def test_simplify_takes_plain_arrays_as_build_mesh_does():
    line = np.column_stack([np.linspace(0, 10, 11) + 5e5, np.full(11, 5.7e6), np.full(11, 10.0)])
    for simplified in (core.simplify_breaklines([line], "keep-every", 4),
                       core.simplify_breaklines([line], "douglas-peucker", 0.1)):
        assert [s.coords[[0, -1]].tolist() for s in simplified] == [line[[0, -1]].tolist()]
    with pytest.raises(core.FloodMeshError, match=r"line 1 must be an \(N, 3\).*third column"):
        core.simplify_breaklines([line[:, :2]], "keep-every", 4)
    with pytest.raises(core.FloodMeshError, match="must be a list of lines"):
        core.simplify_breaklines(line, "keep-every", 4)


def test_write_points_las_takes_the_crs_as_text(tmp_path):
    xyz = np.column_stack([np.arange(10.0) + 5e5, np.arange(10.0) % 3 + 5.7e6, np.full(10, 9.0)])
    write_points_las(tmp_path / "p.laz", core.PointCloud(xyz, "EPSG:25832"))
    assert core.read_points(tmp_path / "p.laz").crs.to_epsg() == 25832
