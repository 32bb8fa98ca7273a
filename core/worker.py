"""Run one FloodMesh step in a process of its own: the QGIS plugin's worker.

QGIS loads its own GEOS (and GDAL, PROJ) into ``qgis.bin`` and ``qgis_process.bin``; shapely's
PyPI wheel brings another GEOS, and Triangle or numba can fail hard on their own. As QGIS's
GRASS, SAGA and point-cloud (``pdal_wrench``) algorithms do, the plugin therefore never imports
the numerical core: it starts ``python -m floodmesh.core.worker`` and talks to it in JSON.

Protocol. The job arrives on stdin as one JSON object ``{"step": NAME, "args": {...}}`` (NAME
one of ``STEPS``; args plain JSON: paths, numbers, strings). The worker answers on stdout with
one JSON object per line:

``{"progress": 0.42}``   fraction done (0–1), at most every 0.1 s and 0.5 %
``{"info": "..."}``      a line for the log
``{"note": "..."}``      something assumed or repaired on the user's behalf
``{"result": {...}}``    the step's outputs (last line, exit code 0)
``{"error": "..."}``     bad input: core's one-line message (last line, exit code 2)

Anything else the libraries print goes to stderr. A crash or a kill ends the process without a
result line; every output is written atomically (``io.atomic_output``), so what remains is a
previous file or none, and the hidden ``.*.partial*`` files a killed worker leaves are the
caller's to remove (``PARTIAL_GLOB``).
"""
from __future__ import annotations

import faulthandler
import json
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

from .compiles import CompileWatch
from .errors import Cancelled, FloodMeshError

PARTIAL_GLOB = ".*.partial*"  # the temporary names io.atomic_output writes under


class Channel:
    """The worker's side of the protocol: JSON lines on a private copy of stdout."""

    def __init__(self, stream):
        self.stream = stream
        self._last = (-1.0, 0.0)

    def send(self, **message) -> None:
        self.stream.write(json.dumps(message, default=str) + "\n")
        self.stream.flush()

    def progress(self, fraction: float) -> None:
        fraction = min(max(float(fraction), 0.0), 1.0)
        last, when = self._last
        now = time.monotonic()
        if fraction >= 1.0 or (fraction - last >= 0.005 and now - when >= 0.1):
            self._last = (fraction, now)
            self.send(progress=round(fraction, 4))

    def info(self, text: str) -> None:
        self.send(info=str(text))

    def note(self, text: str) -> None:
        self.send(note=str(text))

    @staticmethod
    def cancelled() -> bool:
        return False  # the caller cancels by ending the process


# ---------------------------------------------------------------------------------------------
# the steps: one per Processing algorithm, each a few lines around the core calls
def _points_xyz(path, crs=None):
    """(xyz, CRS) of measured points from a point layer (GeoPackage, Shapefile, GeoJSON) or a
    LiDAR point file (LAS/LAZ ground, XYZ/CSV)."""
    from . import io
    from .raster import require_metric_crs

    if io.is_point_source(path):
        cloud = io.read_points(path, crs=crs)
        return cloud.xyz, cloud.crs
    return io.read_points_vector(path), require_metric_crs(crs or io.vector_crs(path),
                                                            Path(path).name)


def _mesh_inputs(dem, breaklines=None, boundary=None, user_lines=None):
    from . import io
    from .pipeline import mesh_constraints

    grid = io.read_raster(dem)
    lines = io.read_lines_gpkg(breaklines) if breaklines else []
    domain, own = mesh_constraints(grid, boundary, user_lines)
    return grid, lines + own, domain


