"""The whole chain, points → grid → slope → breakpoints → break lines → mesh → assessment,
with every intermediate written to an output folder and a report of figures and timings."""
from __future__ import annotations

import re
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing, contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
import shapely

from .. import io
from ..engine.compiles import CompileWatch
from ..engine.arrays import without_huge_pages
from ..engine.limits import BYTES_PER_FITTED_CELL, check_memory, check_triangles, fits_in_memory
from ..engine.nearest import CellIndex, point_index
from ..engine.progress import part, poll, report, steady
from ..engine.tiles import (TiledDem, grid_point_tiles, read_back, read_dem_tiles,
                            read_gridded_points, read_point_tiles, slope_file64,
                            write_front_rasters)
from ..errors import interrupts_unwrapped
from ..io.layer_definition import QLR_NAME, write_layer_definition
from ..io.outputs import check_output_folder, scratch_folder, staged_folder
from ..io.report import BREAKLINES_PNG, HISTOGRAM_PNG, MAP_PNG
from ..io.report_process import PicturesApart
from ..io.report_html import HTML_NAME, write_report_html
from ..options import (BRIDGE_GAP_CELLS, DEFAULT_CELL_SIZE, EXPORT_EXTENSIONS, EXPORT_FORMATS,
                       JOIN_GAP_CELLS, MISFIT_CROSSING_CELLS, MISFIT_DENSITY, MISFIT_EXCESS,
                       MISFIT_FLOOR_CELLS, MISFIT_LOW_FLOOR, MISFIT_SHARE, RunOptions,
                       check_sigma_fits)
from ..points import (PointCloud, every_nth_by_place, repeated_positions_note, sparse_survey_note,
                      split_holdout)
from ..raster import (Grid, bilinear, check_dem_size, fill_from_around, inner_cells,
                      nearest_value, parse_crs, require_same_place)
from ..steps.accuracy import accuracy_statistics, outside_mesh_note, residuals
from ..steps.breaklines import trace_breaklines
from ..steps.breakpoints import breakpoints_file, classify_breakpoints, log_breakpoints
from ..steps.drainage import (CHANNEL_AREA, flow_area_for, flow_refined, flow_size,
                              flow_spacing, height_above_drainage)
from ..steps.export import export_formats
from ..steps.grid import check_grid, grid_points_linear
from ..steps.hydraulic_lines import lines_for_hydraulics, without_wet_bridges
from ..steps.hydraulics import hydraulic_checks
from ..steps.joining import crossing_points
from ..steps.localise import fit_node_elevations, fit_window, localise_traced
from ..steps.mesh import (OwnLines, build_mesh, domain_from_dem, edge_tolerance, honoured_lines,
                          mesh_quality, refuse_height_clashes, size_from_slope, user_domain)
from ..steps.refine import refine_mesh
from ..steps.simplify import max_deviation, simplify_breaklines
from ..steps.sizing import far_field_size, finer
from ..steps.slope import laplacian_of_gaussian, slope
from .source import (DEM, DEM_TILES, POINTS, POINT_TILES, Source, check_outputs_apart,
                     open_source)

OUTPUT_FILES = ("dem.tif", "slope.tif", "breakpoints.tif", "breaklines.gpkg", "mesh.2dm",
                "mesh.prj", "mesh.gpkg", "residuals.gpkg", HISTOGRAM_PNG, MAP_PNG,
                BREAKLINES_PNG, "report.json", HTML_NAME, QLR_NAME)


class _Steps:
    """Times each step, reports overall progress and checks for cancellation between steps."""

    def __init__(self, weights: dict, progress, cancelled, log, background=None):
        self.weights, self.total = weights, float(sum(weights.values()))
        self.progress, self.cancelled, self.log = steady(progress), cancelled, log
        self.done, self.seconds, self.cpu_seconds = 0.0, {}, {}
        self.compiles = CompileWatch(log)  # numba's first-run compile, said when it happens
        self.background = background  # an executor of one thread, or None: no work ahead
        self.ahead_of_time = []  # the steps run on it, beside the others

    def ahead(self, name: str, func: Callable, *args, **kwargs):
        """Start step ``name`` on the background thread, for ``collect``: compiled work that
        lets go of the interpreter, overlapping the single-threaded steps between on the core
        they leave idle. Without a background thread it is run at ``collect``."""
        if self.background is None:
            return lambda: self.run(name, func, *args, **kwargs)

        def timed():
            start, cpu = time.perf_counter(), time.thread_time()
            result = func(*args, **kwargs)
            return result, time.perf_counter() - start, time.thread_time() - cpu

        future = self.background.submit(timed)
        self.ahead_of_time.append(name)

        def collect():
            poll(self.cancelled)
            result, seconds, cpu = future.result()
            self._finished(name, seconds, cpu, self.weights.get(name, 0.0))
            return result
        return collect

    def fold(self, name: str, into: str) -> None:
        """Step ``name``'s share of the bar given to step ``into``, which does its work, unless
        ``name`` has run: the bar still ends at 1, never past it."""
        if name not in self.seconds:
            self.weights[into] = self.weights.get(into, 0.0) + self.weights.pop(name, 0.0)

    def _finished(self, name: str, seconds: float, cpu: float, weight: float) -> None:
        """Step ``name`` took ``seconds`` (wall) and ``cpu``: recorded, and its share of the
        progress bar done."""
        self.seconds[name], self.cpu_seconds[name] = round(seconds, 3), round(cpu, 3)
        self.done += weight
        if self.progress:
            self.progress(self.done / self.total)

    def run(self, name: str, func: Callable, *args, **kwargs):
        poll(self.cancelled)
        if self.log:
            self.log(f"{name}...")
        start, cpu = time.perf_counter(), time.process_time()
        weight = self.weights.get(name, 0.0)  # none listed: no share, the bar kept within 1
        if "progress" in kwargs and self.progress:
            base = self.done
            kwargs["progress"] = lambda f: self.progress((base + f * weight) / self.total)
        with self.compiles.watching(), interrupts_unwrapped():
            result = func(*args, **kwargs)
        self._finished(name, time.perf_counter() - start,
                       time.process_time() - cpu, weight)  # CPU: all threads
        return result


@contextmanager
def _background_thread():
    """An executor of one thread for the work run ahead (``_Steps.ahead``: computations in
    memory, no files), joined at the end, but not after an interrupt: one that arrives while the
    main thread takes an import's module lock can leave that lock taken (as numba's:
    ``errors.compiler_locks_freed``), and the background thread, importing the same module,
    then waits forever, and so did the run joining it (Python 3.13: SIGHUP at random moments
    hung 1 run in 60, in ``ThreadPoolExecutor.shutdown``). The command ends the process without
    joining it (``frontends.process.end_process``)."""
    pool = ThreadPoolExecutor(max_workers=1)
    try:
        yield pool
    except KeyboardInterrupt:  # Ctrl-C, SIGTERM, SIGHUP (errors.Terminated)
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    except BaseException:
        pool.shutdown(wait=True)
        raise
    pool.shutdown(wait=True)


