"""A tile folder as a surveyor delivers it (issues 29 and 30), from the user's side: the real
Topography.laz cut into 100 m tiles with what real deliveries hold besides (a 1-point and a
2-point sliver, an empty tile, a water-only and a ground-less tile, points beyond their tile's
outline, the same tile twice under two names, a README, a tile index, a .prj, check points as
text, a LAStools index) goes through the real command and grids to the DEM of the one file; a
truncated tile is named with the option that leaves it out, in one clean line."""
import copy
import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio

from floodmesh.core import io
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.engine.tiles import expand_tiles, read_dem_tiles

from ..conftest import REAL_DATA

CLI = [sys.executable, "-m", "floodmesh.core.frontends.cli"]
TOPOGRAPHY = REAL_DATA / "Topography.laz"
CELL = "2"
UNIQUE_GROUND = 8159  # Topography.laz's class 2 points, each in one tile once
NOT_TILES = ("README.txt", "tile_index.csv", "tiles.prj", "check_points.csv", "T_0_0.lax")


def _write(las, mask, path):
    import laspy

    part = laspy.LasData(copy.deepcopy(las.header), las.points[mask])
    part.write(str(path))


@pytest.fixture(scope="module")
def delivery(tmp_path_factory):
    """Topography.laz as a delivery folder of LAZ tiles and the files beside them."""
    import laspy

    if not TOPOGRAPHY.is_file():
        pytest.skip("../shared/data/real/Topography.laz is not beside this checkout")
    las = laspy.read(str(TOPOGRAPHY))
    x, y, cls = np.asarray(las.x), np.asarray(las.y), np.asarray(las.classification)
    free = np.ones(len(x), bool)  # points not yet given to a special tile
    folder = tmp_path_factory.mktemp("delivery") / "tiles"
    folder.mkdir()

    def take(mask, name):
        _write(las, mask & free, folder / name)
        free[mask] = False

    ground = np.flatnonzero(cls == 2)
    take(np.isin(np.arange(len(x)), ground[np.argmax(x[ground])]), "sliver_1.laz")
    take(np.isin(np.arange(len(x)), ground[np.argsort(y[ground])[:2]]), "sliver_2.laz")
    take((cls == 9) & (x >= 273500) & (x < 273600) & (y >= 5274500), "water.laz")
    take((cls == 1) & (x >= 273380) & (x < 273400), "forest.laz")  # classified, no ground
    _write(las, np.zeros(len(x), bool), folder / "empty.laz")
    # ground points of the south-west tile delivered in the file of its neighbour
    stray = (cls == 2) & (x < 273400) & (y < 5274400) & (x > 273390) & free
    col = np.digitize(x, [273400, 273500, 273600])
    row = np.digitize(y, [5274400, 5274500, 5274600])
    col[stray], row[stray] = 1, 1
    for c in range(4):
        for r in range(4):
            take((col == c) & (row == r), f"T_{c}_{r}.laz")
    assert not free.any() and stray.sum() > 3
    # the same tile twice: a byte copy, and its points again as uncompressed LAS
    (folder / "T_1_1 copy.laz").write_bytes((folder / "T_1_1.laz").read_bytes())
    laspy.read(str(folder / "T_2_2.laz")).write(str(folder / "T_2_2.las"))
    (folder / "README.txt").write_text("Survey of Charlevoix, 2019.\nTiles of 100 m, EPSG:2949.\n")
    (folder / "tile_index.csv").write_text(
        "tile,xmin,ymin,xmax,ymax\nT_0_0.laz,273300,5274300,273400,5274400\n")
    (folder / "tiles.prj").write_text(las.header.parse_crs().to_wkt())
    # surveyed check points (x, y, z text, no tile beside LAS tiles) and a LAStools index
    (folder / "check_points.csv").write_text("x,y,z\n273450.1,5274450.2,801.3\n")
    (folder / "T_0_0.lax").write_bytes(b"LASX" + bytes(60))
    return folder


# both ways a tile set goes: read in memory (the default where it fits) and on a local cluster
ROUTES = pytest.mark.parametrize("route", [[], ["--scheduler", "local"]],
                                 ids=["in-memory", "dask"])


def _grid(inputs, out, *extra):
    return subprocess.run([*CLI, "grid", *map(str, inputs), "--cell-size", CELL, "--workers",
                           "2", "--out", str(out), *extra], capture_output=True, text=True,
                          timeout=900)


def _dem(path):
    with rasterio.open(path) as src:
        return src.read(1, masked=True).filled(np.nan), src.transform


def _notes(stderr):
    return [line for line in stderr.splitlines() if line.startswith("floodmesh: note:")]


