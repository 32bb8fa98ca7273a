"""The ``floodmesh`` command: the whole chain (``run``, ``demo``) and one subcommand per step.

Errors in the input print one line naming the problem and the fix, and exit with code 2;
Ctrl-C exits with 130 and leaves no half-written file.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

from .. import io
from ..chain import files as steps
from ..errors import (Cancelled, FloodMeshError, Terminated, interrupts_unwrapped,
                      stop_signals_as_interrupts)
from ..options import (BREAKPOINT_METHODS, DEFAULT_MAX_TRIANGLES, EXPORT_FORMATS, LOG_KERNELS,
                       NODE_ELEVATIONS, RunOptions, parse_classes, parse_formats,
                       whole_number)
from .console import ProgressBar, print_note, print_notes
from .flood_cli import add_flood_commands
from .process import end_process, keep_freed_memory

DEFAULTS = RunOptions()


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (and exit code 2), like every other
    error; ``--help`` still prints the full usage."""

    def error(self, message):
        self.exit(2, f"floodmesh: error: {message} (see {self.prog} --help)\n")


def _positive(kind):
    def parse(text):
        value = kind(text)
        if not value > 0:
            raise argparse.ArgumentTypeError(f"must be positive, got {text}")
        return value
    return parse


def _whole(text: str) -> int:
    """An integer option: "3" or "3.0", as RunOptions takes it (``whole_number``)."""
    try:
        value = whole_number(text, "it")
    except FloodMeshError:
        value = None
    if not isinstance(value, int):
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text}")
    return value


def _list(kind):
    """``"400,200,100"`` → (400.0, 200.0, 100.0), each parsed by ``kind``."""
    def parse(text):
        return tuple(kind(item) for item in text.split(",") if item.strip())
    return parse


def _las_classes(text: str) -> tuple[int, ...] | None:
    """``--classes 2,9``: comma-separated LAS class numbers 0-255 (``parse_classes``)."""
    try:
        return parse_classes(text)
    except FloodMeshError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _add_chain_options(p: argparse.ArgumentParser, *, series=False):
    """The chain's options; for ``series`` lists of maximum areas and simplifications instead of
    one of each, and no solver formats."""
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
    if series:
        simplify.add_argument("--keep-every", type=_list(_positive(_whole)), default=(4,),
                              help="keep every n-th break-line point, one mesh per n and "
                                   "area, e.g. 2,4,8 (default 4)")
        simplify.add_argument("--tolerances", type=_list(_positive(float)),
                              help="Douglas–Peucker tolerances in metres, one mesh per "
                                   "tolerance and area, e.g. 0.5,1,2")
        p.set_defaults(tolerance=None, spline=None, formats="", max_area=DEFAULTS.max_area)
    else:
        simplify.add_argument("--keep-every", type=_whole, help="keep every n-th break-line point "
                              "(default 4)")
        simplify.add_argument("--tolerance", type=float,
                              help="Douglas–Peucker tolerance in metres")
        simplify.add_argument("--spline", type=float, metavar="TOLERANCE",
                              help="cubic smoothing spline within this many metres")
    p.add_argument("--min-distance", type=float,
                   help="merge break lines (and vertices) closer than this, m (default d/2)")
    p.add_argument("--min-length", type=float, default=DEFAULTS.min_length,
                   help="drop break lines shorter than this, m (default %(default)s)")
    p.add_argument("--min-spacing", type=float,
                   help="smallest node spacing a flood model affords, m: detected lines kept "
                        "2x this from the domain edge and this from other lines, vertices "
                        "and lines meeting at a sharp corner this far apart (default d; 0: off)")
    p.add_argument("--flow-zone", help="polygon file (wet_zone.gpkg of floodmesh flood "
                   "--size-field-area): detected lines kept only inside it")
    _add_domain_options(p)
    p.add_argument("--min-angle", type=float, default=DEFAULTS.min_angle,
                   help="minimum triangle angle in degrees (default %(default)s)")
    if series:
        p.add_argument("--max-areas", type=_list(float), default=(400, 200, 100, 50),
                       help="maximum triangle areas in m², one mesh each (default 400,200,100,50)")
    else:
        p.add_argument("--max-area", type=float, default=DEFAULTS.max_area,
                       help="maximum triangle area in m² (default %(default)s)")
        _add_size_options(p)
        p.add_argument("--refine", action="store_true",
                       help="refine until the residual bounds hold (the method's step 9): "
                            "triangles whose points' RMS residual exceeds their noise by "
                            "--lower (in quadrature) get smaller, points beyond --upper go into "
                            "the mesh")
        p.add_argument("--lower", type=float, default=DEFAULTS.refine_lower,
                       help="with --refine, m (default %(default)s)")
        p.add_argument("--upper", type=float, default=DEFAULTS.refine_upper,
                       help="with --refine, m (default %(default)s)")
        _add_terrain_fit_options(p)
    _add_max_triangles(p)
    p.add_argument("--holdout", type=float, default=DEFAULTS.holdout,
                   help="fraction of points held out for assessment (default %(default)s)")
    p.add_argument("--seed", type=_whole, default=DEFAULTS.seed, help="random seed (default 0)")
    p.add_argument("--max-gap", type=float,
                   help="longest triangle edge bridged when gridding, m (default 10 cells)")
    p.add_argument("--classes", type=_las_classes,
                   help="LAS classes to grid, e.g. 2,9 (default: 2 when classified)")
    if not series:
        p.add_argument("--formats", default="",
                       help="solver exports written as mesh.<ext> beside mesh.2dm, "
                            f"comma-separated: {','.join(EXPORT_FORMATS)}")


