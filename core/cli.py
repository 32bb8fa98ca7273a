"""The ``floodmesh`` command: the whole chain (``run``, ``demo``) and one subcommand per step.

Errors in the input print one line naming the problem and the fix, and exit with code 2;
Ctrl-C exits with 130 and leaves no half-written file.
"""
from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from .errors import Cancelled, FloodMeshError
from .options import BREAKPOINT_METHODS, DEFAULT_MAX_TRIANGLES, LOG_KERNELS, RunOptions

DEFAULTS = RunOptions()


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (and exit code 2), like every other
    error; ``--help`` still prints the full usage."""

    def error(self, message):
        self.exit(2, f"floodmesh: error: {message} (see {self.prog} --help)\n")


class ProgressBar:
    """A one-line progress bar on stderr when it is a terminal; silent otherwise."""

    def __init__(self, label: str, stream=sys.stderr):
        self.label, self.stream = label, stream
        self.enabled = stream.isatty()
        self.last = -1

    def __call__(self, fraction: float):
        if not self.enabled:
            return
        percent = int(100 * min(max(fraction, 0.0), 1.0))
        if percent != self.last:
            self.last = percent
            bar = "#" * (percent // 4)
            self.stream.write(f"\r{self.label:<12} [{bar:<25}] {percent:3d}%")
            self.stream.flush()

    def log(self, message: str):
        if self.enabled:
            self.label = message.rstrip(".")
            self(max(self.last, 0) / 100)

    def close(self):
        if self.enabled and self.last >= 0:
            self.stream.write("\n")


def _add_chain_options(p: argparse.ArgumentParser):
    p.add_argument("--crs", help="CRS of the input when it has none or a wrong one (EPSG:XXXX)")
    p.add_argument("--cell-size", type=float, default=DEFAULTS.cell_size,
                   help="grid cell size d in metres (default %(default)s)")
    p.add_argument("--slope-method", choices=BREAKPOINT_METHODS, default=DEFAULTS.slope_method,
                   help="slope kernel, or log for Laplacian-of-Gaussian breakpoints "
                        "(default %(default)s)")
    p.add_argument("--s-crit", type=float, default=DEFAULTS.s_crit,
                   help="critical slope S_crit in degrees (default %(default)s)")
    _add_log_options(p)
    simplify = p.add_mutually_exclusive_group()
    simplify.add_argument("--keep-every", type=int, help="keep every n-th break-line point "
                          "(default 4)")
    simplify.add_argument("--tolerance", type=float, help="Douglas–Peucker tolerance in metres")
    p.add_argument("--min-angle", type=float, default=DEFAULTS.min_angle,
                   help="minimum triangle angle in degrees (default %(default)s)")
    p.add_argument("--max-area", type=float, default=DEFAULTS.max_area,
                   help="maximum triangle area in m² (default %(default)s)")
    _add_max_triangles(p)
    p.add_argument("--holdout", type=float, default=DEFAULTS.holdout,
                   help="fraction of points held out for assessment (default %(default)s)")
    p.add_argument("--seed", type=int, default=DEFAULTS.seed, help="random seed (default 0)")
    p.add_argument("--max-gap", type=float,
                   help="longest triangle edge bridged when gridding, m (default 10 cells)")
    p.add_argument("--classes", type=lambda s: tuple(int(c) for c in s.split(",")),
                   help="LAS classes to grid, e.g. 2,9 (default: 2 when classified)")


def _add_max_triangles(p: argparse.ArgumentParser):
    p.add_argument("--max-triangles", type=int, default=DEFAULT_MAX_TRIANGLES,
                   help="refuse, before meshing, a mesh estimated to have more triangles than "
                        "this (default %(default)s)")


def _add_log_options(p: argparse.ArgumentParser, *, response=True):
    p.add_argument("--sigma", type=float, default=DEFAULTS.sigma,
                   help="LoG Gaussian smoothing sigma in metres (default %(default)s)")
    p.add_argument("--log-kernel", choices=LOG_KERNELS, default=DEFAULTS.log_kernel,
                   help="LoG Laplacian: Pratt's 3x3 mask or the analytic kernel")
    if response:
        p.add_argument("--sensitivity", type=float, default=DEFAULTS.sensitivity,
                       help="LoG breakpoint threshold in metres (default %(default)s)")
        p.add_argument("--zero-crossings", action="store_true",
                       help="LoG breakpoints at zero crossings (mid-slope) instead of "
                            "|response| >= sensitivity (crests and toes)")


def _options(args) -> RunOptions:
    return RunOptions(cell_size=args.cell_size, slope_method=args.slope_method,
                      s_crit=args.s_crit, sigma=args.sigma, sensitivity=args.sensitivity,
                      log_kernel=args.log_kernel, zero_crossings=args.zero_crossings,
                      keep_every=args.keep_every, tolerance=args.tolerance,
                      min_angle=args.min_angle, max_area=args.max_area, holdout=args.holdout,
                      seed=args.seed, max_gap=args.max_gap, crs=args.crs, classes=args.classes,
                      max_triangles=args.max_triangles)


def _summary(report: dict, out: Path) -> str:
    rmse = report.get("rmse_m")
    rmse_text = f"{100 * rmse:.1f} cm" if rmse is not None else "n/a"
    classes = report.get("classes", {})
    return (f"{report['nodes']} nodes, {report['triangles']} triangles "
            f"(min angle {report['min_angle_deg']:.1f}°, max area {report['max_area_m2']:.1f} m²), "
            f"{report['n_breaklines']} break lines; holdout RMSE {rmse_text} on "
            f"{report['n_assessed']} points, {100 * classes.get('<10 cm', 0):.0f}% under 10 cm, "
            f"{100 * classes.get('>25 cm', 0):.1f}% over 25 cm\nwritten to {out}/")


def cmd_run(args):
    from .pipeline import run_pipeline

    bar = ProgressBar("run")
    try:
        report = run_pipeline(args.input, args.out, _options(args), progress=bar, log=bar.log)
    finally:
        bar.close()
    _print_notes(report["notes"])
    print(_summary(report, Path(args.out)))


def _print_notes(notes):
    """What FloodMesh assumed or repaired on the user's behalf, one line each on stderr."""
    for message in notes:
        print(f"floodmesh: note: {message}", file=sys.stderr)