def run_pipeline(input_path, out_dir, options: RunOptions = RunOptions(), *,
                 progress: Callable[[float], None] | None = None,
                 cancelled: Callable[[], bool] | None = None,
                 log: Callable[[str], None] | None = None) -> dict:
    """Run the whole chain on a point file or DEM, or their tiles (a path, folder, pattern, list
    or ``source.Source``), and write ``OUTPUT_FILES`` into ``out_dir``, and ``mesh.<ext>`` for
    each of ``options.formats`` (see ``export``).

    ``progress`` receives the overall fraction done (0–1), ``cancelled`` is polled between and
    inside long steps (raising ``Cancelled``), ``log`` receives step names and notes (what was
    assumed or repaired on the user's behalf, also listed in the report). Returns the report.
    """
    options.validate()
    started = time.perf_counter()
    note = Notes(log)
    out, source = Path(out_dir), open_source(input_path)
    inputs = run_inputs(source, options)
    check_output_folder(out, inputs, run_outputs(options.formats))
    check_outputs_apart(source, [out / name for name in run_outputs(options.formats)])
    # every step makes its large arrays afresh: see without_huge_pages
    with (_background_thread() as background, PicturesApart() as pictures,
          without_huge_pages()):
        steps = _Steps(_step_weights(options), progress, cancelled, log, background)
        with interrupts_unwrapped():  # between steps too: the background thread is joined next
            return _run(source, out, inputs, options, steps, pictures, started, note.said,
                        note, cancelled, log)


class Notes:
    """What was assumed or repaired on the user's behalf (``said``, in order): called with a
    message, keeps it and tells ``log`` as ``note: …``, which the front ends show as a note
    (the CLI's ``print_notes``, the QGIS worker's ``note`` lines)."""

    def __init__(self, log: Callable[[str], None] | None = None):
        self.log, self.said = log, []

    def __call__(self, message: str) -> None:
        self.said.append(message)
        if self.log:
            self.log(f"note: {message}")


def _run(source, out: Path, inputs, options: RunOptions, steps: _Steps,
         pictures: PicturesApart, started: float, notes, note, cancelled, log) -> dict:
    """``run_pipeline``'s chain, its steps timed by ``steps``, its pictures drawn apart."""
    front = trace_front(source, options, steps, cancelled=cancelled, note=note)
    pictures.start()  # loads matplotlib beside the single-threaded steps that follow
    n_breakpoints = int(front.breakpoints.values.sum())
    if front.files:  # traced, and on disk for the output: only the size fields may read them
        if options.size_field != "slope":
            front.slope_grid = None
        if options.far_field_area is None:
            front.breakpoints = None
    fits = _TerrainFits(front, options)
    # the background thread takes its work in order: the point index first (started after
    # the gridding), since the fits wait for it right after simplifying; the flow zone and the
    # domain are wanted only after localising
    index = front.index
    flow_area = flow_area_for(options.flow_area, front.dem.cell_size)
    hand = None if flow_area is None else steps.ahead(  # resolution where water flows
        "flow zone", height_above_drainage, front.dem, channel_area=CHANNEL_AREA)
    outline = None if front.domain is not None else steps.ahead(  # the DEM's alone
        "domain", domain_from_dem, front.dem,
        tolerance=edge_tolerance(*options.simplification(), front.dem.cell_size))
    simplified, lines, confidence = _break_lines(front, options, steps, fits, index)
    # the input's checks, which only add notes, beside the single-threaded meshing: the
    # gridding and the terrain fits before it keep both cores busy
    later = say_later(front, note, steps)
    size, flow, spacing, max_area = _size_fields(front, options, fits.window, hand, flow_area)
    low_ground = spacing  # finite on low ground (see drainage.flow_spacing)
    hand = None  # the flow zone's work is in the flow size and spacing now
    domain = front.domain if outline is None else outline()
    plain = steps.run("hydraulic lines", _lines_for_flood, front, options, lines, domain, None,
                      spacing)
    kept = {}

    def build(size, spacing, told, progress=None, cancelled=None):
        """The mesh of ``size``, its lines spaced for a flood model (see hydraulic_lines) and
        thinned to the flow ``spacing`` (a Grid, or None), its repairs said to ``told``."""
        kept["lines"], kept["stats"] = (plain if spacing is None else _lines_for_flood(
            front, options, lines, domain, spacing, low_ground))
        return build_mesh(front.dem, kept["lines"], own_lines=front.own_lines,
                          min_angle=options.min_angle, max_area=max_area,
                          conforming=options.conforming, domain=domain, size_field=size,
                          max_triangles=options.max_triangles,
                          corner_gap=options.min_spacing or None, note=told,
                          progress=progress, cancelled=cancelled)

    mesh, size, flow_zone = steps.run("mesh", flow_refined, build, size, flow, spacing,
                                      front.dem, lines=plain[0] + front.own_lines, note=note,
                                      progress=None, cancelled=cancelled)
    detected, line_stats = kept["lines"], kept["stats"]
    mesh, rounds = _terrain_z(mesh, front, options, steps, fits, detected, domain, size,
                              max_area, cancelled, low_ground, note)
    # the terrain fits are done: their points and index go before the assessment and writing
    size = fits.index = front.measured = None
    res = steps.run("assess", residuals, mesh, front.holdout.xyz, progress=None,
                    cancelled=cancelled)
    outside = outside_mesh_note(front.holdout.xyz, res, front.dem, front.domain is not None)
    if outside:
        note(outside)

    def write_all(stage, figures, pictures, progress=None):
        exported = _write_outputs(stage, front, options, mesh, lines, res, confidence,
                                  group=out.name, progress=part(progress, 0.0, 0.8),
                                  cancelled=cancelled)
        pictures.wait()
        report(progress, cancelled, 0.9)
        run_report = _report(source, front, options, simplified, lines, exported, figures,
                             steps)
        # the page of report.json, written inside the step: "write" is its last timing
        write_report_html(stage, run_report, elapsed_s=time.perf_counter() - started)
        return run_report

    # the folder is replaced as a whole: an interrupt leaves the old run's files or these
    # and the picture process, drawing into it, ended before an interrupted run removes it
    with (staged_folder(out, own=folder_output, keep=inputs) as stage,
          closing(pictures)):
        # drawn in the picture process meanwhile, beside the figures and the files' writing
        pictures.draw(stage, mesh.nodes, mesh.triangles, front.holdout.xyz, res, dem=front.dem,
                      lines=[line.coords for line in lines])
        later()
        deviation, quality, stats, hydraulics = steps.run(
            "figures", _figures, front, options, simplified, mesh, res, detected, max_area,
            note)
        figures = {"n_breakpoints": n_breakpoints, "deviation": deviation, "quality": quality,
                   "stats": stats, "rounds": rounds, "terrain_fit": fits.record(),
                   "line_stats": line_stats, "flow_zone": flow_zone, "hydraulics": hydraulics,
                   "notes": notes}
        run_report = steps.run("write", write_all, stage, figures, pictures, progress=None)
        io.write_json(stage / "report.json", run_report)
    compiled = steps.compiles.summary()
    if compiled and log:
        log(compiled)
    return run_report


