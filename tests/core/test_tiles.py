"""A survey as tiles: gridded tile by tile on a real dask.distributed cluster, the same DEM,
break lines and mesh as one file of the same points, and tiles in another CRS refused by name."""
import subprocess
import sys
from pathlib import Path

import fiona
import numpy as np
import pytest
import rasterio
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.frontends.demo import DEMO_ORIGIN
from floodmesh.core.errors import Cancelled, FloodMeshError
from floodmesh.core.steps.grid import grid_points_linear
from floodmesh.core.options import RunOptions
from floodmesh.core.chain.pipeline import run_pipeline
from floodmesh.core.points import PointCloud, split_holdout
from floodmesh.core.raster import Grid
from floodmesh.core.steps.breakpoints import breakpoints_file, classify_breakpoints
from floodmesh.core.steps.slope import slope
from floodmesh.core.engine.tiles import (_tile_points, grid_point_tiles, read_back, read_dem_tiles,
                                         read_gridded_points, read_point_tiles, slope_file64)

from ..bad_inputs import plane_xyz
from ..conftest import survey_tiles

FLOODMESH = str(Path(sys.executable).parent / "floodmesh")
X0, Y0 = DEMO_ORIGIN
EDGE_X, EDGE_Y = X0 + 150, Y0 + 120  # the inner tile edges


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    return survey_tiles(tmp_path_factory.mktemp("survey"))


