"""A flood's scenario at the edges of what it says: boundaries by side on a mesh with holes
(buildings left out, the domain's own), a boundary that covers every edge, hydrographs that end
before the run, observation points off the mesh or never wet. Run as a modeller runs them:
scenario files through the CLI, short real ANUGA runs."""
import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio

from floodmesh.core.flood.model import prepare, scenario_from_dict
from floodmesh.core.options import RESULT_RASTERS
from floodmesh.core.steps.mesh import PSLG, triangulate_pslg

from .test_flood import CRS, X0, Y0, local, needs_anuga, rectangle_mesh


def flood(tmp_path, mesh, scenario: dict, out="out"):
    """``floodmesh flood`` in a child process on ``scenario`` (written beside the mesh):
    (exit code, stderr, report or None)."""
    (tmp_path / "s.json").write_text(json.dumps(scenario))
    done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "flood",
                           str(mesh), "--scenario", str(tmp_path / "s.json"), "--out",
                           str(tmp_path / out), "--crs", CRS], capture_output=True, text=True)
    report = tmp_path / out / "report.json"
    return (done.returncode, done.stderr,
            json.loads(report.read_text()) if report.is_file() else None)


def slope_up_to_the_south(x, y):
    """Ground 2 m at the south edge falling to 0 at the north (20 m): a level of 1 m outside
    the south edge lies below its ground, so nothing may come in there."""
    return 2.0 - 0.1 * y


def write_houses(folder, houses) -> str:
    """Each house as an x,y CSV (one polygon a file, as the Merewether houses come)."""
    folder.mkdir()
    for k, house in enumerate(houses):
        (folder / f"house_{k}.csv").write_text(
            "x,y\n" + "".join(f"{x},{y}\n" for x, y in house))
    return f"{folder.name}/*.csv"


@needs_anuga
def test_side_boundaries_stay_off_the_walls_of_buildings_left_out_as_holes(tmp_path):
    """Buildings as holes: one inside the domain, one across its west edge (a notch in the
    outer ring). A level of 1 m on the south side, whose ground is 2 m, lets nothing in; given
    to the houses' south-facing walls too (the rims facing into the holes), it poured water
    in through them. Outflow on all sides must not open the houses either."""
    mesh = tmp_path / "m.2dm"
    nodes, tri = rectangle_mesh(mesh, 40, 20, slope_up_to_the_south, max_area=2.0)
    houses = write_houses(tmp_path / "houses", [local([[15, 8], [25, 8], [25, 14], [15, 14]]),
                                                 local([[-5, 9], [5, 9], [5, 13], [-5, 13]])])
    scenario = {"duration_s": 10, "output_interval_s": 5,
                "boundaries": [{"kind": "level", "level_m": 1.0, "sides": ["south"]}],
                "buildings": {"polygons": {"file": houses}, "mode": "holes"}}
    rc, err, report = flood(tmp_path, mesh, scenario)
    assert rc == 0, err
    assert abs(report["mass_balance"]["boundary_inflow_volume_m3"]) < 0.01
    assert report["max_depth_m"] < 0.01
    prepared = prepare(nodes, tri, scenario_from_dict(scenario, tmp_path))
    assert _tagged_midpoints(prepared, "level_1")[:, 1] == pytest.approx(Y0)  # the south edge
    every = {"duration_s": 10, "boundaries": [{"kind": "outflow", "sides": ["all"]}],
             "buildings": scenario["buildings"]}
    outflow = _tagged_midpoints(prepare(nodes, tri, scenario_from_dict(every, tmp_path)),
                                "outflow_1") - (X0, Y0)
    on_rectangle = (np.isclose(outflow[:, 0], 0) | np.isclose(outflow[:, 0], 40)
                    | np.isclose(outflow[:, 1], 0) | np.isclose(outflow[:, 1], 20))
    assert on_rectangle.all()


