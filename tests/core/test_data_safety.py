"""Data safety as a hostile user tries it (issue 13): outputs never replace inputs however they
are spelled, a holdout of 0 runs through, untagged nodata sentinels stay out of the terrain,
the mesh exports refuse what solvers cannot read, their boundaries keep the sections drawn, and
the messages name the real problem. Folder atomicity under interrupts is in test_interrupt.py."""
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.frontends.cli import main
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.steps.export import export_mesh, mesh_boundary
from floodmesh.core.points import PointCloud

from ..bad_inputs import (ORIGIN, UTM, plane_xyz, slope_dem, write_las, write_tif,
                          write_xyz)
from ..conftest import plane_points

FLOODMESH = str(Path(sys.executable).parent / "floodmesh")


def _digest(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _square_mesh(n=6, size=10.0):
    """A structured triangulation of an ``n`` x ``n`` grid of nodes (local coordinates)."""
    xs = np.linspace(0, size, n)
    xx, yy = np.meshgrid(xs, xs)
    nodes = np.column_stack([xx.ravel() + ORIGIN[0], yy.ravel() + ORIGIN[1],
                             np.full(n * n, 5.0)])
    tris = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            tris += [(a, b, e), (a, e, d)]
    return nodes, np.array(tris)


# ---------------------------------------------------------------------------------------------
# 1. an output that is an input
@pytest.fixture
def dem(tmp_path):
    return write_tif(tmp_path / "dem.tif", slope_dem())


@pytest.mark.parametrize("spelling", ["same", "relative", "symlink", "hardlink"])
def test_slope_refuses_to_overwrite_its_input_however_spelled(dem, tmp_path, spelling, capsys,
                                                              monkeypatch):
    before = _digest(dem)
    target = {"same": str(dem), "relative": "./sub/../dem.tif"}.get(spelling)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    if spelling == "symlink":
        os.symlink(dem, tmp_path / "link.tif")
        target = "link.tif"
    elif spelling == "hardlink":
        os.link(dem, tmp_path / "hard.tif")
        target = "hard.tif"
    assert main(["slope", str(dem), "--out", target]) == 2
    assert "FloodMesh never overwrites an input" in capsys.readouterr().err
    assert _digest(dem) == before


def test_grid_refuses_its_own_point_file_and_a_laz_name(tmp_path, capsys):
    points = write_xyz(tmp_path / "pts.xyz", plane_xyz())
    before = _digest(points)
    assert main(["grid", str(points), "--crs", UTM, "--cell-size", "1", "--out",
                 str(points)]) == 2
    assert "never overwrites an input" in capsys.readouterr().err
    assert main(["grid", str(points), "--crs", UTM, "--cell-size", "1", "--out",
                 str(tmp_path / "dem.laz")]) == 2
    assert "this writes a GeoTIFF" in capsys.readouterr().err
    assert _digest(points) == before and not (tmp_path / "dem.laz").exists()


def test_run_into_the_folder_of_its_dem_and_export_onto_its_mesh_are_refused(dem, tmp_path,
                                                                            capsys, monkeypatch):
    before = _digest(dem)
    assert main(["run", str(dem), "--out", str(tmp_path)]) == 2
    assert "never overwrites an input" in capsys.readouterr().err
    monkeypatch.chdir(tmp_path)
    assert main(["run", "dem.tif", "--out", "."]) == 2
    assert "never overwrites an input" in capsys.readouterr().err
    assert _digest(dem) == before
    nodes, tris = _square_mesh()
    mesh = tmp_path / "m.2dm"
    io.write_mesh_2dm(mesh, nodes, tris)
    before = _digest(mesh)
    assert main(["export", str(mesh), str(mesh)]) == 2
    assert "never overwrites an input" in capsys.readouterr().err
    assert _digest(mesh) == before


def _las_tiles(folder, n=2):
    """``n`` LAS tiles of ``plane_xyz`` cut in x, in ``folder`` (made)."""
    folder.mkdir()
    xyz = plane_xyz()
    cut = np.linspace(xyz[:, 0].min(), xyz[:, 0].max() + 1, n + 1)
    for k in range(n):
        write_las(folder / f"T{k}.las", xyz[(xyz[:, 0] >= cut[k]) & (xyz[:, 0] < cut[k + 1])])
    return folder


@pytest.mark.parametrize("rasters, named", [
    (["overview.tif"], "1 DEM raster (overview.tif)"),
    (["a.tif", "b.tif", "c.tif", "d.tif"], "4 DEM rasters (a.tif, b.tif, c.tif and 1 more)")])
def test_rasters_beside_point_tiles_are_named_with_the_fix(tmp_path, capsys, monkeypatch,
                                                           rasters, named):
    """An overview GeoTIFF shipped beside LAS tiles stops the run naming it, how many there are,
    and a pattern that takes the LAS tiles alone, which then grid."""
    monkeypatch.chdir(tmp_path)
    _las_tiles(Path("tiles"), 5)
    for name in rasters:
        write_tif(Path("tiles") / name, slope_dem())
    assert main(["run", "tiles", "--out", "out"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert f"the tiles mix point files and DEM rasters: {named} beside 5 point tiles: move " \
           f"{'it' if len(rasters) == 1 else 'them'} out of tiles, or give the point tiles as " \
           "a quoted pattern, e.g. 'tiles/*.las'" in err, err
    assert not Path("out").exists()
    assert main(["grid", "tiles/*.las", "--cell-size", "1", "--out", "dem.tif"]) == 0


@pytest.mark.parametrize("given, fix", [
    (["tiles"], "move it out of tiles, or give the point tiles as a quoted pattern, e.g. "
                "'tiles/*.las'"),
    (["tiles/*"], "move it out of tiles, or give the point tiles as a quoted pattern, e.g. "
                  "'tiles/*.las'"),
    (["tiles/T0.las", "tiles/T1.las", "tiles/dem.tif"],
     "take it out of the list of tiles (keep T0.las, T1.las)"),
    (["tiles/*.las", "tiles/dem.tif"], "take it out of the list of tiles (keep T0.las, T1.las)"),
    (["dem_tiles"], "move it out of dem_tiles, or give the DEM tiles as a quoted pattern, e.g. "
                    "'dem_tiles/*.tif'"),
    (["dem_tiles/*"], "move it out of dem_tiles, or give the DEM tiles as a quoted pattern, "
                      "e.g. 'dem_tiles/*.tif'"),
    (["dem_tiles/*.tif", "dem_tiles/check.csv"],
     "take it out of the list of tiles (keep east.tif, west.tif)")])
def test_a_mix_of_kinds_is_named_with_the_fix_for_how_the_tiles_were_given(
        tmp_path, capsys, monkeypatch, given, fix):
    """A DEM beside LAS tiles, or a CSV of points beside DEM tiles, is named the same way whether
    the tiles come as a folder, a pattern or a list, with the fix that fits how the odd file
    came in: moved out of the folder a folder or pattern reads (spelled as given), taken out of
    the list where it was listed by name (moving it would not help)."""
    monkeypatch.chdir(tmp_path)
    _las_tiles(Path("tiles"))
    write_tif(Path("tiles") / "dem.tif", slope_dem())
    Path("dem_tiles").mkdir()
    write_tif(Path("dem_tiles") / "west.tif", slope_dem())
    write_tif(Path("dem_tiles") / "east.tif", slope_dem(),
              transform=Affine(1.0, 0.0, ORIGIN[0] + 60, 0.0, -1.0, ORIGIN[1] + 60))
    np.savetxt(Path("dem_tiles") / "check.csv", plane_xyz()[:50], delimiter=",")
    odd = ("1 DEM raster (dem.tif) beside 2 point tiles" if given[0].startswith("tiles")
           else "1 point file (check.csv) beside 2 DEM tiles")
    for command in (["run", *given, "--out", "out"],
                    ["grid", *given, "--cell-size", "1", "--out", "dem.tif"]):
        assert main(command) == 2, command
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert err == f"floodmesh: error: the tiles mix point files and DEM rasters: {odd}: {fix}"
        assert not Path("out").exists() and not Path("dem.tif").exists()


def test_as_many_point_files_as_dem_rasters_give_one_message_naming_both(tmp_path):
    """A folder of a LAS and a LAZ tile beside two DEM rasters: no kind is the odd one out, so
    the run names both kinds with their counts and asks for one kind, in the same words however
    Python orders its sets (runs under other hash seeds)."""
    folder = _las_tiles(tmp_path / "mixed")
    (folder / "T1.las").rename(folder / "T1.laz")
    write_tif(folder / "a.tif", slope_dem())
    write_tif(folder / "b.tif", slope_dem())
    said = set()
    for seed in range(6):
        done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run",
                               str(folder), "--out", str(tmp_path / "out")],
                              capture_output=True, text=True, timeout=600,
                              env={**os.environ, "PYTHONHASHSEED": str(seed)})
        assert done.returncode == 2 and len(done.stderr.splitlines()) == 1, done.stderr
        said.add(done.stderr.strip())
    assert said == {
        "floodmesh: error: the tiles mix point files and DEM rasters, as many of each: 2 point "
        "files (T0.las, T1.laz) and 2 DEM rasters (a.tif, b.tif): give one kind: keep the point "
        "files and the DEM rasters in separate folders and give the folder of the kind to read, "
        f"or give one kind by quoted patterns: '{folder}/*.las' '{folder}/*.laz' for the point "
        f"files, '{folder}/*.tif' for the DEM rasters"}, said
    assert not (tmp_path / "out").exists()


def test_a_list_of_as_many_point_files_as_dem_rasters_is_asked_for_one_kind(tmp_path, capsys):
    """A LAZ and a DEM listed by name: neither is the odd one out, so the message names both and
    asks for a list of one kind, not to move them into folders."""
    folder = _las_tiles(tmp_path / "mixed")
    write_tif(folder / "a.tif", slope_dem())
    code = main(["run", str(folder / "T0.las"), str(folder / "a.tif"), "--out",
                 str(tmp_path / "out")])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and err == [
        "floodmesh: error: the tiles mix point files and DEM rasters, as many of each: 1 point "
        "file (T0.las) and 1 DEM raster (a.tif): give one kind: list the point files or the DEM "
        "rasters, not both"], err
    assert not (tmp_path / "out").exists()


def test_a_run_into_its_own_tile_folder_is_refused_before_any_work(tmp_path, capsys):
    """Outputs written among the tiles would be read as tiles by the next run on the folder (a
    DEM, slope and breakpoints beside LAS tiles; silently among DEM tiles): refused up front,
    the folder left as it was; a folder inside the tile folder is not read with it."""
    tiles = _las_tiles(tmp_path / "tiles")
    dem_tiles = tmp_path / "dem_tiles"
    dem_tiles.mkdir()
    write_tif(dem_tiles / "west.tif", slope_dem())
    write_tif(dem_tiles / "east.tif", slope_dem(),
              transform=Affine(1.0, 0.0, ORIGIN[0] + 60, 0.0, -1.0, ORIGIN[1] + 60))
    before = {p: _digest(p) for folder in (tiles, dem_tiles) for p in folder.iterdir()}
    for args in (["run", tiles, "--out", tiles], ["run", f"{tiles}/*", "--out", tiles],
                 ["run", f"{dem_tiles}/", "--out", dem_tiles],
                 ["grid", tiles, "--cell-size", "1", "--out", tiles / "dem.tif"]):
        assert main(list(map(str, args))) == 2, args
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, err
        assert "dem.tif" in err and "would be written into the tile folder" in err and \
            "next run on it would read" in err and "into another folder" in err, err
    assert {p: _digest(p) for folder in (tiles, dem_tiles) for p in folder.iterdir()} == before
    assert main(["grid", str(tiles), "--cell-size", "1", "--out", str(tiles / "run" / "dem.tif")]
                ) == 0


def test_run_keeps_the_users_files_in_its_folder_and_drops_its_own_stale_ones(tmp_path):
    """An input and a file of the user's in the output folder stay; a solver export of an
    earlier run that this run does not write goes (the folder holds one run)."""
    from floodmesh.core.chain.pipeline import RunOptions, run_pipeline

    out = tmp_path / "out"
    out.mkdir()
    source = out / "points.laz"
    io.write_points_las(source, PointCloud(plane_points(size=30.0, density=3.0), CRS.from_epsg(
        25832)))
    (out / "notes.txt").write_text("mine\n")
    (out / "mesh.slf").write_bytes(b"an earlier run's export")
    before = _digest(source)
    run_pipeline(source, out, RunOptions(holdout=0.05, cell_size=2.0, max_area=80.0))
    names = {p.name for p in out.iterdir()}
    assert {"points.laz", "notes.txt", "report.json", "mesh.2dm"} <= names
    assert "mesh.slf" not in names
    assert _digest(source) == before and (out / "notes.txt").read_text() == "mine\n"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_kill_between_moving_the_old_folder_aside_and_the_new_in_is_undone(tmp_path):
    """Where the folder cannot be exchanged in one step, it is moved aside, then the new one in:
    a kill between the two leaves the old one hidden, and the next run puts it back first."""
    from floodmesh.core.io.outputs import _clean_run_leftovers

    aside = tmp_path / ".out.floodmesh-99999999-0123abcd.old"
    aside.mkdir()
    (aside / "report.json").write_text("old")
    staging = tmp_path / ".out.floodmesh-99999999-89abcdef.staging"
    staging.mkdir()
    _clean_run_leftovers(tmp_path / "out")
    assert (tmp_path / "out" / "report.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_folder_with_folders_of_the_users_is_replaced_file_by_file(tmp_path, monkeypatch):
    """The working folder, holding a folder of the user's: no swap, the user's things stay,
    the earlier run's files this run does not write go."""
    from floodmesh.core.io.outputs import staged_folder

    (tmp_path / "data").mkdir()
    (tmp_path / "mesh.slf").write_text("earlier")
    (tmp_path / "report.json").write_text("earlier")
    monkeypatch.chdir(tmp_path)
    with staged_folder(".", own={"report.json", "mesh.slf"}) as stage:
        assert stage.parent == tmp_path
        (stage / "report.json").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "report.json"]
    assert (tmp_path / "report.json").read_text() == "new"


def _other_group() -> int:
    """A group other than this user's own that this user may give a folder (any, for root)."""
    if os.geteuid() == 0:
        return 4242
    groups = [g for g in os.getgroups() if g != os.getegid()]
    if not groups:
        pytest.skip("this user is in no group but its own")
    return groups[0]


def _small_run(folder, out, command="run", *extra):
    points = write_xyz(folder / "pts.xyz", plane_xyz(n=4000, size=30.0))
    return main([command, str(points), "--crs", UTM, "--cell-size", "2", "--out", str(out),
                 *extra])


def test_run_and_series_into_one_folder_leave_one_commands_files(tmp_path):
    """A series into a run's folder replaces the run's files, a run the series' (never a mix);
    files of the user's stay, one named like a series mesh too."""
    from floodmesh.core.chain.pipeline import OUTPUT_FILES
    from floodmesh.core.chain.series import SERIES_FILES

    out = tmp_path / "out"
    assert _small_run(tmp_path, out) == 0
    mine = ["notes.txt", "mesh_v1.2dm"]
    for name in mine:
        (out / name).write_text("mine\n")
    assert _small_run(tmp_path, out, "series", "--max-areas", "100") == 0
    assert sorted(os.listdir(out)) == sorted([*SERIES_FILES, "mesh_a100-k4.2dm",
                                              "mesh_a100-k4.prj", *mine])
    assert _small_run(tmp_path, out) == 0
    assert sorted(os.listdir(out)) == sorted([*OUTPUT_FILES, *mine])
    assert all((out / name).read_text() == "mine\n" for name in mine)


@pytest.mark.parametrize("kind", ["private", "group"])
def test_run_keeps_its_folders_permissions_group_and_setgid_bit(tmp_path, kind):
    """A private folder (700) stays private; a group's folder (2770, setgid) keeps its group and
    setgid bit, and the files the run writes into it get the group."""
    out = tmp_path / "out"
    out.mkdir()
    mode, group = (0o700, os.getegid()) if kind == "private" else (0o2770, _other_group())
    os.chown(out, -1, group)
    os.chmod(out, mode)
    assert _small_run(tmp_path, out) == 0
    assert (oct(out.stat().st_mode & 0o7777), out.stat().st_gid) == (oct(mode), group)
    assert (out / "mesh.2dm").stat().st_gid == group


def test_run_keeps_the_access_control_list_of_its_folder(tmp_path):
    """A folder shared by an access control list (user 4242 may write) keeps it."""
    import struct

    out = tmp_path / "out"
    out.mkdir()
    # POSIX ACL xattr, version 2: (tag, permissions, id) for the owner, user 4242, the group,
    # the mask and others
    entries = [(0x01, 7, 0xFFFFFFFF), (0x02, 7, 4242), (0x04, 5, 0xFFFFFFFF),
               (0x10, 7, 0xFFFFFFFF), (0x20, 5, 0xFFFFFFFF)]
    acl = struct.pack("<I", 2) + b"".join(struct.pack("<HHI", *e) for e in entries)
    try:
        os.setxattr(out, "system.posix_acl_access", acl)
    except OSError as exc:
        pytest.skip(f"no access control lists here ({exc.strerror})")
    assert _small_run(tmp_path, out) == 0
    assert os.getxattr(out, "system.posix_acl_access") == acl


# ---------------------------------------------------------------------------------------------
# 2. holdout 0
@pytest.mark.parametrize("command", ["run", "series"])
def test_holdout_zero_runs_through_and_says_it_did_not_assess(tmp_path, command, capsys):
    """No check points: the summary says the mesh was not assessed (no '0% under 10 cm'), and
    the shares of the residual classes are null, not 0."""
    points = write_xyz(tmp_path / "pts.xyz", plane_xyz(n=4000, size=30.0))
    extra = ["--max-areas", "100"] if command == "series" else []
    code = main([command, str(points), "--crs", UTM, "--cell-size", "2", "--holdout", "0",
                 "--out", str(tmp_path / "out"), *extra])
    said = capsys.readouterr()
    assert code == 0, said.err
    if command == "run":
        report = json.loads((tmp_path / "out" / "report.json").read_text())
        assert report["n_holdout"] == 0 and report["rmse_m"] is None
        assert set(report["classes"].values()) == {None}
        assert "not assessed: no check points were held out" in said.out
        assert "%" not in said.out and "n/a" not in said.out
    else:
        (row,) = json.loads((tmp_path / "out" / "series.json").read_text())["rows"]
        assert row["rmse_m"] is None and row["share_over_25cm"] is None
        assert said.out.splitlines()[1].split()[2:] == ["n/a", "n/a", "n/a"]


# ---------------------------------------------------------------------------------------------
# 4. an unwritable home and install folder: numba caches elsewhere
@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a command as user nobody")
def test_a_user_who_can_write_neither_home_nor_install_folder_can_run():
    """User nobody, home /nonexistent, the install folder root's: numba's default cache
    locations are all unwritable ('no locator available' before the fix)."""
    import shutil
    import tempfile

    out = Path(tempfile.mkdtemp(prefix="floodmesh-nobody-"))
    out.chmod(0o777)
    dem = write_tif(out / "dem.tif", slope_dem())
    env = {"PATH": os.environ["PATH"], "HOME": "/nonexistent"}
    proc = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups",
                           FLOODMESH, "slope", str(dem), "--out", str(out / "slope.tif")],
                          env=env, capture_output=True, text=True, timeout=600)
    try:
        assert proc.returncode == 0, proc.stderr
        assert "Traceback" not in proc.stderr and (out / "slope.tif").exists()
    finally:
        shutil.rmtree(out)


