"""A flood on the mesh: real, small, short ANUGA runs (a few thousand triangles, 60–120 s
simulated) checked against physics: still water stays still, a steady inflow down a wide
channel reaches Manning's normal depth, volumes balance; and the scenario's pieces (inflow
hydrograph into a region, outflow, walls, roughness polygons, buildings raised or as holes)
do what they say."""
import gzip
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import fiona
import numpy as np
import pytest
import rasterio

from floodmesh.core import io
from floodmesh.core.engine.arrays import spatial_order
from floodmesh.core.errors import Cancelled, FloodMeshError
from floodmesh.core.flood.model import (flood_python, load_scenario, prepare, run_flood,
                                        scenario_from_dict)
from floodmesh.core.options import RESULT_RASTERS
from floodmesh.core.steps.mesh import PSLG, triangulate_pslg

DATA = Path(__file__).parent.parent / "data"
CRS = "EPSG:32756"
X0, Y0 = 382_000.0, 6_354_000.0

needs_anuga = pytest.mark.skipif(flood_python() is None,
                                 reason="ANUGA is not installed (make setup builds .venv-flood)")


def rectangle_mesh(path, length, width, z_of, max_area=1.0):
    """A length × width m rectangle at UTM coordinates meshed by Triangle (25°), node z from
    ``z_of(local x, local y)``, written as 2DM; returns (nodes, triangles)."""
    corners = np.array([[0, 0], [length, 0], [length, width], [0, width]], float) + (X0, Y0)
    xy, tri = triangulate_pslg(PSLG(corners, np.array([[0, 1], [1, 2], [2, 3], [3, 0]]),
                                    np.empty((0, 2))), min_angle=25.0, max_area=max_area)
    nodes = np.column_stack([xy, z_of(xy[:, 0] - X0, xy[:, 1] - Y0)])
    io.write_mesh_2dm(path, nodes, tri)
    return nodes, tri


def local(points):
    return [[x + X0, y + Y0] for x, y in points]


@needs_anuga
def test_still_water_stays_still_over_a_bumpy_bed(tmp_path):
    """A lake at rest (level 0.3 m over bumps up to 0.5 m, so with dry islands) behind walls:
    nothing may move (ANUGA's DE0 is well balanced)."""
    mesh = tmp_path / "lake.2dm"
    rectangle_mesh(mesh, 60, 30, lambda x, y: 0.25 + 0.25 * np.sin(x / 5) * np.cos(y / 4))
    scenario = scenario_from_dict({"duration_s": 60, "output_interval_s": 10,
                                   "initial_stage_m": 0.3,
                                   "observation_points": [{"name": "a", "x": X0 + 30,
                                                           "y": Y0 + 15}]})
    report = run_flood(mesh, scenario, tmp_path / "out", crs=CRS)
    assert report["max_speed_ms"] < 1e-3
    stage = np.loadtxt(tmp_path / "out" / "observations.csv", delimiter=",", skiprows=1)
    assert np.abs(stage[:, 1] - stage[0, 1]).max() < 1e-4
    assert report["mass_balance"]["inflow_volume_m3"] == 0
    assert abs(report["mass_balance"]["final_volume_m3"]
               - report["mass_balance"]["initial_volume_m3"]) < 1e-6 * report[
                   "mass_balance"]["initial_volume_m3"]


@needs_anuga
def test_steady_inflow_down_a_wide_channel_reaches_mannings_normal_depth(tmp_path):
    """2 m³/s across the top of a 100 × 20 m channel at slope 0.02, n = 0.03, outflow at its
    foot: after 120 s the flow is steady at the normal depth h = (q·n/√S)^(3/5) = 0.099 m and
    the outflow equals the inflow; the volumes balance to round-off."""
    mesh = tmp_path / "channel.2dm"
    nodes, tri = rectangle_mesh(mesh, 100, 20, lambda x, y: 0.02 * (100 - x))
    scenario = scenario_from_dict({
        "duration_s": 120, "output_interval_s": 5, "manning": 0.03,
        "inflows": [{"line": local([[1, 0.5], [1, 19.5]]), "discharge_m3s": 2.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}],
        "observation_points": [{"name": "lower", "x": X0 + 75, "y": Y0 + 10}]})
    report = run_flood(mesh, scenario, tmp_path / "out", crs=CRS)
    normal_depth = (2.0 / 20 * 0.03 / np.sqrt(0.02)) ** 0.6
    depth = report["observations"][0]["peak_stage_m"] - 0.02 * 25
    assert depth == pytest.approx(normal_depth, rel=0.10)
    hydrograph = np.loadtxt(tmp_path / "out" / "hydrograph.csv", delimiter=",", skiprows=1)
    assert hydrograph[0, 1] == pytest.approx(0, abs=1e-9)   # nothing out before it arrives
    assert hydrograph[-1, 1] == pytest.approx(2.0, rel=0.05)
    balance = report["mass_balance"]
    assert balance["inflow_volume_m3"] == pytest.approx(240.0, rel=1e-6)
    assert abs(balance["relative_error"]) < 1e-6
    assert report["boundary_edges"]["outflow_1"] > 0
    # the rasters: the mesh's CRS, arrival later downstream, dry where nothing came
    with rasterio.open(tmp_path / "out" / RESULT_RASTERS["arrival_s"]) as src:
        assert src.crs.to_epsg() == 32756
        arrival = src.read(1, masked=True)
        row = src.index(X0 + 50, Y0 + 10)[0]
        cols = [src.index(X0 + x, Y0 + 10)[1] for x in (10, 50, 90)]
    times = [float(arrival[row, c]) for c in cols]
    assert times[0] < times[1] < times[2]
    with rasterio.open(tmp_path / "out" / RESULT_RASTERS["max_depth"]) as src:
        depth_grid = src.read(1, masked=True)
    assert 0.05 < float(depth_grid.max()) < 1.0
    assert report["hydraulics"]["min_inradius_m"] > 0.1