def test_sides_pick_the_outer_boundary_not_the_rim_of_a_hole_in_the_mesh(tmp_path):
    """A mesh with a hole of its own (an island or a building its domain left out): outflow
    on all sides opens the outer boundary only; the hole's rim stays a wall. A line picks the
    rim where a modeller wants it open."""
    corners = local([[0, 0], [40, 0], [40, 20], [0, 20]])
    hole = local([[15, 8], [25, 8], [25, 14], [15, 14]])
    ring = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    xy, tri = triangulate_pslg(PSLG(np.array(corners + hole), np.vstack([ring, ring + 4]),
                                    np.array(local([[20, 11]]))), min_angle=25, max_area=2.0)
    nodes = np.column_stack([xy, np.zeros(len(xy))])
    scenario = scenario_from_dict({"duration_s": 10, "boundaries": [
        {"kind": "outflow", "sides": ["all"]},
        {"kind": "level", "level_m": 1, "line": [hole[0], hole[1]], "snap_m": 0.1}]})
    prepared = prepare(nodes, tri, scenario)
    outflow = _tagged_midpoints(prepared, "outflow_1") - (X0, Y0)
    assert ((outflow[:, 0] < 1e-6) | (outflow[:, 0] > 40 - 1e-6) | (outflow[:, 1] < 1e-6)
            | (outflow[:, 1] > 20 - 1e-6)).all()
    assert _tagged_midpoints(prepared, "level_2")[:, 1] == pytest.approx(Y0 + 8)
    assert prepared["boundary_edges"]["wall"] > 0  # the rest of the rim


def _tagged_midpoints(prepared, tag):
    """The midpoints (x, y) of the boundary edges tagged ``tag``."""
    arrays = prepared["arrays"]
    edges = arrays["boundary_edges"]
    pick = edges[edges[:, 2] == prepared["job"]["boundary_tags"].index(tag)]
    tri = arrays["triangles"][pick[:, 0]]
    rows = np.arange(len(pick))
    a = arrays["nodes"][tri[rows, (pick[:, 1] + 1) % 3], :2]
    b = arrays["nodes"][tri[rows, (pick[:, 1] + 2) % 3], :2]
    assert len(pick), f"no edge tagged {tag}"
    return (a + b) / 2


@needs_anuga
def test_a_wall_on_all_sides_runs_as_a_closed_basin(tmp_path):
    """{"kind": "wall", "sides": ["all"]} leaves no edge to the default walls: ANUGA refused
    the unused tag ('Tag "wall" provided does not exist'). It is a closed basin: still water
    stays. A boundary that later ones override everywhere is said to do nothing."""
    mesh = tmp_path / "m.2dm"
    rectangle_mesh(mesh, 30, 10, lambda x, y: 0.02 * x, max_area=2.0)
    rc, err, report = flood(tmp_path, mesh, {
        "duration_s": 10, "output_interval_s": 5, "initial_stage_m": 0.5,
        "boundaries": [{"kind": "outflow", "sides": ["all"]}, {"kind": "wall", "sides": ["all"]}]})
    assert rc == 0, err
    assert report["boundary_edges"] == {"wall_2": report["boundary_edges"]["wall_2"]}
    assert report["max_speed_ms"] < 1e-3
    assert report["mass_balance"]["outflow_volume_m3"] == pytest.approx(0, abs=1e-9)
    assert "the outflow boundary 1 is overridden on all its edges" in err


@needs_anuga
def test_an_inflow_hydrograph_that_ends_before_the_run_is_held_at_its_last_value(tmp_path):
    """A hydrograph of 1 then 2 m³/s over the first 10 s of a 20 s run, into a walled basin:
    held at 2 m³/s, as a level hydrograph is held, it brings 15 + 20 = 35 m³ (it dropped to 0
    and brought 15), and a note says it was held; so does one for a level series."""
    mesh = tmp_path / "m.2dm"
    rectangle_mesh(mesh, 40, 20, lambda x, y: 0.005 * x, max_area=2.0)
    rc, err, report = flood(tmp_path, mesh, {
        "duration_s": 20, "output_interval_s": 10,
        "inflows": [{"circle": {"centre": [X0 + 10, Y0 + 10], "radius": 3},
                     "hydrograph": [[0, 1], [10, 2]]}],
        "boundaries": [{"kind": "level", "levels": [[0, -1], [5, -0.5]], "sides": ["west"]}]})
    assert rc == 0, err
    assert report["mass_balance"]["inflow_volume_m3"] == pytest.approx(35, rel=0.03)
    assert ("inflow 1's hydrograph ends at 10 s, before the run's 20 s: held at its last value, "
            "2 m³/s, to the end") in err
    assert "the level boundary 1's levels ends at 5 s" in err