# ---------------------------------------------------------------------------------------------
# 5. and 12: what a raster or point file does not say
def _raster(path, values, *, dtype="float32", nodata=None, count=1):
    values = np.asarray(values)
    with rasterio.open(path, "w", driver="GTiff", width=values.shape[1], height=values.shape[0],
                       count=count, dtype=dtype, crs=UTM, nodata=nodata,
                       transform=Affine(1.0, 0, ORIGIN[0], 0, -1.0, ORIGIN[1] + 60)) as dst:
        for band in range(1, count + 1):
            dst.write(values.astype(dtype), band)
    return path


@pytest.mark.parametrize("sentinel", [-9999.0, -32768.0, float(np.finfo(np.float32).min)])
def test_untagged_nodata_sentinels_are_nodata_with_a_note(tmp_path, sentinel):
    values = slope_dem()
    values[10:20, 10:20] = sentinel
    notes = []
    grid = io.read_input(_raster(tmp_path / "untagged.tif", values), note=notes.append)
    assert np.isnan(grid.values[10:20, 10:20]).all()
    assert np.nanmin(grid.values) >= 10.0
    assert any("taken as nodata" in n and "gdal_edit.py -a_nodata" in n for n in notes)


def test_a_run_on_an_untagged_dem_meshes_no_pit(tmp_path, capsys):
    values = slope_dem()
    values[10:20, 10:20] = -9999.0
    dem = _raster(tmp_path / "untagged.tif", values)
    assert main(["run", str(dem), "--out", str(tmp_path / "out")]) == 0
    assert "taken as nodata" in capsys.readouterr().err
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert nodes[:, 2].min() >= 10.0


