"""Error-driven mesh refinement (step 9 of the method).

Each round meshes the DEM with its break lines, then measures the residual (point − TIN) of
the refinement points (the LiDAR points used for gridding, or DEM cell centres): a point whose
|residual| exceeds the ``upper`` bound goes into the TIN as a vertex with its measured
elevation (the worst one per triangle and round); a triangle whose points' mean square residual
exceeds the survey's noise² by more than ``lower``² (a systematic misfit, a fold the lines
missed, not noise: the excess must also stand three standard errors above the noise of that
many points) gets a quarter of its area as its local maximum. Rounds stop when the target holds
(RMSE and/or largest |residual| of the refinement points), at the node budget (the last round
taking the worst of its picks that fit within it), or when nothing is left to refine.
Check points (held out, never used for refinement) are assessed every round, so the error
reported is independent of the refinement.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..engine.progress import part, poll, report
from ..errors import FloodMeshError
from ..options import check_refinement
from ..points import at_places_of, step_points, xyz_array
from ..raster import Grid, usable_dem
from .accuracy import residuals
from .localise import beyond_noise, estimate_noise
from .mesh import Mesh, build_mesh, domain_from_dem, triangle_areas


@dataclass(frozen=True)
class RefineRound:
    """One round's mesh: nodes, triangles, and RMSE / max |residual| (m) of the refinement
    points and of the check points, with how many measured points went into it as nodes and how
    many triangles were refined around to make it (of the previous round's picks; 0 in the
    first): a picked point too close to a node, a line or an edge is not inserted."""

    nodes: int
    triangles: int
    rmse_m: float
    max_abs_m: float
    check_rmse_m: float
    check_max_abs_m: float
    inserted: int
    refined: int


def refine_mesh(dem: Grid, lines: list[np.ndarray], points: np.ndarray, *,
                check: np.ndarray | None = None, domain=None, size_field=None,
                min_angle: float = 25.0, conforming: bool = False, elevations=None,
                max_area: float = 100.0, lower: float = 0.10, upper: float | None = 0.25,
                target_rmse: float | None = None, target_max: float | None = None,
                max_nodes: int = 1_000_000, max_rounds: int = 8, noise: float | None = None,
                floor: float | None = None, mesh_options: dict | None = None,
                first: Mesh | None = None, most: float | None = None,
                measure_last: bool = True,
                floor_at: Callable[[np.ndarray], np.ndarray] | None = None,
                progress: Callable[[float], None] | None = None,
                cancelled: Callable[[], bool] | None = None,
                note: Callable[[str], None] | None = None) -> tuple[Mesh, list[RefineRound]]:
    """Refine until the target holds on ``points`` (n, 3), within ``max_nodes`` nodes and
    ``max_rounds`` rounds. Bounds and targets in metres (``upper`` None: no point is
    inserted); with no target, rounds go on until nothing is left to refine. ``noise`` (m): the
    points' vertical noise (None: estimated from them, ``localise.estimate_noise``);
    ``floor`` (m²): no triangle is refined to less (default half a DEM cell). ``domain``,
    ``size_field`` and ``mesh_options`` as for ``build_mesh``; ``elevations(mesh)`` (or None)
    gives each round's mesh its node z (one that takes ``progress`` and ``cancelled`` keywords
    hears its share of the bar and is polled, as ``build_mesh`` is); ``first``: the first
    round's mesh if already built; ``most``: the share of a round's triangles split at most,
    the worst misfits first;
    ``measure_last`` False: the last of ``max_rounds`` rounds measures only the check points
    (its refinement points' figures NaN), as nothing is refined after it; ``floor_at(xy)``: the
    floor (m²) at triangle centroids (k, 2), where it varies (None: ``floor`` everywhere);
    ``note`` hears why the rounds stopped where points are left beyond ``upper`` or triangles
    beyond ``lower``, and how many picked points were too close to a node, a line or an edge to
    be inserted. A round whose picks would pass ``max_nodes`` takes the worst of them that fit
    (``_within_budget``) and is the last. Returns the last mesh and every round."""
    points = xyz_array(points, "the refinement's points")
    if not len(points):
        raise FloodMeshError("refinement needs measured points (x, y, z); none were given")
    # the readers' rule on what the caller gives: rows without a finite x, y, z or with a z
    # no ground has left out, DEM cells no ground has nodata (``note`` told)
    points = step_points(points, "the refinement's points", note, least=1)
    if check is not None and len(check):
        check = step_points(check, "the check points", note)
    dem = usable_dem(dem, "the DEM", note)
    check_refinement(lower, upper, target_rmse=target_rmse, target_max=target_max, noise=noise,
                     max_rounds=max_rounds, max_nodes=max_nodes)
    # no refinement below the DEM's own resolution
    floor = dem.cell_size ** 2 / 2 if floor is None else floor
    # lazy: numba loads only when this runs
    from .._kernels.mesh import locate

    inserted = np.empty((0, 3))  # measured points put into the TIN so far
    local = np.empty((0, 3))  # x, y, local maximum area (m²) of every triangle refined so far
    rounds, best = [], None
    picks = _Picks.none(points)  # points to insert and triangles to refine, of the last mesh
    taken = tried = 0  # measured points in the last mesh; points picked so far
    full = False  # whether the node budget cut a round's picks
    left = None  # (points beyond upper, triangles beyond lower) of the best mesh
    stop = (f"it reached its limit of {max_rounds} round{'s' if max_rounds != 1 else ''}, and "
            "more would refine them")

    def build(picked: _Picks, progress=None) -> Mesh:
        """The mesh with the points and triangles of earlier rounds and ``picked``, its share
        of the work told to ``progress``: its node z from ``elevations`` the last fifth."""
        nonlocal domain
        poll(cancelled)  # each mesh, the node budget's tries too
        if domain is None:  # the DEM's outline once, where build_mesh would trace it each round
            domain = domain_from_dem(dem)
        meshed = 1.0 if elevations is None else 0.8
        mesh = build_mesh(dem, lines, min_angle=min_angle, max_area=max_area,
                          points=np.vstack([inserted, picked.points]),
                          local_areas=np.vstack([local, picked.triangles]), domain=domain,
                          size_field=size_field, conforming=conforming,
                          progress=part(progress, 0.0, meshed), cancelled=cancelled,
                          **(mesh_options or {}))
        return _with_z(mesh, elevations, part(progress, meshed, 1.0), cancelled)

    for k in range(max_rounds):
        poll(cancelled)
        # the mesh (or the first one's node z) takes half its round's share of the bar, the
        # measuring the rest; all of it where the round measures only the check points
        told = part(progress, k / max_rounds, (k + 1) / max_rounds)
        meshed = 1.0 if k == max_rounds - 1 and not measure_last else 0.5
        if k == 0 and first is not None:
            mesh = _with_z(first, elevations, part(told, 0.0, meshed), cancelled)
        else:
            mesh = build(picks, part(told, 0.0, meshed))
        if len(mesh.nodes) > max_nodes:
            if best is None:
                raise FloodMeshError(f"the unrefined mesh already has {len(mesh.nodes)} nodes, "
                                     f"over the budget of {max_nodes}; raise the budget or the "
                                     "maximum triangle area")
            mesh, within = _within_budget(build, picks, rounds[-1].nodes, len(mesh.nodes),
                                          max_nodes)
            if mesh is None:
                stop = (f"refining them would pass the node budget of {max_nodes:,} nodes, "
                        "even with only the worst of them")
                break
            stop = (f"it reached the node budget of {max_nodes:,} nodes, which let its last "
                    f"round take only the worst {len(within.points):,} of the "
                    f"{len(picks.points):,} points and {len(within.triangles):,} of the "
                    f"{len(picks.triangles):,} triangles picked")
            picks, full = within, True
        inserted = np.vstack([inserted, picks.points])
        local = np.vstack([local, picks.triangles])
        tried += len(picks.points)
        # the picked points Triangle took in (none too close to a node, a line or an edge)
        now = int(at_places_of(mesh.nodes, inserted).sum()) if len(inserted) else 0
        added, taken = now - taken, now
        if rounds and len(mesh.nodes) == rounds[-1].nodes:
            stop = ("a further round changed no node, what is left lying too close to a node, "
                    "a line or the domain's edge to be inserted")
            break
        if k == max_rounds - 1 and not measure_last:  # nothing is refined after it
            rounds.append(RefineRound(len(mesh.nodes), len(mesh.triangles), np.nan, np.nan,
                                      *_check_figures(mesh, check), added,
                                      len(picks.triangles)))
            best, left = mesh, None
            break
        found, tin = locate(mesh.nodes, mesh.triangles, points, mesh.nodes[:, 2])
        res = points[:, 2] - tin
        report(told, cancelled, 0.7)
        if noise is None:  # from planes fitted to some 30 points each (as the run's window)
            noise = estimate_noise(points, len(points) / (np.isfinite(dem.values).sum()
                                                          * dem.cell_size ** 2))
        misfit, excess = _misfit_triangles(mesh, found, res, lower, floor, noise, most,
                                           floor_at)
        report(told, cancelled, 0.8)
        rounds.append(RefineRound(len(mesh.nodes), len(mesh.triangles), _rmse(res),
                                  _max_abs(res), *_check_figures(mesh, check), added,
                                  len(picks.triangles)))
        report(told, cancelled, 0.9)
        best = mesh
        picks = _Picks.none(points) if upper is None else _worst_per_triangle(points, res,
                                                                              found, upper)
        picks = _Picks(picks.points, picks.score, misfit, excess)
        left = (0 if upper is None else int(np.count_nonzero(np.abs(np.nan_to_num(res)) > upper)),
                len(misfit))
        report(told, None, 1.0)
        if _met(res, target_rmse, target_max):
            stop = "the target holds"
            break
        if full:  # this round took what the budget allowed
            break
        if not len(picks.points) and not len(misfit):
            break
    report(progress, cancelled, 1.0)  # Cancel pressed while the last mesh was made
    if note is not None and tried > taken:
        note(_not_inserted(tried, taken))
    if note is not None and upper is not None and left is not None and any(left):
        note(_left_over(*left, upper, lower, stop))
    return best, rounds


def _with_z(mesh: Mesh, elevations, progress, cancelled) -> Mesh:
    """``mesh`` with its node z from ``elevations(mesh)`` (None: as it is), told ``progress``
    and ``cancelled`` where it takes them (see ``refine_mesh``)."""
    if elevations is None:
        return mesh
    takes = inspect.signature(elevations).parameters
    if {"progress", "cancelled"} <= takes.keys() or any(
            p.kind is p.VAR_KEYWORD for p in takes.values()):
        return elevations(mesh, progress=progress, cancelled=cancelled)
    mesh = elevations(mesh)
    report(progress, cancelled, 1.0)
    return mesh


@dataclass(frozen=True)
class _Picks:
    """What a round picked on its mesh: ``points`` (k, 3) to insert and ``triangles`` (j, 3:
    centroid x, y and local maximum area m²) to refine, each with a ``score`` of how badly it
    misfits (|residual| m; the excess mean square over the area, m²·m²)."""

    points: np.ndarray
    score: np.ndarray
    triangles: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    excess: np.ndarray = field(default_factory=lambda: np.empty(0))

    @classmethod
    def none(cls, points) -> "_Picks":
        return cls(points[:0], np.empty(0))

    def worst(self, share: float) -> "_Picks":
        """The worst ``share`` of the points and of the triangles, in their order."""
        def keep(score):
            mask = np.zeros(len(score), bool)
            mask[np.argsort(-score, kind="stable")[:int(share * len(score))]] = True
            return mask
        points, triangles = keep(self.score), keep(self.excess)
        return _Picks(self.points[points], self.score[points], self.triangles[triangles],
                      self.excess[triangles])


# tries at a round that passes the node budget with a share of its picks (the worst first)
BUDGET_TRIES = 4


def _within_budget(build, picks: _Picks, before: int, after: int, max_nodes: int):
    """(mesh, the picks it took): the mesh of the worst share of ``picks`` that stays within
    ``max_nodes`` where all of them made ``after`` nodes from ``before``, the share shrunk to
    what the nodes added say would fit, 10 % under, for up to ``BUDGET_TRIES`` meshes; (None,
    None) where none fits."""
    share = 1.0
    for _ in range(BUDGET_TRIES):
        share *= 0.9 * (max_nodes - before) / (after - before)
        within = picks.worst(share)
        if not len(within.points) and not len(within.triangles):
            break
        mesh = build(within)
        if len(mesh.nodes) <= max_nodes:
            return mesh, within
        after = len(mesh.nodes)
    return None, None


def _not_inserted(tried: int, taken: int) -> str:
    """What to say of the measured points picked for insertion that Triangle did not take."""
    return (f"{tried - taken:,} of the {tried:,} measured points the refinement picked for "
            "insertion lay too close to a node, a line, the domain's edge or another picked "
            f"point to be inserted; the mesh took in the other {taken:,} (the rounds' "
            "'inserted')")


def _left_over(points: int, triangles: int, upper: float, lower: float, why: str) -> str:
    """What to say of the ``points`` beyond ``upper`` m and the ``triangles`` beyond ``lower``
    m that the refinement left, and ``why`` it stopped."""
    beyond = [f"{points:,} measured point{'s' if points != 1 else ''} misfitting by more than "
              f"the upper bound ({upper:g} m)"] if points else []
    beyond += [f"{triangles:,} triangle{'s' if triangles != 1 else ''} whose points misfit by "
               f"more than the lower bound ({lower:g} m beyond their noise)"] if triangles else []
    return f"the refinement stopped with {' and '.join(beyond)}: {why}"


def _check_figures(mesh: Mesh, check) -> tuple[float, float]:
    """RMSE and largest |residual| (m) of the check points (NaN without them)."""
    res = residuals(mesh, check) if check is not None and len(check) else np.array([])
    return _rmse(res), _max_abs(res)


def _worst_per_triangle(points, res, found, upper) -> _Picks:
    """The point of largest |residual| in each triangle, where it exceeds ``upper``: one new
    vertex per triangle and round, as greedy TIN insertion does (its neighbours' residuals
    change once it is in); its |residual| (m) the score."""
    big = np.flatnonzero((np.abs(np.nan_to_num(res)) > upper) & (found >= 0))
    if not len(big):
        return _Picks.none(points)
    order = big[np.lexsort((-np.abs(res[big]), found[big]))]
    worst = order[np.r_[True, found[order][1:] != found[order][:-1]]]
    return _Picks(points[worst], np.abs(res[worst]))


def _misfit_triangles(mesh: Mesh, found, res, lower, floor, noise, most=None,
                      floor_at=None) -> tuple[np.ndarray, np.ndarray]:
    """Centroid x, y and a quarter of the area of each triangle whose points' mean square
    residual exceeds ``noise``² by more than ``lower``² and by three standard errors of that
    many points' (χ²: noise²·√(2/n)), where that quarter is at least ``floor`` m²; of them, the
    share ``most`` of all triangles (None: every one) whose excess over the triangle's area
    (m²·m²) is largest; and that excess of each."""
    ok = (found >= 0) & np.isfinite(res)
    n_tri = len(mesh.triangles)
    count = np.bincount(found[ok], minlength=n_tri)
    square = np.bincount(found[ok], weights=res[ok] ** 2, minlength=n_tri)
    mean_square = square / np.maximum(count, 1)
    excess = mean_square - noise ** 2
    quarter = triangle_areas(mesh.nodes, mesh.triangles) / 4
    centroid = mesh.nodes[mesh.triangles, :2].mean(axis=1)
    pick = (count > 2) & (excess > lower ** 2) & beyond_noise(mean_square, noise, count)
    if floor_at is None:
        pick &= quarter >= floor
    elif pick.any():  # the floor only where a triangle misfits: a few % of them
        at = np.flatnonzero(pick)
        pick[at] = quarter[at] >= floor_at(centroid[at])
    if most is not None and pick.sum() > most * n_tri:
        worst = np.argsort(np.where(pick, -excess * quarter, np.inf))[:int(most * n_tri)]
        pick = np.zeros_like(pick)
        pick[worst] = True
    return np.column_stack([centroid[pick], quarter[pick]]), (excess * quarter)[pick]


def _met(res, target_rmse, target_max) -> bool:
    if target_rmse is None and target_max is None:
        return False  # refine until nothing is left to refine
    return ((target_rmse is None or _rmse(res) <= target_rmse)
            and (target_max is None or _max_abs(res) <= target_max))


def _rmse(res) -> float:
    res = res[np.isfinite(res)]
    return float(np.sqrt(np.mean(res ** 2))) if res.size else float("nan")


def _max_abs(res) -> float:
    res = res[np.isfinite(res)]
    return float(np.abs(res).max()) if res.size else float("nan")
