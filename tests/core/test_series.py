"""Scale series (core.chain.series): one mesh per setting on the demo floodplain, the table,
the plot and the meshes agree."""
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from floodmesh.core import io
from floodmesh.core.errors import Cancelled, FloodMeshError
from floodmesh.core.steps.mesh import triangle_areas
from floodmesh.core.options import RunOptions
from floodmesh.core.chain.series import COLUMNS, Setting, run_series, settings_grid

AREAS = (400.0, 100.0, 25.0)


@pytest.fixture(scope="module")
def series_run(demo_points_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("series")
    steps, events = [], []  # the log; the bar's fractions and the log, in the order told

    def log(message):
        steps.append(message)
        events.append(message)

    result = run_series(demo_points_file, out, RunOptions(holdout=0.01),
                        settings_grid(AREAS, "keep-every", (4,)), log=log,
                        progress=events.append)
    return out, result, steps, events


def test_smaller_triangles_give_more_nodes_and_no_larger_error(series_run):
    _, result, steps, _ = series_run
    rows = result["rows"]
    assert [r["max_area_m2"] for r in rows] == list(AREAS)
    assert [s for s in steps if not s.startswith("note: ")] == [f"mesh {r['label']}..."
                                                                for r in rows]
    nodes = [r["nodes"] for r in rows]
    rmse = [r["rmse_m"] for r in rows]
    assert nodes[0] < nodes[1] < nodes[2]
    # monotone within 2 mm: refinement adds nodes bilinear from the DEM
    assert all(b <= a + 0.002 for a, b in zip(rmse, rmse[1:])), rmse
    assert all(0 < r < 0.15 for r in rmse)
    # the same check points for every mesh (a few at the grid's edge fall outside each)
    assert len({r["n_assessed"] for r in rows}) == 1
    assert 0.98 * result["n_holdout"] < rows[0]["n_assessed"] <= result["n_holdout"]


def test_the_bar_moves_along_each_mesh(series_run):
    """`floodmesh series` and run_series tell the bar along each mesh and its assessment, not
    only the tracing: several distinct fractions after each mesh's name, never back, within
    0–1, ending at 1."""
    *_, events = series_run
    fractions = [f for f in events if not isinstance(f, str)]
    assert all(0 <= f <= 1 for f in fractions) and fractions == sorted(fractions), fractions
    assert fractions[-1] == 1.0
    named = [k for k, e in enumerate(events) if isinstance(e, str) and e.startswith("mesh ")]
    assert len(named) == len(AREAS)
    for start, end in zip(named, named[1:] + [len(events)]):
        inside = {f for f in events[start:end] if not isinstance(f, str)}
        assert len(inside) >= 3, (events[start], inside)


def test_cancel_at_a_mesh_stops_the_series_and_writes_nothing(demo_points_file, tmp_path):
    """Cancel pressed as the first mesh begins stops the series there with Cancelled: no
    later mesh is made, and no folder is written."""
    seen = []
    with pytest.raises(Cancelled):
        run_series(demo_points_file, tmp_path / "out", RunOptions(holdout=0.01),
                   settings_grid(AREAS, "keep-every", (4,)), log=seen.append,
                   cancelled=lambda: any(s.startswith("mesh ") for s in seen))
    assert [s for s in seen if s.startswith("mesh ")] == ["mesh a400-k4..."]
    assert list(tmp_path.iterdir()) == []


def test_csv_and_json_agree(series_run):
    out, result, _, _ = series_run
    stored = json.loads((out / "series.json").read_text())
    assert stored == result
    with open(out / "series.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert list(table[0]) == list(COLUMNS)
    assert len(table) == len(stored["rows"])
    for line, row in zip(table, stored["rows"]):
        assert line["label"] == row["label"]
        assert int(line["nodes"]) == row["nodes"] and int(line["triangles"]) == row["triangles"]
        for key in ("rmse_m", "max_abs_m", "share_over_25cm", "max_area_m2"):
            assert float(line[key]) == pytest.approx(row[key], rel=1e-12)
        assert line["nssda_pass"] == str(row["nssda_pass"])


def test_each_mesh_file_has_the_tables_node_count(series_run):
    out, result, _, _ = series_run
    for row in result["rows"]:
        nodes, triangles = io.read_mesh_2dm(out / f"mesh_{row['label']}.2dm")
        assert (len(nodes), len(triangles)) == (row["nodes"], row["triangles"])
        areas = np.abs(triangle_areas(nodes, triangles))
        assert areas.max() <= row["max_area_m2"] * (1 + 1e-9)
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(result["files"])  # nothing else, no temporary file


def test_plot_is_a_png(series_run):
    out, _, _, _ = series_run
    image = imread(out / "series.png")
    assert image.ndim == 3 and image.shape[0] >= 300
    assert len(np.unique((image[:, :, :3] * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 10


def test_settings_grid_and_labels():
    grid = settings_grid([200, 50], "douglas-peucker", [0.5, 2])
    assert [s.label for s in grid] == ["a200-dp0.5", "a200-dp2", "a50-dp0.5", "a50-dp2"]
    assert Setting(100.0).label == "a100-k4"
    for bad in (([], "keep-every", [4]), ([100], "keep-every", []), ([0], "keep-every", [4]),
                ([100], "bezier", [1])):
        with pytest.raises(FloodMeshError):
            settings_grid(*bad)


def test_series_command_with_tolerances(demo_points_file, tmp_path):
    floodmesh = str(Path(sys.executable).parent / "floodmesh")
    out = tmp_path / "s"
    result = subprocess.run([floodmesh, "series", str(demo_points_file), "--out", str(out),
                             "--max-areas", "200", "--tolerances", "0.25,2", "--holdout", "0.01"],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    rows = json.loads((out / "series.json").read_text())["rows"]
    assert [r["label"] for r in rows] == ["a200-dp0.25", "a200-dp2"]
    assert rows[0]["nodes"] > rows[1]["nodes"]  # a tighter tolerance keeps more vertices
    assert "a200-dp2" in result.stdout
    bad = subprocess.run([floodmesh, "series", str(demo_points_file), "--out", str(out),
                          "--max-areas", "0"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2


def test_series_meshes_have_runs_spacing_for_a_flood_model(series_run, demo_points_file,
                                                           tmp_path):
    """Each series mesh gets run's default --min-spacing (the cell size): no sliver at the
    domain edge where detected lines graze it; 0 turns it off, as for run."""
    from floodmesh.core.steps.hydraulics import inradii

    out, result, _, _ = series_run
    plain = run_series(demo_points_file, tmp_path / "plain",
                       RunOptions(holdout=0.01, min_spacing=0),
                       settings_grid(AREAS[:1], "keep-every", (4,)))
    label = result["rows"][0]["label"]
    spaced = io.read_mesh_2dm(out / f"mesh_{label}.2dm")
    unspaced = io.read_mesh_2dm(tmp_path / "plain" / f"mesh_{label}.2dm")
    r_spaced, r_plain = (inradii(nodes, tri) for nodes, tri in (spaced, unspaced))
    assert r_plain.min() < 0.15 <= r_spaced.min()
    assert plain["rows"][0]["nodes"] > result["rows"][0]["nodes"]


def test_series_meshes_carry_their_crs_to_export(tmp_path, capsys):
    """Every 2DM a series writes has its .prj beside it (as run's mesh.2dm): export then needs
    no --crs and gives the DEM's CRS."""
    import fiona
    from pyproj import CRS

    from floodmesh.core.frontends.cli import main

    from .test_mesh import _plane_dem

    dem, out = tmp_path / "dem.tif", tmp_path / "series"
    io.write_raster(dem, _plane_dem())
    assert main(["series", str(dem), "--out", str(out), "--max-areas", "100,50"]) == 0
    for label in ("a100-k4", "a50-k4"):
        wkt = io.read_prj(out / f"mesh_{label}.2dm")
        assert wkt is not None and CRS.from_wkt(wkt) == CRS.from_epsg(25832), label
    capsys.readouterr()
    assert main(["export", str(out / "mesh_a50-k4.2dm"), str(tmp_path / "mesh.gpkg")]) == 0, \
        capsys.readouterr().err
    with fiona.open(tmp_path / "mesh.gpkg") as layer:
        assert CRS.from_user_input(layer.crs_wkt) == CRS.from_epsg(25832)


def test_series_says_the_notes_run_says_each_once(demo_points_file, tmp_path, capsys):
    """floodmesh series says what it assumed or repaired on the user's behalf as run does (a
    row without z left out, the break lines' repairs), on the terminal and in series.json,
    each once: a note of the input as run says it, one that only some meshes say naming
    them."""
    from floodmesh.core.frontends.cli import main

    points = io.read_points(demo_points_file)
    table = tmp_path / "points.csv"
    rows = [f"{x:.3f},{y:.3f},{z:.3f}" for x, y, z in points.xyz]
    table.write_text("x,y,z\n" + "\n".join(rows) + f"\n{points.xyz[0, 0] + 0.1:.3f},1,\n")
    common = ["--crs", "EPSG:25832", "--holdout", "0.01"]
    assert main(["run", str(table), "--out", str(tmp_path / "run"), *common]) == 0
    run_notes = json.loads((tmp_path / "run" / "report.json").read_text())["notes"]
    capsys.readouterr()
    assert main(["series", str(table), "--out", str(tmp_path / "series"), *common,
                 "--max-areas", "200,100", "--keep-every", "2,8"]) == 0
    printed = [line.removeprefix("floodmesh: note: ")
               for line in capsys.readouterr().err.splitlines()
               if line.startswith("floodmesh: note: ")]
    notes = json.loads((tmp_path / "series" / "series.json").read_text())["notes"]
    assert printed == notes and len(set(notes)) == len(notes)
    left_out = [n for n in run_notes if "without a finite x, y and z" in n]
    assert len(left_out) == 1 and left_out[0] in notes
    named = [n for n in notes if n.startswith("mesh")]
    assert named and all(n.startswith("meshes a200-k2, a100-k2: ") for n in named), notes