def cmd_demo(args):
    from . import io
    from .demo import synthetic_floodplain

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    points, classes = synthetic_floodplain(seed=args.seed)
    source = out / "demo_points.laz"
    io.write_points_las(source, points, classes=classes)
    print(f"synthetic floodplain: {len(points):,} points (9 ground points/m²) in {source}")
    args.input = str(source)
    for name in ("crs", "max_gap", "classes", "keep_every", "tolerance"):
        setattr(args, name, None)
    cmd_run(args)


def cmd_grid(args):
    from . import io
    from .grid import grid_points_linear
    from .options import check_cell_size, check_holdout, check_max_gap
    from .points import split_holdout

    check_cell_size(args.cell_size)
    check_max_gap(args.max_gap)
    check_holdout(args.holdout)
    notes = []
    points = io.read_points(args.input, crs=args.crs, classes=args.classes, note=notes.append)
    _print_notes(notes)
    gridding, holdout = split_holdout(points, args.holdout, args.seed)
    dem = grid_points_linear(gridding, args.cell_size, max_gap=args.max_gap)
    io.write_raster(args.out, dem)
    if len(holdout):
        target = args.holdout_out or str(Path(args.out).with_name("holdout.gpkg"))
        io.write_points_gpkg(target, holdout.xyz, points.crs, layer="holdout")
        print(f"{len(holdout)} held-out points written to {target}")
    print(f"DEM {dem.shape[1]} x {dem.shape[0]} cells of {dem.cell_size} m written to {args.out}")


def cmd_slope(args):
    from . import io
    from .slope import laplacian_of_gaussian, slope

    dem = io.read_raster(args.dem, crs=args.crs)
    if args.method == "log":
        io.write_raster(args.out, laplacian_of_gaussian(dem, args.sigma, kernel=args.log_kernel))
        print(f"Laplacian-of-Gaussian response (sigma {args.sigma} m, m) written to {args.out}")
    else:
        io.write_raster(args.out, slope(dem, args.method))
        print(f"slope ({args.method}, degrees) written to {args.out}")


