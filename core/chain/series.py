"""Scale series: one mesh per maximum triangle area and break-line simplification on one input,
each assessed on the same held-out points, and a table (and plot) of nodes against error, so that
a modeller can pick the coarsest mesh that meets the need."""
from __future__ import annotations

import csv
import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .. import io
from ..engine.progress import along, part, report
from ..errors import FloodMeshError
from ..io.outputs import check_output_folder, staged_folder
from ..io.report import new_figure, save_png
from ..options import RunOptions, check_max_area
from ..points import step_points
from ..raster import usable_dem
from ..steps.accuracy import (accuracy_statistics, nssda_threshold_m, outside_mesh_note,
                              residuals)
from ..steps.hydraulic_lines import lines_for_hydraulics
from ..steps.mesh import Mesh, build_mesh, domain_from_dem, edge_tolerance
from ..steps.simplify import simplify_breaklines
from .pipeline import (SERIES_FILES, Notes, folder_output, front_steps, run_inputs, say_later,
                       trace_front)
from .source import open_source

def _mesh_files(labels) -> list[str]:
    """The files of each labelled mesh: the 2DM and the .prj beside it."""
    return [f"mesh_{label}.{ext}" for label in labels for ext in ("2dm", "prj")]


COLUMNS = ("label", "max_area_m2", "simplification", "amount", "nodes", "triangles",
           "n_assessed", "rmse_m", "mean_m", "max_abs_m", "share_over_25cm", "nssda_pass")
_SHORT = {"keep-every": "k", "douglas-peucker": "dp", "spline": "sp"}


@dataclass(frozen=True)
class Setting:
    """One mesh of the series: maximum triangle area (m²) and break-line simplification
    (keep-every n, or douglas-peucker / spline within ``amount`` metres)."""

    max_area: float
    method: str = "keep-every"
    amount: float = 4.0

    @property
    def label(self) -> str:
        """Short name used in file names and on the plot, e.g. ``a100-k4``, ``a50-dp0.5``."""
        return f"a{self.max_area:g}-{_SHORT[self.method]}{self.amount:g}"


def settings_grid(max_areas, method: str = "keep-every", amounts=(4,)) -> list[Setting]:
    """Every combination of ``max_areas`` (m²) and simplification ``amounts``, areas first."""
    if not len(max_areas) or not len(amounts):
        raise FloodMeshError("a scale series needs at least one maximum area and one "
                             "simplification amount, e.g. --max-areas 400,200,100")
    if method not in _SHORT:
        raise FloodMeshError(f"unknown simplification {method!r}; choose from "
                             f"{', '.join(_SHORT)}")
    for area in max_areas:
        check_max_area(area)
    for what, values in (("maximum area", max_areas), ("simplification amount", amounts)):
        values = [float(v) for v in values]
        twice = sorted({v for v in values if values.count(v) > 1})
        if twice:
            raise FloodMeshError(f"the {what} {', '.join(f'{v:g}' for v in twice)} is given "
                                 "more than once: give each once (each gives one mesh)")
    return [Setting(float(a), method, float(n)) for a, n in itertools.product(max_areas, amounts)]


