"""The ``floodmesh flood`` and ``floodmesh compare`` commands (added to ``cli.py``'s parser)."""
from __future__ import annotations

from pathlib import Path

from .. import io
from ..flood.compare import COMPARISON_FILES, compare_floods
from ..flood.model import FLOW_FIELD_FILES, check_flood_inputs, load_scenario, run_flood
from ..io.outputs import check_output_folder
from ..flood.summary import time_step_summary
from ..options import check_comparison_cell_size, check_size_field_area
from ..steps.hydraulic_lines import flood_size_field, wet_zone
from .console import ProgressBar, print_notes


def cmd_flood(args):
    if args.size_field_area is not None:
        check_size_field_area(args.size_field_area)
    if args.reference:
        check_comparison_cell_size(args.cell_size)
    scenario = load_scenario(args.scenario)
    runs = [(args.mesh, Path(args.out) if not args.reference else Path(args.out) / "mesh")]
    if args.reference:
        runs.append((args.reference, Path(args.out) / "reference"))
    for mesh, out in runs:  # every flood's folder and mesh, before minutes of the first
        check_flood_inputs(mesh, scenario, out, crs=args.crs)
    if args.reference:
        check_output_folder(args.out, [out for _, out in runs], COMPARISON_FILES)
    reports = []
    for mesh, out in runs:
        bar = ProgressBar(f"flood {Path(mesh).stem}")
        try:
            reports.append(run_flood(mesh, scenario, out, crs=args.crs, progress=bar,
                                     log=bar.log))
        finally:
            bar.close()
        print_notes(reports[-1]["notes"])
        print(_summary(reports[-1], out))
        if args.size_field_area is not None:
            print(_write_flow_fields(out, args.size_field_area, reports[-1]))
    if args.reference:
        print(_comparison(compare_floods(runs[0][1], runs[1][1], args.out,
                                         cell_size=args.cell_size)))


def _write_flow_fields(out: Path, wet_area: float, report: dict) -> str:
    """size_field.tif and wet_zone.gpkg (``FLOW_FIELD_FILES``) from the run's max depth, for a
    second mesh."""
    depth = io.read_raster(out / "max_depth.tif", elevations=False)
    wet = report["scenario"]["wet_depth_m"]
    size_field, zone = FLOW_FIELD_FILES
    io.write_raster(out / size_field, flood_size_field(depth, wet_area=wet_area, wet_depth=wet),
                    quantity="size_field")
    write_zone(out / zone, wet_zone(depth, wet_depth=wet), depth.crs)
    return (f"size_field.tif ({wet_area} m² where it flooded) and wet_zone.gpkg written: "
            f"floodmesh run DEM --size-field {out}/size_field.tif --flow-zone "
            f"{out}/wet_zone.gpkg meshes for this flood")


def write_zone(path, zone, crs) -> None:
    """A (Multi)Polygon as a GeoPackage of polygons (layer wet_zone)."""
    # lazy: GEOS loads only when this runs
    import shapely.geometry

    parts = list(getattr(zone, "geoms", [zone]))
    io.write_gpkg(path, "wet_zone", "Polygon", {"id": "int"},
                   ({"geometry": shapely.geometry.mapping(g), "properties": {"id": k + 1}}
                    for k, g in enumerate(parts)), crs)


def _summary(report: dict, out) -> str:
    h, mb = report["hydraulics"], report["mass_balance"]
    lines = [f"{report['nodes']} nodes, {report['triangles']} triangles: ANUGA "
             f"{report['cpu_s']:.1f} s CPU, {report['time_steps']} steps (mean "
             f"{report['mean_time_step_s']:.3g} s; smallest inradius {h['min_inradius_m']:.3g} m); "
             f"flooded {report['flooded_area_m2']:.0f} m², max depth {report['max_depth_m']:.2f} "
             f"m, mass balance error {mb['error_m3']:.3g} m³ ({_share(mb)})",
             time_step_summary(report), f"written to {out}/"]
    return "\n".join(line for line in lines if line)


def _share(mb: dict) -> str:
    """The mass balance error's share, or why there is none."""
    if mb["relative_error"] is None:
        return (f"no share: under {mb['relative_error_floor_m3']:.3g} m³, 1 mm over the mesh, "
                "came in or was there")
    return f"{100 * mb['relative_error']:.2g} %"


def _comparison(c: dict) -> str:
    flood = (f"extent IoU {c['extent_iou']:.3f}, max-depth RMSE {c['max_depth_rmse_m']:.3f} m "
             f"(bias {c['max_depth_bias_m']:+.3f} m)" if c["extent_iou"] is not None else
             f"neither flood is deeper than {c['wet_depth_m']:g} m anywhere: no extent or depth "
             "to compare")
    lines = [f"{flood}, CPU {c['mesh_cpu_s']:.1f} s against {c['reference_cpu_s']:.1f} s "
             f"({c['cpu_ratio']:.2f}x)"]
    for o in c["observations"]:
        mesh, reference = (o[f"{run}_peak_stage_m"] for run in ("mesh", "reference"))
        if mesh is not None or reference is not None:
            only = "" if o["wet"] == "both" else f", wet on the {o['wet']}"
            lines.append(f"  {o['name']}: peak stage {_stage(mesh)}, reference "
                         f"{_stage(reference)}; peak depth difference "
                         f"{o['peak_depth_difference_m']:+.2f} m{only}")
    return "\n".join(lines)


def _stage(stage) -> str:
    return "dry" if stage is None else f"{stage:.2f} m"


def cmd_compare(args):
    print(_comparison(compare_floods(args.mesh_run, args.reference_run, args.out,
                                     cell_size=args.cell_size)))
    print(f"comparison.json, depth_difference.tif and extent_difference.tif written to "
          f"{args.out}/")


def add_flood_commands(sub) -> None:
    p = sub.add_parser("flood", help="run a flood on a mesh with ANUGA: max depth, level, speed "
                                     "and arrival rasters, outflow hydrograph, mass balance")
    p.add_argument("mesh", help="SMS 2DM mesh (e.g. mesh.2dm of floodmesh run)")
    p.add_argument("--scenario", required=True, help="scenario JSON: inflows, boundaries, "
                   "roughness, buildings, duration (see docs/user-guide.md, The scenario)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--crs", help="CRS of the mesh (default: its .prj, else that of "
                                 "mesh.gpkg or dem.tif beside it)")
    p.add_argument("--reference", metavar="MESH", help="also run the scenario on this mesh "
                   "and compare (results in OUT/mesh, OUT/reference, comparison in OUT)")
    p.add_argument("--cell-size", type=float, default=1.0,
                   help="grid of the comparison, m (default %(default)s)")
    p.add_argument("--size-field-area", type=float, metavar="M2",
                   help="also write size_field.tif (M2 where it flooded, 5 m around) and "
                        "wet_zone.gpkg, for a second mesh (run --size-field, --flow-zone)")
    p.set_defaults(func=cmd_flood)

    p = sub.add_parser("compare", help="compare two flood runs: extent IoU, max-depth RMSE and "
                                       "bias, arrival times, observation stages, cost")
    p.add_argument("mesh_run", help="output folder of floodmesh flood on the mesh to judge")
    p.add_argument("reference_run", help="output folder of floodmesh flood on the reference")
    p.add_argument("--out", required=True, help="folder for comparison.json and the maps")
    p.add_argument("--cell-size", type=float, default=1.0,
                   help="grid of the comparison, m (default %(default)s)")
    p.set_defaults(func=cmd_compare)