def _add_size_options(p: argparse.ArgumentParser):
    p.add_argument("--size-field", metavar="RASTER|slope",
                   help="local maximum triangle areas: a raster of m², or 'slope' (max area on "
                        "flat ground down to --min-area where the slope reaches S_crit)")
    p.add_argument("--min-area", type=float,
                   help="smallest area of the slope size field, m² (default max area / 25)")


def _add_terrain_fit_options(p: argparse.ArgumentParser):
    p.add_argument("--localise", action=argparse.BooleanOptionalAction, default=DEFAULTS.localise,
                   help="move break-line vertices onto the kink of a two-plane (hinge) fit to "
                        "the measured points, z from the fit (default on)")
    p.add_argument("--node-elevation", choices=NODE_ELEVATIONS, default=DEFAULTS.node_elevation,
                   help="z of nodes off the break lines: a local least-squares plane of the "
                        "measured points, or bilinear from the DEM (default %(default)s)")
    p.add_argument("--node-radius", type=float,
                   help="radius of the node elevation plane fit, m (default from the point "
                        "density and noise)")
    p.add_argument("--join-gap", type=float,
                   help="join localised break-line pieces whose ends face each other across at "
                        "most this gap, m (default 10 cell sizes; 0: off)")
    p.add_argument("--misfit-passes", type=_whole, default=DEFAULTS.misfit_passes,
                   help="passes splitting the triangles whose points misfit the mesh beyond "
                        "their noise (folds no break line describes: crossings, junctions, "
                        "rounded ends), with plane node elevations (default %(default)s; 0: off)")
    p.add_argument("--far-field-area", type=float,
                   help="larger triangles, up to this many m², away from the break lines where "
                        "the terrain is plane (default: max area everywhere)")
    _add_flow_area(p, thinned=True)
    _add_conforming(p)


def _add_flow_area(p: argparse.ArgumentParser, *, thinned: bool = False):
    """--flow-area of run and the mesh step (and QGIS's FLOW_AREA); ``thinned``: run's, which
    also thins the break lines there."""
    lines = ("; break lines where a flood may go thinned to that triangle's side where "
             "straight and even" if thinned else "")
    p.add_argument("--flow-area", type=float,
                   help="smaller triangles, at most this many m², where water flows: ground "
                        f"less than 1 m above a drainage line draining 5000 m²{lines} (default "
                        "23 cells: 23 m² at 1 m; 0: off)")


def _add_conforming(p: argparse.ArgumentParser):
    p.add_argument("--conforming-delaunay", dest="conforming", action="store_true",
                   help="a conforming Delaunay mesh (Triangle's switch D; 10–20%% more nodes), "
                        "which some solvers want")


def _add_domain_options(p: argparse.ArgumentParser):
    p.add_argument("--boundary", help="polygon file: the model domain, holes (buildings, "
                   "islands) left out (default: the data's extent)")
    p.add_argument("--lines", dest="user_lines",
                   help="line file: your own break or structure lines, kept as mesh edges "
                        "(2-D lines take z from the DEM)")


