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


def _dem(strip_value=None):
    y, x = np.mgrid[0:60, 0:80]
    z = 10 + 0.01 * y + np.clip((x - 40) / 2, 0, 1) * 2.0
    if strip_value is not None:
        z[:5, :] = strip_value
    return core.Grid(z, Affine(1, 0, 500000, 0, -1, 5700060), CRS)


@pytest.mark.parametrize("value", [-9999.0, np.inf, -np.inf, 1e38])
def test_dem_cells_no_ground_has_are_nodata_in_every_step(value):
    bad, nodata = _dem(value), _dem(np.nan)
    given = bad.values.copy()
    notes = []
    mesh = core.build_mesh(bad, [], max_area=50, note=notes.append)
    assert mesh.nodes[:, 2].min() > 9 and mesh.nodes[:, 2].max() < 13
    assert np.array_equal(mesh.nodes, core.build_mesh(nodata, [], max_area=50).nodes)
    slope = core.terrain_slope(bad, "one-over-distance", note=notes.append)
    expected = core.terrain_slope(nodata, "one-over-distance")
    assert np.array_equal(slope.values, expected.values, equal_nan=True)
    breakpoints = core.classify_breakpoints(expected, 10.0)
    lines = core.trace_breaklines(breakpoints, expected, bad, 10.0, note=notes.append)
    alike = core.trace_breaklines(breakpoints, expected, nodata, 10.0)
    assert [line.coords.tolist() for line in lines] == [line.coords.tolist() for line in alike]
    assert np.array_equal(bad.values, given)  # the caller's Grid untouched
    assert len(notes) == 3 and all("400 cells" in n and "nodata" in n for n in notes)


def test_refine_mesh_leaves_out_what_no_ground_has():
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(2, 78, 400) + 500000, rng.uniform(8, 58, 400) + 5700000,
                           np.full(400, 10.3)])
    bad_pts = pts.copy()
    bad_pts[:3, 2] = [np.nan, -9999.0, np.inf]
    notes = []
    mesh, _ = core.refine_mesh(_dem(-9999.0), [], bad_pts, check=bad_pts[:40], max_rounds=1,
                               note=notes.append)
    assert mesh.nodes[:, 2].min() > 9
    assert np.isnan(bad_pts[0, 2]) and bad_pts[1, 2] == -9999.0  # the caller's points untouched
    assert sum("left out" in n for n in notes) == 4 and any("nodata" in n for n in notes)


def test_assess_leaves_out_check_points_no_ground_has_and_says_so():
    y, x = np.mgrid[0:60, 0:80]
    dem = core.Grid(10 + 0.01 * y, Affine(1, 0, 500000, 0, -1, 5700060), CRS)
    mesh = core.build_mesh(dem, [], max_area=50)
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(10, 70, 30) + 500000, rng.uniform(10, 50, 30) + 5700000,
                           np.full(30, 10.3)])
    clean_res, clean = core.assess(mesh, pts[2:])
    bad = pts.copy()
    bad[0, 2], bad[1, 2] = np.nan, -9999.0
    given = bad.copy()
    notes = []
    res, stats = core.assess(mesh, bad, note=notes.append)
    assert np.array_equal(bad, given, equal_nan=True)
    assert stats["n_outside_mesh"] == 0 and stats["n_assessed"] == 28
    assert stats["rmse_m"] == pytest.approx(clean["rmse_m"])
    assert len(res) == 30 and np.isnan(res[:2]).all() and np.array_equal(res[2:], clean_res)
    assert sum("1 points" in n and "left out" in n for n in notes) == 2


def test_build_mesh_leaves_out_measured_points_no_ground_has():
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(5, 75, 50) + 500000, rng.uniform(10, 55, 50) + 5700000,
                           np.full(50, 10.4)])
    bad = np.vstack([pts, [[500040.3, 5700030.3, -9999.0], [500041.3, 5700031.3, np.nan]]])
    notes = []
    mesh = core.build_mesh(_dem(), [], max_area=50, points=bad, note=notes.append)
    assert np.isfinite(mesh.nodes).all() and mesh.nodes[:, 2].min() > 9
    assert np.array_equal(mesh.nodes, core.build_mesh(_dem(), [], max_area=50, points=pts).nodes)
    assert sum("left out" in n for n in notes) == 2