def say_later(front: Front, note, steps: _Steps | None = None) -> Callable[[], None]:
    """Start ``front.later``'s checks on ``steps``' background thread (after the work already
    queued there; None: run at the call); the callable returned waits for them and gives their
    notes to ``note``."""
    steps = steps or _Steps({}, None, None, None)
    started = [steps.ahead(name, func, *args) for name, func, args in front.later]
    front.later = []

    def collect():
        for result in started:
            message = result()
            if message and note:
                note(message)
    return collect


def _step_weights(options: RunOptions) -> dict:
    """The steps a run with ``options`` takes, each with its share of the progress bar (a step
    not listed, such as the tiles' points read back where they may not be, takes none)."""
    weights = {"read": 1, "grid": 4, "mesh inputs": 0.1, "slope": 1, "breakpoints": 0.5,
               "tracing slope": 0.5, "breaklines": 1, "simplify": 0.5, "fit window": 0.2,
               "localise": 0.5, "flow zone": 0.5, "hydraulic lines": 0.1, "mesh": 2,
               "refine": 4, "node elevations": 0.5, "assess": 1, "figures": 0.2, "write": 2}
    if options.slope_method != "log":  # the Laplacian's breakpoints, traced on first-order slope
        del weights["tracing slope"]
    del weights["node elevations" if _refining(options) else "refine"]
    if not options.localise:
        del weights["localise"]
    if not (options.localise or options.node_elevation == "plane"):
        del weights["fit window"]
    if flow_area_for(options.flow_area, 1.0) is None:
        del weights["flow zone"]
    return weights


# the steps of trace_front
FRONT_STEPS = ("read", "grid", "mesh inputs", "slope", "breakpoints", "tracing slope",
               "breaklines")


def front_steps(options: RunOptions, progress=None, cancelled=None) -> _Steps:
    """Silent steps for ``trace_front`` alone, which tell ``progress`` the share of its work
    done (a run's weights) and poll ``cancelled``."""
    weights = _step_weights(options)
    return _Steps({name: weights[name] for name in FRONT_STEPS if name in weights}, progress,
                  cancelled, None)


class _TerrainFits:
    """The points of every terrain fit of a run (localisation, node z, refinement) and their one
    index: the points gridded, or the DEM's cell centres drawn (the same seeded draw each time)
    when a fit needs them, as ``Front.measured`` says; the fits' window and what they did."""

    def __init__(self, front: Front, options: RunOptions):
        self.front, self.seed = front, options.seed
        self.cell_centres = front.measured is None  # the DEM's, drawn when a fit needs them
        self.index = self.window = None
        self.counts = {"localise": options.localise, "node_elevation": options.node_elevation,
                       "points": "DEM cell centres" if self.cell_centres
                       else "LiDAR points gridded"}
        self.node_counts = {}

    def measured(self) -> tuple[np.ndarray, object]:
        """The fits' points and their index (None: not built yet)."""
        if self.front.measured is None:
            self.front.measured, self.index = _dem_measured(self.front.dem, self.seed)
        return self.front.measured, self.index

    def let_go(self) -> None:
        """The DEM's cell centres (28 B a cell) are drawn again for the node fits after the
        mesh, not held over the flow zone and meshing, the steps of the command's peak."""
        if self.cell_centres:
            self.front.measured = self.index = None

    def record(self) -> dict:
        """The report's ``terrain_fit``: options, window, localisation and node-fit counts."""
        return {**self.counts, **({"nodes": self.node_counts} if self.node_counts else {})}


def _point_index_ahead(measured, options: RunOptions, steps: _Steps):
    """The terrain fits' point index of ``measured`` (``Front.measured``) started on the
    background thread (``_Steps.ahead``: call it for the index), or None where no fit needs
    the points or they are not read yet."""
    return (steps.ahead("point index", point_index, measured)
            if _fitting(options) and measured is not None else None)


def _fitting(options: RunOptions) -> bool:
    """Whether a run with ``options`` fits the terrain to the points (localisation, node z)."""
    return options.localise or options.node_elevation == "plane"


def _break_lines(front: Front, options: RunOptions, steps: _Steps, fits: _TerrainFits, index):
    """(simplified, final lines, their fit RMS or None): the traced lines simplified, then moved
    onto the terrain's kinks by the hinge fits (``localise``) where asked; ``index``: the
    points' index from ``_point_index_ahead``."""
    dem, (method, amount) = front.dem, options.simplification()
    min_distance = dem.cell_size / 2 if options.min_distance is None else options.min_distance
    simplified = lines = steps.run("simplify", simplify_breaklines, front.traced, method, amount,
                                   min_distance=min_distance, progress=None,
                                   cancelled=steps.cancelled)
    confidence = None
    if _fitting(options):
        area = float(np.isfinite(dem.values).sum()) * dem.cell_size ** 2
        points, built = fits.measured()
        fits.index, fits.window = steps.run(
            "fit window", _fit_window, points, index() if index else built, area,
            dem.cell_size, node_radius=options.node_radius, seed=options.seed, progress=None,
            cancelled=steps.cancelled)
        fits.counts.update(asdict(fits.window))
    if options.localise:
        join_gap = (JOIN_GAP_CELLS * dem.cell_size if options.join_gap is None
                    else options.join_gap)
        lines, confidence, counts = steps.run(
            "localise", localise_traced, lines, front.measured, fits.window,
            s_crit=options.s_crit, tolerance=dem.cell_size / 10, max_gap=20 * dem.cell_size,
            join_gap=join_gap, join_lateral=dem.cell_size,
            bridge_gap=BRIDGE_GAP_CELLS * dem.cell_size if join_gap else None,
            cell_size=dem.cell_size, index=fits.index, progress=None,
            cancelled=steps.cancelled)
        fits.counts.update(counts)
    fits.let_go()
    return simplified, lines, confidence


