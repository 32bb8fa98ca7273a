"""Merewether: FloodMesh's defaults at several flow areas, each against a uniform mesh of its
node count (CPU of the two interleaved, best of --repeat), and uniform meshes within ±1 % of
that node count, to show how much the comparison itself varies (the noise band).

    .venv/bin/python benchmarks/merewether_sweep.py --flow-areas 21 22 23 24 25 [--duration 300]
    .venv/bin/python benchmarks/merewether_sweep.py --reference-only   # the 2 m² reference alone

The reference (uniform, --reference-area) is flooded once into OUT/runs/reference and reused;
the scenario and domain are merewether.py's.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from merewether import CRS, DEM, scenario, uniform_mesh, write_domain  # noqa: E402

from floodmesh.core import io  # noqa: E402
from floodmesh.core.flood.compare import compare_floods  # noqa: E402
from floodmesh.core.flood.model import load_scenario, run_flood  # noqa: E402
from floodmesh.core.steps.mesh import build_mesh, user_domain  # noqa: E402
from floodmesh.core.options import RunOptions  # noqa: E402
from floodmesh.core.chain.pipeline import run_pipeline  # noqa: E402


def matched_area(dem, domain, nodes_wanted):
    """The max area uniform_mesh settles on for ``nodes_wanted`` (the same tuning)."""
    area = 20.0
    for _ in range(4):
        n = len(build_mesh(dem, [], min_angle=25.0, max_area=area, domain=domain).nodes)
        if abs(n - nodes_wanted) < 0.01 * nodes_wanted:
            break
        area *= n / nodes_wanted
    return area


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench_merewether_sweep")
    p.add_argument("--duration", type=float, default=300.0)
    p.add_argument("--reference-area", type=float, default=2.0)
    p.add_argument("--flow-areas", type=float, nargs="*", default=[25.0])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--noise", type=float, nargs="*", default=[0.99, 1.01],
                   help="uniform max areas as factors of the matched one (the noise band)")
    p.add_argument("--reference-only", action="store_true")
    args = p.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_domain(out / "domain.gpkg")
    sc = load_scenario(scenario(out, args.duration, False))
    dem = io.read_raster(DEM, crs=CRS)
    domain = user_domain(io.read_boundary(out / "domain.gpkg"), dem)
    ref = out / "runs" / "reference"
    if args.reference_only:
        uniform_mesh(dem, domain, None, out / "reference.2dm", max_area=args.reference_area)
        r = run_flood(out / "reference.2dm", sc, ref, crs=CRS)
        print(f"reference: {r['nodes']} nodes, {r['cpu_s']:.1f} s CPU, {r['time_steps']} steps")
        return

    def flood(mesh, label, runs=1):
        cpus = []
        for _ in range(runs):
            r = run_flood(mesh, sc, out / "runs" / label, crs=CRS)
            cpus.append(r["cpu_s"])
        r["cpu_s"] = min(cpus)
        return r

    rows = []
    for area in args.flow_areas:
        label = f"floodmesh-{area:g}"
        report = run_pipeline(DEM, out / label, RunOptions(
            crs=CRS, boundary=str(out / "domain.gpkg"), flow_area=area))
        m = uniform_mesh(dem, domain, report["nodes"], out / f"uniform-{area:g}.2dm")
        cpu = {label: [], f"uniform-{area:g}": []}
        for _ in range(args.repeat):  # interleaved: the machine's load falls on both alike
            for name, mesh in ((label, out / label / "mesh.2dm"),
                               (f"uniform-{area:g}", out / f"uniform-{area:g}.2dm")):
                r = flood(mesh, name)
                cpu[name].append(r["cpu_s"])
                cpu[name + "/r"] = r
        for name in (label, f"uniform-{area:g}"):
            r = cpu[name + "/r"]
            rows.append({"mesh": name, "nodes": r["nodes"], "cpu_s": min(cpu[name]),
                         "cpu_runs_s": cpu[name], "time_steps": r["time_steps"]})
        print(f"{label}: {rows[-2]}\n  {rows[-1]}  (load {os.getloadavg()[0]:.1f})", flush=True)
        # the noise band: uniform meshes a little finer and coarser than the matched one
        for f in args.noise:
            name = f"uniform-{area:g}-x{f:g}"
            mesh = build_mesh(dem, [], min_angle=25.0, max_area=matched_area(
                dem, domain, report["nodes"]) * f, domain=domain)
            io.write_mesh_2dm(out / f"{name}.2dm", mesh.nodes, mesh.triangles)
            r = flood(out / f"{name}.2dm", name)
            rows.append({"mesh": name, "nodes": r["nodes"], "cpu_s": r["cpu_s"],
                         "cpu_runs_s": [r["cpu_s"]], "time_steps": r["time_steps"]})
            print("  ", rows[-1], flush=True)
    while not (ref / "report.json").is_file():  # the reference may be running beside this
        time.sleep(10)
    for row in rows:
        c = compare_floods(out / "runs" / row["mesh"], ref, out / "compare" / row["mesh"])
        row.update(extent_iou=c["extent_iou"], max_depth_rmse_m=c["max_depth_rmse_m"])
    io.write_json(out / "sweep.json", {"duration_s": args.duration, "rows": rows})
    print(f"\nMerewether {args.duration:.0f} s, reference uniform {args.reference_area} m²; CPU "
          f"best of {args.repeat}, interleaved with its uniform mesh")
    print(f"{'mesh':<20}{'nodes':>7}{'CPU s':>8}{'steps':>7}{'IoU':>7}{'RMSE m':>8}")
    for row in rows:
        print(f"{row['mesh']:<20}{row['nodes']:>7}{row['cpu_s']:>8.2f}{row['time_steps']:>7}"
              f"{row['extent_iou']:>7.3f}{row['max_depth_rmse_m']:>8.3f}")


if __name__ == "__main__":
    main()