def _assess_command(tmp_path, check: np.ndarray, *, code: int = 0):
    """``floodmesh assess`` (as QGIS's Assess: the same step) of a mesh of ``_dem``'s plane on
    the ``check`` points as a GeoPackage: (the mesh, its stats.json (None where it exits with
    ``code`` other than 0), what it said)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    from pyproj import CRS as ProjCRS

    from floodmesh.core import io

    dem = core.Grid(10 + 0.01 * np.mgrid[0:60, 0:80][0], Affine(1, 0, 500000, 0, -1, 5700060),
                    CRS)
    mesh = core.build_mesh(dem, [], max_area=50)
    io.write_mesh_2dm(tmp_path / "mesh.2dm", mesh.nodes, mesh.triangles, crs=CRS)
    io.write_points_gpkg(tmp_path / "check.gpkg", check, ProjCRS(CRS))
    said = subprocess.run([str(Path(sys.executable).parent / "floodmesh"), "assess",
                           tmp_path / "mesh.2dm", "--points", tmp_path / "check.gpkg", "--out",
                           tmp_path / "res.gpkg", "--report", tmp_path / "stats.json"],
                          capture_output=True, text=True, timeout=600)
    assert said.returncode == code, said.stderr
    if code:
        return mesh, None, said
    return mesh, json.loads((tmp_path / "stats.json").read_text()), said


def _check_points(n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    return np.column_stack([rng.uniform(10, 70, n) + 500000, rng.uniform(10, 50, n) + 5700000,
                            np.full(n, 10.3)])


def test_assess_command_leaves_out_check_points_no_ground_has_as_the_library_does(tmp_path):
    """A check point at -9999 m (a survey's no-data z) in the point layer: left out with a
    note, as ``core.assess`` leaves it out, not a residual of 10 km that makes the RMSE 1.8 km."""
    bad = np.vstack([_check_points(30), [[500040.5, 5700030.5, -9999.0]]])
    mesh, stats, said = _assess_command(tmp_path, bad)
    _, expected = core.assess(mesh, bad)
    assert stats["n_holdout"] == expected["n_holdout"] == 30
    assert stats["rmse_m"] == pytest.approx(expected["rmse_m"], rel=1e-3)  # 2DM: to 1 mm
    assert "1 points with a z no ground has (-9999 m" in said.stderr


def test_assess_command_says_why_the_nssda_test_is_null_as_the_library_does(tmp_path):
    """Five check points: the NSSDA test needs 20, so nssda_pass is null, and the command says
    why, as ``core.assess`` and ``floodmesh run`` do."""
    mesh, stats, said = _assess_command(tmp_path, _check_points(5))
    notes = []
    core.assess(mesh, _check_points(5), note=notes.append)
    assert stats["nssda_pass"] is None and len(notes) == 1
    assert notes[0] in said.stderr


@pytest.mark.parametrize("value", [-9999.0, np.inf])
def test_laplacian_of_gaussian_takes_dem_cells_no_ground_has_as_nodata(value):
    """``core.laplacian_of_gaussian`` as ``core.terrain_slope`` and the LoG of a DEM file: the
    -9999 cells are nodata (said to ``note``), not ground 10 km deep whose rim is all crests."""
    notes = []
    response = core.laplacian_of_gaussian(_dem(value), 1.0, note=notes.append)
    expected = core.laplacian_of_gaussian(_dem(np.nan), 1.0)
    assert np.array_equal(response.values, expected.values, equal_nan=True)
    assert len(notes) == 1 and "400 cells" in notes[0] and "nodata" in notes[0]


@pytest.mark.parametrize("case", ["line", "diagonal", "one place"])
def test_grid_points_says_points_on_a_line_cover_no_area_as_the_readers_do(case):
    """Points along one straight line (an x or y column read twice) or at one place: the library
    says so, as reading them from a file does, and does not send the caller after ever smaller
    cells or a larger gap (which would never cover a line 0 m wide)."""
    along = np.linspace(0, 100, 500)
    x = {"line": along, "diagonal": along, "one place": np.zeros(500)}[case]
    y = along if case == "diagonal" else np.zeros(500)
    xyz = np.column_stack([500000 + x, 5700000 + y, 10 + 0.01 * along])
    with pytest.raises(core.FloodMeshError, match="one place" if case == "one place"
                       else "one straight line") as refused:
        core.grid_points(core.PointCloud(xyz, CRS), 1.0)
    assert "smaller cell size" not in str(refused.value)
    assert "max gap" not in str(refused.value)


@pytest.mark.parametrize("dtype, value", [(np.int16, -9999), (np.int16, -32768),
                                          (np.uint16, 65535)])
def test_an_integer_dem_grid_takes_cells_no_ground_has_as_nodata(dtype, value):
    """A Grid of whole metres as an integer band holds it (-32768 in an SRTM tile, 65535 in an
    unsigned one): its no-data value is nodata in every step, as a DEM file's is when read, not
    ground 10 km deep that makes every slope around it 90°."""
    heights = np.rint(_dem().values * 4)  # whole metres, with slopes to find
    bad = heights.astype(dtype)
    bad[:5, :] = value
    nan = heights.copy()
    nan[:5, :] = np.nan
    as_int, as_nan = (core.Grid(v, _dem().transform, CRS) for v in (bad, nan))
    notes = []
    slope = core.terrain_slope(as_int, note=notes.append)
    assert np.array_equal(slope.values, core.terrain_slope(as_nan).values, equal_nan=True)
    mesh = core.build_mesh(as_int, [], max_area=50, note=notes.append)
    assert np.array_equal(mesh.nodes, core.build_mesh(as_nan, [], max_area=50).nodes)
    assert len(notes) == 2 and all("400 cells" in n and "nodata" in n for n in notes)
    assert (as_int.values[:5] == value).all()  # the caller's Grid untouched


def test_assess_command_refuses_a_layer_without_a_usable_check_point(tmp_path):
    """Every check point at -9999 m: one line naming the layer and the fix, and no residuals or
    report of nothing (as a point file of no usable point is refused)."""
    bad = np.array([[500040.5, 5700030.5, -9999.0], [500041.5, 5700030.5, -9999.0]])
    _, _, said = _assess_command(tmp_path, bad, code=2)
    error = said.stderr.strip().splitlines()[-1]  # after the note of the points left out
    assert "point layer check.gpkg: 0 usable" in error and "check their values" in error
    assert not (tmp_path / "stats.json").exists() and not (tmp_path / "res.gpkg").exists()


def _plane_points(n=20000, seed=3):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 60, (n, 2))
    return np.column_stack([xy + [500000, 5700000], 10 + 0.01 * xy[:, 0]
                            + rng.normal(0, 0.02, n)])


def _spoilt(xyz):
    bad = xyz.copy()
    bad[:3, 2] = [-9999.0, np.inf, np.nan]
    return bad


def test_fit_node_elevations_leaves_out_points_no_ground_has():
    from floodmesh.core.steps.localise import fit_node_elevations

    xyz = _plane_points()
    nodes = xyz[::500].copy()
    clean, _ = fit_node_elevations(nodes, xyz[3:], [], 1.5, on_line=0.05)
    bad = _spoilt(xyz)
    given = bad.copy()
    notes = []
    z, _ = fit_node_elevations(nodes, bad, [], 1.5, on_line=0.05, note=notes.append)
    assert np.array_equal(bad, given, equal_nan=True)
    assert np.allclose(z, clean) and np.isfinite(z).all()
    assert sum("left out" in n for n in notes) == 2
    with pytest.raises(core.FloodMeshError, match=r"mesh's nodes must be an \(N, 3\)"):
        fit_node_elevations(nodes[:, :2], xyz, [], 1.5, on_line=0.05)
    with pytest.raises(core.FloodMeshError, match=r"measured points must be an \(N, 3\)"):
        fit_node_elevations(nodes, xyz[:, :2], [], 1.5, on_line=0.05)


def test_localise_traced_leaves_out_points_no_ground_has():
    from floodmesh.core.steps.localise import fit_window

    xyz = _plane_points()
    line = np.column_stack([np.linspace(10, 50, 21) + 500000, np.full(21, 5700030.0),
                            np.full(21, 10.3)])
    window = fit_window(xyz[3:], 3600.0, 1.0)
    clean, _, _ = core.localise_traced([line], xyz[3:], window)
    notes = []
    lines, _, _ = core.localise_traced([line], _spoilt(xyz), window, note=notes.append)
    assert [x.coords.tolist() for x in lines] == [x.coords.tolist() for x in clean]
    assert sum("left out" in n for n in notes) == 2
    with pytest.raises(core.FloodMeshError, match=r"measured points must be an \(N, 3\)"):
        core.localise_traced([line], xyz[:, :2], window)


def test_scale_series_takes_dem_cells_and_check_points_no_ground_has_as_nodata():
    from floodmesh.core.chain.series import Setting, scale_series

    check = _plane_points(60, seed=4)
    settings = [Setting(50.0)]
    clean_rows, _ = scale_series(_dem(np.nan), [], check[3:], settings)
    notes = []
    rows, meshes = scale_series(_dem(-9999.0), [], _spoilt(check), settings, note=notes.append)
    assert np.isfinite(meshes[0].nodes).all() and meshes[0].nodes[:, 2].min() > 9
    assert rows == clean_rows
    assert sum("nodata" in n for n in notes) == 1 and sum("left out" in n for n in notes) == 2
    with pytest.raises(core.FloodMeshError, match=r"check points must be an \(N, 3\)"):
        scale_series(_dem(), [], check[:, :2], settings)


@pytest.mark.parametrize("given", [[], ()])
def test_an_empty_list_of_inputs_is_refused_naming_what_to_give(given, tmp_path):
    """run_pipeline (and open_source) on an empty list of tiles stopped with a ValueError from
    unpacking it; a caller's list built from a folder that held nothing is a plain mistake."""
    with pytest.raises(core.FloodMeshError, match="no input given: give a point file"):
        core.run_pipeline(given, tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("max_nodes", [1_000_000, 200])
def test_refine_mesh_stops_on_a_cancel_given_while_its_last_mesh_is_built(max_nodes):
    """Cancel pressed while the last round's mesh is built (the round's own, or one of the
    meshes that fit the node budget, 200 nodes here): the refinement stops with ``Cancelled``,
    as in any earlier round, rather than hand back a mesh for QGIS to write."""
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(2, 78, 2000) + 500000,
                           rng.uniform(8, 58, 2000) + 5700000,
                           10 + rng.normal(0, 0.3, 2000)])
    first, _ = core.refine_mesh(_dem(), [], pts, max_area=50, max_rounds=1)
    pressed = []

    def elevations(mesh):  # every mesh built: the user presses Cancel after the first
        if len(mesh.nodes) > len(first.nodes):
            pressed.append(True)
        return mesh

    with pytest.raises(core.Cancelled):
        core.refine_mesh(_dem(), [], pts, max_area=50, max_rounds=2, max_nodes=max_nodes,
                         elevations=elevations, cancelled=lambda: bool(pressed))


def test_an_own_line_left_out_of_the_mesh_gives_no_node_its_height():
    """An own line with a vertex without coordinates is left out of the mesh (with a note):
    its heights are left out too, not given to the nodes of a break line beside it."""
    crest = np.array([[500041.0, 5700010.0, 12.0], [500041.0, 5700050.0, 12.4]])
    own = np.vstack([crest + [0, 0, 0.5], [np.nan, np.nan, 12.0]])  # one vertex unreadable
    notes = []
    mesh = core.build_mesh(_dem(), [crest], own_lines=[own], max_area=50, note=notes.append)
    alone = core.build_mesh(_dem(), [crest], max_area=50)
    assert any("left out" in n for n in notes)
    assert np.array_equal(mesh.nodes, alone.nodes)
