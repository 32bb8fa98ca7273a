"""The ``floodmesh flood`` and ``floodmesh compare`` commands (added to ``cli.py``'s parser)."""
from __future__ import annotations

from pathlib import Path


def cmd_flood(args):
    from .cli import ProgressBar, _print_notes
    from .compare import compare_floods
    from .flood import load_scenario, run_flood

    scenario = load_scenario(args.scenario)
    runs = [(args.mesh, Path(args.out) if not args.reference else Path(args.out) / "mesh")]
    if args.reference:
        runs.append((args.reference, Path(args.out) / "reference"))
    reports = []
    for mesh, out in runs:
        bar = ProgressBar(f"flood {Path(mesh).stem}")
        try:
            reports.append(run_flood(mesh, scenario, out, crs=args.crs, progress=bar,
                                     log=bar.log))
        finally:
            bar.close()
        _print_notes(reports[-1]["notes"])
        print(_summary(reports[-1], out))
    if args.reference:
        print(_comparison(compare_floods(runs[0][1], runs[1][1], args.out,
                                         cell_size=args.cell_size)))


def _summary(report: dict, out) -> str:
    h, mb = report["hydraulics"], report["mass_balance"]
    return (f"{report['nodes']} nodes, {report['triangles']} triangles: ANUGA {report['cpu_s']:.1f} s "
            f"CPU, {report['time_steps']} steps (mean {report['mean_time_step_s']:.3g} s; "
            f"smallest inradius {h['min_inradius_m']:.3g} m); flooded "
            f"{report['flooded_area_m2']:.0f} m², max depth {report['max_depth_m']:.2f} m, "
            f"mass balance error {mb['error_m3']:.3g} m³ ({100 * mb['relative_error']:.2g} %)\n"
            f"written to {out}/")


def _comparison(c: dict) -> str:
    lines = [f"extent IoU {c['extent_iou']:.3f}, max-depth RMSE {c['max_depth_rmse_m']:.3f} m "
             f"(bias {c['max_depth_bias_m']:+.3f} m), CPU {c['mesh_cpu_s']:.1f} s against "
             f"{c['reference_cpu_s']:.1f} s ({c['cpu_ratio']:.2f}x)"]
    for o in c["observations"]:
        if o["difference_m"] is not None:
            lines.append(f"  {o['name']}: peak stage {o['mesh_peak_stage_m']:.2f} m, "
                         f"reference {o['reference_peak_stage_m']:.2f} m")
    return "\n".join(lines)


def cmd_compare(args):
    from .compare import compare_floods

    print(_comparison(compare_floods(args.mesh_run, args.reference_run, args.out,
                                     cell_size=args.cell_size)))
    print(f"comparison.json, depth_difference.tif and extent_difference.tif written to "
          f"{args.out}/")


def add_flood_commands(sub) -> None:
    p = sub.add_parser("flood", help="run a flood on a mesh with ANUGA: max depth, level, speed "
                                     "and arrival rasters, outflow hydrograph, mass balance")
    p.add_argument("mesh", help="SMS 2DM mesh (e.g. mesh.2dm of floodmesh run)")
    p.add_argument("--scenario", required=True, help="scenario JSON: inflows, boundaries, "
                   "roughness, buildings, duration (see the README)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--crs", help="CRS of the mesh (default: that of mesh.gpkg or dem.tif "
                                 "beside it)")
    p.add_argument("--reference", metavar="MESH", help="also run the scenario on this mesh "
                   "and compare (results in OUT/mesh, OUT/reference, comparison in OUT)")
    p.add_argument("--cell-size", type=float, default=1.0,
                   help="grid of the comparison, m (default %(default)s)")
    p.set_defaults(func=cmd_flood)

    p = sub.add_parser("compare", help="compare two flood runs: extent IoU, max-depth RMSE and "
                                       "bias, arrival times, observation stages, cost")
    p.add_argument("mesh_run", help="output folder of floodmesh flood on the mesh to judge")
    p.add_argument("reference_run", help="output folder of floodmesh flood on the reference")
    p.add_argument("--out", required=True, help="folder for comparison.json and the maps")
    p.add_argument("--cell-size", type=float, default=1.0,
                   help="grid of the comparison, m (default %(default)s)")
    p.set_defaults(func=cmd_compare)