def _size_fields(front: Front, options: RunOptions, window, hand, flow_area):
    """(size field or None, flow size or None, flow spacing or None, the largest area): the
    user's size field, finer off the lines where asked (far field), and where water flows
    (``flow_area``, with the height above drainage that ``hand`` collects: see drainage) the
    triangles' size and the break lines' spacing, which the mesh takes where its terrain
    needs them (``flow_refined``)."""
    dem, max_area = front.dem, options.max_area
    size = size_field(options.size_field, dem, front.slope_grid, max_area=max_area,
                      min_area=options.min_area, s_crit=options.s_crit)
    if options.far_field_area is not None:  # grows off the lines, where the terrain is plane
        far = far_field_size(dem, front.breakpoints, max_area=max_area,
                             far_field_area=options.far_field_area,
                             tolerance=max(0.01, window.noise / 2) if window else 0.02)
        size = finer(size, far)
        max_area = options.far_field_area
    if hand is None:
        return size, None, None, max_area
    hand, _ = hand()
    return (size, flow_size(dem, flow_area=flow_area, hand=hand),
            flow_spacing(dem, flow_area=flow_area, hand=hand), max_area)


def _line_spacing(front: Front, options: RunOptions) -> float:
    """The smallest spacing a flood model affords (m): ``--min-spacing``, else the cell size;
    0 where it is off. The detected lines keep twice it clear of the domain edge."""
    return front.dem.cell_size if options.min_spacing is None else options.min_spacing


def _lines_for_flood(front: Front, options: RunOptions, lines, domain, spacing, low_ground):
    """(the detected lines' coordinates, their statistics or None): lines a flood model can
    afford (see hydraulic_lines), without their bridges on ``low_ground`` (a Grid, finite there,
    or None), thinned to the flow ``spacing`` (a Grid) where given, unless
    ``options.min_spacing`` is 0."""
    detected = without_wet_bridges([line.coords for line in lines],
                                   [line.bridged for line in lines], low_ground)
    least = _line_spacing(front, options)
    if least <= 0:
        return detected, None
    within = (shapely.union_all(io.read_boundary(options.flow_zone)) if options.flow_zone
              else None)
    return lines_for_hydraulics(detected, domain, spacing=least, own_lines=front.own_lines,
                                within=within, flow_spacing=spacing)


def _refining(options: RunOptions) -> bool:
    """Whether a run refines its mesh on the points (--refine, or the misfit passes, which take
    their noise from the plane fits' window)."""
    return options.refine or bool(options.misfit_passes and options.node_elevation == "plane")


def _terrain_z(mesh, front: Front, options: RunOptions, steps: _Steps, fits: _TerrainFits,
               detected, domain, size, max_area, cancelled, low_ground=None, note=None):
    """(mesh, refinement rounds): refined on the points gridded until the bounds hold (``note``
    hears what they left), or its node z fitted on them (``node_elevation="plane"``); the
    held-out points stay independent. ``detected``: the mesh's detected lines, meshed with the
    modeller's own."""
    delta = front.dem.cell_size / 2

    def elevations(mesh, progress=None, cancelled=None):
        """Node z with the noise taken out, from the points gridded only (never the held-out);
        the share fitted told to ``progress``, ``cancelled`` polled."""
        if options.node_elevation != "plane":
            return mesh
        points, fit_index = fits.measured()
        z, counts = fit_node_elevations(mesh.nodes, points, detected + front.own_lines,
                                        fits.window.node_radius, on_line=delta / 10,
                                        own_lines=front.own_lines, index=fit_index,
                                        noise=fits.window.noise, progress=progress,
                                        cancelled=cancelled)
        fits.node_counts.update(counts)
        return replace(mesh, nodes=np.column_stack([mesh.nodes[:, :2], z]))

    if not _refining(options):
        return steps.run("node elevations", elevations, mesh, progress=None,
                         cancelled=cancelled), []
    common = dict(check=front.holdout.xyz, domain=domain, size_field=size,
                  min_angle=options.min_angle, max_area=max_area, conforming=options.conforming,
                  elevations=elevations, max_nodes=options.max_triangles,
                  noise=fits.window.noise if fits.window else None, progress=None,
                  cancelled=cancelled, note=note,
                  mesh_options=dict(own_lines=front.own_lines,
                                    max_triangles=options.max_triangles,
                                    corner_gap=options.min_spacing or None))
    if options.refine:
        return steps.run("refine", refine_mesh, front.dem, detected, fits.measured()[0],
                         lower=options.refine_lower, upper=options.refine_upper, **common)
    # folds no line describes (crossings, junctions, rounded ends), split without new points;
    # one point in k, some MISFIT_DENSITY a m² (a split triangle holds 8 cells² or more), chosen
    # by place so that the survey's order does not change the mesh
    every = max(1, int(fits.window.density / MISFIT_DENSITY))
    points = every_nth_by_place(fits.measured()[0], every)
    floor = MISFIT_FLOOR_CELLS * front.dem.cell_size ** 2
    low_floor = None if low_ground is None else _low_ground_floor(
        low_ground, detected + front.own_lines, floor, MISFIT_CROSSING_CELLS * front.dem.cell_size)
    clearance = 2 * _line_spacing(front, options)  # the band the lines keep clear of
    return steps.run("refine", refine_mesh, front.dem, detected, points,
                     lower=MISFIT_EXCESS, upper=None, max_rounds=options.misfit_passes + 1,
                     most=MISFIT_SHARE, measure_last=False,
                     floor_at=_off_edge(low_floor, floor, domain, clearance),
                     floor=floor, first=mesh, **common)


def _off_edge(floor_at, floor: float, domain, clearance: float):
    """``floor_at`` (or ``floor`` everywhere), but no split of a triangle whose centroid lies
    within ``clearance`` m of the ``domain``'s edge: the band the detected lines keep clear of,
    where a split made the smallest triangles at the edge a flood flows in and out by (91 % of
    the demo levee flood's time steps)."""
    edge = shapely.boundary(domain) if domain is not None and clearance > 0 else None
    if edge is not None:
        shapely.prepare(edge)  # an outline of a survey has hundreds of vertices

    def off_edge(xy):
        at = floor_at(xy) if floor_at is not None else np.full(len(xy), floor)
        if edge is None:
            return at
        return np.where(shapely.dwithin(edge, shapely.points(xy[:, :2]), clearance), np.inf, at)
    return off_edge


def _low_ground_floor(low_ground: Grid, lines, floor: float, reach: float):
    """The misfit pass's floor (m²) at x, y (k, 2+): ``MISFIT_LOW_FLOOR`` times ``floor`` on
    ``low_ground`` (finite there), where the smallest wet triangle sets a flood model's time
    step, but ``floor`` within ``reach`` m of where two ``lines`` cross or meet (the folds of
    two features' overlapping slopes) and off low ground."""
    crossings = crossing_points(lines)
    near = point_index(crossings) if len(crossings) else None

    def floor_at(xy):
        low = np.isfinite(nearest_value(low_ground, xy[:, 0], xy[:, 1]))
        if near is not None:
            low &= np.diff(near.neighbours(xy, reach, ascending=False)[0]) == 0
        return np.where(low, MISFIT_LOW_FLOOR * floor, floor)
    return floor_at