def step_grid(ch, *, input, output, cell_size, crs=None, classes=None, max_gap=None,
              holdout=0.0, seed=0, holdout_output=None, workers=None, scheduler=None):
    from . import io
    from .tiles import grid_point_tiles, is_tile_set

    classes = tuple(classes) if classes else None
    if is_tile_set(input):  # several tiles: gridded tile by tile on Dask, written block by block
        tiled = grid_point_tiles(input, cell_size, max_gap=max_gap, crs=crs, classes=classes,
                                 holdout=holdout, seed=seed, out_path=output, keep=False,
                                 workers=workers, scheduler=scheduler, progress=ch.progress,
                                 cancelled=ch.cancelled)
        for message in tiled.notes:
            ch.note(message)
        held, points_crs = tiled.holdout, tiled.crs
    else:
        from .grid import grid_points_linear
        from .points import split_holdout

        points = io.read_points(input, crs=crs, classes=classes, note=ch.note)
        gridding, held = split_holdout(points, holdout, seed, note=ch.note)
        dem = grid_points_linear(gridding, cell_size, max_gap=max_gap, progress=ch.progress)
        io.write_raster(output, dem)
        held, points_crs = held.xyz, points.crs
    result = {"OUTPUT": output, "crs": points_crs.to_wkt()}
    if holdout_output and len(held):
        io.write_points_gpkg(holdout_output, held, points_crs, layer="holdout")
        result["HOLDOUT_OUTPUT"] = holdout_output
    return result


def step_slope(ch, *, input, output, method, sigma=1.0, log_kernel="pratt"):
    from .slope import slope_raster_file

    slope_raster_file(input, output, method, sigma=sigma, log_kernel=log_kernel, note=ch.note,
                      progress=ch.progress, cancelled=ch.cancelled)
    return {"OUTPUT": output}


def step_breakpoints(ch, *, input, output, s_crit=10.0, sensitivity=None, zero_crossings=False):
    import numpy as np

    from . import io
    from .breakpoints import classify_breakpoints, log_breakpoints

    grid = io.read_raster(input)
    if sensitivity is not None:
        points = log_breakpoints(grid, sensitivity, zero_crossings=zero_crossings)
    else:
        points = classify_breakpoints(grid, s_crit)
    io.write_raster(output, points, valid=np.isfinite(grid.values))
    return {"OUTPUT": output}


def step_trace(ch, *, breakpoints, slope, dem, output, s_crit, mode="auto", min_points=3,
               min_length=0.0, join=True, seed=0):
    from . import io
    from .breaklines import trace_breaklines

    points = io.read_raster(breakpoints)
    points = points.with_values((points.values == 1).astype("uint8"))
    grid = io.read_raster(dem)
    lines = trace_breaklines(points, io.read_raster(slope), grid, s_crit, mode=mode,
                             min_points=min_points, min_length=min_length, join=join, seed=seed)
    io.write_breaklines(output, lines, grid.crs)
    ch.info(f"{len(lines)} break lines")
    return {"OUTPUT": output, "crs": grid.crs.to_wkt()}


def step_simplify(ch, *, input, output, crs, method, amount, min_distance):
    from . import io
    from .raster import require_metric_crs
    from .simplify import simplify_breaklines

    crs = require_metric_crs(crs or io.vector_crs(input), Path(input).name)
    lines = simplify_breaklines(io.read_breaklines(input), method, amount,
                                min_distance=min_distance)
    io.write_breaklines(output, lines, crs)
    return {"OUTPUT": output, "crs": crs.to_wkt()}