@pytest.mark.parametrize("where, says", [
    ((151.75, -32.94), "observation point X (151.75, -32.94) lies outside the mesh (x 382000 "
                       "to 382030, y 6354000 to 6354010): check its coordinates and CRS"),
    ((X0 + 15, Y0 + 5), f"observation point X ({X0 + 15}, {Y0 + 5}) lies in a building "
                        "left out of the mesh as a hole")])
def test_an_observation_point_off_the_mesh_is_refused_naming_it(tmp_path, where, says):
    """A point outside the mesh (here in degrees, not the mesh's UTM) gave an empty column and
    a null peak with exit 0; one in a building left out as a hole the same."""
    mesh = tmp_path / "m.2dm"
    rectangle_mesh(mesh, 30, 10, lambda x, y: 0 * x, max_area=2.0)
    rc, err, report = flood(tmp_path, mesh, {
        "duration_s": 10, "observation_points": [{"name": "X", "x": where[0], "y": where[1]}],
        "buildings": {"polygons": [local([[12, 3], [18, 3], [18, 7], [12, 7]])],
                      "mode": "holes"}})
    assert rc == 2 and err.count("\n") == 1
    assert says in err
    assert not (tmp_path / "out").exists()


@needs_anuga
def test_a_point_the_water_never_reaches_is_dry_not_its_ground_as_peak_stage(tmp_path):
    """An inflow at the low end of a sloping basin (ground at a real town's 23 to 27 m) and a
    point up the slope it never reaches: its peak stage was its ground level, read as a water
    level; now it is dry (no stage, peak depth 0, its ground given), blank in
    observations.csv, and a note says so. Where ANUGA leaves round-off (1e-15 m) over dry
    ground, the max water level map has no level either (it had one: the ground)."""
    mesh = tmp_path / "m.2dm"
    rectangle_mesh(mesh, 40, 10, lambda x, y: 23.4792 + 0.1 * x + 0.01 * y, max_area=2.0)
    rc, err, report = flood(tmp_path, mesh, {
        "duration_s": 20, "output_interval_s": 10,
        "inflows": [{"circle": {"centre": [X0 + 3, Y0 + 5], "radius": 2.5}, "discharge_m3s": 0.5}],
        "observation_points": [{"name": "low", "x": X0 + 2, "y": Y0 + 5},
                               {"name": "high", "x": X0 + 35, "y": Y0 + 5}]})
    assert rc == 0, err
    low, high = report["observations"]
    assert not low["dry"] and low["peak_depth_m"] > 0.05
    assert low["peak_stage_m"] == pytest.approx(low["ground_m"] + low["peak_depth_m"], abs=0.05)
    assert high["dry"] and high["peak_stage_m"] is None and high["peak_depth_m"] == 0
    assert high["ground_m"] == pytest.approx(27.0, abs=0.2)
    assert "observation point high stays dry (ground 27.0" in err
    rows = (tmp_path / "out" / "observations.csv").read_text().splitlines()
    assert rows[0] == "time_s,stage_low,stage_high,depth_low,depth_high"
    assert all(row.split(",")[2] == "" and float(row.split(",")[4]) == 0 for row in rows[1:])
    with rasterio.open(tmp_path / "out" / RESULT_RASTERS["max_stage"]) as src:
        level = src.read(1, masked=True)
    with rasterio.open(tmp_path / "out" / RESULT_RASTERS["max_depth"]) as src:
        depth = src.read(1, masked=True)
    assert level.count() > 0 and (depth[~level.mask] >= 1e-3).all()