def _figures(front: Front, options: RunOptions, simplified, mesh, res, detected, max_area,
             note=None):
    """(largest simplification deviation, mesh quality, accuracy statistics, hydraulic checks)."""
    method, amount = options.simplification()
    delta = front.dem.cell_size / 2
    deviation = max_deviation(front.traced, simplified)
    alpha = deviation / delta if method == "keep-every" else amount / delta
    return (deviation, mesh_quality(mesh, min_angle=options.min_angle, max_area=max_area),
            accuracy_statistics(res, alpha=alpha, delta=delta, note=note),
            hydraulic_checks(mesh.nodes, mesh.triangles, own_lines=front.own_lines,
                             detected_lines=detected, dem=front.dem))


def _write_outputs(out: Path, front: Front, options: RunOptions, mesh, lines, res, confidence,
                   *, group: str, progress=None, cancelled=None) -> list:
    """The run's files into ``out`` (``OUTPUT_FILES`` but the report's two and the pictures);
    returns the solver exports written; the pictures are drawn apart (``write_report_pngs``).
    ``progress`` hears the share written, ``cancelled`` is polled between the files."""
    dem, holdout = front.dem, front.holdout
    io.write_raster(out / "dem.tif", dem, quantity=io.ELEVATION)
    report(progress, cancelled, 0.2)
    if front.files:
        write_front_rasters(front.files, out)
    else:
        io.write_raster(out / "slope.tif", front.slope_grid, quantity="slope")
        io.write_raster(out / "breakpoints.tif", front.breakpoints, valid=np.isfinite(dem.values),
                        quantity="breakpoints")
    report(progress, cancelled, 0.4)
    io.write_breaklines(out / "breaklines.gpkg", lines, dem.crs, fit_rms=confidence)
    report(progress, cancelled, 0.5)
    # the solver exports of mesh.2dm and mesh.gpkg hold more (node strings, layers)
    if "2dm" not in options.formats:
        io.write_mesh_2dm(out / "mesh.2dm", mesh.nodes, mesh.triangles, crs=dem.crs)
    if "gpkg" not in options.formats:
        io.write_mesh_gpkg(out / "mesh.gpkg", mesh.nodes, mesh.triangles, dem.crs)
    report(progress, cancelled, 0.7)
    io.write_residuals(out / "residuals.gpkg", holdout.xyz, res, dem.crs)
    write_layer_definition(out, group=group, crs_wkt=dem.crs.to_wkt(),
                           elevation_range=(mesh.nodes[:, 2].min(), mesh.nodes[:, 2].max()))
    report(progress, cancelled, 0.8)
    # the lines as the mesh has them, own and detected, for a solver that meshes anew
    return (export_formats(out / "mesh", mesh.nodes, mesh.triangles, options.formats,
                           crs=dem.crs, breaklines=honoured_lines(mesh),
                           progress=part(progress, 0.8, 1.0), cancelled=cancelled)
            if options.formats else [])


def _report(source: Source, front: Front, options: RunOptions, simplified, lines, exported,
            figures: dict, steps: _Steps) -> dict:
    """report.json: the input, grid, lines, mesh quality, accuracy, terrain fits, notes, files
    and the steps' timings."""
    dem, traced, (method, amount) = front.dem, front.traced, options.simplification()
    min_distance = dem.cell_size / 2 if options.min_distance is None else options.min_distance
    return {
        "input": source.named,
        "crs": dem.crs.to_string(),
        "options": {k: v for k, v in asdict(options).items()},
        "n_points": front.n_points,
        "holdout_source": front.holdout_source,
        "grid": {"rows": dem.shape[0], "cols": dem.shape[1], "cell_size_m": dem.cell_size,
                 "valid_cells": int(np.isfinite(dem.values).sum())},
        "n_breakpoints": figures["n_breakpoints"],
        "n_breaklines_traced": len(traced),
        "n_breaklines": len(lines),
        "breakline_length_m": float(sum(line.length for line in lines)),
        "breakline_points_traced": int(sum(len(t.coords) for t in traced)),
        "breakline_points_kept": int(sum(len(t.coords) for t in lines)),
        "simplification": {"method": method, "value": amount, "min_distance_m": min_distance,
                           "max_deviation_m": figures["deviation"]},
        **figures["quality"],
        **figures["stats"],
        "refinement": [asdict(r) for r in figures["rounds"]],
        "terrain_fit": figures["terrain_fit"],
        "hydraulic_lines": figures["line_stats"],
        "flow_zone": figures["flow_zone"],
        "hydraulics": figures["hydraulics"],
        "notes": figures["notes"],
        "files": sorted(set(OUTPUT_FILES) | {path.name for path in exported}),
        "seconds": steps.seconds,
        "cpu_seconds": steps.cpu_seconds,
        "steps_in_background": steps.ahead_of_time,
    }


def _fit_window(points, index, area, cell_size, *, node_radius, seed, progress=None,
                cancelled=None):
    """(index of the points, built if None, ``FitWindow``): the index serves every later
    terrain fit. ``progress`` hears the share done (0–1), ``cancelled`` is polled."""
    start = 0.0
    if index is None:
        index, start = point_index(points), 0.8  # most of the step where built here
        report(progress, cancelled, start)
    return index, fit_window(points, area, cell_size, node_radius=node_radius, seed=seed,
                             index=index, progress=part(progress, start, 1.0),
                             cancelled=cancelled)


def run_inputs(source: Source, options: RunOptions) -> list:
    """The files a run reads: never to be replaced by its outputs."""
    size = options.size_field if options.size_field != "slope" else None
    own = [io.vector_path(p) for p in (options.boundary, options.user_lines) if p]
    return [*source.paths, *own, size]


def run_outputs(formats) -> list:
    """The names a run with these solver formats writes into its folder."""
    return [*OUTPUT_FILES, *(f"mesh{EXPORT_EXTENSIONS[f]}" for f in formats),
            *(["mesh.cli"] if "slf" in formats else [])]


# a scale series' files (``series``): its table, record and plot, and a mesh per setting named
# by ``series.Setting.label`` (a100-k4, a50-dp0.5, a200-sp1e-05)
SERIES_FILES = ("series.csv", "series.json", "series.png")
SERIES_MESH = re.compile(r"^mesh_a[0-9.e+-]+-(?:k|dp|sp)[0-9.e+-]+\.(?:2dm|prj)$")


def folder_output(name: str) -> bool:
    """Whether ``run`` or ``series`` writes a file of this name into its output folder: an
    earlier one's that this one does not write again goes (``outputs.staged_folder``), so that
    the folder holds one command's files, never a run's mesh beside a series' table."""
    return (name in run_outputs(EXPORT_FORMATS) or name in SERIES_FILES
            or bool(SERIES_MESH.match(name)))