def _add_max_triangles(p: argparse.ArgumentParser):
    p.add_argument("--max-triangles", type=_whole, default=DEFAULT_MAX_TRIANGLES,
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
                      keep_every=args.keep_every, tolerance=args.tolerance, spline=args.spline,
                      min_distance=args.min_distance, min_length=args.min_length,
                      min_spacing=getattr(args, "min_spacing", None),
                      flow_zone=getattr(args, "flow_zone", None),
                      boundary=args.boundary, user_lines=args.user_lines,
                      size_field=getattr(args, "size_field", None),
                      min_area=getattr(args, "min_area", None),
                      refine=getattr(args, "refine", False),
                      refine_lower=getattr(args, "lower", DEFAULTS.refine_lower),
                      refine_upper=getattr(args, "upper", DEFAULTS.refine_upper),
                      min_angle=args.min_angle, max_area=args.max_area, holdout=args.holdout,
                      seed=args.seed, max_gap=args.max_gap, crs=args.crs, classes=args.classes,
                      formats=parse_formats(args.formats),
                      max_triangles=args.max_triangles,
                      localise=getattr(args, "localise", DEFAULTS.localise),
                      node_elevation=getattr(args, "node_elevation", DEFAULTS.node_elevation),
                      node_radius=getattr(args, "node_radius", None),
                      join_gap=getattr(args, "join_gap", None),
                      misfit_passes=getattr(args, "misfit_passes", DEFAULTS.misfit_passes),
                      far_field_area=getattr(args, "far_field_area", None),
                      flow_area=getattr(args, "flow_area", None),
                      conforming=getattr(args, "conforming", DEFAULTS.conforming),
                      workers=getattr(args, "workers", None),
                      scheduler=getattr(args, "scheduler", None))


def _input(args):
    """The run's ``source.Source``, decided here once: one file, or the tiles of the folders,
    patterns and files given; with --skip-unreadable-tiles, unreadable tiles left out."""
    # lazy: PROJ loads only when this runs
    from ..chain.source import open_source

    items = args.input if isinstance(args.input, list) else [args.input]
    return open_source(items[0] if len(items) == 1 else items,
                       skip_unreadable=getattr(args, "skip_unreadable_tiles", False))


def _add_dask_options(p: argparse.ArgumentParser):
    p.add_argument("--workers", type=_whole,
                   help="point tiles: threads reading them, or local Dask worker processes "
                        "(default one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="point tiles: send the per-tile work to this running dask.distributed "
                        "scheduler (tcp://HOST:8786), or 'local' to a local cluster (default: "
                        "the tiles are read into memory where they fit with their grid, else "
                        "gridded tile by tile on a local cluster)")
    p.add_argument("--skip-unreadable-tiles", action="store_true",
                   help="point tiles: leave out a tile that cannot be read (a truncated or "
                        "corrupt file), with a note naming it, instead of stopping")


def _summary(report: dict, out: Path) -> str:
    n, held = report["n_assessed"], report["n_holdout"]
    if n:
        classes = report["classes"]
        accuracy = (f"holdout RMSE {100 * report['rmse_m']:.1f} cm on {n} points, "
                    f"{100 * classes['<10 cm']:.0f}% under 10 cm, "
                    f"{100 * classes['>25 cm']:.1f}% over 25 cm")
    elif held:
        accuracy = f"not assessed: none of the {held} held-out points lies inside the mesh"
    else:
        accuracy = "not assessed: no check points were held out"
    return (f"{report['nodes']} nodes, {report['triangles']} triangles "
            f"(min angle {report['min_angle_deg']:.1f}°, max area {report['max_area_m2']:.1f} m²), "
            f"{report['n_breaklines']} break lines; {accuracy}\nwritten to {out}/")


def cmd_run(args):
    # lazy: numba, PROJ and GEOS load only when this runs
    from ..chain.pipeline import run_pipeline

    bar = ProgressBar("run")
    try:
        report = run_pipeline(_input(args), args.out, _options(args), progress=bar,
                              log=bar.log)
    finally:
        bar.close()
    print_notes(report["notes"])
    print(_summary(report, Path(args.out)))