@needs_anuga
def test_hydrograph_into_a_region_fills_a_closed_basin_by_its_volume(tmp_path):
    """A triangular hydrograph (peak 1 m³/s at 30 s, over by 60 s: 30 m³) into a circle in a
    walled basin: the basin holds exactly that; a raised building next to the inflow stays
    dry on top; a rough polygon is read."""
    mesh = tmp_path / "basin.2dm"
    rectangle_mesh(mesh, 50, 30, lambda x, y: 0.005 * x, max_area=1.5)
    (tmp_path / "q.csv").write_text("time_s,discharge_m3s\n0,0\n30,1\n60,0\n")
    house = local([[20, 10], [26, 10], [26, 18], [20, 18]])
    scenario = load_scenario(_write(tmp_path / "scenario.json", {
        "duration_s": 90, "output_interval_s": 10,
        "inflows": [{"circle": {"centre": [X0 + 8, Y0 + 15], "radius": 3},
                     "hydrograph": "q.csv"}],
        "roughness": [{"polygons": [local([[30, 0], [50, 0], [50, 30], [30, 30]])],
                       "manning": 0.1}],
        "buildings": {"polygons": [house], "mode": "raised", "height_m": 3},
        "observation_points": [{"name": "roof", "x": X0 + 23, "y": Y0 + 14}]}))
    report = run_flood(mesh, scenario, tmp_path / "out", crs=CRS)
    balance = report["mass_balance"]
    assert balance["inflow_volume_m3"] == pytest.approx(30.0, rel=0.02)
    assert balance["final_volume_m3"] == pytest.approx(balance["inflow_volume_m3"], rel=1e-6)
    assert balance["outflow_volume_m3"] == pytest.approx(0, abs=1e-9)  # all walls
    roof = report["observations"][0]
    assert roof["dry"] and roof["peak_stage_m"] is None and roof["ground_m"] > 3.0
    assert any("raised 3.0 m" in n for n in report["notes"])


@needs_anuga
def test_cancel_ends_the_child_and_writes_nothing(tmp_path):
    mesh = tmp_path / "channel.2dm"
    rectangle_mesh(mesh, 100, 20, lambda x, y: 0.02 * (100 - x))
    scenario = scenario_from_dict({
        "duration_s": 3600, "output_interval_s": 1,
        "inflows": [{"line": local([[1, 0.5], [1, 19.5]]), "discharge_m3s": 2.0}]})
    seen = []
    start = time.perf_counter()
    with pytest.raises(Cancelled):
        run_flood(mesh, scenario, tmp_path / "out", crs=CRS, progress=seen.append,
                  cancelled=lambda: bool(seen))
    assert time.perf_counter() - start < 60 and seen[0] < 0.01
    assert not (tmp_path / "out").exists()


