"""Merewether end to end: FloodMesh's mesh against a uniform mesh of the same node count, each
flooded by ANUGA and compared with a finer uniform reference and with the surveyed peak levels
(and TUFLOW's) of ARR Project 15.

    .venv/bin/python benchmarks/merewether.py [--duration 700] [--reference-area 2] [--out DIR]

Data: ../shared/data/real/merewether_topography1.asc (1 m, UTM 56S) and merewether_validation/
(scenario of ANUGA's own validation run: 19.7 m³/s into a 10 m circle in the south-west, south
and west walls, east and north open, Manning 0.02 on the road, 0.04 elsewhere; bare earth).
Meshes: FloodMesh's defaults, the same without --min-spacing, the defaults without the flow area
(--flow-area 0: no smaller triangles on low ground by the drainage lines), FloodMesh's second mesh for this
flood (size field and flow zone from the first mesh's flood: --size-field, --flow-zone), each
with a uniform Triangle mesh of its node count, and a finer uniform reference. Prints one
table: nodes, smallest inradius, ANUGA CPU, extent IoU, max-depth RMSE and bias against the
reference, peak-stage RMSE against the survey.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from floodmesh.core import io
from floodmesh.core.flood.compare import compare_floods
from floodmesh.core.flood.model import load_scenario, run_flood
from floodmesh.core.frontends.flood_cli import write_zone
from floodmesh.core.steps.hydraulic_lines import flood_size_field, wet_zone
from floodmesh.core.steps.hydraulics import hydraulic_checks
from floodmesh.core.steps.mesh import build_mesh, user_domain
from floodmesh.core.options import RunOptions
from floodmesh.core.chain.pipeline import run_pipeline

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real"
CASE = DATA / "merewether_validation"
DEM = DATA / "merewether_topography1.asc"
CRS = "EPSG:32756"


def read_xy(path) -> np.ndarray:
    with open(path) as fh:
        return np.array([[float(v) for v in row[:2]] for row in csv.reader(fh) if row])


def observations():
    with open(CASE / "ObservationPoints.csv") as fh:
        rows = list(csv.reader(fh))[1:]
    return [{"name": f"P{int(float(r[2]))}", "x": float(r[0]), "y": float(r[1]),
             "observed": float(r[4]), "tuflow": float(r[5])} for r in rows]


def write_domain(path) -> None:
    import fiona

    ring = read_xy(CASE / "extent.csv")
    schema = {"geometry": "Polygon", "properties": {"id": "int"}}
    with fiona.open(path, "w", driver="GPKG", crs=CRS, schema=schema) as dst:
        dst.write({"geometry": {"type": "Polygon", "coordinates": [ring.tolist()
                                                                   + [ring[0].tolist()]]},
                   "properties": {"id": 1}})


def scenario(folder: Path, duration: float, houses: bool) -> Path:
    data = {
        "duration_s": duration, "output_interval_s": 10, "manning": 0.04,
        "inflows": [{"circle": {"centre": [382265.0, 6354280.0], "radius": 10.0},
                     "discharge_m3s": 19.7}],
        "boundaries": [{"kind": "outflow", "sides": ["east", "north"]}],
        "roughness": [{"polygons": [read_xy(CASE / "RoadPolygon.csv").tolist()],
                       "manning": 0.02}],
        "observation_points": [{k: o[k] for k in ("name", "x", "y")} for o in observations()],
    }
    if houses:
        data["buildings"] = {"polygons": {"file": str(CASE / "houses" / "house*.csv")},
                             "mode": "raised", "height_m": 3.0}
    path = folder / "scenario.json"
    path.write_text(json.dumps(data, indent=1))
    return path


def uniform_mesh(dem, domain, nodes_wanted: int | None, path: Path, max_area=None):
    """A Triangle mesh without break lines (25°), its max area tuned to ``nodes_wanted``."""
    area = max_area or 20.0
    for _ in range(4 if max_area is None else 1):
        mesh = build_mesh(dem, [], min_angle=25.0, max_area=area, domain=domain)
        if max_area is not None or abs(len(mesh.nodes) - nodes_wanted) < 0.01 * nodes_wanted:
            break
        area *= len(mesh.nodes) / nodes_wanted
    io.write_mesh_2dm(path, mesh.nodes, mesh.triangles)
    return mesh


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench_merewether")
    p.add_argument("--duration", type=float, default=700.0)
    p.add_argument("--reference-area", type=float, default=2.0,
                   help="max triangle area of the uniform reference, m² (default 2)")
    p.add_argument("--houses", action="store_true", help="houses raised 3 m")
    p.add_argument("--wet-area", type=float, default=8.0,
                   help="floodmesh-flow: max triangle area where the first flood went, m²")
    p.add_argument("--flow-spacing", type=float,
                   help="floodmesh-flow: --min-spacing, m (default: the cell size)")
    p.add_argument("--reuse", action="store_true",
                   help="keep flood runs already in OUT (e.g. the reference)")
    p.add_argument("--flow-area", type=float,
                   help="FloodMesh's meshes: run --flow-area, m² (default: run's, 23 cells)")
    p.add_argument("--repeat", type=int, default=3,
                   help="ANUGA runs per mesh, the best CPU counts (default 3; the reference once)")
    p.add_argument("--max-area", type=float, default=100.0,
                   help="FloodMesh's maximum area (default: its default, 100 m²)")
    args = p.parse_args(argv)
    if not DEM.is_file():
        sys.exit(f"merewether.py: {DEM} is missing (../shared beside the checkout)")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_domain(out / "domain.gpkg")
    scenario_path = scenario(out, args.duration, args.houses)
    dem = io.read_raster(DEM, crs=CRS)
    domain = user_domain(io.read_boundary(out / "domain.gpkg"), dem)

    meshes = {}
    for label, spacing, flow_area in (("floodmesh", None, args.flow_area),
                                      ("floodmesh-no-spacing", 0.0, args.flow_area),
                                      ("floodmesh-no-flow-area", None, 0.0)):
        report = run_pipeline(DEM, out / label, RunOptions(crs=CRS, boundary=str(
            out / "domain.gpkg"), min_spacing=spacing, max_area=args.max_area,
            flow_area=flow_area))
        meshes[label] = (out / label / "mesh.2dm", report["nodes"])
    for label, wanted in (("uniform", "floodmesh"),
                          ("uniform-no-flow-area", "floodmesh-no-flow-area")):
        uniform_mesh(dem, domain, meshes[wanted][1], out / f"{label}.2dm")
        meshes[label] = (out / f"{label}.2dm", None)
    uniform_mesh(dem, domain, None, out / "reference.2dm", max_area=args.reference_area)
    meshes["reference"] = (out / "reference.2dm", None)

    sc = load_scenario(scenario_path)
    runs = {}

    def flood(label):
        folder = out / "runs" / label
        if args.reuse and (folder / "report.json").is_file():
            runs[label] = json.loads((folder / "report.json").read_text())
            return
        start, cpus = time.perf_counter(), []
        for _ in range(1 if label == "reference" else max(1, args.repeat)):
            runs[label] = run_flood(meshes[label][0], sc, folder, crs=CRS)
            cpus.append(runs[label]["cpu_s"])
        runs[label]["cpu_runs_s"], runs[label]["cpu_s"] = cpus, min(cpus)
        print(f"{label}: {runs[label]['nodes']} nodes, ANUGA {min(cpus):.1f} s CPU, best of "
              f"{[round(c, 1) for c in cpus]} ({time.perf_counter() - start:.0f} s wall, "
              f"load {os.getloadavg()[0]:.1f})", flush=True)

    # the second mesh puts its resolution where the first flood went, and its detected lines
    flood("floodmesh")
    first = out / "runs" / "floodmesh"
    depth = io.read_raster(first / "max_depth.tif")
    io.write_raster(out / "size_field.tif", flood_size_field(depth, wet_area=args.wet_area))
    write_zone(out / "wet_zone.gpkg", wet_zone(depth), depth.crs)
    report = run_pipeline(DEM, out / "floodmesh-flow", RunOptions(
        crs=CRS, boundary=str(out / "domain.gpkg"), max_area=args.max_area,
        size_field=str(out / "size_field.tif"), flow_zone=str(out / "wet_zone.gpkg"),
        min_spacing=args.flow_spacing, flow_area=args.flow_area))
    meshes["floodmesh-flow"] = (out / "floodmesh-flow" / "mesh.2dm", report["nodes"])
    uniform_mesh(dem, domain, report["nodes"], out / "uniform-flow.2dm")
    meshes["uniform-flow"] = (out / "uniform-flow.2dm", None)
    for label in ("reference", "floodmesh-no-spacing", "uniform", "floodmesh-no-flow-area",
                  "uniform-no-flow-area", "floodmesh-flow", "uniform-flow"):
        flood(label)
    obs = observations()
    rows = []
    labels = ("floodmesh", "floodmesh-no-spacing", "uniform", "floodmesh-no-flow-area",
              "uniform-no-flow-area", "floodmesh-flow", "uniform-flow", "reference")
    for label in labels:
        r = runs[label]
        c = (compare_floods(out / "runs" / label, out / "runs" / "reference",
                            out / "compare" / label) if label != "reference" else None)
        peaks = np.array([o["peak_stage_m"] if o["peak_stage_m"] is not None else np.nan
                          for o in r["observations"]])
        observed = np.array([o["observed"] for o in obs])
        rows.append({
            "mesh": label, "nodes": r["nodes"],
            "min_inradius_m": r["hydraulics"]["min_inradius_m"],
            "cpu_s": r["cpu_s"], "cpu_runs_s": r.get("cpu_runs_s", [r["cpu_s"]]),
            "cpu_per_step_ms": 1000 * r["cpu_s"] / max(r["time_steps"], 1),
            "mean_time_step_s": r["mean_time_step_s"],
            "time_steps": r["time_steps"],
            "extent_iou": c["extent_iou"] if c else 1.0,
            "max_depth_rmse_m": c["max_depth_rmse_m"] if c else 0.0,
            "max_depth_bias_m": c["max_depth_bias_m"] if c else 0.0,
            "peak_stage_rmse_vs_observed_m": float(np.sqrt(np.nanmean((peaks - observed) ** 2))),
            "peak_stages_m": peaks.tolist(),
            "mass_balance_relative_error": r["mass_balance"]["relative_error"]})
    tuflow = np.array([o["tuflow"] for o in obs])
    observed = np.array([o["observed"] for o in obs])
    summary = {"duration_s": args.duration, "reference_area_m2": args.reference_area,
               "houses": args.houses, "rows": rows,
               "tuflow_peak_stage_rmse_vs_observed_m": float(np.sqrt(np.mean(
                   (tuflow - observed) ** 2))),
               "observed_m": observed.tolist(), "tuflow_m": tuflow.tolist()}
    io.write_json(out / "merewether.json", summary)
    print(f"\nMerewether, {args.duration:.0f} s, {'houses raised' if args.houses else 'bare earth'};"
          f" reference: uniform {args.reference_area} m² ({runs['reference']['nodes']} nodes)")
    print(f"load average {os.getloadavg()[0]:.1f} ({os.cpu_count()} cores); CPU: best of "
          f"{args.repeat} runs, ms/step: that CPU per time step")
    print(f"{'mesh':<24}{'nodes':>7}{'min r_in m':>11}{'CPU s':>8}{'steps':>7}{'ms/step':>8}{'IoU':>7}"
          f"{'RMSE m':>8}{'bias m':>8}{'stage RMSE m':>13}")
    for row in rows:
        print(f"{row['mesh']:<24}{row['nodes']:>7}{row['min_inradius_m']:>11.3f}"
              f"{row['cpu_s']:>8.1f}{row['time_steps']:>7}{row['cpu_per_step_ms']:>8.2f}"
              f"{row['extent_iou']:>7.3f}"
              f"{row['max_depth_rmse_m']:>8.3f}{row['max_depth_bias_m']:>+8.3f}"
              f"{row['peak_stage_rmse_vs_observed_m']:>13.2f}")
    print(f"{'TUFLOW (ARR report)':<24}{'':>7}{'':>11}{'':>8}{'':>7}{'':>8}{'':>7}{'':>8}{'':>8}"
          f"{summary['tuflow_peak_stage_rmse_vs_observed_m']:>13.2f}")
    print("peak stages (m) at " + ", ".join(o["name"] for o in obs) + ":")
    print(f"  observed {observed.tolist()}\n  TUFLOW   {tuflow.tolist()}")
    for row in rows:
        print(f"  {row['mesh']:<23}{[round(v, 2) for v in row['peak_stages_m']]}")
    # the cheap checks of each mesh, for the table in benchmarks/RESULTS.md
    for label in labels[:-1]:
        nodes, triangles = io.read_mesh_2dm(meshes[label][0])
        h = hydraulic_checks(nodes, triangles)
        print(f"  {label}: {h['n_small_inradius']} triangles under {h['small_inradius_threshold_m']}"
              f" m inradius ({h['n_small_inradius_near_edge']} at the edge), CFL step "
              f"{h['cfl_time_step_s']:.3f} s at 1 m")


if __name__ == "__main__":
    main()