@pytest.fixture(scope="module")
def scheduler():
    """A real local dask.distributed cluster of two worker processes, by its address."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        yield cluster.scheduler_address


def test_tiles_grid_to_the_dem_of_the_whole_cloud(survey, scheduler, tmp_path):
    tiles = sorted((survey / "tiles").glob("*.laz"))
    crs = CRS.from_epsg(25832).to_wkt()
    # 0.5 m cells: blocks of one tile (300 x 240 cells) meet at the tile edges
    tiled = grid_point_tiles(survey / "tiles", 0.5, holdout=0.01, seed=5, scheduler=scheduler,
                             out_path=tmp_path / "dem.tif")
    kept = np.concatenate([_tile_points(str(p), crs, None, tiled.held_below, 5)[0]
                           for p in tiles])
    whole = grid_points_linear(PointCloud(kept, tiled.crs), 0.5)
    assert tiled.dem.transform == whole.transform and tiled.dem.shape == whole.shape
    assert np.array_equal(np.isnan(tiled.dem.values), np.isnan(whole.values))
    np.testing.assert_allclose(tiled.dem.values, whole.values, rtol=0, atol=1e-9)
    # the tiled GeoTIFF on disk holds the same DEM
    with rasterio.open(tmp_path / "dem.tif") as src:
        assert src.profile["tiled"] and src.block_shapes[0] == (256, 256)
    on_disk = io.read_raster(tmp_path / "dem.tif")
    np.testing.assert_array_equal(on_disk.values, whole.values.astype(np.float32))
    # the check points: the 1 % that one file of all the tiles' points holds out (drawn by
    # place, not by tile), the rest gridded
    merged = PointCloud(np.concatenate([io.read_points(p).xyz for p in tiles]), tiled.crs)
    one_file = split_holdout(merged, 0.01, 5)
    assert len(kept) + len(tiled.holdout) == len(merged) == tiled.n_points
    assert len(tiled.holdout) == round(0.01 * len(merged))
    assert _rows(tiled.holdout) == _rows(one_file[1].xyz)
    assert _rows(kept) == _rows(one_file[0].xyz)


def _rows(xyz):
    return {tuple(row) for row in np.asarray(xyz).tolist()}


def test_a_void_by_a_block_edge_on_a_cluster_stays_nodata_as_in_one_file(scheduler, tmp_path):
    """A pond 12 m wide (more than the 10 m max gap) ending at the edge between two blocks of
    round two (256 cells from the west): the thin triangles along its east shore have circles
    reaching past the east block's halo to points of the west shore, so one TIN of all the
    points bridges the pond there with long triangles (nodata). On a cluster the east block
    once gridded only the points within its halo and gave those cells the thin triangles'
    heights (one to sixteen cells a seed: the tester's 804.99 m in a gap of Topography.laz)."""
    rng = np.random.default_rng(0)
    gx, gy = np.meshgrid(np.arange(0.5, 280, 1.0), np.arange(0.5, 30, 1.0))
    xy = np.column_stack([gx.ravel(), gy.ravel()]) + rng.uniform(-0.45, 0.45, (gx.size, 2))
    xy = xy[(xy[:, 0] < 244) | (xy[:, 0] > 256.2)]  # the pond
    xyz = np.round(np.column_stack([xy[:, 0] + X0, xy[:, 1] + Y0,
                                    100 + 0.01 * xy[:, 0] + 0.3 * np.sin(xy[:, 1] / 5)]), 2)
    crs = CRS.from_epsg(25832)
    (tmp_path / "tiles").mkdir()
    for west in (0, 95, 190):  # tiles narrower than a block
        inside = (xyz[:, 0] >= X0 + west) & (xyz[:, 0] < X0 + west + 95)
        io.write_points_las(tmp_path / "tiles" / f"strip_{west}.laz",
                            PointCloud(xyz[inside], crs))
    io.write_points_las(tmp_path / "one.laz", PointCloud(xyz, crs))
    whole = grid_points_linear(io.read_points(tmp_path / "one.laz"), 1.0)
    tiled = grid_point_tiles(tmp_path / "tiles", 1.0, scheduler=scheduler,
                             out_path=tmp_path / "dem.tif")
    assert tiled.dem.transform == whole.transform and tiled.dem.shape == whole.shape
    assert whole.shape[1] > 256 and np.isnan(whole.values[:, 244:257]).any()
    assert np.array_equal(np.isnan(tiled.dem.values), np.isnan(whole.values))
    np.testing.assert_allclose(tiled.dem.values, whole.values, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(io.read_raster(tmp_path / "dem.tif").values,
                                  whole.values.astype(np.float32))


def test_a_local_cluster_keeps_the_edge_bands_in_scratch_files(survey, scheduler, tmp_path,
                                                               monkeypatch):
    """On its own local cluster round one writes each tile's edge band to a scratch file instead
    of keeping it in a worker's memory (the one term of the gridding that grows with the area):
    the files are there before round two, hold the points within two halos of the tile's
    outline, and are gone after; the DEM is the one of a running scheduler's workers, which
    keep the bands in memory."""
    import tempfile

    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    seen = {}

    def check(plan):
        for band in sorted(scratch.glob("floodmesh-bands-*/*.npy")):
            seen[band.name] = np.load(band)

    local = grid_point_tiles(survey / "tiles", 0.5, workers=2, check=check)
    assert sorted(seen) == [f"band-{i}.npy" for i in range(4)]
    first = io.read_points(sorted((survey / "tiles").glob("*.laz"))[0]).xyz
    lo, hi = first[:, :2].min(axis=0), first[:, :2].max(axis=0)
    band = seen["band-0.npy"]
    inner = ((band[:, :2] > lo + 1) & (band[:, :2] < hi - 1)).all(axis=1)
    assert len(band) and inner.mean() < 1  # an edge band, not the tile
    assert not list(scratch.glob("floodmesh-bands-*"))  # (dask keeps its own scratch there)
    remote = grid_point_tiles(survey / "tiles", 0.5, scheduler=scheduler)
    assert np.array_equal(local.dem.values, remote.dem.values, equal_nan=True)


def _lines(path):
    return sorted(tuple(map(tuple, np.round(c, 6))) for c in io.read_lines_gpkg(path))


@pytest.mark.parametrize("route", ["dask", "in-memory"])
def test_run_on_tiles_equals_run_on_one_file(survey, scheduler, tmp_path, route):
    # on Dask the terrain fits (localisation, node z) take the tiles' points read back, as one
    # file's; in memory (the default where the tiles fit) the points read. With the default
    # options the tiles hold out the check points one file of their points holds out (each
    # tile held out its own share before: 7 of the 288 were other points, and the mesh had
    # 1,499 nodes against 1,493) and give the same lines and mesh to the byte either way
    options = RunOptions(scheduler=scheduler if route == "dask" else None)
    told = []
    tiled = run_pipeline(survey / "tiles", tmp_path / "tiled", options, progress=told.append)
    single = run_pipeline(survey / "single.laz", tmp_path / "single", options)
    assert ("read back" in tiled["seconds"]) == (route == "dask")
    # Dask reads the tiles as it grids them: the bar ends at 100 %, never past it
    assert all(0 <= f <= 1 for f in told) and told == sorted(told) and told[-1] == 1.0, told
    assert tiled["n_holdout"] == single["n_holdout"] == 288
    checks = [io.read_points_vector(tmp_path / name / "residuals.gpkg") for name in
              ("tiled", "single")]
    assert _rows(checks[0]) == _rows(checks[1])
    assert tiled["holdout_source"] == single["holdout_source"]
    assert io.read_raster(tmp_path / "tiled" / "dem.tif").values.tobytes() == \
        io.read_raster(tmp_path / "single" / "dem.tif").values.tobytes()
    for key in ("nodes", "triangles", "n_breakpoints", "n_breaklines", "min_angle_deg",
                "terrain_fit"):
        assert tiled[key] == single[key], key
    assert tiled["terrain_fit"]["points"] == "LiDAR points gridded"
    for name in ("mesh.2dm", "breaklines.gpkg"):
        assert (tmp_path / "tiled" / name).read_bytes() == \
            (tmp_path / "single" / name).read_bytes(), name
    # slope and breakpoints went file to file for the tiles on Dask, in memory otherwise
    for name in ("slope.tif", "breakpoints.tif"):
        with rasterio.open(tmp_path / "tiled" / name) as a, \
                rasterio.open(tmp_path / "single" / name) as b:
            assert a.profile == b.profile, name
            assert np.array_equal(a.read(1), b.read(1)), name
    lines = _lines(tmp_path / "tiled" / "breaklines.gpkg")
    assert lines == _lines(tmp_path / "single" / "breaklines.gpkg")
    # break lines run on across the tile edges: the river and the levee cross x = EDGE_X
    crossing_x = [c for c in lines if min(p[0] for p in c) < EDGE_X - 5 < EDGE_X + 5
                  < max(p[0] for p in c)]
    crossing_y = [c for c in lines if min(p[1] for p in c) < EDGE_Y - 5 < EDGE_Y + 5
                  < max(p[1] for p in c)]
    assert len(crossing_x) >= 4 and len(crossing_y) >= 1


def test_slope_and_breakpoints_file_to_file_equal_them_in_memory(survey, scheduler, tmp_path):
    # what run does with point tiles: the gridded float64 DEM on disk, slope and breakpoints
    # block by block (strips of 512 rows: the halo crosses strip edges), read back for the tracer
    tiled = grid_point_tiles(survey / "tiles", 0.25, scheduler=scheduler, keep=False,
                             dtype="float64", out_path=tmp_path / "dem.tif")
    assert tiled.dem is None
    dem = read_back(tmp_path / "dem.tif", tiled.crs)
    whole = grid_point_tiles(survey / "tiles", 0.25, scheduler=scheduler).dem
    assert np.array_equal(dem.values, whole.values, equal_nan=True)
    assert dem.shape[0] > 512
    slope_file64(tmp_path / "dem.tif", tmp_path / "slope.tif", "one-over-distance")
    breakpoints_file(tmp_path / "slope.tif", tmp_path / "bp.tif", s_crit=10.0,
                     input_dtype=np.float64)
    in_memory = slope(dem, "one-over-distance")
    assert np.array_equal(read_back(tmp_path / "slope.tif", tiled.crs).values, in_memory.values,
                          equal_nan=True)
    marks = classify_breakpoints(in_memory, 10.0).values
    streamed = read_back(tmp_path / "bp.tif", tiled.crs).values
    assert streamed.dtype == np.uint8 and marks.sum() > 1000
    assert np.array_equal(streamed, marks)


def test_a_tile_in_another_crs_or_none_is_refused_by_name(survey, tmp_path):
    import laspy

    folder = tmp_path / "tiles"
    folder.mkdir()
    tiles = sorted((survey / "tiles").glob("*.laz"))
    for p in tiles[:2]:
        (folder / p.name).write_bytes(p.read_bytes())
    pts = io.read_points(tiles[2])
    io.write_points_las(folder / "other.laz", PointCloud(pts.xyz, CRS.from_epsg(25833)))
    result = subprocess.run([FLOODMESH, "grid", str(folder), "--cell-size", "1", "--out",
                             str(tmp_path / "dem.tif")], capture_output=True, text=True)
    assert result.returncode == 2
    assert "tile other.laz is in ETRS89 / UTM zone 33N" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "dem.tif").exists()
    (folder / "other.laz").unlink()
    header = laspy.LasHeader(point_format=3, version="1.4")  # no CRS
    header.offsets, header.scales = pts.xyz.min(axis=0), [0.001] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.xyz.T
    las.classification = np.full(len(pts), 2, np.uint8)
    las.write(str(folder / "nocrs.laz"))
    with pytest.raises(FloodMeshError, match="tile nocrs.laz has no coordinate reference"):
        grid_point_tiles(folder, 1.0)
    (folder / "broken.laz").write_bytes(b"not a LAS file")
    with pytest.raises(FloodMeshError, match="tile broken.laz is not a readable LAS/LAZ"):
        grid_point_tiles(folder, 1.0, crs="EPSG:25832")


def test_grid_command_on_its_own_local_cluster_with_progress_and_cancel(survey, tmp_path):
    out = tmp_path / "dem.tif"
    result = subprocess.run([FLOODMESH, "grid", str(survey / "tiles" / "*.laz"), "--cell-size",
                             "1", "--holdout", "0.01", "--workers", "2", "--scheduler", "local",
                             "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert "DEM of 4 tiles" in result.stdout and (tmp_path / "holdout.gpkg").exists()
    assert np.isfinite(io.read_raster(out).values).mean() > 0.99
    seen = []
    with pytest.raises(Cancelled):
        grid_point_tiles(survey / "tiles", 1.0, workers=1, processes=False,
                         out_path=tmp_path / "cancelled.tif", progress=seen.append,
                         cancelled=lambda: len(seen) >= 1)
    assert seen and not (tmp_path / "cancelled.tif").exists()


def test_tiles_that_fit_in_memory_are_read_without_a_cluster_to_the_same_dem(survey, tmp_path):
    """By default tiles that fit in memory with their grid are read on threads and gridded at
    once, as one file, with no cluster to start: the local cluster's DEM and check points; a
    cancel between tiles stops the reading."""
    local = tmp_path / "local"
    local.mkdir()
    grid = [FLOODMESH, "grid", str(survey / "tiles"), "--cell-size", "0.5", "--holdout", "0.01"]
    said = []
    for folder, route in ((tmp_path, []), (local, ["--scheduler", "local"])):
        result = subprocess.run([*grid, *route, "--out", str(folder / "dem.tif")],
                                capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr
        said.append(result.stdout)
    assert "m from 4 tiles (288,000 points) written" in said[0]
    assert "DEM of 4 tiles (288,000 points) written" in said[1]
    in_memory, on_dask = io.read_raster(tmp_path / "dem.tif"), io.read_raster(local / "dem.tif")
    assert in_memory.transform == on_dask.transform
    np.testing.assert_array_equal(in_memory.values, on_dask.values)
    held = []
    for folder in (tmp_path, local):  # read by GDAL (fiona), as QGIS reads them
        with fiona.open(folder / "holdout.gpkg") as layer:
            held.append(sorted(f.geometry.coordinates for f in layer))
    assert len(held[0]) == 2880 and held[0] == held[1]
    read = read_point_tiles(survey / "tiles", 1.0, holdout=0.01, seed=5, workers=2)
    merged = PointCloud(np.concatenate([io.read_points(p).xyz for p in
                                        sorted((survey / "tiles").glob("*.laz"))]), read.crs)
    kept, check = split_holdout(merged, 0.01, 5)  # one file of the same points
    assert _rows(read.gridding) == _rows(kept.xyz) and _rows(read.holdout) == _rows(check.xyz)
    assert (read.n_tiles, read.n_points) == (4, len(read.gridding) + len(read.holdout))
    polls = []
    with pytest.raises(Cancelled):
        read_point_tiles(survey / "tiles", 1.0, workers=1,
                         cancelled=lambda: polls.append(1) or len(polls) > 1)
    # where they would not fit, None: the caller grids them on Dask
    assert read_point_tiles(survey / "tiles", 1.0, memory=1) is None


def test_dem_tiles_are_read_as_one_grid(tmp_path):
    from affine import Affine

    rng = np.random.default_rng(0)
    whole = Grid(rng.uniform(10, 20, (40, 60)), Affine(1.0, 0, X0, 0, -1.0, Y0),
                 CRS.from_epsg(25832))
    west = Grid(whole.values[:, :25], whole.transform, whole.crs)
    east = Grid(whole.values[:, 25:], whole.transform * Affine.translation(25, 0), whole.crs)
    io.write_raster(tmp_path / "w.tif", west)
    io.write_raster(tmp_path / "e.tif", east)
    mosaic = read_dem_tiles(tmp_path)
    assert mosaic.transform == whole.transform
    np.testing.assert_allclose(mosaic.values, whole.values.astype(np.float32))
    shifted = Grid(east.values, east.transform * Affine.translation(0.5, 0), whole.crs)
    io.write_raster(tmp_path / "e.tif", shifted)
    with pytest.raises(FloodMeshError, match="tile e.tif has cells of 1 m .* not on the grid"):
        read_dem_tiles([tmp_path / "w.tif", tmp_path / "e.tif"])


def test_xyz_tiles_with_a_given_crs(survey, scheduler, tmp_path):
    tiles = sorted((survey / "tiles").glob("*.laz"))[:2]  # the western column
    for p in tiles:
        np.savetxt(tmp_path / f"{p.stem}.xyz", io.read_points(p).xyz, fmt="%.3f")
    from_laz = grid_point_tiles(tiles, 1.0, scheduler=scheduler)
    with pytest.raises(FloodMeshError, match=r"tile tile_0_0.xyz has no coordinate reference"):
        grid_point_tiles(str(tmp_path / "*.xyz"), 1.0, scheduler=scheduler)
    from_xyz = grid_point_tiles(str(tmp_path / "*.xyz"), 1.0, crs="EPSG:25832",
                                scheduler=scheduler)
    assert from_xyz.dem.transform == from_laz.dem.transform
    np.testing.assert_allclose(from_xyz.dem.values, from_laz.dem.values, atol=1e-6)


def test_xyz_tiles_with_zone_prefixed_eastings_are_refused_once_read(scheduler, tmp_path):
    """XYZ tiles have no header to place them before they are read: their points, once read on
    the cluster, are checked as a LAS tile's header is (eastings with the UTM zone before them,
    32 412 000 m, placed the DEM 32,000 km off)."""
    xyz = plane_xyz() + [32_000_000.0, 0.0, 0.0]
    west = xyz[:, 0] < xyz[:, 0].mean()
    np.savetxt(tmp_path / "west.xyz", xyz[west], fmt="%.3f")
    np.savetxt(tmp_path / "east.xyz", xyz[~west], fmt="%.3f")
    with pytest.raises(FloodMeshError, match=r"tile east.xyz \(and west.xyz alike\) lies at "
                       r"x 32,41.* far outside the "
                       r"area where ETRS89 / UTM zone 32N is used .* --crs EPSG:4647"):
        grid_point_tiles(str(tmp_path / "*.xyz"), 1.0, crs="EPSG:25832", scheduler=scheduler,
                         out_path=tmp_path / "dem.tif")
    assert not (tmp_path / "dem.tif").exists()


def test_refine_on_tiles_fits_the_points_and_checks_on_the_tiles_holdout(survey, scheduler,
                                                                          tmp_path):
    # the points gridded, read back from the tiles, drive the refinement and the points each
    # tile held back check it, round by round
    options = RunOptions(holdout=0.01, scheduler=scheduler, refine=True, localise=False,
                         node_elevation="dem")
    report = run_pipeline(survey / "tiles", tmp_path / "refined", options)
    assert report["terrain_fit"]["points"] == "LiDAR points gridded"
    rounds = report["refinement"]
    assert len(rounds) >= 2 and report["nodes"] == rounds[-1]["nodes"] > rounds[0]["nodes"]
    assert rounds[-1]["max_abs_m"] < rounds[0]["max_abs_m"]
    assert rounds[-1]["rmse_m"] < rounds[0]["rmse_m"]
    assert rounds[-1]["check_rmse_m"] < rounds[0]["check_rmse_m"]
    assert report["holdout_source"] == "LiDAR points withheld from gridding"
    # the check points are held-out LiDAR points, 1 % of the tiles' points
    assert report["n_holdout"] == round(0.01 * report["n_points"])


def test_tiles_whose_points_exceed_memory_fit_the_dem_cells_with_a_note(survey, scheduler,
                                                                        tmp_path, monkeypatch):
    # the fits' points are read back only where memory holds them beside the DEM: here the
    # estimate says it does not (the run's own memory checks, which refuse, are left as they are)
    from floodmesh.core.chain import pipeline

    monkeypatch.setattr(pipeline, "fits_in_memory", lambda **sizes: False)
    told = []
    report = run_pipeline(survey / "tiles", tmp_path / "out", RunOptions(scheduler=scheduler),
                          progress=told.append)
    assert report["terrain_fit"]["points"] == "DEM cell centres"
    # without the points read back the bar still ends at 100 % (it stopped at 95 %)
    assert all(0 <= f <= 1 for f in told) and told == sorted(told) and told[-1] == 1.0, told
    assert any("more than memory holds" in n and "cell centres" in n for n in report["notes"])


def test_overlapping_tiles_count_their_shared_points_once(survey, tmp_path):
    """A buffered delivery: each tile carries its neighbours' points 10 m beyond its edge. Read
    in memory (the default where they fit), every point is counted once, with a note naming the
    tiles that overlap, the DEM is the one file's, and no check point is a copy of a point
    gridded."""
    whole = io.read_points(survey / "single.laz")
    xyz = whole.xyz
    (tmp_path / "buffered").mkdir()
    for xs in (0, 150):
        for ys in (0, 120):
            inside = ((xyz[:, 0] >= X0 + xs - 10) & (xyz[:, 0] < X0 + xs + 160)
                      & (xyz[:, 1] >= Y0 + ys - 10) & (xyz[:, 1] < Y0 + ys + 130))
            io.write_points_las(tmp_path / "buffered" / f"tile_{xs}_{ys}.laz",
                                PointCloud(xyz[inside], whole.crs))
    read = read_point_tiles(tmp_path / "buffered", 1.0, holdout=0.01, seed=3)
    assert read.n_points == len(xyz) == len(read.gridding) + len(read.holdout)
    overlap = [n for n in read.notes if "where the two overlap: they are counted once" in n]
    assert len(overlap) == 5, read.notes  # 3 later tiles meet the first; 2 more pairs
    assert any("tile_150_120.laz repeats" in n and "of tile tile_0_0.laz" in n for n in overlap)
    keys = {tuple(p) for p in np.rint(read.gridding * 1e4).astype(np.int64)}
    assert not any(tuple(p) in keys for p in np.rint(read.holdout * 1e4).astype(np.int64))
    assert len(keys) == len(read.gridding)
    report = run_pipeline(tmp_path / "buffered", tmp_path / "out", RunOptions(holdout=0.0))
    single = run_pipeline(survey / "single.laz", tmp_path / "single", RunOptions(holdout=0.0))
    assert report["n_points"] == single["n_points"] == len(xyz)
    np.testing.assert_array_equal(io.read_raster(tmp_path / "out" / "dem.tif").values,
                                  io.read_raster(tmp_path / "single" / "dem.tif").values)
    assert any("counted once" in n for n in report["notes"])


def _buffered(xyz, crs, folder, buffer, scales=None):
    """The points as 2 x 2 tiles of the survey's cut, each ``buffer`` m wider on every side (its
    neighbours' points there too), written at the LAS ``scales`` given by tile (default
    0.001 m)."""
    # lazy: laspy loads only in the tests that write other scales
    import laspy

    folder.mkdir()
    for k, (xs, ys) in enumerate(((0, 0), (0, 120), (150, 0), (150, 120))):
        inside = ((xyz[:, 0] >= X0 + xs - buffer) & (xyz[:, 0] < X0 + xs + 150 + buffer)
                  & (xyz[:, 1] >= Y0 + ys - buffer) & (xyz[:, 1] < Y0 + ys + 120 + buffer))
        header = laspy.LasHeader(point_format=3, version="1.4")
        header.offsets = np.floor(xyz.min(axis=0))
        header.scales = np.full(3, 0.001 if scales is None else scales[k])
        header.add_crs(crs)
        las = laspy.LasData(header)
        las.x, las.y, las.z = xyz[inside, 0], xyz[inside, 1], xyz[inside, 2]
        las.classification = np.full(inside.sum(), 2, np.uint8)
        las.write(str(folder / f"tile_{xs}_{ys}.laz"))


def _check_points_gpkg(path):
    with fiona.open(path) as layer:  # read by GDAL, as QGIS reads them
        return sorted(tuple(f.geometry.coordinates) for f in layer)


def test_buffered_tiles_hold_out_and_grid_what_one_file_of_their_points_does(survey, tmp_path):
    """Buffered tiles (5 m of each neighbour's points) through `grid` as a user runs it: the
    shared points are counted once before the check points are drawn, so the tiles hold out
    the check points one file of their points holds out, as many, and grid its DEM. The draw
    once came first: the copies of a shared point took two of the least hashes (one point),
    the count was of the copies, and the check points and the DEM were others."""
    whole = io.read_points(survey / "single.laz")
    _buffered(whole.xyz, whole.crs, tmp_path / "buffered", 5.0)
    said = []
    for source, out in ((tmp_path / "buffered", "tiles"), (survey / "single.laz", "one")):
        (tmp_path / out).mkdir()
        result = subprocess.run([FLOODMESH, "grid", str(source), "--cell-size", "1",
                                 "--holdout", "0.01", "--out", str(tmp_path / out / "dem.tif")],
                                capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr
        said.append(result.stdout + result.stderr)
    assert "from 4 tiles (288,000 points)" in said[0] and "counted once" in said[0]
    tiles, one = (_check_points_gpkg(tmp_path / out / "holdout.gpkg") for out in ("tiles", "one"))
    assert len(tiles) == len(one) == 2880 and tiles == one
    np.testing.assert_array_equal(io.read_raster(tmp_path / "tiles" / "dem.tif").values,
                                  io.read_raster(tmp_path / "one" / "dem.tif").values)


def test_buffered_tiles_at_other_las_scales_count_their_shared_points_once(survey, tmp_path):
    """Buffered tiles, two written at 1 cm, two at 1 mm: a shared point's copies differ by up
    to 5.5 mm, and are found as one point (within half the two scales' sum), with a note
    saying so; every point counts once, and no check point has a copy among the points
    gridded (they were matched to 0.1 mm only: most copies were counted twice, and a check
    point's copy gridded)."""
    whole = io.read_points(survey / "single.laz")
    _buffered(whole.xyz, whole.crs, tmp_path / "buffered", 10.0, (0.01, 0.001, 0.01, 0.001))
    result = subprocess.run([FLOODMESH, "grid", str(tmp_path / "buffered"), "--cell-size", "1",
                             "--holdout", "0.01", "--out", str(tmp_path / "dem.tif")],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert "from 4 tiles (288,000 points)" in result.stdout, result.stdout
    assert "found within 5.5 mm: the tiles store coordinates to 1 and 10 mm" in result.stderr
    read = read_point_tiles(tmp_path / "buffered", 1.0, holdout=0.01, seed=0)
    assert len(read.gridding) + len(read.holdout) == read.n_points == len(whole.xyz)
    assert len(read.holdout) == 2880
    from scipy.spatial import cKDTree

    gap, _ = cKDTree(read.gridding).query(read.holdout, p=np.inf)
    assert gap.min() > 0.0055


def test_buffered_xyz_tiles_of_other_decimals_count_their_shared_points_once(survey, tmp_path):
    """XYZ text tiles have no scale: their step is read from their numbers (2 and 3 decimals),
    and the copies of a shared point are found as in LAS tiles."""
    xyz = io.read_points(survey / "single.laz").xyz
    xyz = xyz[(xyz[:, 0] < X0 + 60) & (xyz[:, 1] < Y0 + 40)]
    for name, west, decimals in (("a.xyz", 0, 2), ("b.xyz", 25, 3)):
        inside = (xyz[:, 0] >= X0 + west) & (xyz[:, 0] < X0 + west + 35)
        np.savetxt(tmp_path / name, xyz[inside], fmt=f"%.{decimals}f")
    read = read_point_tiles(str(tmp_path / "*.xyz"), 1.0, crs="EPSG:25832")
    assert read.n_points == len(read.gridding) == len(xyz)
    assert any("tile b.xyz repeats" in n and "to 1 and 10 mm" in n for n in read.notes)


@pytest.mark.parametrize("buffer, scales", [(5.0, None), (15.0, (0.01, 0.001, 0.01, 0.001))])
def test_buffered_tiles_on_a_cluster_grid_and_hold_out_what_one_file_does(
        survey, scheduler, tmp_path, buffer, scales):
    """Buffered tiles (``buffer`` m of each neighbour's points; the wider buffer beyond the
    tiles' edge bands, at LAS scales of 1 cm and 1 mm) through `grid --scheduler` as a user
    runs it on a cluster: the shared points are counted once before the check points are drawn,
    as in memory, so the tiles hold out the check points one file of their points holds out
    and grid its DEM, and `run` reads back the points one file grids. On a cluster they were
    counted twice, with a note only: other check points, and another DEM."""
    whole = io.read_points(survey / "single.laz")
    _buffered(whole.xyz, whole.crs, tmp_path / "buffered", buffer, scales)
    said = []
    for source, out, extra in ((tmp_path / "buffered", "tiles", ["--scheduler", scheduler]),
                               (tmp_path / "buffered", "memory", []),
                               (survey / "single.laz", "one", [])):
        (tmp_path / out).mkdir()
        result = subprocess.run([FLOODMESH, "grid", str(source), "--cell-size", "1",
                                 "--holdout", "0.01", "--out", str(tmp_path / out / "dem.tif"),
                                 *extra], capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr
        said.append(result.stdout + result.stderr)
    assert "DEM of 4 tiles (288,000 points)" in said[0], said[0]
    # 3 later tiles meet the first; 2 more pairs
    assert said[0].count("where the two overlap: they are counted once") == 5, said[0]
    # the one file's points where the tiles store them as it does (at 1 mm), else the tiles'
    # in memory, whose coordinates at 1 cm are another survey's
    same = ("tiles", "one" if scales is None else "memory")
    tiles, other = (_check_points_gpkg(tmp_path / out / "holdout.gpkg") for out in same)
    assert len(tiles) == len(other) == 2880 and tiles == other
    np.testing.assert_array_equal(*(io.read_raster(tmp_path / out / "dem.tif").values
                                    for out in same))
    with rasterio.open(tmp_path / "tiles" / "dem.tif") as src:  # as every DEM FloodMesh writes
        assert src.tags()["FLOODMESH_QUANTITY"] == "elevation"
    tiled = grid_point_tiles(tmp_path / "buffered", 1.0, holdout=0.01, scheduler=scheduler,
                             keep=False)
    read = read_point_tiles(tmp_path / "buffered", 1.0, holdout=0.01)
    assert tiled.n_points == read.n_points == len(whole.xyz)
    assert [n for n in tiled.notes if "counted once" in n] == \
        [n for n in read.notes if "counted once" in n]
    gridded = read_gridded_points(tiled)
    assert sorted(map(tuple, gridded)) == sorted(map(tuple, read.gridding))
