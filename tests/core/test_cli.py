"""The floodmesh command as scripts use it: the whole chain, each step, errors and Ctrl-C."""
import argparse
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rasterio

from floodmesh.core import io
from floodmesh.core.chain.pipeline import OUTPUT_FILES

FLOODMESH = str(Path(sys.executable).parent / "floodmesh")


def floodmesh(*args, check=True):
    result = subprocess.run([FLOODMESH, *map(str, args)], capture_output=True, text=True,
                            timeout=600)
    if check:
        assert result.returncode == 0, result.stderr
    return result


def test_demo_writes_every_output_and_meets_the_bounds(tmp_path):
    out = tmp_path / "demo"
    floodmesh("demo", "--out", out)
    for name in OUTPUT_FILES:
        assert (out / name).stat().st_size > 0, name
    report = json.loads((out / "report.json").read_text())
    assert report["min_angle_deg"] >= 25.0 - 1e-6
    assert report["max_area_m2"] <= 100.0
    assert report["n_below_min_angle"] == 0 and report["n_above_max_area"] == 0
    # 9 points/m² over 300 x 240 m, 0.1 % held out
    assert report["n_holdout"] == round(0.001 * 9 * 300 * 240)
    assert report["rmse_m"] < 0.10 and report["classes"]["<10 cm"] > 0.75
    assert set(report["seconds"]) >= {"grid", "slope", "breakpoints", "breaklines", "mesh"}
    nodes, triangles = io.read_mesh_2dm(out / "mesh.2dm")
    assert (len(nodes), len(triangles)) == (report["nodes"], report["triangles"])


def test_each_step_as_its_own_command(demo_points_file, tmp_path):
    t = tmp_path
    floodmesh("grid", demo_points_file, "--cell-size", 1, "--out", t / "dem.tif",
              "--holdout", 0.01, "--seed", 3)
    assert (t / "holdout.gpkg").exists()
    floodmesh("slope", t / "dem.tif", "--method", "sharpnack-akin", "--out", t / "slope.tif")
    floodmesh("breakpoints", t / "slope.tif", "--s-crit", 10, "--out", t / "bp.tif")
    floodmesh("breaklines", t / "bp.tif", "--slope", t / "slope.tif", "--dem", t / "dem.tif",
              "--out", t / "lines.gpkg")
    floodmesh("simplify", t / "lines.gpkg", "--tolerance", 0.9, "--out", t / "simple.gpkg")
    floodmesh("mesh", t / "dem.tif", "--breaklines", t / "simple.gpkg", "--min-angle", 28,
              "--max-area", 50, "--out", t / "mesh.2dm", "--gpkg", t / "mesh.gpkg")
    stats = json.loads(floodmesh("assess", t / "mesh.2dm", "--points", t / "holdout.gpkg",
                                 "--out", t / "res.gpkg", "--png", t / "pics").stdout)
    for name in ("residual_histogram.png", "residual_map.png"):
        assert (t / "pics" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    traced, simple = io.read_lines_gpkg(t / "lines.gpkg"), io.read_lines_gpkg(t / "simple.gpkg")
    assert len(traced) == len(simple) > 10
    assert sum(map(len, simple)) < sum(map(len, traced))
    nodes, triangles = io.read_mesh_2dm(t / "mesh.2dm")
    from floodmesh.core.steps.mesh import triangle_angles, triangle_areas
    assert triangle_angles(nodes, triangles).min() >= 28 - 1e-6
    assert triangle_areas(nodes, triangles).max() <= 50
    assert stats["n_holdout"] == round(0.01 * 2 * 300 * 240)
    assert 0 < stats["rmse_m"] < 0.15


@pytest.mark.parametrize("args, words", [
    (["run", "missing.laz", "--out", "o"], "does not exist"),
    (["run", "{xyz}", "--out", "o"], "--crs"),
    (["run", "{xyz}", "--out", "o", "--crs", "EPSG:4326"], "geographic"),
    (["run", "{xyz}", "--out", "o", "--crs", "EPSG:25832", "--min-angle", "40"], "34"),
    (["run", "{xyz}", "--out", "o", "--crs", "EPSG:25832", "--s-crit", "95"], "S_crit"),
])
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, args, words):
    xyz = tmp_path / "points.xyz"
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 50, 4000), rng.uniform(0, 50, 4000)
    np.savetxt(xyz, np.column_stack([x + 4e5, y + 5.6e6, 0.3 * x]), fmt="%.3f")
    args = [a.format(xyz=xyz) for a in args]
    args[args.index("--out") + 1] = str(tmp_path / "out")
    result = floodmesh(*args, check=False)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("floodmesh: error:") and words in lines[0]
    assert not (tmp_path / "out" / "mesh.2dm").exists()