def _clean(stderr):
    """No traceback or library log reached the user."""
    assert "Traceback" not in stderr and "distributed." not in stderr, stderr
    assert not any(line.startswith(("WARNING", "ERROR", "INFO", "20")) for line in
                   stderr.splitlines()), stderr


@ROUTES
def test_a_delivery_folder_grids_to_the_dem_of_its_points_as_one_file(delivery, tmp_path,
                                                                       route):
    result = _grid([delivery], tmp_path / "tiles.tif", *route)
    assert result.returncode == 0, result.stderr
    _clean(result.stderr)
    notes = _notes(result.stderr)
    skipped = [n for n in notes if all(name in n for name in NOT_TILES)]
    assert len(skipped) == 1, notes  # the other files, once
    assert not any("T_0_0.laz" in n for n in skipped)
    assert any("T_1_1 copy.laz" in n and "T_1_1.laz" in n for n in notes), notes
    assert any("T_2_2.las" in n and "T_2_2.laz" in n for n in notes), notes
    for name in ("empty.laz", "water.laz", "forest.laz", "sliver_1.laz", "sliver_2.laz"):
        assert any(name in n for n in notes), (name, notes)
    # each ground point counted once: the copies and the ground-less tiles add none
    assert f"({UNIQUE_GROUND:,} points)" in result.stdout, result.stdout
    one = _grid([TOPOGRAPHY], tmp_path / "one.tif")
    assert one.returncode == 0, one.stderr
    tiled, transform = _dem(tmp_path / "tiles.tif")
    whole, whole_transform = _dem(tmp_path / "one.tif")
    assert transform == whole_transform and tiled.shape == whole.shape
    assert np.array_equal(tiled, whole, equal_nan=True)  # the same TIN: cell for cell


def _run(source, out, *extra):
    return subprocess.run([*CLI, "run", str(source), "--out", str(out), "--workers", "2",
                           "--cell-size", CELL, "--holdout", "0.01", "--max-area", "400", *extra],
                          capture_output=True, text=True, timeout=1800)


@ROUTES
def test_run_on_a_delivery_folder(delivery, tmp_path, route):
    out = tmp_path / "reach"
    result = _run(delivery, out, *route)
    assert result.returncode == 0, result.stderr
    _clean(result.stderr)
    report = json.loads((out / "report.json").read_text())
    assert report["n_points"] == UNIQUE_GROUND
    # 1 % of the ground points counted, held back: none of the ground-less tile's
    # unclassified points
    assert report["n_holdout"] == round(0.01 * UNIQUE_GROUND)
    notes = " ".join(report["notes"])
    for name in (*NOT_TILES, "T_1_1 copy.laz", "T_2_2.las", "empty.laz", "sliver_1.laz"):
        assert name in notes, name
    # the one file the tiles were cut from: the same check points and the same mesh (each
    # tile held back its own share before: 81 check points against 82, 70 of them shared,
    # and 1,435 nodes against 1,434)
    one = _run(TOPOGRAPHY, tmp_path / "one")
    assert one.returncode == 0, one.stderr
    checks = [io.read_points_vector(folder / "residuals.gpkg") for folder in
              (out, tmp_path / "one")]
    assert np.array_equal(*[c[np.lexsort(c.T)] for c in checks])
    assert (out / "mesh.2dm").read_bytes() == (tmp_path / "one" / "mesh.2dm").read_bytes()