@needs_anuga
def test_flood_with_a_reference_compares_the_two_meshes(tmp_path, capsys):
    """The CLI runs the scenario on a coarse and a fine mesh of the same channel and compares:
    the extents nearly agree, max depths within centimetres; the maps are written."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "coarse.2dm", 100, 20, lambda x, y: 0.02 * (100 - x), max_area=4)
    rectangle_mesh(tmp_path / "fine.2dm", 100, 20, lambda x, y: 0.02 * (100 - x), max_area=1)
    _write(tmp_path / "s.json", {
        "duration_s": 60, "output_interval_s": 5, "manning": 0.03,
        "inflows": [{"line": local([[1, 0.5], [1, 19.5]]), "discharge_m3s": 2.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}],
        "observation_points": [{"name": "mid", "x": X0 + 30, "y": Y0 + 10}]})
    assert main(["flood", str(tmp_path / "coarse.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "cmp"), "--crs", CRS,
                 "--reference", str(tmp_path / "fine.2dm")]) == 0
    assert "extent IoU" in capsys.readouterr().out
    c = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    assert c["mesh_nodes"] < c["reference_nodes"]
    assert 0.8 < c["extent_iou"] < 1.0
    assert c["max_depth_rmse_m"] < 0.05 and abs(c["max_depth_bias_m"]) < 0.03
    assert abs(c["observations"][0]["difference_m"]) < 0.03
    assert c["arrival_mean_abs_difference_s"] < 10
    with rasterio.open(tmp_path / "cmp" / "extent_difference.tif") as src:
        codes = src.read(1, masked=True)
    assert (codes == 3).sum() > 10 * ((codes == 1).sum() + (codes == 2).sum())
    same = main(["compare", str(tmp_path / "cmp" / "mesh"), str(tmp_path / "cmp" / "mesh"),
                 "--out", str(tmp_path / "same")])
    assert same == 0
    assert json.loads((tmp_path / "same" / "comparison.json").read_text())["extent_iou"] == 1


@needs_anuga
def test_compare_says_where_a_point_is_wet_in_one_flood_only(tmp_path, capsys):
    """Two floods on one channel (100 × 20 m, slope 0.02): 2 m³/s in at its top, and the same in
    just above its outflow, for 60 s. The point at 30 m is wet in the first only, the one at
    95 m in the second only; the comparison gave both a null difference and the command no
    figure. It says where each got wet and its peak depth difference, dry taken as 0 m deep."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 100, 20, lambda x, y: 0.02 * (100 - x), max_area=4)
    for name, x in (("top", 1), ("foot", 90)):
        _write(tmp_path / f"{name}.json", {
            "duration_s": 60, "output_interval_s": 5, "manning": 0.03,
            "inflows": [{"line": local([[x, 0.5], [x, 19.5]]), "discharge_m3s": 2.0}],
            "boundaries": [{"kind": "outflow", "sides": ["east"]}],
            "observation_points": [{"name": "mid", "x": X0 + 30, "y": Y0 + 10},
                                   {"name": "low", "x": X0 + 95, "y": Y0 + 10}]})
        assert main(["flood", str(tmp_path / "m.2dm"), "--scenario",
                     str(tmp_path / f"{name}.json"), "--out", str(tmp_path / name),
                     "--crs", CRS]) == 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "top"), str(tmp_path / "foot"), "--out",
                 str(tmp_path / "cmp")]) == 0
    printed = capsys.readouterr().out
    mid, low = json.loads((tmp_path / "cmp" / "comparison.json").read_text())["observations"]
    top = json.loads((tmp_path / "top" / "report.json").read_text())["observations"][0]
    assert mid["wet"] == "mesh only" and low["wet"] == "reference only"
    assert mid["reference_peak_stage_m"] is None and mid["difference_m"] is None
    assert mid["reference_peak_depth_m"] == low["mesh_peak_depth_m"] == 0
    assert mid["peak_depth_difference_m"] == mid["mesh_peak_depth_m"] == top["peak_depth_m"] > 0
    assert low["peak_depth_difference_m"] == -low["reference_peak_depth_m"] < 0
    assert (f"mid: peak stage {mid['mesh_peak_stage_m']:.2f} m, reference dry; peak depth "
            f"difference +{top['peak_depth_m']:.2f} m, wet on the mesh only") in printed, printed
    # the maps say what they hold, so that none is taken for a DEM
    for path, held in ((tmp_path / "top" / "max_depth.tif", "max_depth"),
                       (tmp_path / "top" / "max_water_level.tif", "max_stage"),
                       (tmp_path / "top" / "arrival_time.tif", "arrival_s"),
                       (tmp_path / "cmp" / "depth_difference.tif", "depth_difference"),
                       (tmp_path / "cmp" / "extent_difference.tif", "extent_difference")):
        with rasterio.open(path) as src:
            assert src.tags()["FLOODMESH_QUANTITY"] == held, path