def test_the_slope_command_keeps_untagged_sentinels_out_of_the_slope(tmp_path, capsys):
    # the command streams tagged rasters block by block; an untagged one must still be cleaned
    values = slope_dem()
    values[10:20, 10:20] = -9999.0
    out = tmp_path / "slope.tif"
    assert main(["slope", str(_raster(tmp_path / "untagged.tif", values)), "--out", str(out)]) == 0
    assert "taken as nodata" in capsys.readouterr().err
    slope_deg = io.read_raster(out).values
    assert np.isnan(slope_deg[10:20, 10:20]).all()
    assert np.nanmax(slope_deg) < 80.0  # the DEM's own steepest is 61°; a -9999 m pit: 89.99°


def _holes(tmp_path, case):
    """A DEM (``slope_dem``, 10-16 m) whose 100 cells [10:20, 10:20] hold a no-data value no
    tag names; (path, the value as the note writes it, extra run arguments)."""
    values = slope_dem()
    if case == "ascii":  # -3.40282e+38 as many writers print it, and no NODATA_value line
        values[10:20, 10:20] = -3.40282e38
        path = tmp_path / "holes.asc"
        path.write_text(f"ncols 60\nnrows 60\nxllcorner {ORIGIN[0]}\nyllcorner {ORIGIN[1]}\n"
                        "cellsize 1\n" + "\n".join(" ".join(f"{v:g}" for v in row)
                                                    for row in values) + "\n")
        return path, "-3.40282e+38", ["--crs", UTM]
    if case == "float64":  # -3.4e38, not FLT_MAX bit for bit, untagged
        values[10:20, 10:20] = -3.4e38
        return _raster(tmp_path / "holes.tif", values, dtype="float64"), "-3.4e+38", []
    values[10:20, 10:20] = -9999.0  # tagged, but with 0
    return _raster(tmp_path / "holes.tif", values, nodata=0.0), "-9999", []


