"""Accuracy assessment: held-out LiDAR points against the mesh's TIN.

Residual = measured z − TIN z, the TIN z interpolated linearly (barycentric) in the triangle that
holds the point. Statistics follow the method: RMSE, mean, skew, 1.96·RMSE (95 % accuracy,
NSSDA), the FEMA/NSSDA sample test and the residual classes <10 cm, 10–25 cm, >25 cm.
"""
from __future__ import annotations

import math

import numpy as np

from ..engine.progress import REPORTS, along
from ..options import MIN_CHECK_POINTS
from ..points import usable_rows, without_unusable, xyz_array
from ..raster import MESH_CRS, Grid, metric_crs_at, nearest_value
from .mesh import Mesh

CHUNK_POINTS = 20_000  # check points located at a time, at least (each time sorts the buckets)

CLASS_LIMITS_M = (0.10, 0.25)
CLASS_NAMES = ("<10 cm", "10-25 cm", ">25 cm")


def tin_elevation(mesh: Mesh, x, y) -> np.ndarray:
    """Linear interpolation of the mesh's node elevations at (x, y); NaN outside the mesh."""
    # lazy: numba loads only when this runs
    from .._kernels.mesh import locate

    points = np.column_stack([np.ravel(x), np.ravel(y)]).astype(float)
    return locate(mesh.nodes, mesh.triangles, points, mesh.nodes[:, 2])[1]