@needs_anuga
def test_the_report_names_the_wet_sliver_that_sets_the_time_step_not_the_smallest_dry_one(
        tmp_path, capsys):
    """A channel (100 × 20 m, slope 0.02) beside a dry bank 2 m higher: a 0.3 m segment in the
    water and a 0.1 m one on the bank leave slivers in both; the bank's are the mesh's
    smallest, but the water's set the solver's time step, and the report (and the command's
    summary) name that place, where a modeller would look to make the flood cheaper."""
    from floodmesh.core.frontends.cli import main

    corners = [[0, 0], [100, 0], [100, 30], [0, 30]]
    wet, dry = [[50, 10], [50.3, 10]], [[60, 26], [60.1, 26]]
    xy = np.array(corners + wet + dry, float) + (X0, Y0)
    segments = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [6, 7]])
    xy, tri = triangulate_pslg(PSLG(xy, segments, np.empty((0, 2))), min_angle=25.0,
                               max_area=2.0)
    x, y = xy[:, 0] - X0, xy[:, 1] - Y0
    nodes = np.column_stack([xy, 0.02 * (100 - x) + 2.0 * np.clip(y - 20, 0, 2) / 2])
    io.write_mesh_2dm(tmp_path / "m.2dm", nodes, tri)
    _write(tmp_path / "s.json", {
        "duration_s": 100, "output_interval_s": 5, "manning": 0.03,
        "inflows": [{"line": local([[1, 0.5], [1, 19.5]]), "discharge_m3s": 3.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}]})
    assert main(["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "out"), "--crs", CRS]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    setter = report["time_step_set_by"][0]
    assert np.hypot(setter["x"] - X0 - 50.15, setter["y"] - Y0 - 10) < 1.0
    assert setter["share_of_steps"] > 0.5 and setter["max_depth_m"] > 0.05
    assert setter["inradius_m"] > 1.5 * report["hydraulics"]["min_inradius_m"]  # not the bank's
    assert sum(k["share_of_steps"] for k in report["time_step_set_by"]) <= 1 + 1e-9
    assert f"time step set most by the triangle at ({setter['x']:.1f}, {setter['y']:.1f})" in (
        capsys.readouterr().out)
    # and as points to put on the map, ranked, in the mesh's CRS
    with fiona.open(tmp_path / "out" / "time_step.gpkg", layer="time_step_set_by") as src:
        assert src.crs.to_epsg() == 32756
        first = next(iter(src))
    assert first["properties"]["rank"] == 1
    assert first["properties"]["share_of_steps"] == pytest.approx(setter["share_of_steps"])
    assert first["geometry"]["coordinates"][:2] == pytest.approx((setter["x"], setter["y"]))


@needs_anuga
def test_an_eddy_at_the_outflow_edge_is_not_fed_until_the_flood_blows_up(tmp_path):
    """The mesh on which ANUGA's transmissive outflow blew up (tests/data: the oblique corpus
    flood meshed with min_spacing 2 m; benchmarks/RESULTS.md, "An outflow edge that blew up"):
    on the wave's falling limb an eddy turns back in at the west edge, and outside = inside fed
    it until water ran at 70 m/s and stood 168 m deep, a map written as if all were well. Run
    as a user would (the CLI, the CRS from the mesh's own .prj), the flood stays a flood: no
    deeper than the river's 3 m, no faster than its 3 m/s, and the water leaves."""
    from floodmesh.core.frontends.cli import main

    mesh = tmp_path / "mesh.2dm"
    mesh.write_bytes(gzip.decompress((DATA / "oblique_outflow_eddy.2dm.gz").read_bytes()))
    io.write_prj(mesh, "EPSG:25832")
    _write(tmp_path / "s.json", {
        "duration_s": 760, "output_interval_s": 10, "manning": 0.035,
        "inflows": [{"circle": {"centre": [412285.0, 5652216.38], "radius": 10.0},
                     "hydrograph": [[0, 0], [300, 120], [600, 120], [900, 20]]}],
        "boundaries": [{"kind": "outflow", "sides": ["west"]}]})
    assert main(["flood", str(mesh), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["max_depth_m"] < 3.5 and report["max_speed_ms"] < 5.0
    assert report["mass_balance"]["outflow_volume_m3"] > 10_000


@needs_anuga
def test_water_past_the_unstable_speed_stops_the_run_saying_when_and_where(tmp_path):
    """A run whose water (deeper than the wet depth) passes the scenario's unstable_speed_m_s
    stops at that output time (or within 10 s of flood time, when outputs are further apart):
    one error naming the time, the depth and speed, the triangle's place and the setting;
    nothing written. The channel's water runs at about 1 m/s, so a limit of 0.5 m/s stands in
    for a blow-up's 20."""
    mesh = tmp_path / "channel.2dm"
    rectangle_mesh(mesh, 100, 20, lambda x, y: 0.02 * (100 - x))
    scenario_dict = {
        "duration_s": 120, "output_interval_s": 5, "manning": 0.03, "unstable_speed_m_s": 0.5,
        "inflows": [{"line": local([[1, 0.5], [1, 19.5]]), "discharge_m3s": 2.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}]}
    scenario = scenario_from_dict(scenario_dict)
    seen = []
    with pytest.raises(FloodMeshError) as stop:
        run_flood(mesh, scenario, tmp_path / "out", crs=CRS, progress=seen.append)
    message = str(stop.value)
    assert re.search(r"went unstable by t = \d+ s: water 0\.\d\d m deep ran at \d\.\d m/s in the "
                     r"triangle at \(3820\d\d\.\d, 63540\d\d\.\d\) \(inradius 0\.\d\d m, \d+\.\d m "
                     r"from (a wall|an outflow \(outflow_1\))\), at a time step of ", message), \
        message
    assert "unstable_speed_m_s (now 0.5)" in message and "nothing was written" in message
    assert seen and max(seen) < 0.5
    assert not (tmp_path / "out").exists()
    # outputs 10 minutes apart: the run is checked every 10 s of flood time, not only at them
    hourly = scenario_from_dict({**scenario_dict, "duration_s": 3600, "output_interval_s": 600})
    with pytest.raises(FloodMeshError, match=r"went unstable by t = 10 s: "):
        run_flood(mesh, hourly, tmp_path / "out", crs=CRS)
    assert not (tmp_path / "out").exists()


def test_buildings_as_holes_leave_the_mesh_with_walls_around_them(tmp_path):
    nodes, tri = rectangle_mesh(tmp_path / "m.2dm", 40, 20, lambda x, y: 0 * x)
    house = local([[10, 5], [16, 5], [16, 12], [10, 12]])
    scenario = scenario_from_dict({"duration_s": 10, "output_interval_s": 5,
                                   "buildings": {"polygons": [house], "mode": "holes"},
                                   "boundaries": [{"kind": "outflow", "sides": ["east"]}]})
    prepared = prepare(nodes, tri, scenario)
    arrays = prepared["arrays"]
    assert len(arrays["triangles"]) < len(tri)
    centroids = arrays["nodes"][arrays["triangles"]][:, :, :2].mean(axis=1) - (X0, Y0)
    assert not ((centroids[:, 0] > 10) & (centroids[:, 0] < 16) & (centroids[:, 1] > 5)
                & (centroids[:, 1] < 12)).any()
    # the hole's rim is boundary now, and a wall (tag 0); the east side is outflow
    walls = prepared["boundary_edges"]["wall"]
    assert walls > 0 and prepared["boundary_edges"]["outflow_1"] > 0


def test_bad_scenarios_are_refused_with_the_fix(tmp_path):
    nodes, tri = rectangle_mesh(tmp_path / "m.2dm", 40, 20, lambda x, y: 0 * x)
    far = {"duration_s": 10, "boundaries": [{"kind": "outflow",
                                             "line": [[0, 0], [1, 1]]}]}
    with pytest.raises(FloodMeshError, match="meets no boundary edge.*CRS"):
        prepare(nodes, tri, scenario_from_dict(far))
    outside = {"duration_s": 10, "inflows": [{"circle": {"centre": [0, 0], "radius": 5},
                                              "discharge_m3s": 1}]}
    with pytest.raises(FloodMeshError, match="holds no triangle centre"):
        prepare(nodes, tri, scenario_from_dict(outside))
    with pytest.raises(FloodMeshError, match="lacks 'duration_s'"):
        scenario_from_dict({})
    with pytest.raises(FloodMeshError, match="boundary kind 'open'"):
        scenario_from_dict({"duration_s": 10, "boundaries": [{"kind": "open",
                                                              "sides": ["east"]}]})
    with pytest.raises(FloodMeshError, match="level boundary needs"):
        scenario_from_dict({"duration_s": 10, "boundaries": [{"kind": "level",
                                                              "sides": ["east"]}]})
    rising = scenario_from_dict({"duration_s": 10, "boundaries": [
        {"kind": "level", "sides": ["east"], "levels": [[0, 1.0], [5, 2.0]]}]})
    assert rising.boundaries[0].levels == ((0.0, 1.0), (5.0, 2.0))
    with pytest.raises(FloodMeshError, match="unstable speed must be above 0"):
        scenario_from_dict({"duration_s": 10, "unstable_speed_m_s": 0})
    with pytest.raises(FloodMeshError, match="not valid JSON"):
        load_scenario(_write_text(tmp_path / "bad.json", "{"))


def test_a_misspelt_key_at_any_level_is_refused_naming_it_where_and_the_right_one(tmp_path):
    """A key FloodMesh does not read left its default in force without a word ('initial_stage':
    a dry start; 'snap': 1 m): each is named, where it is, with the closest key, in one line."""
    circle = {"center": [X0, Y0], "radius": 5}
    path = _write(tmp_path / "s.json", {
        "duration_s": 10, "inflows": [{"circle": circle, "discharge_m3s": 1, "Q": 2}],
        "roughness": [{"file": "zones.gpkg", "manning": 0.1, "mannings": 0.2}],
        "buildings": {"polygons": [], "height": 4},
        "observation_points": [{"name": "a", "x": X0, "y": Y0, "z": 1}]})
    with pytest.raises(FloodMeshError) as refused:
        load_scenario(path)
    message = str(refused.value)
    for part in ("'center' in inflow 1's circle (did you mean 'centre'?",
                 "'Q' in inflow 1 (did you mean 'discharge_m3s'?",
                 "'mannings' in roughness zone 1 (did you mean 'manning'?",
                 "'height' in the buildings (did you mean 'height_m'? it takes polygons, mode, "
                 "height_m)", "'z' in observation point 1 (it takes name, x, y)"):
        assert part in message
    assert "\n" not in message


def test_keys_beginning_with_an_underscore_are_comments():
    """JSON has no comments: modellers write "_comment" keys, at any level; they are read over,
    and the scenario is the same as without them."""
    plain = {"duration_s": 10, "boundaries": [{"kind": "outflow", "sides": ["east"]}]}
    commented = {"_comment": "design flood", "duration_s": 10,
                 "boundaries": [{"_why": "the river leaves east", "kind": "outflow",
                                 "sides": ["east"]}]}
    assert scenario_from_dict(commented) == scenario_from_dict(plain)


def test_every_key_of_the_documented_scenario_is_read():
    """The user guide's example scenario holds only keys FloodMesh reads."""
    from floodmesh.core.flood import scenario_keys

    guide = (Path(__file__).parents[2] / "docs" / "user-guide.md").read_text()
    example = guide.split("### The scenario")[1].split("```json")[1].split("```")[0]
    known = {key for name in ("SCENARIO", "INFLOW", "BOUNDARY", "ROUGHNESS", "BUILDINGS",
                              "POINT", "CIRCLE", "SHAPES")
             for key in getattr(scenario_keys, name)}
    assert set(re.findall(r'"(\w+)":', example)) <= known


def test_wrong_kinds_of_value_are_named_not_a_traceback(tmp_path):
    """A list where an object belongs, text for a number, a second region: one line each."""
    for scenario, words in [
            ({"duration_s": 10, "inflows": {"line": [[0, 0], [1, 1]]}},
             "the scenario's inflows must be a list of objects"),
            ({"duration_s": 10, "manning": "n=0.03"},
             "the scenario's manning must be a number, got 'n=0.03'"),
            ({"duration_s": 10, "inflows": [{"line": [[0, 0], [1, 1], [2, 0]],
                                             "discharge_m3s": 1}]},
             "inflow 1's line has 3 points; an inflow line has 2"),
            ({"duration_s": 10, "inflows": [{"line": [[0, 0], [1, 1]], "discharge_m3s": 1,
                                             "circle": {"centre": [0, 0], "radius": 1}}]},
             "inflow 1 needs one of region (a polygon), circle or line"),
            ({"duration_s": 10, "inflows": [{"line": [[0, 0], [1, 1]],
                                             "hydrograph": [[0, 1], [10, 2], [10, 3]]}]},
             "the times in inflow 1's hydrograph must increase from row to row: row 3 (10 s)"),
            ({"duration_s": 10, "boundaries": [{"kind": "outflow", "sides": ["east"]},
                                               {"kind": "outflow", "sides": 5}]},
             "boundary 2's sides must be a list of sides (north, south, east, west or all), "
             "got 5"),
            ({"duration_s": 10, "boundaries": [{"kind": "outflow", "sides": {"east": True}}]},
             "boundary 1's sides must be a list of sides")]:
        with pytest.raises(FloodMeshError, match=re.escape(words)):
            load_scenario(_write(tmp_path / "s.json", scenario))



@pytest.mark.parametrize("height", [-3, 0])
def test_buildings_raised_by_no_height_or_below_the_ground_are_refused(tmp_path, height):
    """A height_m of -3 dug the footprints 3 m into the ground ('buildings raised -3 m'),
    a pit where a wall was meant, without a word."""
    house = [[0, 0], [5, 0], [5, 5], [0, 5]]
    with pytest.raises(FloodMeshError, match=re.escape(
            f"the scenario's buildings' height must be above 0, got {height}")):
        load_scenario(_write(tmp_path / "s.json", {
            "duration_s": 10, "buildings": {"polygons": [house], "height_m": height}}))


def test_a_missing_polygon_file_is_looked_for_in_the_scenario_s_folder_named_whole(
        tmp_path, monkeypatch):
    """A scenario loaded by a relative name said its roughness file matched no file 'beside the
    scenario (.)'; the folder is named as the hydrograph's is, in full."""
    monkeypatch.chdir(tmp_path)
    _write(tmp_path / "s.json", {"duration_s": 10, "roughness": [
        {"file": "landuse.gpkg", "manning": 0.08}]})
    with pytest.raises(FloodMeshError, match=re.escape(
            f"roughness zone 1 names landuse.gpkg, which matches no file beside the scenario "
            f"({tmp_path.resolve()}): check the path")):
        load_scenario("s.json")

def test_observation_points_of_one_name_are_refused(tmp_path):
    """Two points named alike gave observations.csv two columns of one name, which a reader
    takes for one (or renames), and a comparison's peaks by name mixed up."""
    with pytest.raises(FloodMeshError, match=re.escape(
            "observation points 1 and 3 are both named 'gauge': give each its own name")):
        load_scenario(_write(tmp_path / "s.json", {"duration_s": 10, "observation_points": [
            {"name": "gauge", "x": 0, "y": 0}, {"name": "b", "x": 1, "y": 0},
            {"name": "gauge", "x": 2, "y": 0}]}))

@needs_anuga
def test_an_outflow_given_as_inflow_is_a_note_and_no_mass_balance_share_of_nothing(
        tmp_path, capsys):
    """-20 m³/s out of dry ground: ANUGA takes nothing; the run says that a negative inflow takes
    only water that is there, and gives no percentage of a mass-balance error of round-off on
    a volume of ~0 m³ (it said '(2.8 %)')."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x, max_area=4.0)
    _write(tmp_path / "s.json", {"duration_s": 10, "output_interval_s": 5, "inflows": [
        {"circle": {"centre": [X0 + 10, Y0 + 5], "radius": 3}, "discharge_m3s": -20}]})
    assert main(["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "out"), "--crs", CRS]) == 0
    printed = capsys.readouterr()
    assert "inflow 1 has a discharge below 0 (-20 m³/s): it takes water out" in printed.err
    assert "(no share: under 0.2 m³, 1 mm over the mesh, came in or was there)" in printed.out
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["mass_balance"]["relative_error"] is None
    assert report["mass_balance"]["relative_error_floor_m3"] == pytest.approx(0.2)
    assert any("below 0" in note for note in report["notes"])


def test_missing_anuga_is_one_line_naming_the_fix(tmp_path):
    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x)
    _write(tmp_path / "s.json", {"duration_s": 10})
    env = {**os.environ, "FLOODMESH_FLOOD_PYTHON": "/usr/bin/python3"}
    done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "flood",
                           str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                           "--out", str(tmp_path / "out"), "--crs", CRS],
                          capture_output=True, text=True, env=env)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1
    assert "needs the ANUGA solver" in done.stderr and "make setup" in done.stderr
    assert not (tmp_path / "out").exists()


@needs_anuga
def test_the_report_names_every_file_the_flood_writes(tmp_path):
    """report.json's files are the folder's files: triangles.npz, which compare reads, too."""
    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0.1 + 0 * x, max_area=4.0)
    scenario = scenario_from_dict({"duration_s": 10, "output_interval_s": 5,
                                   "initial_stage_m": 0.2})
    report = run_flood(tmp_path / "m.2dm", scenario, tmp_path / "out", crs=CRS)
    assert sorted(report["files"]) == sorted(p.name for p in (tmp_path / "out").iterdir())



@needs_anuga
def test_a_flood_run_again_into_its_folder_leaves_no_file_of_the_last_one(tmp_path, capsys):
    """A second flood into the folder of one that wrote a size field (--size-field-area) left
    that size_field.tif and wet_zone.gpkg beside its own results, for a second mesh to be
    sized by the wrong flood; the user's own files there stay."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0.1 + 0 * x, max_area=4.0)
    _write(tmp_path / "s.json", {"duration_s": 10, "output_interval_s": 5,
                                 "initial_stage_m": 0.2})
    out = tmp_path / "out"
    flood = ["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
             "--out", str(out), "--crs", CRS]
    assert main([*flood, "--size-field-area", "4"]) == 0
    assert {"size_field.tif", "wet_zone.gpkg"} <= {p.name for p in out.iterdir()}
    (out / "notes.txt").write_text("the modeller's")
    assert main(flood) == 0
    report = json.loads((out / "report.json").read_text())
    assert sorted(p.name for p in out.iterdir()) == sorted([*report["files"], "notes.txt"])


def test_a_flood_into_a_run_s_folder_is_refused_keeping_the_run_s_report(tmp_path, capsys):
    """floodmesh flood run/mesh.2dm --out run replaced the run's report.json (its accuracy,
    options and notes, which report.html shows) by the flood's, without a word."""
    from affine import Affine
    from pyproj import CRS as ProjCRS

    from floodmesh.core.frontends.cli import main
    from floodmesh.core.raster import Grid

    x = np.arange(40)[None, :]
    z = 10 + 0.02 * x + np.random.default_rng(0).normal(0, 0.05, (30, 40))
    io.write_raster(tmp_path / "dem.tif", Grid(z, Affine(1, 0, X0, 0, -1, Y0 + 30),
                                               ProjCRS.from_user_input(CRS)))
    run = tmp_path / "run"
    assert main(["run", str(tmp_path / "dem.tif"), "--out", str(run)]) == 0
    before = (run / "report.json").read_bytes()
    _write(tmp_path / "s.json", {"duration_s": 10, "output_interval_s": 5})
    assert main(["flood", str(run / "mesh.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(run)]) == 2
    assert (f"the output folder {run} holds a report.json that no flood wrote (a run's), which "
            f"the flood's would replace: give the flood a folder of its own, e.g. {run / 'flood'}"
            in capsys.readouterr().err)
    assert (run / "report.json").read_bytes() == before
    assert not (run / "max_depth.tif").exists()


def test_a_flood_never_writes_over_a_file_its_scenario_reads(tmp_path, capsys):
    """A scenario whose inflow is hydrograph.csv beside it, flooded into its own folder: the
    outflow hydrograph was written over the inflow the scenario had read, after the run."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x, max_area=4.0)
    inflow = _write_text(tmp_path / "hydrograph.csv", "time_s,q\n0,1\n10,1\n")
    _write(tmp_path / "s.json", {"duration_s": 10, "output_interval_s": 5, "inflows": [
        {"line": local([[1, 1], [1, 9]]), "hydrograph": "hydrograph.csv"}]})
    assert main(["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path), "--crs", CRS]) == 2
    assert (f"the output {tmp_path / 'hydrograph.csv'} is the input {inflow}: FloodMesh never "
            "overwrites an input" in capsys.readouterr().err)
    assert inflow.read_text() == "time_s,q\n0,1\n10,1\n"

@pytest.mark.parametrize("out, says", [
    ("taken", "is a file, not a folder"),
    ("m.2dm", "is the input"),
])
def test_an_output_folder_that_cannot_be_one_is_refused_before_the_flood(tmp_path, out, says):
    """--out naming a file (or the mesh itself) is refused in one line before ANUGA runs, not
    a traceback after it; the file stays as it was."""
    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x)
    _write(tmp_path / "s.json", {"duration_s": 10})
    (tmp_path / "taken").write_text("the user's file")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "flood",
                           str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                           "--out", str(tmp_path / out), "--crs", CRS],
                          capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and says in done.stderr, done.stderr
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before



@pytest.mark.parametrize("option, value, says", [
    ("--size-field-area", "-5", "size field area must be a positive number of m², got -5"),
    ("--size-field-area", "0", "size field area must be a positive number of m², got 0"),
    ("--cell-size", "0", "comparison cell size must be a positive number of metres, got 0"),
    ("--cell-size", "nan", "comparison cell size must be a number, got NaN")])
def test_flood_options_out_of_range_are_refused_before_the_flood(tmp_path, capsys, option,
                                                                 value, says):
    """--size-field-area -5 wrote a size field of -5 m² after the flood (0 wrote none, without a
    word); a comparison cell size of 0 or NaN ended in a ValueError traceback after both
    floods. Each is one line before ANUGA runs, and nothing is written."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x)
    _write(tmp_path / "s.json", {"duration_s": 10})
    assert main(["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "out"), "--crs", CRS, "--reference",
                 str(tmp_path / "m.2dm"), option, value]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err
    assert not (tmp_path / "out").exists()



@pytest.mark.parametrize("reference, says", [
    ("file", "reference is a file, not a folder"),
    ("run", "holds a report.json that no flood wrote")])
def test_flood_refuses_the_reference_folder_before_the_first_flood(tmp_path, capsys, reference,
                                                                  says):
    """flood --reference with OUT/reference a file, or holding a run's report.json: refused only
    after the first flood had run for minutes (its results left in OUT/mesh). Now one line
    before ANUGA runs, and OUT/mesh is never written."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x, max_area=4.0)
    _write(tmp_path / "s.json", {"duration_s": 10, "output_interval_s": 5})
    out = tmp_path / "out"
    out.mkdir()
    if reference == "file":
        (out / "reference").write_text("not a folder")
    else:
        (out / "reference").mkdir()
        _write(out / "reference" / "report.json", {"nodes": 10, "min_angle_deg": 30})
    assert main(["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(out), "--crs", CRS, "--reference", str(tmp_path / "m.2dm")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err
    assert not (out / "mesh").exists()


@needs_anuga
def test_a_reference_run_where_neither_floods_says_so_not_a_traceback(tmp_path, capsys):
    """Two floods that stay dry compared: the summary formatted the RMSE, None, and stopped with
    a TypeError after both runs; comparison.json gave an extent IoU of 0, total disagreement."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0 * x, max_area=4.0)
    _write(tmp_path / "s.json", {"duration_s": 10, "output_interval_s": 5})
    assert main(["flood", str(tmp_path / "m.2dm"), "--scenario", str(tmp_path / "s.json"),
                 "--out", str(tmp_path / "out"), "--crs", CRS, "--reference",
                 str(tmp_path / "m.2dm")]) == 0
    assert "neither flood is deeper than 0.05 m anywhere" in capsys.readouterr().out
    comparison = json.loads((tmp_path / "out" / "comparison.json").read_text())
    assert comparison["extent_iou"] is None and comparison["max_depth_rmse_m"] is None

@needs_anuga
@pytest.mark.parametrize("value, says", [
    ("-1", "comparison cell size must be a positive number of metres, got -1"),
    ("0", "comparison cell size must be a positive number of metres, got 0")])
def test_compare_refuses_a_cell_size_out_of_range_writing_nothing(tmp_path, capsys, value,
                                                                  says):
    """compare --cell-size -1 said the raster was not north-up (warp it) and left its folder;
    0 ended in a ValueError traceback."""
    from floodmesh.core.frontends.cli import main

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0.1 + 0 * x, max_area=4.0)
    run_flood(tmp_path / "m.2dm", scenario_from_dict({"duration_s": 10, "output_interval_s": 5,
                                                      "initial_stage_m": 0.2}),
              tmp_path / "run", crs=CRS)
    assert main(["compare", str(tmp_path / "run"), str(tmp_path / "run"), "--out",
                 str(tmp_path / "cmp"), "--cell-size", value]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err
    assert not (tmp_path / "cmp").exists()

@needs_anuga
def test_compare_interrupted_leaves_the_last_comparison_whole(tmp_path):
    """Ctrl-C as compare_floods writes comparison.json (raised there by a trace function, as
    test_interrupt's Ctrl-C inside a kernel), over the last comparison (cell size 2 m) and a
    note of the user's: the two rasters were already the new ones (1 m) beside the last json,
    a half comparison. The folder changes in one step: all the last files, or all new ones, and
    the user's note kept."""
    from floodmesh.core.flood.compare import COMPARISON_FILES, compare_floods

    rectangle_mesh(tmp_path / "m.2dm", 20, 10, lambda x, y: 0.1 + 0 * x, max_area=4.0)
    run_flood(tmp_path / "m.2dm", scenario_from_dict({"duration_s": 10, "output_interval_s": 5,
                                                      "initial_stage_m": 0.2}),
              tmp_path / "run", crs=CRS)
    cmp = tmp_path / "cmp"
    compare_floods(tmp_path / "run", tmp_path / "run", cmp, cell_size=2.0)
    (cmp / "notes.txt").write_text("mine")
    last = {p.name: p.read_bytes() for p in cmp.iterdir()}
    fired = []

    def ctrl_c(frame, event, arg):
        if event == "call" and frame.f_code.co_name == "write_json" and not fired:
            fired.append(True)
            raise KeyboardInterrupt

    previous = sys.gettrace()
    sys.settrace(ctrl_c)
    try:
        with pytest.raises(KeyboardInterrupt):
            compare_floods(tmp_path / "run", tmp_path / "run", cmp, cell_size=1.0)
    finally:
        sys.settrace(previous)
    assert fired
    assert {p.name: p.read_bytes() for p in cmp.iterdir()} == last
    compare_floods(tmp_path / "run", tmp_path / "run", cmp, cell_size=1.0)
    now = {p.name: p.read_bytes() for p in cmp.iterdir()}
    assert set(now) == {*COMPARISON_FILES, "notes.txt"} and now["notes.txt"] == b"mine"
    assert all(now[name] != last[name] for name in COMPARISON_FILES)


def _write(path, data):
    path.write_text(json.dumps(data))
    return path


def _write_text(path, text):
    path.write_text(text)
    return path


@needs_anuga
def test_a_level_boundary_fills_a_basin_to_its_level_not_above(tmp_path):
    """A dry, flat, walled 150 × 10 m basin open at its west end to a level rising from 0.5 to
    1 m over 60 s: the water comes in, runs to the far wall and settles at the level; it may
    not overshoot it (transmitting the inflow's momentum at the boundary, as before, kept
    pushing water in: 1.70 m at the far wall, and the demo's levee overtopped)."""
    mesh = tmp_path / "basin.2dm"
    rectangle_mesh(mesh, 150, 10, lambda x, y: 0.0 * x, max_area=4.0)
    scenario = scenario_from_dict({
        "duration_s": 240, "output_interval_s": 10, "manning": 0.02,
        "boundaries": [{"kind": "level", "sides": ["west"], "levels": [[0, 0.5], [60, 1.0]]}],
        "observation_points": [{"name": "far", "x": X0 + 145, "y": Y0 + 5},
                               {"name": "near", "x": X0 + 5, "y": Y0 + 5}]})
    report = run_flood(mesh, scenario, tmp_path / "out", crs=CRS)
    assert max(o["peak_stage_m"] for o in report["observations"]) < 1.05
    stage = np.genfromtxt(tmp_path / "out" / "observations.csv", delimiter=",", skip_header=1)
    assert np.abs(stage[-1, 1:3] - 1.0).max() < 0.05
    assert report["mass_balance"]["boundary_inflow_volume_m3"] == pytest.approx(
        150 * 10 * stage[-1, 1:3].mean(), rel=0.05)


def test_spatial_order_keeps_the_mesh_and_brings_neighbours_together():
    rng = np.random.default_rng(1)
    corners = np.array([[0, 0], [60, 0], [60, 40], [0, 40]], float)
    xy, tri = triangulate_pslg(PSLG(corners, np.array([[0, 1], [1, 2], [2, 3], [3, 0]]),
                                    np.empty((0, 2))), min_angle=25.0, max_area=2.0)
    shuffle = rng.permutation(len(xy))  # a mesh whose numbering is scattered
    nodes = np.column_stack([xy, np.zeros(len(xy))])[shuffle]
    tri = np.argsort(shuffle)[tri][rng.permutation(len(tri))]
    order, ordered = spatial_order(nodes, tri)
    ordered_nodes = nodes[order]
    as_set = {tuple(sorted(map(tuple, np.round(t, 9)))) for t in nodes[tri][:, :, :2]}
    assert as_set == {tuple(sorted(map(tuple, np.round(t, 9))))
                      for t in ordered_nodes[ordered][:, :, :2]}
    spread = lambda t: np.mean(t.max(axis=1) - t.min(axis=1))  # noqa: E731
    assert spread(ordered) < spread(tri) / 10