def step_build_mesh(ch, *, dem, output, min_angle, max_area, max_triangles, breaklines=None,
                    boundary=None, user_lines=None, size_field=None, triangles=None,
                    flow_area=None):
    from . import io
    from .mesh import build_mesh, mesh_quality
    from .pipeline import size_field as size_from

    grid, lines, domain = _mesh_inputs(dem, breaklines, boundary, user_lines)
    size = size_from(size_field, grid, max_area=max_area) if size_field else None
    from .drainage import flow_area_for, flow_size

    flow_area = flow_area_for(flow_area, grid.cell_size)
    if flow_area is not None:  # smaller triangles where water flows (see drainage)
        from .sizing import finer

        size = finer(size, flow_size(grid, flow_area=flow_area))
    mesh = build_mesh(grid, lines, min_angle=min_angle, max_area=max_area, domain=domain,
                      size_field=size, max_triangles=max_triangles, note=ch.note)
    quality = mesh_quality(mesh, min_angle=min_angle, max_area=max_area)
    ch.info(f"{quality['nodes']} nodes, {quality['triangles']} triangles, smallest angle "
            f"{quality['min_angle_deg']:.2f}°, largest area {quality['max_area_m2']:.1f} m²")
    io.write_mesh_2dm(output, mesh.nodes, mesh.triangles, crs=grid.crs)
    result = {"OUTPUT": output, "NODES": quality["nodes"], "TRIANGLE_COUNT": quality["triangles"],
              "crs": grid.crs.to_wkt()}
    if triangles:
        io.write_mesh_gpkg(triangles, mesh.nodes, mesh.triangles, grid.crs)
        result["TRIANGLES"] = triangles
    return result


def step_refine_mesh(ch, *, dem, points, output, min_angle, max_area, lower, upper, max_nodes,
                     max_rounds, breaklines=None, boundary=None, user_lines=None, check=None,
                     target_rmse=None, target_max=None, report=None):
    from . import io
    from .refine import refine_mesh

    grid, lines, domain = _mesh_inputs(dem, breaklines, boundary, user_lines)
    measured = _points_xyz(points, grid.crs)[0]
    check_xyz = _points_xyz(check, grid.crs)[0] if check else None
    mesh, rounds = refine_mesh(grid, lines, measured, check=check_xyz, domain=domain,
                               min_angle=min_angle, max_area=max_area, lower=lower, upper=upper,
                               target_rmse=target_rmse, target_max=target_max,
                               max_nodes=max_nodes, max_rounds=max_rounds, progress=ch.progress,
                               cancelled=ch.cancelled)
    for k, r in enumerate(rounds, 1):
        checked = (f", check RMSE {100 * r.check_rmse_m:.1f} cm" if check_xyz is not None
                   else "")
        ch.info(f"round {k}: {r.nodes} nodes, RMSE {100 * r.rmse_m:.1f} cm, max "
                f"{100 * r.max_abs_m:.1f} cm{checked}; {r.inserted} points inserted, "
                f"{r.refined} triangles refined")
    io.write_mesh_2dm(output, mesh.nodes, mesh.triangles, crs=grid.crs)
    result = {"OUTPUT": output, "NODES": len(mesh.nodes), "RMSE": rounds[-1].rmse_m,
              "crs": grid.crs.to_wkt()}
    if report:
        io.write_json(report, {"rounds": [asdict(r) for r in rounds]})
        result["REPORT"] = report
    return result


def step_assess(ch, *, mesh, points, output, crs=None, report=None):
    from . import io
    from .accuracy import accuracy_statistics, residuals
    from .mesh import Mesh

    read = io.read_2dm(mesh)
    xyz, crs = _points_xyz(points, crs or read.crs)
    res = residuals(Mesh(read.nodes, read.triangles, crs), xyz)
    io.write_residuals(output, xyz, res, crs)
    stats = accuracy_statistics(res)
    ch.info(json.dumps(stats, indent=1))
    result = {"OUTPUT": output, "RMSE": stats["rmse_m"]}
    if report:
        io.write_json(report, stats)
        result["REPORT"] = report
    return result


