"""The whole chain, points → grid → slope → breakpoints → break lines → mesh → assessment,
with every intermediate written to an output folder and a report of figures and timings."""
from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np

from . import io
from .accuracy import accuracy_statistics, residuals
from .breaklines import trace_breaklines
from .breakpoints import classify_breakpoints, log_breakpoints
from .errors import Cancelled
from .grid import check_grid, grid_points_linear
from .limits import check_memory, check_triangles
from .mesh import build_mesh, mesh_quality
from .points import PointCloud, split_holdout
from .raster import Grid
from .simplify import max_deviation, simplify_douglas_peucker, simplify_keep_every
from .options import RunOptions
from .slope import laplacian_of_gaussian, slope

OUTPUT_FILES = ("dem.tif", "slope.tif", "breakpoints.tif", "breaklines.gpkg", "mesh.2dm",
                "mesh.gpkg", "residuals.gpkg", "report.json")


class _Steps:
    """Times each step, reports overall progress and checks for cancellation between steps."""

    def __init__(self, weights: dict, progress, cancelled, log):
        self.weights, self.total = weights, float(sum(weights.values()))
        self.progress, self.cancelled, self.log = progress, cancelled, log
        self.done, self.seconds = 0.0, {}

    def run(self, name: str, func: Callable, *args, **kwargs):
        if self.cancelled and self.cancelled():
            raise Cancelled()
        if self.log:
            self.log(f"{name}...")
        start = time.perf_counter()
        weight = self.weights.get(name, 1.0)
        if "progress" in kwargs and self.progress:
            base = self.done
            kwargs["progress"] = lambda f: self.progress((base + f * weight) / self.total)
        result = func(*args, **kwargs)
        self.seconds[name] = round(time.perf_counter() - start, 3)
        self.done += weight
        if self.progress:
            self.progress(self.done / self.total)
        return result


