"""LiDAR points as an (N, 3) array of x, y, z in metres with their CRS, and the holdout split."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import FloodMeshError
from .options import check_seed, holdout_count
from .raster import (CLOUD_CRS, HIGHEST_GROUND_M, LOWEST_GROUND_M, metric_crs_at,
                     require_metric_crs, require_numbers)

if TYPE_CHECKING:  # pyproj is imported where a CRS is checked: it costs 0.1 s of start-up
    from pyproj import CRS


@dataclass(frozen=True)
class PointCloud:
    """Ground points: ``xyz`` (N, 3) float64 in metres, ``crs`` projected in metres."""

    xyz: np.ndarray
    crs: CRS

    def __post_init__(self):
        require_numbers(self.xyz, "a PointCloud's xyz", "x, y, z in metres")
        if self.xyz.ndim != 2 or self.xyz.shape[1] != 3:
            raise FloodMeshError(f"points must be an (N, 3) array of x, y, z, got {self.xyz.shape}")

    def __len__(self) -> int:
        return len(self.xyz)


def clean_points(xyz: np.ndarray, crs, source: str, kind: str | None = "points",
                 note=None, *, repeats: bool = True, scale: bool = True) -> PointCloud:
    """Drop non-finite points and those with a z no ground has (``usable_rows``) and check what
    is left is usable terrain data in a CRS true to scale there (``raster.metric_crs_at`` at
    their sampled bounds, as ``step_cloud`` checks; ``scale=False`` leaves that check to the
    caller, ``raster.check_scale``); ``note`` receives what was left out or found
    doubtful (points without x, y or z, or with a no-data z such as -9999, points at one x, y
    with different z: ``repeats=False`` leaves that check to the caller,
    ``repeated_positions_note``)."""
    crs = require_metric_crs(crs, source, kind)
    xyz = np.asarray(xyz, dtype=np.float64)
    xyz = drop_unusable(xyz, source, note)
    if len(xyz) < 3:
        raise FloodMeshError(f"{source} has {len(xyz)} usable points (finite x, y, z); at least 3 "
                             "are needed to make a terrain model. Check the file and its classes")
    check_spread(xyz[:, :2], source)
    if scale:
        metric_crs_at(crs, _sampled_bounds(xyz), source, kind)
    message = repeated_positions_note(xyz, source) if note and repeats else None
    if message:
        note(message)
    return PointCloud(xyz, crs)


def xyz_array(values, what: str) -> np.ndarray:
    """``values`` as an (N, 3) float array of x, y, z in metres (an empty one as (0, 3)), else a
    FloodMeshError naming ``what`` and the fix."""
    if isinstance(values, PointCloud):
        raise FloodMeshError(f"{what} must be an (N, 3) array of x, y, z, got a PointCloud: "
                             "give its .xyz")
    try:
        array = np.asarray(values, float)
    except (TypeError, ValueError):
        raise FloodMeshError(f"{what} must be an (N, 3) array of x, y, z, got "
                             f"{type(values).__name__}: give numbers") from None
    if not array.size:
        return array.reshape(0, 3)
    if array.ndim != 2 or array.shape[1] != 3:
        raise FloodMeshError(f"{what} must be an (N, 3) array of x, y, z, got shape "
                             f"{array.shape}: give each row's elevation as its third column")
    return array


def line_list(given, what: str) -> list:
    """``given`` (lines: BreakLines or arrays) as a list, refusing one line given for the list
    (a BreakLine, or an array of at most 2 dimensions), named ``what``."""
    if hasattr(given, "coords") or (isinstance(given, np.ndarray) and given.ndim <= 2):
        raise FloodMeshError(f"{what} must be a list of lines, got one "
                             f"{type(given).__name__} of shape {np.shape(given)}: give "
                             f"[line] for a single (k, 3) line")
    return list(given)


def usable_rows(xyz: np.ndarray) -> np.ndarray | None:
    """Which points (n, 3) have a finite x, y, z and a z some ground has (``LOWEST_GROUND_M``
    to ``HIGHEST_GROUND_M``: -9999 and the like are no-data values); None where all do."""
    # lazy: numba loads only where points are read
    import numba

    from ._kernels.points import usable_rows as rows

    return rows(np.ascontiguousarray(xyz, np.float64), LOWEST_GROUND_M, HIGHEST_GROUND_M,
                numba.get_num_threads())


def drop_unusable(xyz: np.ndarray, source: str, note=None) -> np.ndarray:
    """The points (n, 3) that ``usable_rows`` keeps (``xyz`` itself where all are); ``note``
    is told how many were left out and why (no finite x, y and z; a z no ground has)."""
    return without_unusable(xyz, usable_rows(xyz), source, note)


def without_unusable(xyz: np.ndarray, usable: np.ndarray | None, source: str,
                     note=None) -> np.ndarray:
    """``drop_unusable`` where ``usable_rows`` was taken already (``usable``; None: all)."""
    if usable is None:
        return xyz
    if note:
        left = xyz[~usable]
        empty = int((~np.isfinite(left).all(axis=1)).sum())
        if empty:
            note(f"{source}: {empty:,} points without a finite x, y and z (empty or NaN "
                 "values) were left out")
        if len(left) > empty:
            z = left[np.isfinite(left).all(axis=1), 2]
            note(f"{source}: {len(z):,} points with a z no ground has ({z.min():g}"
                 f"{'' if z.min() == z.max() else f' to {z.max():g}'} m; below "
                 f"{LOWEST_GROUND_M:g} m or above {HIGHEST_GROUND_M:g} m: no-data values) "
                 "were left out")
    return xyz[usable]


def step_points(xyz, what: str, note=None, *, least: int = 0) -> np.ndarray:
    """Points (n, 3) as a step takes them from its caller: an (n, 3) float array whose rows
    without a finite x, y, z or with a z no ground has are left out (``drop_unusable``,
    ``note`` told), the rule the readers apply; at least ``least`` of them must be left."""
    xyz = drop_unusable(xyz_array(xyz, what), what, note)
    if len(xyz) < least:
        raise FloodMeshError(f"{what}: {len(xyz)} usable (finite x, y and z, z "
                             f"between {LOWEST_GROUND_M:g} and {HIGHEST_GROUND_M:g} m); at least "
                             f"{least} are needed: check their values")
    return xyz


def step_cloud(points, what: str, note=None, *, least: int = 0) -> np.ndarray:
    """The usable points (n, 3) of the ``PointCloud`` a step takes (``step_points``), refused
    as the readers refuse a file where its CRS is not in metres or far from true scale or its
    area of use at them (``require_metric_crs``, ``check_scale``)."""
    if not isinstance(points, PointCloud):
        raise FloodMeshError(f"{what} must be a PointCloud, got {type(points).__name__}: give "
                             "PointCloud(xyz, crs), as read_points returns")
    xyz = step_points(points.xyz, what, note, least=least)
    if len(xyz):
        metric_crs_at(points.crs, _sampled_bounds(xyz), what, "points", given=CLOUD_CRS)
    else:
        require_metric_crs(points.crs, what, "points", given=CLOUD_CRS)
    return xyz


def usable_points(xyz: np.ndarray) -> np.ndarray:
    """The points (n, 3) that ``usable_rows`` keeps (``xyz`` itself where all are)."""
    usable = usable_rows(xyz)
    return xyz if usable is None else xyz[usable]


def _sampled_bounds(xyz: np.ndarray, sample: int = 65_536) -> tuple[float, ...]:
    """(xmin, ymin, xmax, ymax) of about ``sample`` of the points, evenly through the file: the
    extent where ``check_scale`` looks, without a pass over them all."""
    xy = xyz[::max(1, len(xyz) // sample), :2]
    return (*xy.min(axis=0), *xy.max(axis=0))


def check_spread(xy: np.ndarray, source: str) -> None:
    """Refuse points that all lie at one place or on one straight line (in any direction)."""
    # lazy: numba loads only where points are read
    import numba

    from ._kernels.points import spread

    span, across, along = spread(xy[:, 0], xy[:, 1], numba.get_num_threads())
    if span <= 0:
        raise FloodMeshError(f"{source}: all points lie at one place ({xy[0, 0]:.3f}, "
                             f"{xy[0, 1]:.3f}); a terrain model needs points spread over an area"
                             f"{_degrees_hint(xy)}")
    if across <= max(1e-6 * along, 0.005):  # 5 mm: coordinates rounded to the millimetre
        fix = _degrees_hint(xy) or ": check the file's x and y columns"
        raise FloodMeshError(f"{source}: all points lie on one straight line ({along:.3g} m long, "
                             f"{across:.2g} m across); a terrain model needs points spread over "
                             f"an area{fix}")


def _degrees_hint(xy: np.ndarray) -> str:
    """What to say of points (n, 2) whose x all lie within ±180 and y within ±90: degrees of
    longitude and latitude, which a CRS in metres makes a few millimetres across ("" else)."""
    if np.abs(xy[:, 0]).max() <= 180 and np.abs(xy[:, 1]).max() <= 90:
        return ("; the coordinates look like degrees (longitude/latitude): reproject the "
                "points to a projected CRS in metres (e.g. the survey's UTM zone)")
    return ""


def repeated_positions_note(xyz: np.ndarray, source: str) -> str | None:
    """What to say of the points that repeat another's x, y (to 0.1 mm) with a different z:
    how many and by how much (None: none do)."""
    # lazy: numba loads only when this runs
    from ._kernels.points import repeated_positions

    n, dz = repeated_positions(xyz[:, 0], xyz[:, 1], xyz[:, 2], 1e-4)
    if not n:
        return None
    return (f"{source}: {n:,} point{'s repeat' if n > 1 else ' repeats'} the x, y of another "
            f"with a different z (up to {dz:.3g} m apart); the grid takes their mean: check "
            "for overlapping flight lines or tiles merged twice")


SPARSE_POINTS_PER_CELL = 0.5  # fewer ground points a cell than this: the grid is finer than the survey


def sparse_survey_note(n_points: int, valid_cells: int, cell_size: float) -> str | None:
    """What to say of ``n_points`` ground points gridded onto ``valid_cells`` cells of
    ``cell_size`` m when they are fewer than ``SPARSE_POINTS_PER_CELL`` a cell (None
    otherwise): most cells then lie inside TIN facets whose edges slope breaks and break lines
    follow; a cell of about the points' spacing (one point a cell), to the half metre, suits
    the survey."""
    if n_points <= 0 or valid_cells <= 0 or n_points >= SPARSE_POINTS_PER_CELL * valid_cells:
        return None
    density = n_points / (valid_cells * cell_size ** 2)
    suggested = max(float(np.round(2 / np.sqrt(density)) / 2), cell_size)
    return (f"the survey has {density:.2g} ground points/m², {n_points / valid_cells:.2g} a "
            f"cell of the {cell_size:g} m grid: most cells are interpolated inside TIN facets, "
            f"whose edges the break lines may follow; a cell size of about {suggested:g} m "
            "(one point a cell) suits it (--cell-size, 'Grid cell size d' in QGIS)")


def every_nth_by_place(xyz: np.ndarray, every: int) -> np.ndarray:
    """About one in ``every`` of the points (n, 3), chosen by a hash of their x, y, z (to
    0.1 mm), not by their order: the same survey read in any order (a COPC file's octree, a LAS
    file's flight lines, tiles merged) gives the same points."""
    if every <= 1:
        return xyz
    # lazy: numba loads only where points are read
    import numba

    from ._kernels.points import rows_by_place
    return rows_by_place(np.ascontiguousarray(xyz, float), int(every), numba.get_num_threads())


def held_out_by_place(xyz: np.ndarray, n_out: int, seed: int) -> np.ndarray:
    """Which ``n_out`` of the points (n, 3) are held out (a mask): those whose hash of x, y, z
    (to 0.1 mm), salted by ``seed``, is least. A random draw that follows the points, not
    their order: the same survey as a LAS file or a COPC file, or as tiles named otherwise,
    holds out the same check points; another seed draws others."""
    n = len(xyz)
    if n_out <= 0 or n_out >= n:
        return np.full(n, n_out > 0)
    hashes = place_hashes(xyz, seed)
    # the n_out least: among the hashes under a bound that holds about twice as many
    bound = np.uint64(min((1 << 64) - 1, int(2.0 ** 64 * min(1.0, (2 * n_out + 64) / n))))
    candidates = np.flatnonzero(hashes <= bound)
    if len(candidates) < n_out:
        candidates = np.arange(n)
    kth = np.partition(hashes[candidates], n_out - 1)[n_out - 1]
    mask = hashes <= kth
    extra = int(np.count_nonzero(mask)) - n_out
    if extra:  # the k-th point more than once (the same x, y, z): any of its copies
        mask[np.flatnonzero(hashes == kth)[:extra]] = False
    return mask


def place_hashes(xyz: np.ndarray, seed: int) -> np.ndarray:
    """The points' (n, 3) 64-bit hashes (uint64) of x, y, z to 0.1 mm, salted by ``seed``: the
    order in which ``held_out_by_place`` draws check points."""
    # lazy: numba loads only where points are read
    from ._kernels.points import point_hashes
    salt = np.uint64((int(seed) * 0xD1B54A32D192ED03 + 0x8CB92BA72F3D8DD7) % (1 << 64))
    return point_hashes(np.ascontiguousarray(xyz, float), salt)


def at_places_of(xyz: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Which of the points (n, 3) lie at the x, y (to 0.1 mm) of one of ``others`` (k, 3), by
    their ``place_hashes`` of x, y alone (a mask)."""
    def flat(points):
        return place_hashes(np.column_stack([points[:, :2], np.zeros(len(points))]), 0)
    return np.isin(flat(xyz), flat(others))


def holdout_candidates(hashes: np.ndarray, fraction: float) -> tuple[np.ndarray, int]:
    """(the indices of a part's candidates for the check points, the bound of their hashes):
    the points of one part of a survey (a tile of n = ``len(hashes)`` points, ``place_hashes``)
    whose hash is at most a bound that holds ``fraction`` of them, 8 standard deviations
    (8·√(fraction·n)) and 64 more. The survey's check points, its least hashes
    (``held_out_by_place``: the fraction, or 20), are among the candidates of all its parts
    where they lie under the least bound (``least_hash``), which holds them with 8 standard
    deviations to spare or more (a chance under 1e-15 that it does not)."""
    n = len(hashes)
    if fraction <= 0 or not n:  # none to draw: complete under any bound
        return np.empty(0, np.int64), (1 << 64) - 1
    share = min(1.0, fraction + 8 * np.sqrt(fraction / n) + 64 / n)
    bound = min((1 << 64) - 1, int(2.0 ** 64 * share))
    return np.flatnonzero(hashes <= np.uint64(bound)), bound


def least_hash(candidates: list[np.ndarray], bounds: list[int], n_out: int) -> int | None:
    """The ``n_out``-th least of the survey's hashes from its parts' ``candidates`` (hashes,
    each part's under its bound in ``bounds``, ``holdout_candidates``): the points of hash at
    most this are the check points ``held_out_by_place`` draws from the whole survey at once
    (all copies of a point repeated there); None for none. Where fewer than ``n_out``
    candidates lie under the least bound, the points under it."""
    if n_out <= 0 or not candidates:
        return None
    below = np.uint64(min(bounds))
    pool = np.concatenate([h[h <= below] for h in candidates])
    if len(pool) < n_out:
        return int(below)
    return int(np.partition(pool, n_out - 1)[n_out - 1])


def split_holdout(points: PointCloud, fraction: float, seed: int,
                  note=None) -> tuple[PointCloud, PointCloud]:
    """Split off a random ``fraction`` of the points (``held_out_by_place``) for accuracy
    assessment (at least the 20 check points of the FEMA/NSSDA test, ``options.holdout_count``,
    said through ``note``).

    Returns (points for gridding, held-out points); the same seed gives the same split.
    """
    n = len(points)
    n_out = holdout_count(fraction, n, note)
    seed = check_seed(seed)
    # lazy: numba loads only where points are read
    import numba

    from ._kernels.points import split_rows

    mask = held_out_by_place(points.xyz, n_out, seed)
    gridding, held_out = split_rows(points.xyz, mask, numba.get_num_threads())
    return PointCloud(gridding, points.crs), PointCloud(held_out, points.crs)