@dataclass
class Front:
    """The chain up to the traced break lines: what every mesh of one input shares."""

    dem: Grid
    holdout: PointCloud      # check points: withheld LiDAR points, or DEM cell centres
    holdout_source: str
    n_points: int            # points read (0 for a DEM)
    slope_grid: Grid         # first-order slope (degrees), which the tracer follows
    breakpoints: Grid
    traced: list             # BreakLine, before simplification
    domain: object = None    # the user's domain (Multi)Polygon, None: the DEM's data
    own_lines: list = field(default_factory=list)  # the modeller's own lines (k, 3) arrays
    # (n, 3) points gridded, for the terrain fits and refinement; None: the DEM's cell centres
    # (a DEM, or point tiles too many for memory), drawn from it when a fit needs them
    measured: np.ndarray | None = None
    files: dict | None = None  # point tiles: slope and breakpoints files (and their folder)
    # checks of the input whose notes are said later, beside other steps (``say_later``):
    # (step name, function, arguments), the function giving a note or None
    later: list = field(default_factory=list)
    index: Callable | None = None  # gives the index of ``measured`` (``_point_index_ahead``)


HELD_OUT = "LiDAR points withheld from gridding"  # tiles or one file: the same points
DEM_HELD_OUT = "DEM cells taken out of the DEM and filled from their neighbours"


@dataclass
class _Terrain:
    """What reading a source gives the front: the DEM and the points held out."""

    dem: Grid
    holdout: PointCloud
    holdout_source: str
    n_points: int
    measured: np.ndarray | None = None  # the points gridded (None: the DEM's cell centres)
    files: dict | None = None           # point tiles: the DEM, slope and breakpoints files
    later: list = field(default_factory=list)  # checks left for later, as Front.later


def trace_front(source, options: RunOptions, steps: "_Steps | None" = None, *,
                cancelled: Callable[[], bool] | None = None,
                note: Callable[[str], None] | None = None) -> Front:
    """Read, grid (holding points out), slope, breakpoints and trace ``source`` (a
    ``source.Source``, or what ``open_source`` takes), as ``options`` say; each step timed
    through ``steps`` (a silent one if None); ``note`` receives what was assumed or repaired on
    the user's behalf. Grids and meshes too large for the triangle limit or the memory are
    refused before the work."""
    steps = steps or _Steps({}, None, cancelled, None)
    source = open_source(source)
    terrain = _READERS[source.kind](source, options, steps, cancelled=cancelled, note=note)
    # started now, beside the single-threaded slope and tracing: begun after them, the fits
    # waited some 0.2 s for it
    index = _point_index_ahead(terrain.measured, options, steps)
    dem = terrain.dem
    sparse = sparse_survey_note(terrain.n_points, int(np.isfinite(dem.values).sum()),
                                dem.cell_size)
    if sparse and note:
        note(sparse)
    domain, own_lines = steps.run("mesh inputs", mesh_constraints, dem, options.boundary,
                                  options.user_lines,
                                  tolerance=edge_tolerance(*options.simplification(),
                                                           dem.cell_size), note=note)
    if terrain.files:
        slope_grid = read_back(terrain.files["slope"], dem.crs)
        breakpoints = read_back(terrain.files["breakpoints"], dem.crs)
    else:
        slope_grid, breakpoints = _slope_and_breakpoints(dem, options, steps, cancelled)
    traced = steps.run("breaklines", trace_breaklines, breakpoints, slope_grid, dem,
                       options.s_crit, mode=options.tracing_mode, min_points=options.min_points,
                       min_length=options.min_length, seed=options.seed, progress=None,
                       cancelled=cancelled)
    return Front(dem, terrain.holdout, terrain.holdout_source, terrain.n_points, slope_grid,
                 breakpoints, traced, domain, own_lines, terrain.measured, terrain.files,
                 terrain.later, index)


def _slope_and_breakpoints(dem: Grid, options: RunOptions, steps: _Steps, cancelled):
    """(first-order slope, breakpoints) of a DEM in memory: by the slope method and S_crit, or
    by the Laplacian of Gaussian (the tracer still follows first-order slope)."""
    if options.slope_method != "log":
        slope_grid = steps.run("slope", slope, dem, options.slope_method, cancelled=cancelled)
        return slope_grid, steps.run("breakpoints", classify_breakpoints, slope_grid,
                                     options.s_crit)
    response = steps.run("slope", laplacian_of_gaussian, dem, options.sigma,
                         kernel=options.log_kernel, cancelled=cancelled)
    breakpoints = steps.run("breakpoints", log_breakpoints, response, options.sensitivity,
                            zero_crossings=options.zero_crossings)
    return steps.run("tracing slope", slope, dem, "one-over-distance",
                     cancelled=cancelled), breakpoints


def _read_points(source: Source, options: RunOptions, steps: _Steps, *, cancelled,
                 note) -> _Terrain:
    """One point file, gridded in memory with ``options.holdout`` of its points held out."""
    data, gridding, holdout = steps.run("read", _points_split, source, options, note)
    terrain = _grid_in_memory(gridding, holdout, HELD_OUT,
                              len(data), options, steps, cancelled=cancelled)
    if note:  # the check of repeated positions: a single-threaded pass, left for an idle core
        terrain.later.append(("repeated points", repeated_positions_note,
                              (data.xyz, io.point_file_name(source.path))))
    return terrain


def _points_split(source: Source, options: RunOptions, note):
    """(the point file's points, those for gridding, those held out; ``split_holdout``)."""
    data = io.read_points(source.path, crs=options.crs, classes=options.classes, note=note,
                          repeats=False)
    return (data, *split_holdout(data, options.holdout, options.seed, note=note))


def _grid_in_memory(gridding: PointCloud, holdout: PointCloud, holdout_source: str,
                    n_points: int, options: RunOptions, steps: _Steps, *,
                    cancelled) -> _Terrain:
    """Points gridded in memory, ``holdout`` kept for the check; a grid or mesh too large for
    the limit or the memory refused before the work."""
    plan = check_grid(gridding, options.cell_size, options.max_gap)
    if options.slope_method == "log":
        check_sigma_fits(options.sigma, plan["rows"], plan["cols"], options.cell_size)
    triangles = check_triangles(plan["area"], options.max_area, options.max_triangles)
    check_memory(points=len(gridding), cells=plan["rows"] * plan["cols"],
                 triangles=triangles, advice="give a larger cell size or maximum area, or "
                                             "split the data into tiles")
    dem = steps.run("grid", grid_points_linear, gridding, options.cell_size,
                    max_gap=options.max_gap, progress=None, cancelled=cancelled, plan=plan)
    return _Terrain(dem, holdout, holdout_source, n_points, measured=gridding.xyz)