@pytest.mark.parametrize("case", ["float64", "ascii", "wrong-tag"])
def test_cells_no_ground_has_are_nodata_with_a_note(tmp_path, case, capsys):
    dem, held, extra = _holes(tmp_path, case)
    assert main(["run", str(dem), "--out", str(tmp_path / "out"), *extra]) == 0
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert 10.0 <= nodes[:, 2].min() and nodes[:, 2].max() <= 16.0
    err = capsys.readouterr().err
    assert f"100 cells hold {held}, an elevation no ground has" in err
    assert f"taken as nodata; tag that value in the file to say so (gdal_edit.py -a_nodata " \
           f"{held} {dem.name})" in err


def test_dem_tiles_keep_cells_no_ground_has_out_of_the_mesh(tmp_path, capsys):
    values = slope_dem()
    values[10:20, 10:20] = -9999.0
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    _raster(tiles / "west.tif", values[:, :30])  # untagged
    with rasterio.open(_raster(tiles / "east.tif", values[:, 30:], nodata=-9999.0), "r+") as dst:
        dst.transform = dst.transform * Affine.translation(30, 0)
    assert main(["run", str(tiles), "--out", str(tmp_path / "out")]) == 0
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert 10.0 <= nodes[:, 2].min()
    assert "the DEM tiles: 100 cells hold -9999, an elevation no ground has" \
           in capsys.readouterr().err