def scale_series(dem, traced: list, check_xyz: np.ndarray, settings: list[Setting], *,
                 min_angle: float = 25.0, min_distance: float | None = None, domain=None,
                 own_lines: list = (), min_spacing: float | None = None,
                 log: Callable[[str], None] | None = None,
                 note: Callable[[str], None] | None = None,
                 progress: Callable[[float], None] | None = None,
                 cancelled: Callable[[], bool] | None = None) -> tuple[list[dict], list[Mesh]]:
    """Mesh ``dem`` with the ``traced`` break lines once per setting and assess each mesh on the
    check points ``check_xyz`` (n, 3; m). ``min_distance`` (m) defaults to half a cell;
    ``domain`` and ``own_lines`` as for ``build_mesh`` (a user's domain and lines);
    ``min_spacing`` (m; default the cell size, 0 off) as ``run``'s: the detected lines made
    affordable for a flood model (``hydraulic_lines``). ``note`` hears, after the last mesh,
    what the meshes and their assessments say as ``run``'s do, each once, naming the meshes
    that say it where not every mesh does (``series_notes``). ``progress`` hears the share of
    the meshes done, along each; ``cancelled`` is polled along them (``Cancelled``).

    Returns one row per setting (``COLUMNS``: errors in metres, ``share_over_25cm`` a fraction)
    and the meshes, in the order of ``settings``. DEM cells and check points no ground has
    (-9999, inf) are nodata and left out, as in every step (``note`` told)."""
    dem = usable_dem(dem, "the DEM", note)
    check_xyz = step_points(check_xyz, "the check points", note)
    min_distance = dem.cell_size / 2 if min_distance is None else min_distance
    spacing = dem.cell_size if min_spacing is None else min_spacing
    simplified, domains = {}, {}
    rows, meshes, said = [], [], {}
    for k, setting in enumerate(settings):
        share = part(progress, k / len(settings), (k + 1) / len(settings))
        if log:
            log(f"mesh {setting.label}...")
        key = (setting.method, setting.amount)
        if key not in simplified:
            # the DEM's data, its edge within the setting's tolerance (a user's domain as given)
            domains[key] = domain if domain is not None else domain_from_dem(
                dem, tolerance=edge_tolerance(setting.method, setting.amount, dem.cell_size))
            simplified[key] = [line.coords for line in simplify_breaklines(
                traced, setting.method, setting.amount, min_distance=min_distance,
                cancelled=cancelled)]
            if spacing > 0:
                simplified[key], _ = lines_for_hydraulics(
                    simplified[key], domains[key], spacing=spacing, own_lines=own_lines)
        told = said[setting.label] = []
        mesh = build_mesh(dem, simplified[key], own_lines=own_lines, min_angle=min_angle,
                          max_area=setting.max_area, domain=domains[key], note=told.append,
                          progress=part(share, 0.0, 0.9), cancelled=cancelled)
        res = residuals(mesh, check_xyz, progress=part(share, 0.9, 1.0), cancelled=cancelled)
        outside = outside_mesh_note(check_xyz, res, dem, domain is not None)
        if outside:
            told.append(outside)
        stats = accuracy_statistics(res, note=told.append)
        rows.append({"label": setting.label, "max_area_m2": setting.max_area,
                     "simplification": setting.method, "amount": setting.amount,
                     "nodes": int(len(mesh.nodes)), "triangles": int(len(mesh.triangles)),
                     "n_assessed": stats["n_assessed"], "rmse_m": stats["rmse_m"],
                     "mean_m": stats["mean_m"], "max_abs_m": stats["max_abs_residual_m"],
                     "share_over_25cm": stats["classes"][">25 cm"],
                     "nssda_pass": stats["nssda_pass"]})
        meshes.append(mesh)
    for message in series_notes(said) if note else ():
        note(message)
    return rows, meshes


def series_notes(said: dict) -> list[str]:
    """The notes of a series' meshes ({label: [notes]}, in order), each once: as it is where
    every mesh says it, else naming the meshes that do (``meshes a200-k2, a100-k2: …``)."""
    notes = []
    for message in dict.fromkeys(m for messages in said.values() for m in messages):
        labels = [label for label, messages in said.items() if message in messages]
        notes.append(message if len(labels) == len(said) else
                     f"mesh{'es' if len(labels) > 1 else ''} {', '.join(labels)}: {message}")
    return notes


def write_series_csv(path, rows: list[dict]) -> Path:
    """The rows as CSV (``COLUMNS``; empty cells for missing values), written atomically."""
    path = Path(path)
    with io.atomic_output(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=COLUMNS)
            writer.writeheader()
            for row in rows:
                writer.writerow({k: "" if row[k] is None else row[k] for k in COLUMNS})
    return path