def cmd_breakpoints(args):
    import numpy as np

    from . import io
    from .breakpoints import classify_breakpoints, log_breakpoints

    grid = io.read_raster(args.slope, crs=args.crs)
    if args.sensitivity is not None:
        bp = log_breakpoints(grid, args.sensitivity, zero_crossings=args.zero_crossings)
    else:
        bp = classify_breakpoints(grid, args.s_crit)
    io.write_raster(args.out, bp, valid=np.isfinite(grid.values))
    print(f"{int(bp.values.sum())} breakpoints written to {args.out}")


def cmd_breaklines(args):
    from . import io
    from .breaklines import trace_breaklines

    bp = io.read_raster(args.breakpoints, crs=args.crs)
    bp = bp.with_values((bp.values == 1).astype("uint8"))
    slope_grid = io.read_raster(args.slope, crs=args.crs)
    dem = io.read_raster(args.dem, crs=args.crs)
    lines = trace_breaklines(bp, slope_grid, dem, args.s_crit, mode=args.mode,
                             min_points=args.min_points)
    io.write_breaklines(args.out, lines, dem.crs)
    print(f"{len(lines)} break lines written to {args.out}")


def cmd_simplify(args):
    from . import io
    from .raster import require_metric_crs
    from .simplify import simplify_douglas_peucker, simplify_keep_every

    lines = io.read_breaklines(args.breaklines)
    crs = require_metric_crs(args.crs or io.vector_crs(args.breaklines), Path(args.breaklines).name)
    if args.tolerance is not None:
        out = simplify_douglas_peucker(lines, args.tolerance)
    else:
        out = simplify_keep_every(lines, args.keep_every or 4)
    io.write_breaklines(args.out, out, crs)
    before, after = sum(len(x.coords) for x in lines), sum(len(x.coords) for x in out)
    print(f"{len(out)} break lines, {before} → {after} points, written to {args.out}")


def cmd_mesh(args):
    from . import io
    from .mesh import build_mesh, mesh_quality
    from .options import check_max_area, check_max_triangles, check_min_angle

    check_min_angle(args.min_angle)
    check_max_area(args.max_area)
    check_max_triangles(args.max_triangles)
    dem = io.read_raster(args.dem, crs=args.crs)
    lines = io.read_lines_gpkg(args.breaklines) if args.breaklines else []
    notes = []
    mesh = build_mesh(dem, lines, min_angle=args.min_angle, max_area=args.max_area,
                      max_triangles=args.max_triangles, note=notes.append)
    _print_notes(notes)
    io.write_mesh_2dm(args.out, mesh.nodes, mesh.triangles)
    if args.gpkg:
        io.write_mesh_gpkg(args.gpkg, mesh.nodes, mesh.triangles, dem.crs)
    q = mesh_quality(mesh, min_angle=args.min_angle, max_area=args.max_area)
    print(f"{q['nodes']} nodes, {q['triangles']} triangles (min angle {q['min_angle_deg']:.2f}°, "
          f"max area {q['max_area_m2']:.1f} m²) written to {args.out}")