def _read_dem(source: Source, options: RunOptions, steps: _Steps, *, cancelled,
              note) -> _Terrain:
    """A DEM (one raster, or DEM tiles mosaicked), its own cell size kept (``note`` is told
    when another was given: one other than the default, as QGIS passes the default as a value);
    check points are a seeded draw of its cells."""
    if source.tiled:
        dem = steps.run("read", read_dem_tiles, source.paths, crs=options.crs, note=note)
    else:
        dem = steps.run("read", io.read_dem, source.path, crs=options.crs, note=note)
    check_dem_size(dem.values, dem.cell_size,
                   "the DEM tiles" if source.tiled else f"raster {source.path.name}")
    given = options.cell_size
    if note and given != DEFAULT_CELL_SIZE and not np.isclose(given, dem.cell_size, rtol=1e-9):
        note(f"the input is a DEM: its own cells of {dem.cell_size:g} m are used, not the cell "
             f"size of {given:g} m given, which grids points; resample the DEM for other cells "
             f"(gdalwarp -tr {given:g} {given:g} IN OUT)")
    valid_area = float(np.isfinite(dem.values).sum()) * dem.cell_size ** 2
    triangles = check_triangles(valid_area, options.max_area, options.max_triangles)
    check_memory(cells=dem.values.size, triangles=triangles, cell_bytes=BYTES_PER_FITTED_CELL,
                 advice="resample the DEM to larger cells or split it into tiles")
    check = _hold_dem_cells_out(dem, options.holdout, options.seed, note)
    if note and len(check):
        note(f"{len(check):,} check cells of the DEM (holdout {options.holdout:g}) were taken "
             "out of it and filled from their neighbours before anything was built from it, as "
             "held-out points are left out of gridding, so that the accuracy is measured where "
             "the mesh never saw the data; dem.tif has them filled")
    return _Terrain(dem, check, DEM_HELD_OUT, 0)


def _read_point_tiles(source: Source, options: RunOptions, steps: _Steps, *, cancelled,
                      note) -> _Terrain:
    """Point tiles read into memory where they fit and no scheduler is given
    (``tiles.read_point_tiles``), then gridded as one file's points; else gridded on Dask
    (``_read_tiles_on_dask``). The held-out points, the same as one file of all the tiles'
    points holds out, are the independent check."""
    if not options.scheduler:
        tiles = steps.run("read", read_point_tiles, source.paths, options.cell_size,
                          crs=options.crs, classes=options.classes, holdout=options.holdout,
                          seed=options.seed, workers=options.workers, cancelled=cancelled)
        if tiles is not None:
            for message in tiles.notes if note else ():
                note(message)
            return _grid_in_memory(PointCloud(tiles.gridding, tiles.crs),
                                   PointCloud(tiles.holdout, tiles.crs), HELD_OUT,
                                   tiles.n_points, options, steps, cancelled=cancelled)
    return _read_tiles_on_dask(source, options, steps, cancelled=cancelled, note=note)


def _read_tiles_on_dask(source: Source, options: RunOptions, steps: _Steps, *, cancelled,
                        note) -> _Terrain:
    """Point tiles gridded on Dask; the DEM, slope and breakpoints go file to file, block by
    block (see tiles), unless the Laplacian of Gaussian needs the DEM in memory. The points
    gridded are read back for the terrain fits and --refine, as one file's are kept, where
    memory holds them beside the DEM (else the fits take the DEM's cell centres, with a note)."""
    files = None
    steps.fold("read", into="grid")  # Dask reads the tiles as it grids them
    if options.slope_method != "log":
        files = {"folder": scratch_folder("tiles")}
        files["dem"] = Path(files["folder"].name) / "dem.tif"
    data = steps.run("grid", _grid_tiles, source, options, cancelled=cancelled, note=note,
                     dem_path=files and files["dem"])
    if files:
        folder, crs_wkt = files["dem"].parent, data.crs.to_wkt()
        files["slope"] = steps.run("slope", slope_file64, files["dem"], folder / "slope.tif",
                                   options.slope_method, crs=crs_wkt, cancelled=cancelled)
        files["breakpoints"] = folder / "breakpoints.tif"
        steps.run("breakpoints", breakpoints_file, files["slope"], files["breakpoints"],
                  s_crit=options.s_crit, input_dtype=np.float64, crs=crs_wkt,
                  cancelled=cancelled)
        data.dem = read_back(files["dem"], data.crs)
    measured = None
    if fits_in_memory(points=data.n_gridding, cells=data.dem.values.size,
                      cell_bytes=BYTES_PER_FITTED_CELL):
        measured = steps.run("read back", read_gridded_points, data, cancelled=cancelled)
    elif note:
        note(f"the tiles' {data.n_gridding:,} points gridded are more than memory holds beside "
             "the DEM: the terrain fits take the DEM's cell centres")
    return _Terrain(data.dem, PointCloud(data.holdout, data.dem.crs),
                    HELD_OUT, data.n_points,
                    measured=measured, files=files)


_READERS = {POINTS: _read_points, DEM: _read_dem, DEM_TILES: _read_dem,
            POINT_TILES: _read_point_tiles}


def _grid_tiles(source: Source, options: RunOptions, *, cancelled=None, note=None,
                dem_path=None) -> TiledDem:
    """Point tiles gridded on Dask (``tiles.TiledDem``); with ``dem_path`` the DEM goes there
    (float64) instead of into memory."""
    def check(plan):  # before round two: the chain after gridding, which holds the whole DEM
        triangles = check_triangles(plan["area"], options.max_area, options.max_triangles)
        check_memory(cells=plan["rows"] * plan["cols"], triangles=triangles,
                     cell_bytes=BYTES_PER_FITTED_CELL,
                     advice="give a larger cell size or maximum area, or grid the tiles alone "
                            "(floodmesh grid TILES --out dem.tif) and mesh it in parts")

    tiled = grid_point_tiles(source.paths, options.cell_size, max_gap=options.max_gap,
                             crs=options.crs, classes=options.classes, holdout=options.holdout,
                             seed=options.seed, out_path=dem_path, keep=dem_path is None,
                             dtype="float32" if dem_path is None else "float64",
                             workers=options.workers, scheduler=options.scheduler,
                             processes=options.processes, progress=None,
                             cancelled=cancelled, check=check)
    for message in tiled.notes:
        if note:
            note(message)
    return tiled


def size_field(source, dem: Grid, slope_grid: Grid | None = None, *, max_area: float,
               min_area: float | None = None, s_crit: float = 10.0) -> Grid | None:
    """The size field a user asked for: None, "slope" (from ``slope_grid``, or the DEM's
    one-over-distance slope; ``min_area`` defaults to ``max_area``/25) or a raster file of local
    maximum areas (m²) in the DEM's CRS (taken where it has none)."""
    if source is None:
        return None
    if source == "slope":
        slope_grid = slope(dem, "one-over-distance") if slope_grid is None else slope_grid
        return size_from_slope(slope_grid, max_area=max_area, s_crit=s_crit,
                               min_area=max_area / 25 if min_area is None else min_area)
    field = io.read_raster(source, default_crs=dem.crs, elevations=False, holds=(
        "size_field", "give a raster of maximum triangle areas in m² (a flood's size_field.tif), "
        "or slope for one from the DEM's slope"))
    require_same_place(field.crs, dem.crs, f"size field {Path(source).name}", "DEM")
    return field


