"""report.html: one self-contained page of a run, from the report that report.json holds.

Plain HTML with a little inline CSS, no script and nothing fetched: the figures are embedded as
``data:`` URIs, so that the page works when opened alone, mailed, or shown in QGIS's Results
Viewer. Every figure comes from the report dict; no statistic is computed again. The lines that
depend on the clock (the run's date and duration) carry ``class="run-time"``: the rest of the
page is the same bytes for the same inputs and options.
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import json
from pathlib import Path

from .. import io
from ..steps.accuracy import CLASS_NAMES
from .report import BREAKLINES_PNG, CLASS_LABELS, HISTOGRAM_PNG, MAP_PNG

HTML_NAME = "report.html"
FIGURES = (HISTOGRAM_PNG, MAP_PNG, BREAKLINES_PNG)
CAPTIONS = {
    HISTOGRAM_PNG: "Holdout residuals (measured − mesh) in cm, coloured by class; the class "
                   "edges ±10 and ±25 cm dashed.",
    MAP_PNG: "The mesh's edges and the held-out points coloured by the class of their residual "
             "(< 10 cm green, 10–25 cm orange, > 25 cm red, outside the mesh grey).",
    BREAKLINES_PNG: "The break lines (breaklines.gpkg) over a hillshade of the DEM (sun from "
                    "the north-west, 315°, 45° above the horizon).",
}
NSSDA_RULE = "15·√(((n−1) − 2.326·√(n−1))/n) cm"

CSS = """\
body{font-family:sans-serif;color:#222;max-width:62em;margin:1em auto;padding:0 1em;line-height:1.4}
h1{font-size:1.5em;margin-bottom:.2em}
h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0}
th,td{border:1px solid #ddd;padding:.2em .6em;text-align:left;vertical-align:top}
th{background:#f4f4f4;font-weight:normal}
td.n{text-align:right}
.meta{color:#555;margin:.2em 0}
.pass{color:#1a7a36;font-weight:bold}
.fail{color:#c0141a;font-weight:bold}
.untested{color:#777;font-weight:bold}
figure{margin:1em 0}
img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}"""


class _Markup(str):
    """Text that is HTML already (built here from escaped parts): not escaped again."""


def _e(value) -> str:
    """``value`` as HTML text: escaped unless it is ``_Markup``."""
    return value if isinstance(value, _Markup) else html.escape(str(value), quote=True)


def cm(value_m) -> str:
    """A length in metres as centimetres with two decimals (0.1 mm); "n/a" for None."""
    return "n/a" if value_m is None else f"{100 * value_m:.2f} cm"


def _number(value, digits: int = 0) -> str:
    return "n/a" if value is None else f"{value:,.{digits}f}"


def _table(rows, header=None, css_id=None) -> str:
    """Rows of (label, value[, row id[, value cells' class]]) as a two-column table; values
    may be tuples (one cell each)."""
    out = [f'<table id="{_e(css_id)}">' if css_id else "<table>"]
    if header:
        out.append("<tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>")
    for label, value, *rest in rows:
        row_id = rest[0] if rest else None
        cls = f' class="{_e(rest[1])}"' if len(rest) > 1 and rest[1] else ""
        cells = value if isinstance(value, tuple) else (value,)
        out.append((f'<tr id="{_e(row_id)}">' if row_id else "<tr>") + f"<th>{_e(label)}</th>"
                   + "".join(f"<td{cls}>{_e(c)}</td>" for c in cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def input_name(report: dict) -> str:
    """The run's input as a short name: the file's, or the first tile's and how many more."""
    source = report.get("input", "")
    if isinstance(source, (list, tuple)):
        if not source:
            return "(no input)"
        more = len(source) - 1
        return Path(source[0]).name + (f" and {more} more tile{'s' * (more > 1)}" if more
                                       else "")
    return Path(str(source)).name


def _header(report: dict, when, elapsed_s) -> str:
    name = input_name(report)
    source = report.get("input", "")
    paths = ", ".join(map(str, source)) if isinstance(source, (list, tuple)) else str(source)
    grid = report.get("grid", {})
    lines = [f'<h1 id="title">FloodMesh run: {_e(name)}</h1>',
             f'<p class="meta">Input {_e(paths)}'
             + (f" ({report['n_points']:,} points)" if report.get("n_points") else "")
             + f"; CRS {_e(report.get('crs', 'unknown'))}"
             + (f"; DEM {grid['cols']:,} × {grid['rows']:,} cells of {grid['cell_size_m']:g} m"
                if grid else "") + ".</p>"]
    if when is not None or elapsed_s is not None:
        text = "Run" + (when.strftime(" finished %Y-%m-%d %H:%M:%S %Z").rstrip()
                        if when else "")
        if elapsed_s is not None:
            text += f" in {elapsed_s:.1f} s"
        lines.append(f'<p class="meta run-time">{_e(text.strip())}.</p>')
    return "\n".join(lines)


def _nssda(report: dict) -> str:
    """The FEMA/NSSDA verdict and what it tested, as a paragraph."""
    n, rmse, bound = report["n_assessed"], report["rmse_m"], report.get("nssda_threshold_m")
    verdict = report.get("nssda_pass")
    if verdict is None or bound is None:
        why = ("FEMA asks for 20 or more" if bound is not None else
               "it needs at least 7; FEMA asks for 20 or more")
        return (f'<p id="nssda">FEMA/NSSDA sample test: <span class="untested">not tested'
                f"</span>: too few check points ({n:,}) for the bound {_e(NSSDA_RULE)} "
                f"({why}).</p>")
    word, cls, relation = (("PASS", "pass", "≤") if verdict else ("FAIL", "fail", ">"))
    return (f'<p id="nssda">FEMA/NSSDA sample test: <span class="{cls}">{word}</span>: the '
            f"RMSE of the {n:,} check points, {_e(cm(rmse))}, {relation} {_e(cm(bound))}, "
            f"the bound {_e(NSSDA_RULE)} for n = {n:,} against the 15 cm RMSE requirement."
            "</p>")


def _accuracy(report: dict) -> str:
    out = ["<h2>Accuracy</h2>"]
    n_holdout, n = report.get("n_holdout", 0), report.get("n_assessed", 0)
    holdout = report.get("options", {}).get("holdout")
    if not n_holdout:
        out.append('<p id="no-assessment">No points were held out'
                   + (f" (holdout {_e(holdout)})" if holdout is not None else "")
                   + ", so the mesh was not assessed: no residuals, no RMSE and no FEMA/NSSDA "
                   "test. Hold out a share of the points (e.g. 0.001) to assess it.</p>")
        return "\n".join(out)
    if not n:
        out.append(f'<p id="no-assessment">None of the {n_holdout:,} held-out points lies '
                   "inside the mesh, so no residual could be measured: no RMSE and no "
                   "FEMA/NSSDA test.</p>")
        return "\n".join(out)
    rows = [("check points", report.get("holdout_source", "held-out points"), "source"),
            ("held out", f"{n_holdout:,}", "n-holdout", "n"),
            ("assessed (inside the mesh)", f"{n:,}", "n-assessed", "n"),
            ("outside the mesh", f"{report.get('n_outside_mesh', 0):,}", "n-outside", "n"),
            ("RMSE", cm(report["rmse_m"]), "rmse", "n"),
            ("mean (measured − mesh)", cm(report["mean_m"]), "mean", "n"),
            ("standard deviation", cm(report["std_m"]), "std", "n"),
            ("skew", _number(report["skew"], 2), "skew", "n"),
            ("1.96·RMSE (NSSDA 95 % accuracy)", cm(report["accuracy_95_m"]), "accuracy-95",
             "n"),
            ("max |residual|", cm(report["max_abs_residual_m"]), "max-abs", "n")]
    if report.get("vertex_error_bound_m") is not None:
        rows.append(("vertex bound E = RMSE + α·Δ",
                     f"{report['vertex_error_bound_m']:.3f} m (α = {report['alpha']:g}, "
                     f"Δ = {report['delta_m']:g} m)", "vertex-bound"))
    out.append(_table(rows, css_id="accuracy"))
    classes = report.get("classes", {})
    out.append(_table([(label, (f"{round(classes.get(name, 0.0) * n):,}",
                                f"{100 * classes.get(name, 0.0):.1f} %"),
                        f"class-{k}", "n")
                       for k, (name, label) in enumerate(zip(CLASS_NAMES, CLASS_LABELS))],
                      header=("|residual|", "points", "share"), css_id="classes"))
    out.append(_nssda(report))
    return "\n".join(out)


def _mesh(report: dict) -> str:
    options = report.get("options", {})
    area_bound = options.get("far_field_area") or options.get("max_area")
    rows = [("nodes", _number(report.get("nodes")), "nodes", "n"),
            ("triangles", _number(report.get("triangles")), "triangles", "n"),
            ("smallest angle", f"{report['min_angle_deg']:.1f}°"
             + (f" (bound {options['min_angle']:g}°)" if options.get("min_angle") else ""),
             "min-angle", "n"),
            ("largest area", f"{report['max_area_m2']:,.1f} m²"
             + (f" (bound {area_bound:g} m²)" if area_bound else ""), "max-area", "n"),
            ("triangles below the angle bound", _number(report.get("n_below_min_angle")),
             "n-below-min-angle", "n"),
            ("triangles at sharp input corners", f"{report.get('n_small_input_angles', 0):,}"
             + (f" (smallest input angle {report['smallest_input_angle_deg']:.1f}°)"
                if report.get("n_small_input_angles") else ""), "n-small-input-angles", "n"),
            ("triangles above the area bound", _number(report.get("n_above_max_area")),
             "n-above-max-area", "n"),
            ("input segments missing from the mesh", _number(report.get("n_missing_segments")),
             "n-missing-segments", "n"),
            ("duplicate nodes", _number(report.get("n_duplicate_nodes")), "n-duplicate-nodes",
             "n"),
            ("all triangles counter-clockwise",
             {True: "yes", False: "no"}.get(report.get("all_counter_clockwise"), "n/a"),
             "counter-clockwise", "n")]
    hydraulics = report.get("hydraulics") or {}
    if hydraulics.get("cfl_time_step_s") is not None:
        text = (f"{hydraulics['cfl_time_step_s']:.3g} s at {hydraulics['check_depth_m']:g} m "
                f"depth (smallest inradius {hydraulics['min_inradius_m']:.2f} m)")
        if hydraulics.get("uniform_mesh_cfl_time_step_s"):
            text += (f"; a uniform mesh of as many nodes: "
                     f"{hydraulics['uniform_mesh_cfl_time_step_s']:.3g} s")
        rows.append(("CFL time step of the smallest element", text, "cfl"))
    if hydraulics.get("n_small_inradius") is not None:
        rows.append((f"triangles with an inradius under "
                     f"{hydraulics.get('small_inradius_threshold_m', 0):g} m",
                     f"{hydraulics['n_small_inradius']:,} "
                     f"({hydraulics.get('n_small_inradius_near_edge', 0):,} near the edge)",
                     "n-small-inradius", "n"))
    if report.get("refinement"):
        rows.append(("refinement rounds", f"{len(report['refinement'])}", "refinement", "n"))
    return "<h2>Mesh quality</h2>\n" + _table(rows, css_id="mesh")


def _breaklines(report: dict) -> str:
    simplification = report.get("simplification") or {}
    rows = [("break lines", _number(report.get("n_breaklines")), "n-breaklines", "n")]
    if report.get("breakline_length_m") is not None:
        rows.append(("total length", f"{report['breakline_length_m']:,.1f} m",
                     "breakline-length", "n"))
    rows += [("traced before simplification", _number(report.get("n_breaklines_traced")),
              "n-traced", "n"),
             ("breakpoints", _number(report.get("n_breakpoints")), "n-breakpoints", "n"),
             ("points kept of traced", f"{_number(report.get('breakline_points_kept'))} of "
              f"{_number(report.get('breakline_points_traced'))}", "points-kept", "n")]
    if simplification:
        text = " ".join(f"{v:g}" if isinstance(v, float) else str(v)
                        for v in (simplification.get("method"), simplification.get("value"))
                        if v is not None)
        if simplification.get("max_deviation_m") is not None:
            text += f" (max deviation {simplification['max_deviation_m']:.2f} m)"
        rows.append(("simplification", text, "simplification"))
    lines = report.get("hydraulic_lines") or {}
    if lines.get("lines_out") is not None:
        rows.append(("lines in the mesh (node spacing "
                     f"{lines.get('spacing_m', 0):g} m)", f"{lines['lines_out']:,}",
                     "n-meshed", "n"))
    return "<h2>Break lines</h2>\n" + _table(rows, css_id="breaklines")


def _figures(report: dict, figures: dict) -> str:
    out = ["<h2>Figures</h2>"]
    assessed = report.get("n_assessed", 0) > 0
    for name, data in figures.items():
        if name == HISTOGRAM_PNG and not assessed:
            continue  # no residuals: an empty histogram
        caption = CAPTIONS.get(name, name)
        if name == MAP_PNG and not assessed:
            caption = "The mesh's edges (no residuals to show)."
        uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        out.append(f'<figure id="{_e(Path(name).stem)}"><img src="{uri}" alt="{_e(caption)}">'
                   f"<figcaption>{_e(caption)} ({_e(name)})</figcaption></figure>")
    if len(out) == 1:
        out.append("<p>No figures.</p>")
    return "\n".join(out)


def _notes(report: dict) -> str:
    notes = report.get("notes") or []
    if not notes:
        return '<h2>Notes</h2>\n<p id="notes">Nothing was assumed or repaired.</p>'
    return ("<h2>Notes</h2>\n<p>What was assumed or repaired on your behalf:</p>\n"
            '<ul id="notes">\n' + "\n".join(f"<li>{_e(n)}</li>" for n in notes) + "\n</ul>")


def _value(value) -> str:
    return value if isinstance(value, str) else json.dumps(value, ensure_ascii=False)


def _options(report: dict) -> str:
    options = report.get("options") or {}
    out = ["<h2>Options</h2>",
           _table([(key, _value(value)) for key, value in options.items()],
                  header=("option", "value"), css_id="options")]
    if report.get("files"):
        out.append(f'<p id="files">Files of the run: {_e(", ".join(report["files"]))}.</p>')
    return "\n".join(out)


def report_html(report: dict, figures: dict | None = None, *, when=None,
                elapsed_s: float | None = None) -> str:
    """The page of ``report`` (the dict report.json holds) with ``figures`` (PNG file name →
    bytes) embedded, ``when`` (a datetime) and ``elapsed_s`` the run's date and duration."""
    title = f"FloodMesh run: {input_name(report)}"
    return "\n".join([
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>{_e(title)}</title>",
        f"<style>\n{CSS}\n</style>",
        "</head>",
        "<body>",
        _header(report, when, elapsed_s),
        _accuracy(report),
        _mesh(report),
        _breaklines(report),
        _figures(report, figures or {}),
        _notes(report),
        _options(report),
        "</body>",
        "</html>",
    ]) + "\n"


def write_report_html(folder, report: dict, *, figures=FIGURES, when=None,
                      elapsed_s: float | None = None) -> Path:
    """``report.html`` in ``folder``: the page of ``report`` with the PNGs ``figures`` of that
    folder (those present) embedded; ``when`` defaults to now. Written atomically."""
    folder = Path(folder)
    when = _dt.datetime.now().astimezone() if when is None else when
    images = {name: (folder / name).read_bytes() for name in figures
              if (folder / name).is_file()}
    page = report_html(report, images, when=when, elapsed_s=elapsed_s)
    del images
    path = folder / HTML_NAME
    with io.atomic_output(path) as tmp:
        Path(tmp).write_text(page, encoding="utf-8")
    return path