@ROUTES
def test_a_truncated_tile_is_named_with_the_option_that_leaves_it_out(delivery, tmp_path,
                                                                       route):
    folder = tmp_path / "tiles"
    folder.mkdir()
    for name in ("T_1_1.laz", "T_1_2.laz", "T_2_1.laz", "T_2_2.laz"):
        (folder / name).write_bytes((delivery / name).read_bytes())
    data = (delivery / "T_1_2.laz").read_bytes()
    (folder / "T_1_2.laz").write_bytes(data[:len(data) // 2])  # the copy broke off
    result = _grid([folder], tmp_path / "dem.tif", *route)
    assert result.returncode == 2
    _clean(result.stderr)  # found on a worker: one clean line, no Dask log
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("floodmesh: error: "), result.stderr
    assert "T_1_2.laz" in lines[0] and "--skip-unreadable-tiles" in lines[0]
    assert not (tmp_path / "dem.tif").exists()

    result = _grid([folder], tmp_path / "dem.tif", "--skip-unreadable-tiles", *route)
    assert result.returncode == 0, result.stderr
    _clean(result.stderr)
    assert any("T_1_2.laz" in n for n in _notes(result.stderr)), result.stderr
    (folder / "T_1_2.laz").unlink()
    without = _grid([folder], tmp_path / "without.tif", *route)
    assert without.returncode == 0, without.stderr
    assert np.array_equal(_dem(tmp_path / "dem.tif")[0], _dem(tmp_path / "without.tif")[0],
                          equal_nan=True)


def test_withheld_points_of_a_tile_are_not_gridded(delivery, tmp_path):
    """Points flagged withheld (deleted, by the LAS specification; here a copy of a tile's
    ground raised 30 m) grid to nothing: the DEM is that of the tiles without them."""
    import laspy

    names = ("T_1_1.laz", "T_1_2.laz", "T_2_1.laz", "T_2_2.laz")
    flagged, plain = tmp_path / "flagged", tmp_path / "plain"
    for folder in (flagged, plain):
        folder.mkdir()
        for name in names:
            (folder / name).write_bytes((delivery / name).read_bytes())
    las = laspy.read(str(delivery / "T_1_1.laz"))
    raised = laspy.LasData(copy.deepcopy(las.header), las.points[las.classification == 2])
    raised.z = np.asarray(raised.z) + 30.0
    raised.withheld = np.ones(len(raised.points), bool)
    both = laspy.ScaleAwarePointRecord(np.concatenate([las.points.array, raised.points.array]),
                                       las.points.point_format, las.header.scales,
                                       las.header.offsets)
    laspy.LasData(copy.deepcopy(las.header), both).write(str(flagged / "T_1_1.laz"))
    results = [_grid([folder], tmp_path / f"{folder.name}.tif") for folder in (flagged, plain)]
    assert all(r.returncode == 0 for r in results), [r.stderr for r in results]
    assert np.array_equal(_dem(tmp_path / "flagged.tif")[0], _dem(tmp_path / "plain.tif")[0],
                          equal_nan=True)


def test_a_file_is_a_tile_by_its_content(tmp_path):
    """Only LAS/LAZ ('LASF'), GeoTIFF (a TIFF header) and XYZ text of numbers are tiles; the
    rest of a folder is left out with one note; a .laz that is no LAS is a broken tile."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core import io
    from floodmesh.core.raster import Grid

    values = np.arange(12.0).reshape(3, 4) + 10
    grid = Grid(values, Affine(1.0, 0, 500000.0, 0, -1.0, 6e6), CRS.from_epsg(25832))
    io.write_raster(tmp_path / "a.tif", grid)
    (tmp_path / "README.txt").write_text("DEM tiles\n")
    (tmp_path / "dem.prj").write_text(grid.crs.to_wkt())
    (tmp_path / "notes.tif").write_text("not a TIFF")  # a tile by its name, broken
    found = expand_tiles(tmp_path)
    assert [p.name for p in found] == ["a.tif", "notes.tif"]
    assert len(found.notes) == 1 and "README.txt" in found.notes[0] \
        and "dem.prj" in found.notes[0]
    (tmp_path / "notes.tif").unlink()
    assert np.array_equal(read_dem_tiles(tmp_path).values, values)
    # XYZ text: by its extension and numbers in its first lines
    (tmp_path / "a.tif").unlink()
    (tmp_path / "p.xyz").write_text("x y z\n1 2 3\n4 5 6\n")
    (tmp_path / "q.csv").write_text("1.5,2.5,3.5\n4,5,6\n")
    (tmp_path / "index.csv").write_text("tile,xmin,ymin\na.laz,1,2\n")
    (tmp_path / "bounds.csv").write_text("xmin,ymin,xmax,ymax\n1,2,3,4\n")
    assert [p.name for p in expand_tiles(tmp_path)] == ["p.xyz", "q.csv"]
    for p in list(tmp_path.iterdir()):
        if p.suffix in (".xyz", ".csv"):
            p.unlink()
    with pytest.raises(FloodMeshError, match="holds no LAS/LAZ/XYZ point tiles"):
        expand_tiles(tmp_path)


@pytest.mark.parametrize("route", [[], ["--scheduler", "local"]], ids=["in-memory", "dask"])
def test_a_tiled_run_leaves_no_scratch_and_removes_a_killed_runs(tmp_path, route):
    """Scratch lives in floodmesh-KIND-PID-… folders of the temporary folder, Dask's workers'
    too (no dask-scratch-space of their own): gone after the run, and what a killed run left
    (its process gone) is removed by the next, whether the tiles are read in memory or go to a
    local cluster."""
    import os
    import subprocess
    import sys

    from ..conftest import survey_tiles

    survey = survey_tiles(tmp_path, density=1.0)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    stale = scratch / "floodmesh-bands-999999999-x1y2"  # no such process
    (stale / "band-0.npy").parent.mkdir()
    (stale / "band-0.npy").write_bytes(b"0")
    run = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run",
                          str(survey / "tiles"), "--out", str(tmp_path / "out"),
                          "--max-area", "400", "--workers", "2", *route],
                         env={**os.environ, "TMPDIR": str(scratch)}, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert sorted(p.name for p in scratch.iterdir()) == []