def layer_crs(path, what: str, crs, *, of: str = "DEM", heights: bool = False, note=None):
    """The CRS of the vector file ``path`` (a ``what`` file), refused where it is not ``crs``,
    the ``of``'s (with ``heights``, the vertical CRS too where both name one); a layer without
    one is taken in ``crs``, as QGIS takes it in the project's, which ``note`` hears."""
    name, own = io.vector_path(path).name, io.vector_crs(path)
    if own is None:
        if note:
            note(f"the {what} file {name} has no CRS: it is taken to be in the {of}'s, "
                 f"{crs.name}; if it is not, assign its own (ogr2ogr -a_srs EPSG:XXXX "
                 "OUT IN, or in QGIS: Assign projection)")
        return crs
    own = parse_crs(own, name)
    require_same_place(own, crs, f"{what} file {name}", of, heights=heights)
    return own


def mesh_constraints(dem: Grid, boundary=None, user_lines=None, *,
                     tolerance: float | None = None, note=None):
    """(domain, lines) from a user's boundary polygon file (None: the DEM's data) and a file of
    their own break or structure lines (2-D lines take z from the DEM), both checked against the
    DEM's CRS (their horizontal parts; the lines' heights too where both name them); a layer
    without a CRS is taken in the DEM's, as QGIS takes it in the project's; lines with a
    coordinate that is no number, or crossing at heights apart, are refused
    (``refuse_height_clashes``: ``OwnLines``, which ``build_mesh`` takes
    unchecked); ``tolerance`` (m) as ``user_domain``'s; ``note`` hears of
    that, of line parts left out (zero length) and of domain left without data."""
    for path, what, heights in ((boundary, "boundary polygon", False),
                                (user_lines, "user line", True)):
        if path is not None:
            layer_crs(path, what, dem.crs, heights=heights, note=note)
    domain = (user_domain(io.read_boundary(boundary), dem, name=io.vector_path(boundary).name,
                          tolerance=tolerance, note=note) if boundary is not None else None)
    lines, features = io.read_own_lines(user_lines, note) if user_lines is not None else ([], [])
    if lines:
        refuse_height_clashes(lines, dem.cell_size, name=io.vector_path(user_lines).name,
                              features=features)
    if lines and note:
        _note_own_z_off_the_ground(lines, dem, io.vector_path(user_lines).name, note)
    return domain, OwnLines(lines)


# An own line whose z lies this many metres (median over its vertices) from the DEM's surface is
# noted: a layer digitised with Z but no values gives z 0 (QGIS's default), tens of metres
# under a floodplain, where surveyed crests and inverts lie within a few metres of the ground
OWN_Z_OFF_GROUND = 5.0


def _note_own_z_off_the_ground(lines, dem: Grid, name: str, note) -> None:
    """Tell ``note`` of the lines ((k, 3) as ``io.read_lines_gpkg`` gives them, z NaN where
    2-D) whose z lies OWN_Z_OFF_GROUND m or more (median) above or below the DEM: kept as
    given, as the modeller's own heights are."""
    off = []
    for number, coords in enumerate(lines, 1):
        gap = coords[:, 2] - bilinear(dem, coords[:, 0], coords[:, 1])
        gap = gap[np.isfinite(gap)]
        median = float(np.median(gap)) if gap.size else 0.0
        if abs(median) >= OWN_Z_OFF_GROUND:
            off.append((number, median))
    if off:
        note(f"{name}: line(s) {', '.join(str(n) for n, _ in off[:10])} lie "
             f"{', '.join(f'{g:+.1f}' for _, g in off[:10])} m from the DEM's surface (median "
             "over their vertices); their z is kept as given. A layer digitised with Z but no "
             "heights has z 0: save such lines without Z to give them the DEM's")


def _hold_dem_cells_out(dem: Grid, fraction: float, seed: int, note=None) -> PointCloud:
    """The check points of a DEM: a seeded random ``fraction`` of its valid cells (at least 30;
    none for 0), drawn among those inside the data (``inner_cells``, so that its edge stays), as
    points (cell centre, z) in the draw's order; the cells are then taken out of ``dem`` and
    filled from their neighbours (``fill_from_around``), so that nothing built from it saw
    them. ``note`` hears where fewer cells than asked are inside the data."""
    if fraction == 0:
        return PointCloud(np.empty((0, 3)), dem.crs)
    inner = inner_cells(dem.values)
    wanted = max(int(round(fraction * np.isfinite(dem.values).sum())), 30)
    n = min(inner.size, wanted)
    if note and n < wanted:
        note(f"{n:,} of the {wanted:,} check cells asked (holdout {fraction:g}) could be held out "
             "of the DEM: a check cell needs data in its eight neighbours, to be filled from "
             "them, and " + ("no cell has it: the mesh is not assessed" if n == 0 else
                             f"only {n:,} cells have it"))
    cells = inner[np.random.default_rng(seed).choice(inner.size, size=n, replace=False)]
    check = PointCloud(_cell_points(dem, cells), dem.crs)
    fill_from_around(dem.values, cells)
    return check


def _dem_measured(dem: Grid, seed: int) -> tuple[np.ndarray, CellIndex]:
    """The DEM's valid cells as the terrain fits' points (all of them, in a seeded order) and
    their index, which finds them from the grid (``nearest.CellIndex``, 4 B a cell, where an
    index of the points themselves took 24 B a point)."""
    cells = _dem_cells(dem, seed)
    return _cell_points(dem, cells), CellIndex(dem.transform, dem.shape, cells)


def _dem_cells(dem: Grid, seed: int) -> np.ndarray:
    """Flat indices of all the DEM's valid cells in a seeded random order."""
    cells = np.flatnonzero(np.isfinite(dem.values))
    return cells[np.random.default_rng(seed).choice(cells.size, size=cells.size, replace=False)]


def _cell_points(dem: Grid, cells: np.ndarray) -> np.ndarray:
    """The centres and z of the DEM's flat ``cells`` as (n, 3) points. Built column by column,
    Fortran-ordered so that each coordinate is contiguous (the terrain fits read them so without
    copies), from the flat cell indices: where row and column grids and a stacked copy took some
    80 B a cell more (the same numbers, as ``Grid.cell_centres`` and ``nearest.CellIndex``)."""
    n = len(cells)
    xyz = np.empty((3, n)).T
    t, width = dem.transform, dem.shape[1]
    for axis, index, scale, offset in ((0, cells % width, t.a, t.c),
                                       (1, cells // width, t.e, t.f)):
        column = xyz[:, axis]
        column[...] = index
        del index
        column += 0.5
        column *= scale
        column += offset
    np.take(dem.values, cells, out=xyz[:, 2])
    return xyz