def test_the_slope_command_keeps_cells_no_ground_has_out_of_a_tagged_dem(tmp_path, capsys):
    # a tagged DEM is streamed block by block: the cells its tag does not name are found there
    dem, _, _ = _holes(tmp_path, "wrong-tag")
    out = tmp_path / "slope.tif"
    assert main(["slope", str(dem), "--out", str(out)]) == 0
    slope_deg = io.read_raster(out).values
    assert np.isnan(slope_deg[10:20, 10:20]).all() and np.nanmax(slope_deg) < 80.0
    assert "(nodata tag 0): 100 cells hold -9999" in capsys.readouterr().err


def test_a_nodata_tag_written_with_six_digits_names_the_cells_gdal_masks(tmp_path, capsys):
    # gdal_edit.py -a_nodata -3.40282e+38 on a float32 DEM whose holes hold -FLT_MAX: GDAL's
    # mask (QGIS, gdalinfo -stats) leaves them out, so must run and slope, with nothing to say
    values = slope_dem()
    values[10:20, 10:20] = np.finfo(np.float32).min
    dem = _raster(tmp_path / "tagged.tif", values, nodata=-3.40282e38)
    assert main(["run", str(dem), "--out", str(tmp_path / "out")]) == 0
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert nodes[:, 2].min() >= 10.0
    out = tmp_path / "slope.tif"
    assert main(["slope", str(dem), "--out", str(out)]) == 0
    slope_deg = io.read_raster(out).values
    assert np.isnan(slope_deg[10:20, 10:20]).all() and np.nanmax(slope_deg) < 80.0
    assert "taken as nodata" not in capsys.readouterr().err


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_nodata_tag_of_flt_max_leaves_the_elevations_of_its_sign_valid(tmp_path, sign):
    # gdal_calc.py tags float32 output +FLT_MAX, QGIS's raster calculator -FLT_MAX: GDAL's mask
    # leaves out only the cells whose float32 sum with the tag overflows (beyond 2^103 of its
    # sign); a polder's elevations (below 0 m, under -FLT_MAX) or any (above, under +FLT_MAX)
    # were all taken as nodata: "no valid cells", or a mesh of half the DEM
    values = (sign * (slope_dem() - 9.0)).astype(np.float32)  # 1 to 7 m of the tag's sign
    values[10:20, 10:20] = sign * np.finfo(np.float32).max
    values[0, 0] = 0.0
    dem = _raster(tmp_path / "calc.tif", values, nodata=sign * float(np.finfo(np.float32).max))
    with rasterio.open(dem) as src:
        gdal_valid = src.read_masks(1) > 0  # GDAL's own mask, as QGIS and gdalinfo take it
    assert gdal_valid.sum() == values.size - 100
    grid = io.read_input(dem)
    np.testing.assert_array_equal(np.isfinite(grid.values), gdal_valid)
    np.testing.assert_array_equal(grid.values[gdal_valid], values[gdal_valid])
    out = tmp_path / "slope.tif"  # streamed block by block
    assert main(["slope", str(dem), "--out", str(out)]) == 0
    np.testing.assert_array_equal(np.isfinite(io.read_raster(out).values), gdal_valid)
    assert main(["run", str(dem), "--out", str(tmp_path / "out")]) == 0
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert np.ptp(nodes[:, 0]) == 59 and np.ptp(nodes[:, 1]) == 59  # the whole DEM