def step_export(ch, *, mesh, output, fmt, crs=None, open_boundaries=None, snap=1.0, regions=None,
                material_field=None, datum_offset=0.0, element_elevations=False,
                breaklines=None):
    from . import io
    from .export import export_mesh, layers_crs

    read = io.read_2dm(mesh)
    crs = layers_crs(crs or read.crs, {"open boundary": open_boundaries, "region": regions,
                                       "break line": breaklines})
    written = export_mesh(
        output, read.nodes, read.triangles, fmt=fmt, crs=crs,
        open_lines=io.read_lines_gpkg(open_boundaries) if open_boundaries else (),
        snap=snap, regions=io.read_regions(regions, field=material_field) if regions else (),
        materials=read.materials, datum_offset=datum_offset,
        element_elevations=element_elevations,
        breaklines=io.read_lines_gpkg(breaklines) if breaklines else ())
    ch.info(f"{len(read.nodes)} nodes, {len(read.triangles)} triangles written to "
            f"{', '.join(str(p) for p in written)}")
    result = {"OUTPUT": output, "files": [str(p) for p in written],
              "crs": crs.to_wkt() if crs is not None else None}
    if fmt == "slf":
        result["CLI"] = str(written[1])
    return result


def step_run(ch, *, input, output_folder, options):
    from .options import RunOptions
    from .pipeline import run_pipeline

    options = dict(options)
    for key in ("formats", "classes"):
        if options.get(key) is not None:
            options[key] = tuple(options[key])
    report = run_pipeline(input, output_folder, RunOptions(**options), progress=ch.progress,
                          cancelled=ch.cancelled, log=_pipeline_log(ch))
    from pyproj import CRS

    return {"nodes": report["nodes"], "triangles": report["triangles"],
            "rmse_m": report["rmse_m"], "crs": CRS.from_user_input(report["crs"]).to_wkt()}


def step_flood(ch, *, mesh, scenario, output, crs=None):
    from .flood import load_scenario, run_flood

    report = run_flood(mesh, load_scenario(scenario), output, crs=crs, progress=ch.progress,
                       log=ch.info)
    for message in report["notes"]:
        ch.note(message)
    return {key: report[key] for key in ("cpu_s", "time_steps", "flooded_area_m2",
                                         "mass_balance")}


def _pipeline_log(ch):
    """run_pipeline's log: its notes (``note: …``) as notes, the rest as info."""
    def log(text):
        text = str(text)
        if text.startswith("note: "):
            ch.note(text[len("note: "):])
        else:
            ch.info(text)
    return log


STEPS = {"grid": step_grid, "slope": step_slope, "breakpoints": step_breakpoints,
         "trace": step_trace, "simplify": step_simplify, "build_mesh": step_build_mesh,
         "refine_mesh": step_refine_mesh, "assess": step_assess, "export": step_export,
         "run": step_run, "flood": step_flood}


def run_job(job: dict, ch: Channel) -> int:
    """Run one job, answering on ``ch``; the exit code (0 done, 2 bad input, 130 cancelled)."""
    from .dependencies import install_hint, missing_dependencies

    missing = missing_dependencies()
    if missing:
        ch.send(error=install_hint(missing))
        return 2
    step = STEPS.get(job.get("step"))
    if step is None:
        ch.send(error=f"unknown FloodMesh worker step {job.get('step')!r}; one of "
                      f"{', '.join(STEPS)}")
        return 2
    # numba's first-run compile said when it really happens (run_pipeline says its own)
    compiles = CompileWatch(ch.info if step is not step_run else None)
    try:
        with compiles.watching():
            result = step(ch, **job.get("args", {}))
        if compiles.summary():
            ch.info(compiles.summary())
        ch.send(result=result)
    except FloodMeshError as exc:
        ch.send(error=str(exc))
        return 2
    except Cancelled:
        ch.send(error="Cancelled; no partial output was written")
        return 130
    return 0


def main() -> int:
    # the protocol owns the real stdout; whatever else prints goes to stderr
    channel = Channel(os.fdopen(os.dup(1), "w", encoding="utf-8"))
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    faulthandler.enable()  # a crash in GEOS, Triangle or numba leaves its trace on stderr
    try:
        job = json.loads(sys.stdin.read())
    except ValueError as exc:
        channel.send(error=f"the FloodMesh worker got a job that is not JSON ({exc})")
        return 2
    return run_job(job, channel)


if __name__ == "__main__":
    sys.exit(main())