@pytest.mark.parametrize("delay", [1.5, 3.0, 4.5])
def test_ctrl_c_leaves_no_half_written_file(demo_points_file, tmp_path, delay):
    out = tmp_path / "interrupted"
    proc = subprocess.Popen([FLOODMESH, "run", str(demo_points_file), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode in (0, 130), stderr
    if proc.returncode == 130:
        assert "interrupted" in stderr and "Traceback" not in stderr
    leftovers = [p.name for p in out.glob("*") if ".partial" in p.name] if out.exists() else []
    assert leftovers == []
    # every file that is there is complete: each opens
    if (out / "mesh.2dm").exists():
        io.read_mesh_2dm(out / "mesh.2dm")
    if (out / "dem.tif").exists():
        io.read_raster(out / "dem.tif")


def test_log_breakpoints_through_the_commands_and_the_chain(demo_points_file, tmp_path):
    """LoG as a step (slope --method log, breakpoints --sensitivity) and in the whole chain."""
    t = tmp_path
    floodmesh("grid", demo_points_file, "--cell-size", 1, "--out", t / "dem.tif")
    floodmesh("slope", t / "dem.tif", "--method", "log", "--sigma", 1.5, "--out", t / "log.tif")
    floodmesh("breakpoints", t / "log.tif", "--sensitivity", 0.03, "--out", t / "bp.tif")
    assert np.nansum(io.read_raster(t / "bp.tif").values) > 500
    floodmesh("run", demo_points_file, "--out", t / "run", "--slope-method", "log",
              "--sigma", 1.5, "--sensitivity", 0.03, "--holdout", 0.01)
    report = json.loads((t / "run" / "report.json").read_text())
    assert report["options"]["slope_method"] == "log" and report["n_breaklines"] > 10
    assert report["n_below_min_angle"] == 0 and report["max_area_m2"] <= 100
    with rasterio.open(t / "run" / "slope.tif") as src:  # the slope the tracer followed
        assert src.tags()["FLOODMESH_QUANTITY"] == "slope" and src.units == ("degree",)


def test_tracing_and_simplification_options(demo_points_file, tmp_path):
    """breaklines --min-length/--no-join/--seed and simplify --spline/--min-distance, and the
    chain with --spline: the report names the method and its bound holds."""
    t = tmp_path
    floodmesh("grid", demo_points_file, "--cell-size", 1, "--out", t / "dem.tif")
    floodmesh("slope", t / "dem.tif", "--out", t / "slope.tif")
    floodmesh("breakpoints", t / "slope.tif", "--out", t / "bp.tif")
    common = ["--slope", t / "slope.tif", "--dem", t / "dem.tif"]
    floodmesh("breaklines", t / "bp.tif", *common, "--out", t / "joined.gpkg")
    floodmesh("breaklines", t / "bp.tif", *common, "--no-join", "--out", t / "pieces.gpkg")
    floodmesh("breaklines", t / "bp.tif", *common, "--min-length", 20, "--seed", 5,
              "--out", t / "long.gpkg")
    joined, pieces = io.read_breaklines(t / "joined.gpkg"), io.read_breaklines(t / "pieces.gpkg")
    long_lines = io.read_breaklines(t / "long.gpkg")
    assert len(pieces) > 2 * len(joined)
    assert long_lines and min(line.length for line in long_lines) >= 20
    floodmesh("simplify", t / "joined.gpkg", "--spline", 0.9, "--min-distance", 0.5,
              "--out", t / "smooth.gpkg")
    smooth = io.read_breaklines(t / "smooth.gpkg")
    assert sum(len(x.coords) for x in smooth) < 0.5 * sum(len(x.coords) for x in joined)
    floodmesh("run", demo_points_file, "--out", t / "run", "--spline", 0.9, "--holdout", 0.01)
    report = json.loads((t / "run" / "report.json").read_text())
    assert report["simplification"]["method"] == "spline"
    # within the tolerance, plus the minimum distance (d/2) where lines or vertices merged
    assert report["simplification"]["max_deviation_m"] <= 0.9 + 0.5 + 1e-9
    assert report["n_below_min_angle"] == 0


def test_mesh_and_run_with_a_size_field(demo_points_file, tmp_path):
    """mesh --size-field slope refines steep ground (more nodes, smaller triangles where the
    slope is steep); a size-field raster is honoured; run --size-field slope reports it."""
    from floodmesh.core.steps.mesh import triangle_areas

    t = tmp_path
    floodmesh("grid", demo_points_file, "--cell-size", 1, "--out", t / "dem.tif")
    floodmesh("mesh", t / "dem.tif", "--max-area", 100, "--out", t / "plain.2dm")
    floodmesh("mesh", t / "dem.tif", "--max-area", 100, "--size-field", "slope",
              "--min-area", 4, "--out", t / "sloped.2dm")
    plain, _ = io.read_mesh_2dm(t / "plain.2dm")
    nodes, tris = io.read_mesh_2dm(t / "sloped.2dm")
    assert len(nodes) > 2 * len(plain)
    dem = io.read_raster(t / "dem.tif")
    io.write_raster(t / "size.tif", dem.with_values(np.full(dem.shape, 9.0)))
    floodmesh("mesh", t / "dem.tif", "--max-area", 100, "--size-field", t / "size.tif",
              "--out", t / "sized.2dm")
    nodes, tris = io.read_mesh_2dm(t / "sized.2dm")
    assert triangle_areas(nodes, tris).max() <= 9 * (1 + 1e-9)
    floodmesh("run", demo_points_file, "--out", t / "run", "--size-field", "slope",
              "--holdout", 0.01)
    report = json.loads((t / "run" / "report.json").read_text())
    assert report["options"]["size_field"] == "slope" and report["nodes"] > 1.5 * len(plain)


def test_the_mesh_step_meshes_as_build_mesh_in_qgis(demo_points_file, tmp_path):
    """floodmesh mesh and QGIS's Build mesh (the worker's job as the algorithm sends it, FLOW_AREA
    left empty) give the same mesh: both finer where water flows (23 cells, as run); --flow-area
    0 turns that off as FLOW_AREA 0 does."""
    import io as stdio

    from floodmesh.core.frontends.worker import Channel, run_job

    t = tmp_path
    floodmesh("grid", demo_points_file, "--cell-size", 1, "--out", t / "dem.tif")
    meshes = {}
    for name, flow_area in (("default", None), ("off", 0.0)):
        flag = [] if flow_area is None else ["--flow-area", flow_area]
        floodmesh("mesh", t / "dem.tif", *flag, "--out", t / f"cli_{name}.2dm")
        job = {"step": "build_mesh", "args": {
            "dem": str(t / "dem.tif"), "breaklines": None, "boundary": None, "user_lines": None,
            "min_angle": 25.0, "max_area": 100.0, "size_field": None, "max_triangles": 5_000_000,
            "flow_area": flow_area, "output": str(t / f"qgis_{name}.2dm"), "triangles": None}}
        assert run_job(job, Channel(stdio.StringIO())) == 0
        cli, qgis = (io.read_mesh_2dm(t / f"{who}_{name}.2dm") for who in ("cli", "qgis"))
        assert len(cli[0]) == len(qgis[0]) and np.array_equal(cli[1], qgis[1]), name
        meshes[name] = cli
    assert len(meshes["default"][0]) > 1.5 * len(meshes["off"][0])


def test_run_with_refinement(demo_points_file, tmp_path):
    """run --refine (step 9): the gridded points drive the rounds, the held-out ones are only
    assessed; the holdout error falls and no more held-out residuals exceed 25 cm than without
    refinement; the report lists every round, and a note what the rounds left."""
    floodmesh("run", demo_points_file, "--out", tmp_path / "plain", "--holdout", 0.01)
    floodmesh("run", demo_points_file, "--out", tmp_path / "refined", "--holdout", 0.01,
              "--refine")
    plain = json.loads((tmp_path / "plain" / "report.json").read_text())
    refined = json.loads((tmp_path / "refined" / "report.json").read_text())
    rounds = refined["refinement"]
    # the plain run's one misfit pass: its first mesh, then that mesh split where it misfits
    assert len(plain["refinement"]) == 2 and len(rounds) >= 2
    assert rounds[0]["nodes"] == plain["refinement"][0]["nodes"]
    assert plain["nodes"] == plain["refinement"][1]["nodes"]
    assert refined["nodes"] == rounds[-1]["nodes"]
    assert refined["rmse_m"] == pytest.approx(rounds[-1]["check_rmse_m"])
    assert refined["rmse_m"] < plain["rmse_m"]
    assert refined["classes"][">25 cm"] <= plain["classes"][">25 cm"]
    assert refined["n_below_min_angle"] == 0 and refined["max_area_m2"] <= 100
    # each round's 'inserted' is what its mesh took in: the written mesh's nodes at survey points
    # (before, the points tried: 449 for a last round 2 nodes larger on Topography.laz)
    from floodmesh.core.points import at_places_of

    nodes, _ = io.read_mesh_2dm(tmp_path / "refined" / "mesh.2dm")
    survey = io.read_points(demo_points_file).xyz
    assert at_places_of(nodes, survey).sum() == sum(r["inserted"] for r in rounds) > 0
    # gridded points left over the upper bound (13 on the demo) are said, with why
    assert rounds[-1]["max_abs_m"] > 0.25 and any(
        note.startswith("the refinement stopped with ") and "upper bound (0.25 m)" in note
        for note in refined["notes"])
    bad = floodmesh("run", demo_points_file, "--out", tmp_path / "bad", "--refine",
                    "--lower", 0.3, "--upper", 0.2, check=False)
    assert bad.returncode == 2 and "lower bound" in bad.stderr


PARAMETERS_MD = Path(__file__).resolve().parents[2] / "docs" / "parameters.md"


def _documented(command: str, page: str) -> str:
    """The part of docs/parameters.md that lists ``command``'s options: the chain's table for
    run, series and demo, else the step commands' row of ``floodmesh COMMAND``."""
    if command in ("run", "series", "demo"):
        return page.split("## The chain", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(rf"^\| `floodmesh {command}\b.*$", page, re.M)
    assert rows, f"docs/parameters.md has no row for floodmesh {command}"
    return rows[0]


def test_the_parameters_page_lists_every_option_of_every_command():
    """docs/parameters.md, the page of every option, names each option `floodmesh COMMAND
    --help` lists where that command's options are: a new option (--skip-unreadable-tiles of
    run, series and grid was missed) fails here until it is documented."""
    from floodmesh.core.frontends.cli import build_parser

    page = PARAMETERS_MD.read_text(encoding="utf-8")
    commands = next(a for a in build_parser()._actions
                    if isinstance(a, argparse._SubParsersAction)).choices
    missing = [f"{command} {option}" for command, parser in commands.items()
               for action in parser._actions for option in action.option_strings
               if option.startswith("--") and option != "--help"
               and not re.search(rf"`{re.escape(option)}[` ]", _documented(command, page))]
    assert not missing, f"not in docs/parameters.md: {', '.join(missing)}"


def test_a_dem_run_holds_its_check_cells_out_of_the_dem(tmp_path):
    """A DEM has no points to hold back: its check cells are taken out of the DEM the run
    builds from (dem.tif has them filled from their neighbours), so the RMSE is measured where
    the mesh never saw the data; with --holdout 0 nothing is assessed (no cells drawn)."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.raster import Grid

    rows, cols = 80, 100
    x = np.arange(cols)[None, :]
    # a noisy plane: no cell's z follows from its neighbours'
    z = 10 + 0.02 * x + np.random.default_rng(0).normal(0, 0.05, (rows, cols))
    io.write_raster(tmp_path / "in.tif", Grid(z, Affine(1, 0, 500_000, 0, -1, 6_000_100),
                                              CRS.from_epsg(32632)))
    given = io.read_raster(tmp_path / "in.tif").values
    said = floodmesh("run", tmp_path / "in.tif", "--out", tmp_path / "r", "--holdout", 0.01,
                     "--max-area", 20)
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["n_holdout"] == 80 and f"on {report['n_assessed']} points" in said.stdout
    check = io.read_points_vector(tmp_path / "r" / "residuals.gpkg")
    r = np.floor(6_000_100 - check[:, 1]).astype(int)
    c = np.floor(check[:, 0] - 500_000).astype(int)
    np.testing.assert_allclose(check[:, 2], given[r, c])  # the DEM's own z is the check
    built = io.read_raster(tmp_path / "r" / "dem.tif").values
    assert (np.abs(built[r, c] - given[r, c]) > 1e-4).all()  # ... which the run never used
    # filled as the midpoint of the opposite neighbours that differ least (along a bank)
    pairs = np.array([(given[r + dr, c + dc], given[r - dr, c - dc])
                      for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1))])
    steady = np.argmin(np.abs(pairs[:, 0] - pairs[:, 1]), axis=0)
    midpoint = pairs[steady, :, np.arange(len(r))].mean(axis=1)
    alone = [not any(abs(r[i] - r[j]) <= 1 and abs(c[i] - c[j]) <= 1
                     for j in range(len(r)) if j != i) for i in range(len(r))]
    np.testing.assert_allclose(built[r, c][alone], midpoint[alone], atol=1e-5)
    untouched = np.ones(given.shape, bool)
    untouched[r, c] = False
    np.testing.assert_allclose(built[untouched], given[untouched], atol=1e-5)

    said = floodmesh("run", tmp_path / "in.tif", "--out", tmp_path / "r0", "--holdout", 0,
                     "--max-area", 20)
    report = json.loads((tmp_path / "r0" / "report.json").read_text())
    assert report["n_holdout"] == 0 and report["rmse_m"] is None
    assert "not assessed: no check points were held out" in said.stdout
    np.testing.assert_allclose(io.read_raster(tmp_path / "r0" / "dem.tif").values, given,
                               atol=1e-5)


def test_a_rewritten_raster_shows_its_own_statistics_not_the_old_files(tmp_path):
    """A slope opened in QGIS (or gdalinfo -stats), which writes its statistics to
    slope.tif.aux.xml, then rewritten as the LoG response: GDAL and QGIS read the new file's
    statistics, not the old file's left beside it."""
    from affine import Affine
    from osgeo import gdal
    from rasterio.crs import CRS

    from floodmesh.core.raster import Grid

    dem = tmp_path / "dem.tif"
    x = np.arange(40.0)
    io.write_raster(dem, Grid(np.add.outer(0.3 * x, 0.1 * x ** 1.5),
                              Affine(1, 0, 500_000, 0, -1, 6_000_040), CRS.from_epsg(32756)))
    slope = tmp_path / "slope.tif"
    floodmesh("slope", dem, "--out", slope)
    gdal.Info(str(slope), stats=True)  # as QGIS does on loading it: the .aux.xml is written
    assert (tmp_path / "slope.tif.aux.xml").exists()
    floodmesh("slope", dem, "--method", "log", "--out", slope)
    with rasterio.open(slope) as src:
        values = src.read(1, masked=True)
    shown = gdal.Info(str(slope), stats=True, format="json")["bands"][0]
    assert shown["minimum"] == pytest.approx(float(values.min()), abs=2e-3)
    assert shown["maximum"] == pytest.approx(float(values.max()), abs=2e-3)


def test_a_dem_too_thin_for_check_cells_says_why_it_is_not_assessed(tmp_path):
    """A check cell must have data all round (it is filled from its neighbours): a DEM of a band
    two cells wide has none, and the run said 'no check points were held out' though
    --holdout asked for them, and nothing said why."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.raster import Grid

    z = np.full((40, 40), np.nan)
    z[:2, :] = z[-2:, :] = z[:, :2] = z[:, -2:] = 10.0
    io.write_raster(tmp_path / "ring.tif", Grid(z, Affine(1, 0, 500_000, 0, -1, 6_000_100),
                                                CRS.from_epsg(32632)))
    said = floodmesh("run", tmp_path / "ring.tif", "--out", tmp_path / "r", "--holdout", 0.01)
    assert ("0 of the 30 check cells asked (holdout 0.01) could be held out of the DEM: a check "
            "cell needs data in its eight neighbours, to be filled from them, and no cell has "
            "it: the mesh is not assessed") in said.stderr