def cmd_assess(args):
    import json

    from . import io
    from .accuracy import accuracy_statistics, residuals
    from .mesh import Mesh
    from .raster import require_metric_crs

    nodes, triangles = io.read_mesh_2dm(args.mesh)
    if Path(args.points).suffix.lower() in (".gpkg", ".shp", ".geojson"):
        xyz = io.read_points_vector(args.points)
        crs = args.crs or io.vector_crs(args.points)
    else:
        cloud = io.read_points(args.points, crs=args.crs)
        xyz, crs = cloud.xyz, cloud.crs
    crs = require_metric_crs(crs, Path(args.points).name)
    res = residuals(Mesh(nodes, triangles, crs), xyz)
    io.write_residuals(args.out, xyz, res, crs)
    stats = accuracy_statistics(res)
    if args.report:
        io.write_json(args.report, stats)
    print(json.dumps(stats, indent=2))


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="floodmesh", description="LiDAR to finite-element meshes for 2D hydrodynamic models.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=_Parser)

    p = sub.add_parser("run", help="the whole chain: points or DEM to mesh and report")
    p.add_argument("input", help="LAS/LAZ/XYZ point file or GeoTIFF DEM")
    p.add_argument("--out", required=True, help="output folder")
    _add_chain_options(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("demo", help="run the whole chain on a built-in synthetic floodplain")
    p.add_argument("--out", default="demo_output", help="output folder (default %(default)s)")
    _add_chain_options(p)
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("grid", help="grid points to a DEM by linear (TIN) interpolation")
    p.add_argument("input")
    p.add_argument("--cell-size", type=float, required=True)
    p.add_argument("--out", required=True, help="DEM GeoTIFF")
    p.add_argument("--crs")
    p.add_argument("--max-gap", type=float)
    p.add_argument("--classes", type=lambda s: tuple(int(c) for c in s.split(",")))
    p.add_argument("--holdout", type=float, default=0.0)
    p.add_argument("--holdout-out", help="held-out points (default holdout.gpkg beside --out)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=cmd_grid)

    p = sub.add_parser("slope", help="slope in degrees (or the LoG response) from a DEM")
    p.add_argument("dem")
    p.add_argument("--method", choices=BREAKPOINT_METHODS, default=DEFAULTS.slope_method)
    _add_log_options(p, response=False)
    p.add_argument("--out", required=True)
    p.add_argument("--crs")
    p.set_defaults(func=cmd_slope)

    p = sub.add_parser("breakpoints", help="thinned breakpoints where slope >= S_crit "
                                          "(or from a LoG response with --sensitivity)")
    p.add_argument("slope", help="slope raster (degrees), or LoG response raster (m)")
    p.add_argument("--s-crit", type=float, default=DEFAULTS.s_crit)
    p.add_argument("--sensitivity", type=float,
                   help="treat the input as a LoG response: breakpoints where |response| >= "
                        "this many metres")
    p.add_argument("--zero-crossings", action="store_true",
                   help="with --sensitivity: breakpoints at the response's zero crossings")
    p.add_argument("--out", required=True)
    p.add_argument("--crs")
    p.set_defaults(func=cmd_breakpoints)

    p = sub.add_parser("breaklines", help="trace break lines through breakpoints")
    p.add_argument("breakpoints")
    p.add_argument("--slope", required=True)
    p.add_argument("--dem", required=True)
    p.add_argument("--s-crit", type=float, default=DEFAULTS.s_crit)
    p.add_argument("--mode", choices=["auto", "flat", "steep"], default="auto")
    p.add_argument("--min-points", type=int, default=DEFAULTS.min_points)
    p.add_argument("--out", required=True)
    p.add_argument("--crs")
    p.set_defaults(func=cmd_breaklines)

    p = sub.add_parser("simplify", help="simplify break lines")
    p.add_argument("breaklines")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--keep-every", type=int)
    group.add_argument("--tolerance", type=float)
    p.add_argument("--out", required=True)
    p.add_argument("--crs")
    p.set_defaults(func=cmd_simplify)

    p = sub.add_parser("mesh", help="quality triangular mesh of a DEM honouring break lines")
    p.add_argument("dem")
    p.add_argument("--breaklines")
    p.add_argument("--min-angle", type=float, default=DEFAULTS.min_angle)
    p.add_argument("--max-area", type=float, default=DEFAULTS.max_area)
    _add_max_triangles(p)
    p.add_argument("--out", required=True, help="SMS 2DM mesh")
    p.add_argument("--gpkg", help="also write the triangles to this GeoPackage")
    p.add_argument("--crs")
    p.set_defaults(func=cmd_mesh)

    p = sub.add_parser("assess", help="residuals of check points against a mesh")
    p.add_argument("mesh", help="SMS 2DM mesh")
    p.add_argument("--points", required=True, help="check points: GeoPackage or point file")
    p.add_argument("--out", required=True, help="residuals GeoPackage")
    p.add_argument("--report", help="statistics as JSON")
    p.add_argument("--crs")
    p.set_defaults(func=cmd_assess)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    start = time.perf_counter()
    try:
        args.func(args)
    except FloodMeshError as exc:
        print(f"floodmesh: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, Cancelled):
        print("floodmesh: interrupted; no partial file was left behind", file=sys.stderr)
        return 130
    # Every file is in place: a Ctrl-C now, during interpreter teardown, would otherwise kill
    # the process with SIGINT and report a finished run as failed.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.stderr.isatty():
        print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