def cmd_series(args):
    # lazy: numba, PROJ and GEOS load only when this runs
    from ..chain.series import run_series, settings_grid

    if args.tolerances:
        settings = settings_grid(args.max_areas, "douglas-peucker", args.tolerances)
    else:
        settings = settings_grid(args.max_areas, "keep-every", args.keep_every)
    args.keep_every = None  # the series' simplifications are in settings
    bar = ProgressBar("series")
    try:
        result = run_series(_input(args), args.out, _options(args), settings, progress=bar,
                            log=bar.log)
    finally:
        bar.close()
    print_notes(result["notes"])
    print(f"{'setting':<14}{'nodes':>8}{'RMSE cm':>9}{'max cm':>8}{'>25 cm':>8}")
    for row in result["rows"]:
        rmse, top, over = row["rmse_m"], row["max_abs_m"], row["share_over_25cm"]
        print(f"{row['label']:<14}{row['nodes']:>8}"
              f"{'n/a' if rmse is None else format(100 * rmse, '.1f'):>9}"
              f"{'n/a' if top is None else format(100 * top, '.1f'):>8}"
              f"{'n/a' if over is None else format(100 * over, '.1f') + '%':>8}")
    print(f"series.csv, series.json, series.png and {len(result['rows'])} meshes written to "
          f"{args.out}/")


def cmd_demo(args):
    # lazy: GEOS loads only when this runs
    from .demo import synthetic_floodplain

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    points, classes = synthetic_floodplain(seed=args.seed)
    source = out / "demo_points.laz"
    io.write_points_las(source, points, classes=classes)
    print(f"synthetic floodplain: {len(points):,} points (9 ground points/m²) in {source}")
    args.input = str(source)
    for name in ("crs", "max_gap", "classes"):
        setattr(args, name, None)
    cmd_run(args)


def _step(label: str, func, *args, **options) -> dict:
    """Run one of ``steps`` with a progress bar and the notes on stderr; print its summary."""
    bar = ProgressBar(label)
    try:
        result = func(*args, progress=bar, note=print_note, **options)
    finally:
        bar.close()
    print(result["summary"])
    return result


def cmd_grid(args):
    _step("grid", steps.grid, _input(args), args.out, cell_size=args.cell_size, crs=args.crs,
          classes=args.classes, max_gap=args.max_gap, holdout=args.holdout, seed=args.seed,
          holdout_output=_holdout_target(args) if args.holdout else None,
          workers=args.workers, scheduler=args.scheduler)


def _holdout_target(args) -> str:
    return args.holdout_out or str(Path(args.out).with_name("holdout.gpkg"))


def cmd_slope(args):
    _step(args.method, steps.slope, args.dem, args.out, method=args.method, sigma=args.sigma,
          log_kernel=args.log_kernel, crs=args.crs)


def cmd_breakpoints(args):
    _step("breakpoints", steps.breakpoints, args.slope, args.out, s_crit=args.s_crit,
          sensitivity=args.sensitivity, zero_crossings=args.zero_crossings, crs=args.crs)


def cmd_breaklines(args):
    _step("breaklines", steps.trace, args.breakpoints, args.slope, args.dem, args.out,
          s_crit=args.s_crit, mode=args.mode, min_points=args.min_points,
          min_length=args.min_length, join=not args.no_join, seed=args.seed, crs=args.crs)


def cmd_simplify(args):
    method, amount = RunOptions(keep_every=args.keep_every, tolerance=args.tolerance,
                                spline=args.spline).simplification()
    _step("simplify", steps.simplify, args.breaklines, args.out, method=method, amount=amount,
          min_distance=args.min_distance, crs=args.crs)


def cmd_mesh(args):
    _step("mesh", steps.mesh, args.dem, args.out, breaklines=args.breaklines,
          boundary=args.boundary, user_lines=args.user_lines, size_field=args.size_field,
          min_area=args.min_area, flow_area=args.flow_area, conforming=args.conforming,
          min_angle=args.min_angle, max_area=args.max_area, max_triangles=args.max_triangles,
          triangles=args.gpkg, crs=args.crs)


def cmd_assess(args):
    result = _step("assess", steps.assess, args.mesh, args.points, args.out,
                   report=args.report, png=args.png, crs=args.crs)
    for path in result.get("figures", ()):
        print(f"{Path(path).name} written to {args.png}", file=sys.stderr)


def cmd_export(args):
    _step("export", steps.export, args.mesh, args.output, fmt=args.format, crs=args.crs,
          open_boundaries=args.open_boundaries, snap=args.snap, regions=args.regions,
          material_field=args.material_field, datum_offset=args.datum_offset,
          element_elevations=args.element_elevations, breaklines=args.breaklines)


def cmd_refine(args):
    _step("refine", steps.refine, args.dem, args.points, args.out, breaklines=args.breaklines,
          boundary=args.boundary, user_lines=args.user_lines, check=args.check,
          min_angle=args.min_angle, max_area=args.max_area, lower=args.lower, upper=args.upper,
          target_rmse=args.target_rmse, target_max=args.target_max, max_nodes=args.max_nodes,
          max_rounds=args.max_rounds, noise=args.noise, report=args.report, crs=args.crs)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="floodmesh", description="LiDAR to finite-element meshes for 2D hydrodynamic models.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=_Parser)

    _add_chain_commands(sub)
    _add_step_commands(sub)
    _add_mesh_commands(sub)
    add_flood_commands(sub)
    return parser