def test_a_cell_size_given_for_a_dem_is_named_as_unused(tmp_path, capsys):
    dem = _raster(tmp_path / "dem.tif", slope_dem())  # 1 m cells
    assert main(["run", str(dem), "--out", str(tmp_path / "out"), "--cell-size", "2"]) == 0
    said = "the input is a DEM: its own cells of 1 m are used, not the cell size of 2 m given"
    assert said in capsys.readouterr().err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert any(said in n for n in report["notes"]) and report["grid"]["cell_size_m"] == 1.0
    assert main(["run", str(dem), "--out", str(tmp_path / "default")]) == 0
    assert "the input is a DEM" not in capsys.readouterr().err


def test_integer_and_multi_band_dems_get_a_note(tmp_path):
    notes = []
    io.read_input(_raster(tmp_path / "int.tif", np.round(slope_dem()), dtype="int16",
                          nodata=-32768), note=notes.append)
    assert any("whole numbers (int16)" in n for n in notes)
    notes.clear()
    io.read_input(_raster(tmp_path / "bands.tif", slope_dem(), count=3), note=notes.append)
    assert any("has 3 bands: band 1 is used" in n for n in notes)


def test_nan_rows_and_duplicate_points_with_other_z_get_a_note(tmp_path):
    xyz = plane_xyz()
    xyz[:5, 2] = np.nan
    xyz[100:110] = xyz[200:210] + [0, 0, 1.0]
    path = tmp_path / "dups.xyz"
    np.savetxt(path, xyz, fmt="%.3f")
    notes = []
    io.read_points(path, crs=UTM, note=notes.append)
    assert any("5 points without a finite x, y and z" in n for n in notes)
    assert any("10 points repeat the x, y of another with a different z (up to 1 m" in n
               for n in notes)