def write_series_png(path, rows: list[dict], *, nssda_threshold_m: float | None = None) -> Path:
    """Nodes (log scale) against holdout RMSE (cm), one line per simplification, each point
    labelled with its setting; the NSSDA bound dashed when given."""
    fig = new_figure(8, 5)
    ax = fig.add_subplot()
    assessed = [r for r in rows if r["rmse_m"] is not None]
    for key, group in itertools.groupby(sorted(assessed, key=lambda r: (
            r["simplification"], r["amount"], r["nodes"])),
            key=lambda r: (r["simplification"], r["amount"])):
        group = list(group)
        ax.plot([r["nodes"] for r in group], [100 * r["rmse_m"] for r in group], "o-",
                label=f"{key[0]} {key[1]:g}")
        for r in group:
            ax.annotate(r["label"], (r["nodes"], 100 * r["rmse_m"]), textcoords="offset points",
                        xytext=(4, 4), fontsize="small")
    if nssda_threshold_m is not None:
        ax.axhline(100 * nssda_threshold_m, color="0.3", linestyle="--",
                   label=f"NSSDA bound {100 * nssda_threshold_m:.1f} cm")
    ax.set_xscale("log")
    ax.set_xlabel("mesh nodes")
    ax.set_ylabel("holdout RMSE (cm)")
    ax.set_title("scale series: nodes against terrain error")
    ax.grid(True, which="both", alpha=0.3)
    if assessed:
        ax.legend()
    fig.tight_layout()
    return save_png(fig, path)


def run_series(input_path, out_dir, options: RunOptions, settings: list[Setting], *,
               log: Callable[[str], None] | None = None,
               progress: Callable[[float], None] | None = None,
               cancelled: Callable[[], bool] | None = None) -> dict:
    """Read, grid, slope, breakpoints and trace ``input_path`` once (as ``options`` say), then
    mesh and assess once per setting; write ``SERIES_FILES`` and ``mesh_<label>.2dm`` (its CRS
    in ``mesh_<label>.prj``) per row into ``out_dir``. ``log`` receives each mesh's name and,
    as ``run_pipeline``'s, the notes (``note: …``), which series.json's ``notes`` holds too.
    ``progress`` hears the share done (0–1: the tracing half, the meshes and their writing the
    rest), ``cancelled`` is polled along (``Cancelled``, nothing written).
    Returns the series.json content."""
    note = Notes(log)
    out, source = Path(out_dir), open_source(input_path)
    inputs = run_inputs(source, options)
    check_output_folder(out, inputs, [*SERIES_FILES, *_mesh_files(s.label for s in settings)])
    front = trace_front(source, options, front_steps(options, part(progress, 0.0, 0.5),
                                                     cancelled),
                        cancelled=cancelled, note=note)
    say_later(front, note)()
    rows, meshes = scale_series(front.dem, front.traced, front.holdout.xyz, settings,
                                min_angle=options.min_angle,
                                min_distance=options.min_distance, domain=front.domain,
                                own_lines=front.own_lines, min_spacing=options.min_spacing,
                                log=log, note=note, progress=part(progress, 0.5, 0.95),
                                cancelled=cancelled)
    # the folder is replaced as a whole: an interrupt leaves the old series' files or these
    with staged_folder(out, own=folder_output, keep=inputs) as stage:
        for row, mesh in along(list(zip(rows, meshes)), part(progress, 0.95, 0.99), cancelled):
            io.write_mesh_2dm(stage / f"mesh_{row['label']}.2dm", mesh.nodes, mesh.triangles,
                              crs=front.dem.crs)
        n = max((r["n_assessed"] for r in rows), default=0)
        threshold = nssda_threshold_m(n)
        write_series_csv(stage / "series.csv", rows)
        write_series_png(stage / "series.png", rows,
                         nssda_threshold_m=None if np.isnan(threshold) else threshold)
        result = {"input": source.named, "crs": front.dem.crs.to_string(),
                  "cell_size_m": front.dem.cell_size, "min_angle_deg": options.min_angle,
                  "n_holdout": len(front.holdout), "holdout_source": front.holdout_source,
                  "n_breaklines_traced": len(front.traced), "rows": rows, "notes": note.said,
                  "files": [*SERIES_FILES, *_mesh_files(r["label"] for r in rows)]}
        io.write_json(stage / "series.json", result)
    report(progress, None, 1.0)
    return io.jsonable(result)