def _add_chain_commands(sub) -> None:
    """run, series and demo: the whole chain."""
    p = sub.add_parser("run", help="the whole chain: points or DEM to mesh and report")
    p.add_argument("input", nargs="+", help="LAS/LAZ/XYZ point file or GeoTIFF DEM, or tiles: "
                                            "a folder, a quoted glob or several files")
    p.add_argument("--out", required=True, help="output folder")
    _add_chain_options(p)
    _add_dask_options(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("series", help="one mesh per maximum area and simplification, and a "
                                      "table and plot of nodes against holdout error")
    p.add_argument("input", nargs="+", help="LAS/LAZ/XYZ point file or GeoTIFF DEM, or tiles: "
                                            "a folder, a quoted glob or several files")
    p.add_argument("--out", required=True, help="output folder")
    _add_chain_options(p, series=True)
    _add_dask_options(p)
    p.set_defaults(func=cmd_series)

    p = sub.add_parser("demo", help="run the whole chain on a built-in synthetic floodplain")
    p.add_argument("--out", default="demo_output", help="output folder (default %(default)s)")
    _add_chain_options(p)
    p.set_defaults(func=cmd_demo)


def _add_step_commands(sub) -> None:
    """grid, slope, breakpoints, breaklines and simplify: steps 2 to 6 one by one."""
    p = sub.add_parser("grid", help="grid points to a DEM by linear (TIN) interpolation")
    p.add_argument("input", nargs="+", help="LAS/LAZ/XYZ point file, or tiles: a folder, a "
                                            "quoted glob or several files")
    p.add_argument("--cell-size", type=float, required=True)
    p.add_argument("--out", required=True, help="DEM GeoTIFF")
    p.add_argument("--crs")
    p.add_argument("--max-gap", type=float)
    p.add_argument("--classes", type=_las_classes)
    p.add_argument("--holdout", type=float, default=0.0)
    p.add_argument("--holdout-out", help="held-out points (default holdout.gpkg beside --out)")
    p.add_argument("--seed", type=_whole, default=0)
    _add_dask_options(p)
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
    p.add_argument("--min-points", type=_whole, default=DEFAULTS.min_points)
    p.add_argument("--min-length", type=float, default=DEFAULTS.min_length,
                   help="drop lines shorter than this, m (default %(default)s)")
    p.add_argument("--no-join", action="store_true",
                   help="keep pieces apart where thinning cut a line at a staircase corner")
    p.add_argument("--seed", type=_whole, default=DEFAULTS.seed,
                   help="seed for ties the 7x7 kernel leaves (default 0)")
    p.add_argument("--out", required=True)
    p.add_argument("--crs")
    p.set_defaults(func=cmd_breaklines)

    p = sub.add_parser("simplify", help="simplify break lines")
    p.add_argument("breaklines")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--keep-every", type=_whole)
    group.add_argument("--tolerance", type=float, help="Douglas–Peucker tolerance, m")
    group.add_argument("--spline", type=float, metavar="TOLERANCE",
                       help="cubic smoothing spline within this many metres")
    p.add_argument("--min-distance", type=float, default=0.0,
                   help="merge lines and vertices closer than this, m (default 0: off; run "
                        "takes half the cell size)")
    p.add_argument("--out", required=True)
    p.add_argument("--crs")
    p.set_defaults(func=cmd_simplify)


def _add_mesh_commands(sub) -> None:
    """mesh, assess, refine and export: the mesh, its error and its solver formats."""
    p = sub.add_parser("mesh", help="quality triangular mesh of a DEM honouring break lines")
    p.add_argument("dem")
    p.add_argument("--breaklines")
    _add_domain_options(p)
    _add_size_options(p)
    p.add_argument("--min-angle", type=float, default=DEFAULTS.min_angle)
    p.add_argument("--max-area", type=float, default=DEFAULTS.max_area)
    _add_flow_area(p)
    _add_conforming(p)
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
    p.add_argument("--png", metavar="DIR", help="folder for residual_histogram.png and "
                   "residual_map.png")
    p.add_argument("--crs")
    p.set_defaults(func=cmd_assess)

    p = sub.add_parser("refine", help="refine a mesh until its residuals meet a target")
    p.add_argument("dem")
    p.add_argument("--points", required=True,
                   help="measured points driving the refinement (point file or GeoPackage)")
    p.add_argument("--check", help="held-out check points, assessed each round, never used")
    p.add_argument("--breaklines")
    _add_domain_options(p)
    p.add_argument("--min-angle", type=float, default=DEFAULTS.min_angle)
    p.add_argument("--max-area", type=float, default=DEFAULTS.max_area)
    p.add_argument("--lower", type=float, default=0.10,
                   help="refine triangles whose points' RMS residual exceeds their noise by "
                        "this (in quadrature), m (0.10)")
    p.add_argument("--upper", type=float, default=0.25,
                   help="insert points whose residual exceeds this into the TIN, m (0.25)")
    p.add_argument("--noise", type=float,
                   help="vertical noise of the points, m (default: estimated from them, the "
                        "median RMS of planes fitted to some 30 points each; 0: exact points)")
    p.add_argument("--target-rmse", type=float, help="stop when the RMSE is at most this, m")
    p.add_argument("--target-max", type=float, help="stop when max |residual| is at most this, m")
    p.add_argument("--max-nodes", type=_whole, default=1_000_000, help="node budget")
    p.add_argument("--max-rounds", type=_whole, default=8)
    p.add_argument("--out", required=True, help="SMS 2DM mesh")
    p.add_argument("--report", help="rounds and mesh quality as JSON")
    p.add_argument("--crs")
    p.set_defaults(func=cmd_refine)

    p = sub.add_parser("export", help="write a mesh for a solver: 2DM, Selafin, fort.14, "
                                      "hgrid.gr3, UGRID netCDF or GeoPackage")
    p.add_argument("mesh", help="SMS 2DM mesh (e.g. mesh.2dm of floodmesh run)")
    p.add_argument("output", help="file to write; its extension names the format: "
                                  f"{' '.join('.' + f for f in EXPORT_FORMATS)}")
    p.add_argument("--format", help=f"the format, whatever the extension: "
                                    f"{', '.join(EXPORT_FORMATS)}")
    p.add_argument("--crs", help="CRS of the mesh (EPSG:XXXX); needed for nc and gpkg unless a "
                                 "given layer carries it")
    p.add_argument("--open-boundaries", help="line layer of open boundary sections (inflow, "
                                             "outflow); all other boundary is land")
    p.add_argument("--snap", type=_positive(float), default=1.0,
                   help="boundary nodes within this many metres of an open boundary line are "
                        "open (default %(default)s)")
    p.add_argument("--regions", help="polygon layer of regions: one material id each")
    p.add_argument("--material-field", help="integer field of --regions holding the material id "
                                            "(default: 2, 3, … in feature order; 1 elsewhere)")
    p.add_argument("--datum-offset", type=float, default=0.0,
                   help="metres added to every elevation before writing (default 0)")
    p.add_argument("--element-elevations", action="store_true",
                   help="2DM: also write each element's centre elevation (BASEMENT 3)")
    p.add_argument("--breaklines", help="line layer written as the breaklines layer (gpkg)")
    p.set_defaults(func=cmd_export)



def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    start = time.perf_counter()
    stop_signals_as_interrupts()
    try:
        with interrupts_unwrapped():
            args.func(args)
    except FloodMeshError as exc:
        print(f"floodmesh: error: {exc}", file=sys.stderr)
        return 2
    except Terminated as exc:
        print(f"floodmesh: stopped by {exc}; no partial file was left behind", file=sys.stderr)
        return 128 + exc.signum
    except (KeyboardInterrupt, Cancelled):
        print("floodmesh: interrupted; no partial file was left behind", file=sys.stderr)
        return 130
    # Every file is in place: a Ctrl-C now, during interpreter teardown, would otherwise kill
    # the process with SIGINT and report a finished run as failed.
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if threading.current_thread() is threading.main_thread():
            signal.signal(signum, signal.SIG_IGN)
    if sys.stderr.isatty():
        print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def command() -> None:
    """The ``floodmesh`` console command: ``main``, then the exit, without the interpreter's
    teardown of every module (``process.end_process``), in a process whose freed memory is
    kept for its next arrays (``process.keep_freed_memory``)."""
    keep_freed_memory()
    try:
        code = main(sys.argv[1:])
    except BrokenPipeError:  # `floodmesh assess … | head`: the reader is gone, so are we
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(141)
    end_process(code)


if __name__ == "__main__":
    command()