def test_a_run_says_the_repeated_points_in_its_report(tmp_path):
    """The check of repeated positions runs beside the meshing, after the gridding: its note
    still reaches the report and the command line, and its time the report's steps."""
    xyz = plane_xyz()
    xyz[100:110] = xyz[200:210] + [0, 0, 1.0]
    path = write_xyz(tmp_path / "dups.xyz", xyz)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--crs", "EPSG:32633",
                 "--max-area", "50"]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    said = [n for n in report["notes"] if "10 points repeat the x, y of another" in n]
    assert len(said) == 1 and "up to 1 m apart" in said[0]
    assert "repeated points" in report["seconds"]


def test_a_header_naming_the_columns_in_another_order_is_followed(tmp_path):
    xyz = plane_xyz(n=2000)
    path = tmp_path / "zxy.csv"
    with open(path, "w") as fh:
        fh.write("z,x,y\n")
        np.savetxt(fh, xyz[:, [2, 0, 1]], fmt="%.3f", delimiter=",")
    np.testing.assert_allclose(io.read_points(path, crs=UTM).xyz, xyz, atol=1e-3)


# ---------------------------------------------------------------------------------------------
# 6. a mesh in metres labelled with degrees or feet
@pytest.mark.parametrize("crs", ["EPSG:4326", "EPSG:2229"])
@pytest.mark.parametrize("fmt", ["nc", "gpkg"])
def test_export_refuses_a_crs_not_in_metres(tmp_path, crs, fmt):
    nodes, tris = _square_mesh()
    with pytest.raises(FloodMeshError, match="is not a projected CRS in metres"):
        export_mesh(tmp_path / f"m.{fmt}", nodes, tris, crs=crs)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# 7. degenerate meshes
FORMATS = ["2dm", "slf", "14", "gr3", "nc", "gpkg"]


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_refuses_triangles_without_area(tmp_path, fmt):
    nodes, tris = _square_mesh()
    nodes = np.vstack([nodes, [ORIGIN[0] + 5.0, ORIGIN[1] - 1.0, 5.0],
                       [ORIGIN[0] + 7.0, ORIGIN[1] - 1.0, 5.0], [ORIGIN[0] + 9.0,
                                                                  ORIGIN[1] - 1.0, 5.0]])
    n = len(nodes)
    tris = np.vstack([tris, [n - 3, n - 2, n - 1]])  # three nodes on one line
    with pytest.raises(FloodMeshError, match="have no area"):
        export_mesh(tmp_path / f"m.{fmt}", nodes, tris, crs=UTM)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_refuses_a_boundary_that_touches_itself(tmp_path, fmt):
    """Two squares meeting at one corner node (node 3, 1-based), the only such node: the
    message said "and 0 other nodes"."""
    local = [(0, 0), (10, 0), (10, 10), (0, 10), (20, 10), (20, 20), (10, 20)]
    nodes = np.array([(ORIGIN[0] + x, ORIGIN[1] + y, 5.0) for x, y in local])
    tris = np.array([(0, 1, 2), (0, 2, 3), (2, 4, 5), (2, 5, 6)])
    with pytest.raises(FloodMeshError, match=r"touches itself at node 3 \(\S+, \S+\): "):
        export_mesh(tmp_path / f"m.{fmt}", nodes, tris, crs=UTM)


