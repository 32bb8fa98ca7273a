"""Does the demo's levee hold? The built-in floodplain's river rising to a level just below
the levee crest (a level boundary across the river and its north floodplain at the west edge,
rising 1.2 m over --rise s, then held; walls elsewhere), flooded by ANUGA on FloodMesh's mesh and on a uniform mesh of the same node
count: how much water gets behind the levee.

    .venv/bin/python benchmarks/demo_levee.py [--out DIR] [--freeboard 0.15] [--duration 600] [--rise 400] [--flow-area A] [--reuse]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import shapely

from floodmesh.core.frontends import demo
from floodmesh.core import io
from floodmesh.core.flood.model import run_flood, scenario_from_dict
from floodmesh.core.steps.mesh import build_mesh, triangle_areas
from floodmesh.core.options import RunOptions
from floodmesh.core.chain.pipeline import run_pipeline

X0, Y0 = demo.DEMO_ORIGIN


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench_levee")
    p.add_argument("--freeboard", type=float, default=0.15,
                   help="the river's level below the lowest true crest, m (default 0.15)")
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--rise", type=float, default=400.0,
                   help="the river rises 1.2 m to its level over this many s, then holds")
    p.add_argument("--reuse", action="store_true", help="keep the demo mesh already in OUT")
    p.add_argument("--flow-area", type=float,
                   help="FloodMesh's mesh with run --flow-area, m² (default: run's default)")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mesh_path = out / "floodmesh" / "mesh.2dm"
    if not (args.reuse and mesh_path.is_file()):
        points, classes = demo.synthetic_floodplain(seed=0)
        source = out / "demo_points.laz"
        io.write_points_las(source, points, classes=classes)
        run_pipeline(source, out / "floodmesh", RunOptions(
            **({} if args.flow_area is None else {"flow_area": args.flow_area})))
    nodes, _ = io.read_mesh_2dm(mesh_path)
    dem = io.read_raster(out / "floodmesh" / "dem.tif")
    area = 40.0
    for _ in range(4):  # a uniform mesh of the same node count
        uniform = build_mesh(dem, [], min_angle=25.0, max_area=area)
        if abs(len(uniform.nodes) - len(nodes)) < 0.01 * len(nodes):
            break
        area *= len(uniform.nodes) / len(nodes)
    io.write_mesh_2dm(out / "uniform.2dm", uniform.nodes, uniform.triangles)

    levee, profile = demo.FEATURES["levee"]
    crest_line = shapely.intersection(levee, shapely.box(0, 0, demo.WIDTH, demo.HEIGHT))
    xy = np.asarray(shapely.segmentize(crest_line, 0.5).coords)
    crest = demo.ground_elevation(xy[:, 0], xy[:, 1])
    level = float(crest.min() - args.freeboard)
    # the west edge from the levee's north toe to the top: the river and its north floodplain
    west_toe = float(np.interp(0.0, *levee.xy)) + profile.half_base
    scenario = scenario_from_dict({
        "duration_s": args.duration, "output_interval_s": 10, "manning": 0.035,
        "boundaries": [{"kind": "level", "snap_m": 0.5,
                        "levels": [[0, level - 1.2], [args.rise, level]],
                        "line": [[X0, Y0 + west_toe], [X0, Y0 + demo.HEIGHT]]}]})
    behind = shapely.Polygon(np.vstack([
        np.column_stack([xy[:, 0], xy[:, 1] - profile.half_base]) + (X0, Y0),
        [[X0 + demo.WIDTH, Y0], [X0, Y0]]]))
    rows = []
    for label, path in (("floodmesh", mesh_path), ("uniform", out / "uniform.2dm")):
        report = run_flood(path, scenario, out / "runs" / label, crs=demo.DEMO_CRS)
        with np.load(out / "runs" / label / "triangles.npz") as r:
            centroids = r["nodes"][r["triangles"]][:, :, :2].mean(axis=1)
            mesh_nodes, mesh_tri, depth = r["nodes"], r["triangles"], r["max_depth"]
        inside = shapely.contains_xy(behind, centroids[:, 0], centroids[:, 1])
        areas = np.abs(triangle_areas(mesh_nodes, mesh_tri))
        wet_behind = inside & (depth > 0.05)
        crest_on_mesh = _crest_on_mesh(mesh_nodes, mesh_tri, xy + (X0, Y0))
        rows.append({"mesh": label, "nodes": report["nodes"], "cpu_s": report["cpu_s"],
                     "min_inradius_m": report["hydraulics"]["min_inradius_m"],
                     "flooded_behind_levee_m2": float(areas[wet_behind].sum()),
                     "volume_behind_levee_m3": float((areas * depth)[inside].sum()),
                     "crest_lowest_m": float(np.nanmin(crest_on_mesh)),
                     "crest_max_lowering_m": float(np.nanmax(crest - crest_on_mesh))})
    io.write_json(out / "levee.json", {"level_m": level, "true_crest_min_m": float(crest.min()),
                                      "rows": rows})
    print(f"river level {level:.2f} m, true crest {crest.min():.2f}–{crest.max():.2f} m")
    print(f"{'mesh':<11}{'nodes':>7}{'CPU s':>8}{'min r_in m':>11}{'crest min m':>12}"
          f"{'lowered m':>10}{'wet behind m²':>15}{'volume m³':>11}")
    for r in rows:
        print(f"{r['mesh']:<11}{r['nodes']:>7}{r['cpu_s']:>8.1f}{r['min_inradius_m']:>11.3f}"
              f"{r['crest_lowest_m']:>12.2f}{r['crest_max_lowering_m']:>10.2f}"
              f"{r['flooded_behind_levee_m2']:>15.0f}{r['volume_behind_levee_m3']:>11.1f}")
    print(json.dumps(rows))


def _crest_on_mesh(nodes, triangles, xy):
    """The mesh's surface (linear on each triangle) at the crest points."""
    from matplotlib.tri import LinearTriInterpolator, Triangulation

    tri = Triangulation(nodes[:, 0], nodes[:, 1], triangles)
    return np.ma.filled(LinearTriInterpolator(tri, nodes[:, 2])(xy[:, 0], xy[:, 1]), np.nan)


if __name__ == "__main__":
    main()