def residuals(mesh: Mesh, points_xyz: np.ndarray, *, progress=None,
              cancelled=None) -> np.ndarray:
    """Measured minus TIN elevation (m) for each point; NaN for points outside the mesh.
    Found in chunks of points, ``progress`` told the share done and ``cancelled`` polled
    between them."""
    # lazy: numba loads only when this runs
    from .._kernels.mesh import Locator

    if not len(points_xyz):  # holdout 0: no accuracy test
        return np.empty(0)
    points_xyz = np.asarray(points_xyz, float)
    locator, z = Locator(mesh.nodes, mesh.triangles), np.empty(len(points_xyz))
    size = max(-(-len(points_xyz) // REPORTS), CHUNK_POINTS)
    for start in along(range(0, len(points_xyz), size), progress, cancelled):
        z[start:start + size] = locator(points_xyz[start:start + size, :2], mesh.nodes[:, 2])[1]
    return points_xyz[:, 2] - z


def assess(mesh: Mesh, points_xyz: np.ndarray, *, alpha: float | None = None,
           delta: float | None = None, note=None, progress=None,
           cancelled=None) -> tuple[np.ndarray, dict]:
    """Step 8: the residuals of held-out points against the mesh's TIN (m, NaN outside it) and
    their statistics (``accuracy_statistics``: RMSE, NSSDA test, classes, E = RMSE + α·Δ).
    Points without a finite x, y, z or with a z no ground has (-9999) are left out, as the
    readers leave them out (``points.drop_unusable``, ``note`` told): their residual is NaN and
    no figure counts them, not even ``n_outside_mesh``. ``progress`` and ``cancelled`` as
    ``residuals``'."""
    nodes = xyz_array(mesh.nodes, "the mesh's nodes")
    metric_crs_at(mesh.crs, (*nodes[:, :2].min(axis=0), *nodes[:, :2].max(axis=0)), "the mesh",
                  given=MESH_CRS)
    given = xyz_array(points_xyz, "the check points")
    kept = usable_rows(given) if len(given) else None
    if kept is None:
        res = residuals(mesh, given, progress=progress, cancelled=cancelled)
        return res, accuracy_statistics(res, alpha=alpha, delta=delta, note=note)
    res = np.full(len(given), np.nan)
    res[kept] = residuals(mesh, without_unusable(given, kept, "the check points", note),
                          progress=progress, cancelled=cancelled)
    return res, accuracy_statistics(res[kept], alpha=alpha, delta=delta, note=note)


OUTSIDE_NOTE_SHARE = 0.02  # of the check points outside the mesh, beyond which a note says so


def outside_mesh_note(xyz: np.ndarray, res: np.ndarray, dem: Grid, boundary: bool = False):
    """What to say of the check points (n, 3) outside the mesh (``res`` NaN), which no figure
    of the assessment counts: how many, and why (the mesh spans the DEM's valid cell centres,
    half a cell inside the survey's edge; and ``boundary``, the user's model domain); None
    where fewer than ``OUTSIDE_NOTE_SHARE`` of them are outside (the summary's count of the
    points assessed says that much: at the default 1 m cells a run's edge leaves some 1 %)."""
    outside = ~np.isfinite(res)
    n = int(np.count_nonzero(outside))
    if n <= OUTSIDE_NOTE_SHARE * len(res):
        return None
    in_gaps = int(np.count_nonzero(~np.isfinite(nearest_value(dem, *xyz[outside, :2].T))))
    gaps = f", {in_gaps:,} of them in its data gaps" if in_gaps else ""
    domain = " or the model domain (--boundary)" if boundary else ""
    return (f"{n:,} of the {len(res):,} check points lie outside the mesh and were not "
            f"assessed: the DEM's valid cell centres bound the mesh{domain}, half a cell "
            f"({dem.cell_size / 2:g} m) inside the survey's edge{gaps}; a smaller cell size "
            "meshes closer to the survey's edge (--cell-size, 'Grid cell size d' in QGIS)")


def residual_class(res: np.ndarray) -> np.ndarray:
    """0, 1, 2 for |residual| <10 cm, 10–25 cm, >25 cm; -1 where the residual is NaN."""
    a = np.abs(res)
    cls = np.digitize(a, CLASS_LIMITS_M).astype(np.int64)
    return np.where(np.isfinite(res), cls, -1)


def nssda_threshold_m(n: int) -> float:
    """FEMA/NSSDA sample test bound: RMSE_sample ≤ 15·√(((n−1) − 2.326·√(n−1))/n) cm, in metres.

    NaN when n is too small for the bound to exist (n < 7).
    """
    if n < 2:
        return math.nan
    inner = ((n - 1) - 2.326 * math.sqrt(n - 1)) / n
    return 0.15 * math.sqrt(inner) if inner > 0 else math.nan


def accuracy_statistics(res: np.ndarray, *, alpha: float | None = None,
                        delta: float | None = None, note=None) -> dict:
    """Residual statistics in metres, with the NSSDA test (null, said to ``note``, on fewer
    than its ``MIN_CHECK_POINTS`` check points) and, given α and Δ, the vertex bound
    E = RMSE + α·Δ."""
    inside = res[np.isfinite(res)]
    n = int(inside.size)
    stats = {"n_holdout": int(res.size), "n_assessed": n, "n_outside_mesh": int(res.size - n)}
    if n == 0:
        stats.update(rmse_m=None, mean_m=None, std_m=None, skew=None, accuracy_95_m=None,
                     max_abs_residual_m=None, nssda_threshold_m=None, nssda_pass=None,
                     classes={name: None for name in CLASS_NAMES})
        return stats
    rmse = float(np.sqrt(np.mean(inside ** 2)))
    mean = float(inside.mean())
    std = float(inside.std(ddof=1)) if n > 1 else 0.0
    skew = float(np.mean((inside - mean) ** 3) / inside.std() ** 3) if n > 2 and inside.std() > 0 else 0.0
    threshold = nssda_threshold_m(n)
    cls = residual_class(inside)
    stats.update(
        rmse_m=rmse, mean_m=mean, std_m=std, skew=skew, accuracy_95_m=1.96 * rmse,
        max_abs_residual_m=float(np.abs(inside).max()),
        nssda_threshold_m=None if math.isnan(threshold) else threshold,
        nssda_pass=(None if math.isnan(threshold) or n < MIN_CHECK_POINTS
                    else bool(rmse <= threshold)),
        classes={name: float((cls == k).mean()) for k, name in enumerate(CLASS_NAMES)},
    )
    if note and n < MIN_CHECK_POINTS:
        note(f"{n} check points lie in the mesh, fewer than the {MIN_CHECK_POINTS} the FEMA/NSSDA "
             "test needs (FGDC-STD-007.3-1998): nssda_pass is null; a larger domain or "
             "--holdout keeps more")
    if alpha is not None and delta is not None:
        stats.update(alpha=float(alpha), delta_m=float(delta),
                     vertex_error_bound_m=rmse + float(alpha) * float(delta))
    return stats


def accuracy_text(stats: dict) -> str:
    """``accuracy_statistics`` as a modeller reads them: centimetres, shares in %, the FEMA/NSSDA
    test passed or failed."""
    n, held = stats["n_assessed"], stats["n_holdout"]
    if not n:
        return f"not assessed: none of the {held} check points lies inside the mesh"

    def cm(metres):
        return f"{100 * metres:.1f} cm"

    outside = stats["n_outside_mesh"]
    classes = {name: f"{100 * share:.0f} %" for name, share in stats["classes"].items()}
    test = ("FEMA/NSSDA test not made: it needs 20 check points" if stats["nssda_pass"] is None
            else f"FEMA/NSSDA test {'passed' if stats['nssda_pass'] else 'failed'} (RMSE at "
                 f"most {cm(stats['nssda_threshold_m'])} on {n} points)")
    return (f"RMSE {cm(stats['rmse_m'])} on {n} of {held} check points"
            f"{f' ({outside} outside the mesh)' if outside else ''}; mean {cm(stats['mean_m'])}, "
            f"standard deviation {cm(stats['std_m'])}, 95 % (1.96 RMSE) "
            f"{cm(stats['accuracy_95_m'])}, largest {cm(stats['max_abs_residual_m'])}\n"
            f"{classes['<10 cm']} under 10 cm, {classes['10-25 cm']} 10–25 cm, "
            f"{classes['>25 cm']} over 25 cm; {test}")