# ---------------------------------------------------------------------------------------------
# 8. fort.14 and hgrid.gr3 through the readers ADCIRC and SCHISM users script with
def _solver_parser(package: str):
    """The fort.14/gr3 parser module of pyschism (or adcircpy), loaded from its installed
    files without the package's heavy __init__ (setup installs both without dependencies)."""
    import importlib.util

    spec = importlib.util.find_spec(package)
    if spec is None:
        pytest.fail(f"{package} is not installed: run make setup")
    path = Path(spec.submodule_search_locations[0]) / "mesh" / "parsers" / "grd.py"
    module_spec = importlib.util.spec_from_file_location(f"_{package}_grd", path)
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("fmt", ["14", "gr3"])
def test_pyschism_reads_our_fort14_and_gr3_as_the_mesh(tmp_path, fmt):
    nodes, tris = _square_mesh()
    nodes[:, 2] = np.linspace(-2.0, 3.0, len(nodes))
    open_line = np.array([[ORIGIN[0] - 0.1, ORIGIN[1] + 2.0], [ORIGIN[0] - 0.1, ORIGIN[1] + 8.0]])
    path = tmp_path / f"mesh.{fmt}"
    export_mesh(path, nodes, tris, open_lines=[open_line])
    grd = _solver_parser("pyschism").read(path, crs=False)
    ids = sorted(grd["nodes"], key=int)
    assert len(ids) == len(nodes) and len(grd["elements"]) == len(tris)
    xy = np.array([grd["nodes"][i][0] for i in ids])
    depth = np.array([grd["nodes"][i][1] for i in ids])
    np.testing.assert_allclose(xy, nodes[:, :2], atol=1e-4)
    np.testing.assert_allclose(depth, -nodes[:, 2], atol=1e-4)
    elements = np.array([grd["elements"][str(k + 1)] for k in range(len(tris))], int) - 1
    assert {tuple(sorted(t)) for t in elements} == {tuple(sorted(t)) for t in tris}
    opened = grd["boundaries"][None]
    assert len(opened) == 1 and len(opened[0]["indexes"]) >= 2


# ---------------------------------------------------------------------------------------------
# 9. open boundary lines meeting end to end
def test_two_open_lines_meeting_end_to_end_stay_two_sections(tmp_path):
    nodes, tris = _square_mesh(n=11, size=10.0)
    x0, y0 = ORIGIN
    lower = np.array([[x0, y0 + 1.0], [x0, y0 + 5.0]])   # on the west side, meeting at y 5
    upper = np.array([[x0, y0 + 5.0], [x0, y0 + 9.0]])
    boundary = mesh_boundary(nodes, tris, [lower, upper], snap=0.1)
    sections = boundary.of_kind("open")
    assert len(sections) == 2
    ys = [sorted(nodes[s.nodes, 1] - y0) for s in sections]
    assert sorted((round(y[0]), round(y[-1])) for y in ys) == [(1, 5), (5, 9)]
    export_mesh(tmp_path / "fort.14", nodes, tris, open_lines=[lower, upper], snap=0.1)
    lines = (tmp_path / "fort.14").read_text().splitlines()
    assert next(l for l in lines if "NOPE" in l).split()[0] == "2"
    export_mesh(tmp_path / "geo.slf", nodes, tris, open_lines=[lower, upper], snap=0.1)
    codes = "".join("o" if l.startswith("4 4 4") else "w"
                    for l in (tmp_path / "geo.cli").read_text().splitlines())
    assert (codes + codes[0]).count("wo") == 2, codes  # two liquid boundaries (the loop)


@pytest.mark.parametrize("fmt", ["14", "gr3"])
def test_adcircpy_reads_our_fort14_and_gr3(tmp_path, fmt):
    """adcircpy 1.2.7's read_fort14 (its parser needs pandas, which setup does not install:
    where pandas is missing this is skipped; pyschism's test above reads line 2 the same way,
    as two integers)."""
    pytest.importorskip("pandas")
    nodes, tris = _square_mesh()
    path = tmp_path / f"mesh.{fmt}"
    export_mesh(path, nodes, tris)
    grd = _solver_parser("adcircpy").read_fort14(path)
    assert len(grd["nodes"]) == len(nodes) and len(grd["elements"]) == len(tris)
    np.testing.assert_allclose(grd["nodes"][["x", "y"]].to_numpy(), nodes[:, :2], atol=1e-4)
