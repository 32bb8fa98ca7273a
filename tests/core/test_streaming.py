"""The streaming block engine (``core.engine.blocks``): every raster step file to file, block by block,
gives exactly what the step gives on the whole grid in memory, across block edges, for any
window list; outputs are tiled, compressed and atomic."""
import numpy as np
import pytest
import rasterio
from affine import Affine
from numpy.testing import assert_array_equal
from pyproj import CRS

from floodmesh.core.engine import blocks
from floodmesh.core import io
from floodmesh.core.steps.breakpoints import (_threshold_block, breakpoints_file,
                                              classify_breakpoints, log_breakpoints,
                                              thin_breakpoints)
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.raster import Grid
from floodmesh.core.steps.slope import (SLOPE_METHODS, laplacian_of_gaussian,
                                        laplacian_of_gaussian_file, slope, slope_file)

CRS_M = CRS.from_epsg(25832)


def rough_dem(rows=300, cols=280, seed=5):
    """Rolling ground with embankments and holes: many breakpoints and nodata at block edges."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(float)
    z = 3 * np.sin(xx / 9) * np.cos(yy / 7) + np.clip((xx % 60) - 40, 0, 4)
    z += rng.normal(0, 0.05, z.shape)
    z[rng.random(z.shape) < 0.01] = np.nan
    z[127:131, :] = np.nan  # a gap across a block edge
    return Grid(z.astype(np.float32).astype(np.float64),
                Affine(0.5, 0, 400000, 0, -0.5, 5600000), CRS_M)


@pytest.fixture
def dem_file(tmp_path):
    path = tmp_path / "dem.tif"
    io.write_raster(path, rough_dem())
    return path


def tiles(shape, size):
    rows, cols = shape
    return [(r, c, min(size, rows - r), min(size, cols - c))
            for r in range(0, rows, size) for c in range(0, cols, size)]


@pytest.mark.parametrize("windows", [None, "rows7", "tiles33"])
@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_slope_file_equals_slope_in_memory(dem_file, tmp_path, method, windows):
    dem = io.read_raster(dem_file)
    windows = {None: None, "rows7": blocks.row_windows(dem.shape, 7),
               "tiles33": tiles(dem.shape, 33)}[windows]
    slope_file(dem_file, tmp_path / "s.tif", method, windows=windows)
    ours = io.read_raster(tmp_path / "s.tif").values
    assert_array_equal(ours, slope(dem, method).values.astype(np.float32))


def test_breakpoints_blocked_equal_whole():
    """Thinning across block edges: strips of 1..13 rows and square tiles give the whole grid's
    breakpoints, cell for cell (thinning needs the neighbours' breakpoints, hence the halo)."""
    s = slope(rough_dem(), "one-over-distance")
    with np.errstate(invalid="ignore"):
        whole = thin_breakpoints(s.values >= 10.0)
    assert 1000 < whole.sum() < 0.5 * np.isfinite(s.values).sum()
    assert_array_equal(classify_breakpoints(s, 10.0).values, whole)
    block, halo = _threshold_block(10.0, True)
    for rows in (1, 2, 5, 13):
        assert_array_equal(blocks.map_overlap(s.values, block, halo=halo, block_rows=rows), whole)
    assert_array_equal(blocks.map_overlap(s.values, block, halo=halo,
                                          windows=tiles(s.shape, 17)), whole)


def test_breakpoints_file_equals_memory_and_marks_nodata(dem_file, tmp_path):
    slope_file(dem_file, tmp_path / "s.tif", "one-over-distance")
    s = io.read_raster(tmp_path / "s.tif")
    count = breakpoints_file(tmp_path / "s.tif", tmp_path / "bp.tif", s_crit=10.3,
                             windows=blocks.row_windows(s.shape, 9))
    with rasterio.open(tmp_path / "bp.tif") as src:
        bp = src.read(1)
        assert src.nodata == 255 and src.dtypes[0] == "uint8"
    expected = classify_breakpoints(s, 10.3).values
    assert count == expected.sum() > 1000
    assert_array_equal(bp == 255, np.isnan(s.values))
    assert_array_equal(np.where(bp == 255, 0, bp), expected)


def test_float32_threshold_is_the_float64_comparison():
    """S_crit not representable in float32: a float32 slope just below it is no breakpoint."""
    s_crit = 10.1
    below = np.nextafter(np.float32(s_crit), np.float32(0))
    above = np.nextafter(below, np.float32(np.inf))
    values = np.array([[below, above]], np.float32)
    grid = Grid(values, Affine(1, 0, 0, 0, -1, 2), CRS_M)
    expected = (values.astype(np.float64) >= s_crit).astype(np.uint8)
    assert_array_equal(classify_breakpoints(grid, s_crit, thin=False).values, expected)


@pytest.mark.parametrize("zero_crossings", [False, True])
@pytest.mark.parametrize("kernel, sigma", [("pratt", 1.0), ("analytic", 1.0)])
def test_log_and_its_breakpoints_file_equal_memory(dem_file, tmp_path, kernel, sigma,
                                                   zero_crossings):
    dem = io.read_raster(dem_file)
    laplacian_of_gaussian_file(dem_file, tmp_path / "log.tif", sigma, kernel=kernel,
                               windows=blocks.row_windows(dem.shape, 11))
    response = io.read_raster(tmp_path / "log.tif")
    assert_array_equal(response.values,
                       laplacian_of_gaussian(dem, sigma, kernel=kernel).values.astype(np.float32))
    breakpoints_file(tmp_path / "log.tif", tmp_path / "bp.tif", sensitivity=0.02,
                     zero_crossings=zero_crossings, windows=tiles(dem.shape, 23))
    with rasterio.open(tmp_path / "bp.tif") as src:
        bp = src.read(1)
    expected = log_breakpoints(response, 0.02, zero_crossings=zero_crossings).values
    assert expected.sum() > 20
    assert_array_equal(np.where(bp == 255, 0, bp), expected)


def test_output_is_tiled_georeferenced_and_compressed_when_integer(dem_file, tmp_path):
    """Float rasters are written uncompressed (as gdaldem does: ZSTD saved too little for its
    CPU), breakpoints with ZSTD."""
    slope_file(dem_file, tmp_path / "s.tif", crs="EPSG:25833")
    breakpoints_file(tmp_path / "s.tif", tmp_path / "bp.tif", s_crit=10.0)
    with rasterio.open(tmp_path / "s.tif") as src, rasterio.open(dem_file) as dem, \
            rasterio.open(tmp_path / "bp.tif") as bp:
        assert src.profile["tiled"] and src.block_shapes[0] == (256, 256)
        assert src.compression is None
        assert bp.compression.name.lower() == io.INTEGER_COMPRESSION["compress"]
        assert bp.profile["tiled"] and bp.block_shapes[0] == (256, 256)
        assert src.transform == dem.transform and src.nodata == blocks.FLOAT_NODATA
        assert src.crs.to_epsg() == 25833  # --crs overrides the file's


def test_failure_leaves_no_output_and_keeps_the_old_one(dem_file, tmp_path):
    out = tmp_path / "s.tif"
    out.write_bytes(b"old")
    calls = []

    def failing(padded):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("disk full")
        return padded[1:-1, 1:-1]

    with pytest.raises(RuntimeError):
        blocks.map_raster(dem_file, out, failing, halo=1, block_rows=64)
    assert out.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dem.tif", "s.tif"]


def test_all_nodata_is_refused_without_output(tmp_path):
    grid = Grid(np.full((20, 20), np.nan), Affine(1, 0, 0, 0, -1, 20), CRS_M)
    profile = dict(driver="GTiff", height=20, width=20, count=1, dtype="float32",
                   crs=CRS_M.to_wkt(), transform=grid.transform, nodata=-9999.0)
    with rasterio.open(tmp_path / "empty.tif", "w", **profile) as dst:
        dst.write(np.full((1, 20, 20), -9999.0, np.float32))
    with pytest.raises(FloodMeshError, match="no valid cells"):
        slope_file(tmp_path / "empty.tif", tmp_path / "s.tif")
    assert not (tmp_path / "s.tif").exists()


def test_unlisted_windows_are_nodata(dem_file, tmp_path):
    dem = io.read_raster(dem_file)
    slope_file(dem_file, tmp_path / "s.tif", windows=[(0, 0, 40, 50)])
    ours = io.read_raster(tmp_path / "s.tif").values
    assert_array_equal(ours[:40, :50],
                       slope(dem, "one-over-distance").values[:40, :50].astype(np.float32))
    assert np.isnan(ours[40:]).all() and np.isnan(ours[:, 50:]).all()


@pytest.mark.parametrize("command", ["slope", "breakpoints"])
def test_streaming_commands_refuse_bad_rasters_in_one_line(tmp_path, capsys, command):
    """The file-to-file commands check a raster as reading it whole did: a rotated grid and a
    missing file are one-line errors, and nothing is written."""
    from floodmesh.core.frontends.cli import main

    rotated = tmp_path / "rotated.tif"
    profile = dict(driver="GTiff", height=30, width=30, count=1, dtype="float32",
                   crs=CRS_M.to_wkt(), transform=Affine.rotation(20.0) * Affine.scale(1, -1))
    with rasterio.open(rotated, "w", **profile) as dst:
        dst.write(np.ones((1, 30, 30), np.float32))
    for source, words in ((rotated, "is rotated"), (tmp_path / "missing.tif", "does not exist")):
        assert main([command, str(source), "--out", str(tmp_path / "out.tif")]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and words in lines[0], lines
        assert not (tmp_path / "out.tif").exists()


@pytest.mark.parametrize("command", ["slope", "breakpoints"])
def test_quick_exit_commands_flush_and_keep_exit_codes(dem_file, tmp_path, command):
    """The ``floodmesh`` command ends the quick raster steps without the interpreter's teardown
    (``cli.command``): what they print to a pipe still arrives, the output is complete, and
    the exit codes are those of ``main`` (0 done, 2 a bad input)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    exe = str(Path(sys.executable).parent / "floodmesh")
    source = dem_file
    if command == "breakpoints":
        source = tmp_path / "slope.tif"
        slope_file(dem_file, source, "sharpnack-akin")
    out = tmp_path / "out.tif"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # stdout buffered
    done = subprocess.run([exe, command, str(source), "--out", str(out)], capture_output=True,
                          text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr
    assert f"written to {out}" in done.stdout
    if command == "slope":
        expected = slope(io.read_raster(dem_file), "one-over-distance").values
        assert_array_equal(io.read_raster(out).values, expected.astype(np.float32))
    else:
        from floodmesh.core.options import RunOptions

        breakpoints_file(source, tmp_path / "again.tif", s_crit=RunOptions().s_crit)
        with rasterio.open(out) as a, rasterio.open(tmp_path / "again.tif") as b:
            assert_array_equal(a.read(1), b.read(1))
    bad = subprocess.run([exe, command, str(tmp_path / "missing.tif"), "--out", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "does not exist" in bad.stderr


def _dem_in(path, crs):
    """A small nodata-tagged float32 DEM in ``crs`` (any GDAL user input)."""
    z = rough_dem(rows=40, cols=50).values.astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", height=40, width=50, count=1,
                       dtype="float32", crs=crs, transform=Affine(0.5, 0, 400, 0, -0.5, 900),
                       nodata=-9999.0) as dst:
        dst.write(np.where(np.isnan(z), -9999.0, z), 1)
    return path


@pytest.mark.parametrize("crs", ["EPSG:25832", "EPSG:25832+5783"])
def test_streamed_slope_keeps_a_metric_crs(tmp_path, crs):
    """The streaming steps pass the file's CRS through as WKT (pyproj only where GDAL does not
    call it a plain projected CRS in metres): the output has the input's CRS."""
    dem = _dem_in(tmp_path / "dem.tif", crs)
    slope_file(dem, tmp_path / "s.tif", "sharpnack-akin")
    with rasterio.open(dem) as a, rasterio.open(tmp_path / "s.tif") as b:
        assert b.crs == a.crs


@pytest.mark.parametrize("crs", ["EPSG:2272", "EPSG:4326", "EPSG:25832+6360"])
def test_streamed_slope_refuses_a_crs_not_in_metres_as_reading_does(tmp_path, crs):
    """Feet, degrees, or elevations in feet: the same one-line error as reading the raster,
    and no output."""
    dem = _dem_in(tmp_path / "dem.tif", crs)
    with pytest.raises(FloodMeshError) as read:
        io.read_raster(dem)
    with pytest.raises(FloodMeshError) as streamed:
        slope_file(dem, tmp_path / "s.tif", "sharpnack-akin")
    assert str(streamed.value) == str(read.value)
    assert not (tmp_path / "s.tif").exists()


def test_slope_files_say_what_they_hold_and_breakpoints_take_them_so(dem_file, tmp_path):
    """The slope step tags its GeoTIFF as a slope (degrees) or a LoG response (m), which QGIS
    and gdalinfo show and the breakpoints step reads: a LoG response read as degrees gave 0
    breakpoints without a word. A slope without the tag (gdaldem slope's) is taken as degrees."""
    slope_file(dem_file, tmp_path / "s.tif")
    laplacian_of_gaussian_file(dem_file, tmp_path / "log.tif", 1.0)
    for name, tag, description, unit in (("s.tif", "slope", "slope", "degree"),
                                         ("log.tif", "log", "Laplacian-of-Gaussian response",
                                          "m")):
        with rasterio.open(tmp_path / name) as src:
            assert src.tags()["FLOODMESH_QUANTITY"] == tag
            assert src.descriptions == (description,) and src.units == (unit,)
    bp = tmp_path / "bp.tif"
    with pytest.raises(FloodMeshError, match=r"raster log.tif holds a Laplacian-of-Gaussian "
                       r"response in metres, .* not a slope in degrees: give its LoG sensitivity"):
        breakpoints_file(tmp_path / "log.tif", bp, s_crit=10.0)
    for log_options in ({"sensitivity": 0.02}, {"s_crit": 10.0, "zero_crossings": True}):
        with pytest.raises(FloodMeshError, match=r"raster s.tif holds a slope in degrees, .* not "
                           r"a Laplacian-of-Gaussian response in metres: leave out"):
            breakpoints_file(tmp_path / "s.tif", bp, **log_options)
    assert not bp.exists()
    assert breakpoints_file(tmp_path / "log.tif", bp, sensitivity=0.02) > 20
    slope_values = io.read_raster(tmp_path / "s.tif", elevations=False)
    io.write_raster(tmp_path / "gdaldem.tif", slope_values)  # no tag
    assert (breakpoints_file(tmp_path / "gdaldem.tif", tmp_path / "bp2.tif", s_crit=10.0)
            == breakpoints_file(tmp_path / "s.tif", bp, s_crit=10.0) > 20)


def test_a_slope_raster_is_refused_where_a_dem_belongs(dem_file, tmp_path, capsys):
    """A slope the slope step wrote, given where a DEM belongs (mesh, slope, run, or left among
    DEM tiles by an earlier run), was taken as ground: a mesh of degrees, exit 0."""
    import shutil

    from floodmesh.core.frontends.cli import main

    slope = tmp_path / "slope.tif"
    slope_file(dem_file, slope)
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    shutil.copy(dem_file, tiles / "dem.tif")
    shutil.copy(slope, tiles / "slope.tif")
    out = tmp_path / "out"
    for args, name in ((["mesh", slope, "--out", out / "m.2dm"], "raster slope.tif"),
                       (["slope", slope, "--out", out / "s.tif"], "raster slope.tif"),
                       (["run", slope, "--out", out], "raster slope.tif"),
                       (["run", tiles, "--out", out], "tile slope.tif")):
        assert main([str(a) for a in args]) == 2, args
        assert (f"{name} holds a slope in degrees, as FloodMesh's slope step wrote it, not "
                "elevations") in capsys.readouterr().err
        assert not out.exists()


def test_breaklines_given_the_slope_and_breakpoints_swapped_is_refused(dem_file, tmp_path,
                                                                      capsys):
    """The breakpoints raster and the slope given the wrong way round (breaklines SLOPE --slope
    BREAKPOINTS) traced lines along slope values of exactly 1 degree, exit 0: the breakpoints
    step tags its raster too, and each is refused where the other belongs."""
    from floodmesh.core.frontends.cli import main

    slope, points = tmp_path / "slope.tif", tmp_path / "bp.tif"
    slope_file(dem_file, slope)
    breakpoints_file(slope, points, s_crit=10.0)
    out = tmp_path / "lines.gpkg"
    for given, says in (
            ((slope, points, dem_file), "raster slope.tif holds a slope in degrees, as "
             "FloodMesh's slope step wrote it, not breakpoints"),
            ((points, points, dem_file), "raster bp.tif holds breakpoints"),
            ((points, slope, points), "raster bp.tif holds breakpoints")):
        breakpoints, slope_given, dem = map(str, given)
        assert main(["breaklines", breakpoints, "--slope", slope_given, "--dem", dem,
                     "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err, err
        assert not out.exists()
    assert main(["breaklines", str(points), "--slope", str(slope), "--dem", str(dem_file),
                 "--out", str(out)]) == 0


def test_breaklines_refuses_breakpoints_of_other_values_than_0_and_1(dem_file, tmp_path, capsys):
    """A DEM (or another program's slope, untagged) given as the breakpoints traced lines where
    a cell happened to hold exactly 1, exit 0."""
    from floodmesh.core.frontends.cli import main

    slope = tmp_path / "slope.tif"
    slope_file(dem_file, slope)
    out = tmp_path / "lines.gpkg"
    assert main(["breaklines", str(dem_file), "--slope", str(slope), "--dem", str(dem_file),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "raster dem.tif holds values other than 0 and 1 (such as " in err
    assert "it is no breakpoints raster: give the slope's breakpoints" in err
    assert not out.exists()


def test_a_file_whose_name_holds_brackets_is_one_file_not_tiles(dem_file, tmp_path, capsys):
    """An existing file named with glob characters ("slope [1].tif") is the file, not a pattern:
    it was run as DEM tiles, its error naming a tile and telling to take it out of the tiles."""
    from floodmesh.core.frontends.cli import main

    slope = tmp_path / "slope [1].tif"
    slope_file(dem_file, slope)
    assert main(["run", str(slope), "--out", str(tmp_path / "out")]) == 2
    assert ("floodmesh: error: raster slope [1].tif holds a slope in degrees, as FloodMesh's "
            "slope step wrote it, not elevations: give the DEM") in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_run_s_other_rasters_left_among_dem_tiles_are_refused_by_tag_or_name(tmp_path,
                                                                                capsys):
    """A run on two DEM tiles, then its rasters left in the tile folder (a copy of the run
    folder's files, or a run of an older FloodMesh, which tagged none). The next run on the
    folder read breakpoints.tif (0s and 1s) as a DEM tile, ended 0 and meshed a terrain of
    breakpoints. Every raster FloodMesh writes now says what it holds (the DEM that it is
    elevations); those that are not elevations are refused among DEM tiles, by their tag, or
    untagged by the names FloodMesh gives them, all named in one line, before any output."""
    import shutil

    from floodmesh.core.frontends.cli import main

    from ..bad_inputs import ORIGIN, slope_dem, write_tif

    tiles = tmp_path / "tiles"
    tiles.mkdir()
    write_tif(tiles / "west.tif", slope_dem())
    write_tif(tiles / "east.tif", slope_dem(),
              transform=Affine(1.0, 0.0, ORIGIN[0] + 60, 0.0, -1.0, ORIGIN[1] + 60))
    assert main(["run", str(tiles), "--out", str(tmp_path / "first")]) == 0
    quantities = {}
    for name in ("dem.tif", "slope.tif", "breakpoints.tif"):
        with rasterio.open(tmp_path / "first" / name) as src:
            quantities[name] = (src.tags().get("FLOODMESH_QUANTITY"), src.descriptions[0])
    assert quantities == {"dem.tif": ("elevation", "elevation"),
                          "slope.tif": ("slope", "slope"),
                          "breakpoints.tif": ("breakpoints", "breakpoints")}
    shutil.copy(tmp_path / "first" / "breakpoints.tif", tiles)
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["run", str(tiles), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["floodmesh: error: tile breakpoints.tif holds breakpoints (1) and other cells "
                   "(0), as FloodMesh's breakpoint step wrote it, not elevations: take it out "
                   "of the DEM tiles (a run's outputs go into a folder beside them)"], err
    assert not out.exists()
    # an older run's, untagged: by their names
    (tiles / "breakpoints.tif").unlink()
    write_tif(tiles / "breakpoints.tif", (slope_dem() > 10).astype(np.uint8))
    write_tif(tiles / "max_depth.tif", np.zeros_like(slope_dem()))
    assert main(["run", str(tiles), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["floodmesh: error: tile breakpoints.tif is named as FloodMesh names "
                   "breakpoints (1) and other cells (0), an earlier run's output; tile "
                   "max_depth.tif is named as FloodMesh names a flood's maximum depth in "
                   "metres, an earlier run's output: take them out of the DEM tiles (a run's "
                   "outputs go into a folder beside them), or rename a tile of elevations so "
                   "named"], err
    assert not out.exists()
    for name in ("breakpoints.tif", "max_depth.tif"):
        (tiles / name).rename(tmp_path / name)
    assert main(["run", str(tiles), "--out", str(out)]) == 0
    # given alone where a DEM belongs
    capsys.readouterr()
    assert main(["mesh", str(tmp_path / "breakpoints.tif"), "--out", str(tmp_path / "m.2dm")]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "floodmesh: error: raster breakpoints.tif is named as FloodMesh names breakpoints (1) and "
        "other cells (0), an earlier run's output: give the DEM (a run's dem.tif), or rename it "
        "if it holds elevations"]
    assert not (tmp_path / "m.2dm").exists()


def test_zero_crossings_without_a_sensitivity_are_refused(dem_file, tmp_path, capsys):
    """Zero crossings are the LoG response's, at least its sensitivity apart: asked for without
    a sensitivity, on a raster without FloodMesh's tag (another tool's LoG response), the
    switch was dropped without a word and the response thresholded as degrees of slope."""
    from floodmesh.core.frontends.cli import main

    laplacian_of_gaussian_file(dem_file, tmp_path / "log.tif", 1.0)
    response = io.read_raster(tmp_path / "log.tif", elevations=False)
    io.write_raster(tmp_path / "other.tif", response.with_values(response.values))  # no tag
    out = tmp_path / "bp.tif"
    assert main(["breakpoints", str(tmp_path / "other.tif"), "--zero-crossings", "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "zero crossings" in err[0] and "--sensitivity" in err[0], err
    assert not out.exists()