def run_pipeline(input_path, out_dir, options: RunOptions = RunOptions(), *,
                 progress: Callable[[float], None] | None = None,
                 cancelled: Callable[[], bool] | None = None,
                 log: Callable[[str], None] | None = None) -> dict:
    """Run the whole chain on a point file or DEM and write ``OUTPUT_FILES`` into ``out_dir``.

    ``progress`` receives the overall fraction done (0–1), ``cancelled`` is polled between and
    inside long steps (raising ``Cancelled``), ``log`` receives step names and notes (what was
    assumed or repaired on the user's behalf, also listed in the report). Returns the report.
    """
    options.validate()
    notes = []

    def note(message: str):
        notes.append(message)
        if log:
            log(f"note: {message}")

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    method, amount = options.simplification()
    steps = _Steps({"read": 1, "grid": 4, "slope": 1, "breakpoints": 0.5, "breaklines": 1,
                    "simplify": 0.5, "mesh": 2, "assess": 1, "write": 2}, progress, cancelled, log)
    data = steps.run("read", io.read_input, input_path, crs=options.crs, classes=options.classes,
                     note=note)
    if isinstance(data, PointCloud):
        gridding, holdout = split_holdout(data, options.holdout, options.seed)
        # refuse, before the work, a grid or mesh too large for the limit or the memory
        plan = check_grid(gridding, options.cell_size, options.max_gap)
        triangles = check_triangles(plan["area"], options.max_area, options.max_triangles)
        check_memory(points=len(gridding), cells=plan["rows"] * plan["cols"],
                     triangles=triangles, advice="give a larger cell size or maximum area, or "
                                                 "split the data into tiles")
        dem = steps.run("grid", grid_points_linear, gridding, options.cell_size,
                        max_gap=options.max_gap, progress=None, cancelled=cancelled)
        holdout_source = "LiDAR points withheld from gridding"
        n_points = len(data)
    else:
        dem = data  # a DEM keeps its own cell size
        valid_area = float(np.isfinite(dem.values).sum()) * dem.cell_size ** 2
        triangles = check_triangles(valid_area, options.max_area, options.max_triangles)
        check_memory(cells=dem.values.size, triangles=triangles,
                     advice="resample the DEM to larger cells or split it into tiles")
        holdout = _dem_check_points(dem, options.holdout, options.seed)
        holdout_source = "DEM cell centres (not independent of the DEM)"
        n_points = 0
    if options.slope_method == "log":
        # second order: breakpoints from the LoG; the tracer still follows first-order slope
        response = steps.run("slope", laplacian_of_gaussian, dem, options.sigma,
                             kernel=options.log_kernel, cancelled=cancelled)
        breakpoints = steps.run("breakpoints", log_breakpoints, response, options.sensitivity,
                                zero_crossings=options.zero_crossings)
        slope_grid = steps.run("tracing slope", slope, dem, "one-over-distance",
                               cancelled=cancelled)
    else:
        slope_grid = steps.run("slope", slope, dem, options.slope_method, cancelled=cancelled)
        breakpoints = steps.run("breakpoints", classify_breakpoints, slope_grid, options.s_crit)
    traced = steps.run("breaklines", trace_breaklines, breakpoints, slope_grid, dem,
                       options.s_crit, mode=options.tracing_mode, min_points=options.min_points)
    if method == "douglas-peucker":
        lines = steps.run("simplify", simplify_douglas_peucker, traced, amount)
    else:
        lines = steps.run("simplify", simplify_keep_every, traced, int(amount))
    mesh = steps.run("mesh", build_mesh, dem, [line.coords for line in lines],
                     min_angle=options.min_angle, max_area=options.max_area,
                     max_triangles=options.max_triangles, note=note)
    res = steps.run("assess", residuals, mesh, holdout.xyz)

    delta = dem.cell_size / 2
    deviation = max((max_deviation(a, b) for a, b in zip(traced, lines)), default=0.0)
    alpha = amount / delta if method == "douglas-peucker" else deviation / delta
    quality = mesh_quality(mesh, min_angle=options.min_angle, max_area=options.max_area)
    stats = accuracy_statistics(res, alpha=alpha, delta=delta)

    def write_all():
        valid = np.isfinite(dem.values)
        io.write_raster(out / "dem.tif", dem)
        io.write_raster(out / "slope.tif", slope_grid)
        io.write_raster(out / "breakpoints.tif", breakpoints, valid=valid)
        io.write_breaklines(out / "breaklines.gpkg", lines, dem.crs)
        io.write_mesh_2dm(out / "mesh.2dm", mesh.nodes, mesh.triangles)
        io.write_mesh_gpkg(out / "mesh.gpkg", mesh.nodes, mesh.triangles, dem.crs)
        io.write_residuals(out / "residuals.gpkg", holdout.xyz, res, dem.crs)

    steps.run("write", write_all)
    report = {
        "input": str(input_path),
        "crs": dem.crs.to_string(),
        "options": {k: v for k, v in asdict(options).items()},
        "n_points": n_points,
        "holdout_source": holdout_source,
        "grid": {"rows": dem.shape[0], "cols": dem.shape[1], "cell_size_m": dem.cell_size,
                 "valid_cells": int(np.isfinite(dem.values).sum())},
        "n_breakpoints": int(breakpoints.values.sum()),
        "n_breaklines_traced": len(traced),
        "n_breaklines": len(lines),
        "breakline_points_traced": int(sum(len(t.coords) for t in traced)),
        "breakline_points_kept": int(sum(len(t.coords) for t in lines)),
        "simplification": {"method": method, "value": amount,
                           "max_deviation_m": deviation},
        **quality,
        **stats,
        "notes": notes,
        "seconds": steps.seconds,
    }
    io.write_json(out / "report.json", _jsonable(report))
    return report


def _dem_check_points(dem: Grid, fraction: float, seed: int) -> PointCloud:
    rows, cols = np.nonzero(np.isfinite(dem.values))
    n = max(int(round(fraction * rows.size)), min(rows.size, 30))
    pick = np.random.default_rng(seed).choice(rows.size, size=n, replace=False)
    x, y = dem.cell_centres(rows[pick], cols[pick])
    return PointCloud(np.column_stack([x, y, dem.values[rows[pick], cols[pick]]]), dem.crs)


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    return value
