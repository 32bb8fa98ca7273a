"""Floods on the evaluation corpus (issue 28 item 1): a wave down the river of a corpus terrain
(``benchmarks/corpus.py``), run by ANUGA on FloodMesh's default mesh of a survey of it and on a
uniform 25° mesh of the same node count from the same DEM, each scored against a fine uniform
mesh of the TRUE surface (the reference): extent IoU, max-depth RMSE, CPU and time steps.

    .venv/bin/python benchmarks/corpus_flood.py [--terrains "crossings, seed 17",…]
        [--noise 0.05] [--density 9] [--peak 120] [--duration 900] [--reference-area 2]
        [--out bench_corpus_flood] [--reuse-reference] [--reference-lines]

The terrains are the corpus's analytic floodplains (300 x 240 m; the plain falls 1 m/km to the
west, the river runs east to west): an inflow of ``--peak`` m³/s at the river's east end,
rising over 300 s, held to 600 s and falling to a sixth by 900 s, more than the channel holds;
the west edge lets water out, the other edges are walls. Manning 0.035 everywhere.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import shapely

sys.path.insert(0, str(Path(__file__).resolve().parent))
from corpus import TERRAINS  # noqa: E402  (benchmarks/corpus.py)

from floodmesh.core import io  # noqa: E402
from floodmesh.core.chain.pipeline import run_pipeline  # noqa: E402
from floodmesh.core.flood.compare import compare_floods  # noqa: E402
from floodmesh.core.flood.model import run_flood, scenario_from_dict  # noqa: E402
from floodmesh.core.frontends import demo  # noqa: E402
from floodmesh.core.options import RunOptions  # noqa: E402
from floodmesh.core.raster import Grid  # noqa: E402
from floodmesh.core.steps.mesh import Mesh, build_mesh, domain_from_dem  # noqa: E402

X0, Y0 = demo.DEMO_ORIGIN
DEFAULT_TERRAINS = ("crossings, seed 17", "demo geometry, seed 7")


def scenario(floodplain, peak: float, duration: float):
    """The wave: ``peak`` m³/s into a 10 m circle on the river's centreline 15 m inside the
    east edge (where no river runs inside the area, as beside the narrow embankments, at that
    edge's middle: the wave then ponds against the embankments across the plain and
    overtops them); the west edge an outflow."""
    river = floodplain.features["river"][0]
    east = shapely.intersection(river, shapely.box(0, 0, demo.WIDTH - 15.0, demo.HEIGHT))
    x, y = (max(shapely.get_coordinates(east), key=lambda c: c[0]) if not east.is_empty
            else (demo.WIDTH - 15.0, demo.HEIGHT / 2))
    return scenario_from_dict({
        "duration_s": duration, "output_interval_s": 10, "manning": 0.035,
        "inflows": [{"circle": {"centre": [X0 + x, Y0 + y], "radius": 10.0},
                     "hydrograph": [[0, 0], [300, peak], [600, peak],
                                    [min(900, duration), peak / 6], [duration, peak / 6]]}],
        "boundaries": [{"kind": "outflow", "sides": ["west"]}]})


def uniform_like(dem: Grid, domain, nodes_wanted: int, path: Path) -> Mesh:
    """A 25° Triangle mesh without break lines of ``nodes_wanted`` nodes (within 1 %), node z
    bilinear from ``dem``."""
    area = demo.WIDTH * demo.HEIGHT / max(nodes_wanted, 1) * 1.8
    for _ in range(5):
        mesh = build_mesh(dem, [], min_angle=25.0, max_area=area, domain=domain)
        if abs(len(mesh.nodes) - nodes_wanted) < 0.01 * nodes_wanted:
            break
        area *= len(mesh.nodes) / nodes_wanted
    io.write_mesh_2dm(path, mesh.nodes, mesh.triangles, crs=dem.crs)
    return mesh


def reference_mesh(floodplain, dem: Grid, domain, area: float, path: Path, *,
                   true_lines: bool = False) -> Mesh:
    """A uniform mesh of ``area`` m² triangles whose nodes carry the true surface; with
    ``true_lines``, its edges follow the true break lines too, so that it is the true surface
    wherever that is planar between them (a crest 1 m wide that 2 m² triangles would cut)."""
    lines = []
    if true_lines:
        inside = shapely.box(0, 0, demo.WIDTH, demo.HEIGHT)
        for line in demo.true_breaklines(floodplain):
            part = shapely.intersection(line, inside)
            lines += [shapely.get_coordinates(g) + (X0, Y0)
                      for g in getattr(part, "geoms", [part]) if g.length > 1.0]
    mesh = build_mesh(dem, lines, min_angle=25.0, max_area=area, domain=domain)
    nodes = mesh.nodes.copy()
    nodes[:, 2] = demo.ground_elevation(nodes[:, 0] - X0, nodes[:, 1] - Y0, floodplain)
    io.write_mesh_2dm(path, nodes, mesh.triangles, crs=dem.crs)
    return Mesh(nodes, mesh.triangles, dem.crs)


def run_case(name: str, args, out: Path) -> list[dict]:
    floodplain, seed = TERRAINS[name]
    case = out / name.replace(", ", "_").replace(" ", "_").replace("°", "deg")
    case.mkdir(parents=True, exist_ok=True)
    points, classes = demo.synthetic_floodplain(density=args.density, noise=args.noise,
                                                seed=seed, floodplain=floodplain)
    source = case / "points.laz"
    io.write_points_las(source, points, classes=classes)
    run_pipeline(source, case / "floodmesh", RunOptions())
    dem = io.read_raster(case / "floodmesh" / "dem.tif")
    domain = domain_from_dem(dem)
    nodes, _ = io.read_mesh_2dm(case / "floodmesh" / "mesh.2dm")
    uniform_like(dem, domain, len(nodes), case / "uniform.2dm")
    reference = reference_mesh(floodplain, dem, domain, args.reference_area,
                               case / "reference.2dm", true_lines=args.reference_lines)
    wave = scenario(floodplain, args.peak, args.duration)
    runs = {}
    for label, path in (("reference", case / "reference.2dm"),
                        ("floodmesh", case / "floodmesh" / "mesh.2dm"),
                        ("uniform", case / "uniform.2dm")):
        done = case / "runs" / label / "report.json"
        if label == "reference" and args.reuse_reference and done.is_file():
            runs[label] = json.loads(done.read_text())  # the same survey, DEM and wave
            continue
        start = time.perf_counter()
        runs[label] = run_flood(path, wave, case / "runs" / label, crs=demo.DEMO_CRS)
        print(f"  {name}: {label} flooded in {time.perf_counter() - start:.0f} s", flush=True)
    rows = []
    for label in ("floodmesh", "uniform"):
        c = compare_floods(case / "runs" / label, case / "runs" / "reference",
                           case / "compare" / label, crs=demo.DEMO_CRS)
        report = runs[label]
        setter = (report.get("time_step_set_by") or [None])[0]
        rows.append({"terrain": name, "mesh": label, "nodes": report["nodes"],
                     "cpu_s": report["cpu_s"], "time_steps": report["time_steps"],
                     "min_inradius_m": report["hydraulics"]["min_inradius_m"],
                     "step_set_by": setter and {
                         "x_local": setter["x"] - X0, "y_local": setter["y"] - Y0,
                         "inradius_m": setter["inradius_m"],
                         "share_of_steps": setter["share_of_steps"]},
                     "extent_iou": c["extent_iou"], "max_depth_rmse_m": c["max_depth_rmse_m"],
                     "max_depth_bias_m": c["max_depth_bias_m"]})
    ref = runs["reference"]
    rows.append({"terrain": name, "mesh": "reference", "nodes": ref["nodes"],
                 "cpu_s": ref["cpu_s"], "time_steps": ref["time_steps"],
                 "min_inradius_m": ref["hydraulics"]["min_inradius_m"],
                 "extent_iou": 1.0, "max_depth_rmse_m": 0.0, "max_depth_bias_m": 0.0})
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--terrains", default=",".join(f'"{t}"' for t in DEFAULT_TERRAINS),
                   help='corpus terrains, as "name, seed N", comma-separated in quotes')
    p.add_argument("--noise", type=float, default=0.05)
    p.add_argument("--density", type=float, default=9.0)
    p.add_argument("--peak", type=float, default=120.0, help="the wave's peak inflow, m³/s")
    p.add_argument("--duration", type=float, default=900.0)
    p.add_argument("--reference-area", type=float, default=2.0)
    p.add_argument("--reference-lines", action="store_true",
                   help="the reference mesh's edges follow the true break lines too")
    p.add_argument("--out", default="bench_corpus_flood")
    p.add_argument("--reuse-reference", action="store_true",
                   help="keep the reference floods already in OUT (the same options)")
    args = p.parse_args(argv)
    names = [t.strip().strip('"') for t in args.terrains.split('",')]
    out = Path(args.out)
    rows = []
    for name in names:
        rows += run_case(name.strip('"'), args, out)
    io.write_json(out / "corpus_flood.json", rows)
    print(f"\n{args.noise * 100:g} cm noise, {args.density:g} points/m², peak {args.peak:g} m³/s, "
          f"{args.duration:g} s; reference: uniform {args.reference_area:g} m² on the true surface"
          + (" and its break lines" if args.reference_lines else ""))
    print(f"{'terrain':<36}{'mesh':<11}{'nodes':>7}{'CPU s':>8}{'steps':>7}{'min r_in m':>11}"
          f"{'IoU':>7}{'RMSE m':>8}{'bias m':>8}")
    for r in rows:
        print(f"{r['terrain']:<36}{r['mesh']:<11}{r['nodes']:>7,}{r['cpu_s']:>8.1f}"
              f"{r['time_steps']:>7,}{r['min_inradius_m']:>11.3f}{r['extent_iou']:>7.3f}"
              f"{r['max_depth_rmse_m']:>8.3f}{r['max_depth_bias_m']:>8.3f}")
    print("time step set most by (local x, y; inradius; share of the steps):")
    for r in rows:
        if r.get("step_set_by"):
            k = r["step_set_by"]
            print(f"  {r['terrain']:<36}{r['mesh']:<11}({k['x_local']:.0f}, {k['y_local']:.0f})"
                  f"  {k['inradius_m']:.2f} m  {100 * k['share_of_steps']:.0f} %")
    for name in names:
        ours, uni = ([r for r in rows if r["terrain"] == name and r["mesh"] == m][0]
                     for m in ("floodmesh", "uniform"))
        print(f"{name}: CPU {ours['cpu_s'] / uni['cpu_s']:.2f}x the uniform mesh's, steps "
              f"{ours['time_steps'] / uni['time_steps']:.2f}x; IoU {ours['extent_iou']:.3f} vs "
              f"{uni['extent_iou']:.3f}, RMSE {ours['max_depth_rmse_m']:.3f} vs "
              f"{uni['max_depth_rmse_m']:.3f} m")
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
