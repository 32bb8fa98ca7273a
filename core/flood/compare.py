"""Two floods compared: the same scenario on two meshes (FloodMesh's and a reference), judged on
one common grid by what a modeller reads from a flood map.

Figures: flood-extent IoU (depth above the wet depth, 5 cm), max-depth RMSE and bias (mesh −
reference, over cells wet in either), arrival-time differences (cells wet in both), peak stage
and depth at the observation points (a point dry in one flood: where it got wet, and its depth
difference with dry as 0 m), and simulation cost. Maps: the depth difference and where the
extents disagree.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import io
from ..errors import FloodMeshError
from ..io.outputs import check_output_folder, staged_folder
from ..options import check_comparison_cell_size
from ..raster import Grid
from .model import cell_centres

EXTENT_CODES = {1: "wet on the mesh only", 2: "wet on the reference only", 3: "wet on both"}
COMPARISON_FILES = ("comparison.json", "depth_difference.tif", "extent_difference.tif")
WET_AT = {(True, True): "both", (True, False): "mesh only", (False, True): "reference only",
          (False, False): "neither"}


def _load(folder) -> tuple[dict, dict]:
    folder = Path(folder)
    try:
        report = json.loads((folder / "report.json").read_text())
        with np.load(folder / "triangles.npz") as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError as exc:
        raise FloodMeshError(f"{folder} is not the output folder of `floodmesh flood` "
                             f"({Path(exc.filename).name} is missing)") from None
    return report, arrays


def _sample(arrays: dict, grid_xy: np.ndarray) -> dict:
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import containing_triangle

    tri = containing_triangle(arrays["nodes"][:, :2], arrays["triangles"], grid_xy)
    inside = tri >= 0
    out = {"inside": inside}
    for name in ("max_depth", "max_stage", "arrival_s"):
        values = np.full(len(grid_xy), np.nan)
        values[inside] = arrays[name][tri[inside]]
        out[name] = values
    return out


def _observed(mesh: dict, reference: dict) -> dict:
    """One observation point in both floods (their reports' peaks): peak stages (m; None where
    dry) and their difference (mesh − reference; None unless wet in both), peak depths (m; 0
    where dry, under 1 mm) and their difference, and where it got wet (``WET_AT``)."""
    stages = mesh["peak_stage_m"], reference["peak_stage_m"]
    return {"name": mesh["name"], "wet": WET_AT[stages[0] is not None, stages[1] is not None],
            "mesh_peak_stage_m": stages[0], "reference_peak_stage_m": stages[1],
            "difference_m": None if None in stages else stages[0] - stages[1],
            "mesh_peak_depth_m": mesh["peak_depth_m"],
            "reference_peak_depth_m": reference["peak_depth_m"],
            "peak_depth_difference_m": mesh["peak_depth_m"] - reference["peak_depth_m"]}


def compare_floods(mesh_run, reference_run, out_dir=None, *, cell_size: float = 1.0,
                   wet_depth: float | None = None, crs=None) -> dict:
    """Compare the flood in folder ``mesh_run`` with the one in ``reference_run`` (both written
    by ``run_flood``) on a grid of ``cell_size`` m over their common extent; with ``out_dir``
    write ``comparison.json``, ``depth_difference.tif`` and ``extent_difference.tif`` there, the
    three in one step (``outputs.staged_folder``). Returns the figures."""
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    check_comparison_cell_size(cell_size)
    if out_dir is not None:
        check_output_folder(out_dir, [mesh_run, reference_run], COMPARISON_FILES)
    rep_a, arr_a = _load(mesh_run)
    rep_b, arr_b = _load(reference_run)
    wet = wet_depth or rep_b["scenario"]["wet_depth_m"]
    lo = np.maximum(arr_a["nodes"][:, :2].min(0), arr_b["nodes"][:, :2].min(0))
    hi = np.minimum(arr_a["nodes"][:, :2].max(0), arr_b["nodes"][:, :2].max(0))
    if np.any(hi <= lo):
        raise FloodMeshError("the two meshes do not overlap: check that both runs are of the "
                             "same place and CRS")
    transform, (rows, cols), xy = cell_centres(lo, hi, cell_size)
    a, b = _sample(arr_a, xy), _sample(arr_b, xy)
    both = a["inside"] & b["inside"]
    wet_a, wet_b = both & (a["max_depth"] > wet), both & (b["max_depth"] > wet)
    union, inter = wet_a | wet_b, wet_a & wet_b
    diff = a["max_depth"] - b["max_depth"]
    arrival = (a["arrival_s"] - b["arrival_s"])[inter]
    arrival = arrival[np.isfinite(arrival)]
    figures = {
        "mesh_run": str(mesh_run), "reference_run": str(reference_run),
        "cell_size_m": cell_size, "wet_depth_m": wet,
        "mesh_nodes": rep_a["nodes"], "reference_nodes": rep_b["nodes"],
        "extent_iou": float(inter.sum() / union.sum()) if union.any() else None,
        "flooded_area_mesh_m2": float(wet_a.sum() * cell_size ** 2),
        "flooded_area_reference_m2": float(wet_b.sum() * cell_size ** 2),
        "max_depth_rmse_m": float(np.sqrt(np.mean(diff[union] ** 2))) if union.any() else None,
        "max_depth_bias_m": float(np.mean(diff[union])) if union.any() else None,
        "arrival_mean_abs_difference_s": float(np.mean(np.abs(arrival))) if arrival.size
        else None,
        "arrival_bias_s": float(np.mean(arrival)) if arrival.size else None,
        "mesh_cpu_s": rep_a["cpu_s"], "reference_cpu_s": rep_b["cpu_s"],
        "cpu_ratio": rep_a["cpu_s"] / max(rep_b["cpu_s"], 1e-9),
        "mesh_mean_time_step_s": rep_a["mean_time_step_s"],
        "reference_mean_time_step_s": rep_b["mean_time_step_s"],
        "observations": [_observed(oa, ob)
                         for oa, ob in zip(rep_a["observations"], rep_b["observations"])],
    }
    if out_dir is None:
        return figures
    grid_crs = CRS.from_user_input(crs or rep_a["crs"])
    depth = np.where(both & union, diff, np.where(both, 0.0, np.nan)).reshape(rows, cols)
    code = (wet_a.astype(np.uint8) + 2 * wet_b.astype(np.uint8)).reshape(rows, cols)
    # the folder is replaced as a whole, as a flood's is (an interrupt leaves the last
    # comparison's files or these, never some of each); the user's own files stay
    with staged_folder(out_dir, own=COMPARISON_FILES) as out:
        io.write_raster(out / "depth_difference.tif", Grid(depth.astype(np.float32), transform,
                                                           grid_crs), quantity="depth_difference")
        io.write_raster(out / "extent_difference.tif", Grid(code, transform, grid_crs),
                        valid=both.reshape(rows, cols), quantity="extent_difference")
        io.write_json(out / "comparison.json", {**figures, "extent_codes": EXTENT_CODES})
    return figures
