"""Break lines: breakpoints joined into lines by the method's tracing rules.

Only breakpoints are joined, and only grid neighbours (3x3 kernel). Breakpoints open lines in
priority order (line ends first, i.e. breakpoints with one breakpoint neighbour, then by
descending slope). From the opening point a path grows one neighbour at a time; the first two
paths from it form one line through it, any further candidates of the opening point start lines of
their own. Every other breakpoint belongs to at most one line. A candidate must:

* differ in slope from the current point by less than S_crit (slope varies continuously);
* not turn more than ±90° from the line's trend (the direction over the last three steps);
* not cross an existing line diagonally.

Among the candidates, "flat" terrain takes the one of least slope, "steep" terrain the one of
least change of slope; remaining ties go to the smallest turn, then to a fixed neighbour order,
so results are reproducible.

Thinning keeps the interior cells of steep bands that run obliquely to the grid (they have a
non-breakpoint diagonal neighbour); traced on their own they give short lines across the band.
A short line every point of which lies next to a line at least twice as long adds nothing, and
is dropped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from .errors import FloodMeshError
from .options import TRACING_MODES, check_choice, check_min_points, check_s_crit
from .raster import Grid

MODES = TRACING_MODES
# neighbour order: E, NE, N, NW, W, SW, S, SE as (row, col) offsets
DR = np.array([0, -1, -1, -1, 0, 1, 1, 1], dtype=np.int64)
DC = np.array([1, 1, 0, -1, -1, -1, 0, 1], dtype=np.int64)


@dataclass(frozen=True)
class BreakLine:
    """One break line: ``coords`` (k, 3) x, y, z in metres, the slope (degrees) at each point,
    and the connected break-line system it belongs to (lines that touch share a component)."""

    coords: np.ndarray
    slopes: np.ndarray
    component: int = 0

    @property
    def length(self) -> float:
        """Horizontal length in metres."""
        return float(np.hypot(*np.diff(self.coords[:, :2], axis=0).T).sum())


def trace_breaklines(breakpoints: Grid, slope: Grid, dem: Grid, s_crit: float, *,
                     mode: str = "auto", min_points: int = 3) -> list[BreakLine]:
    """Join thinned breakpoints into break lines (see the module docstring for the rules).

    ``mode`` is "flat", "steep" or "auto" (steep when the median slope of the DEM is at least
    S_crit). Lines with fewer than ``min_points`` points are dropped.
    """
    check_choice(mode, MODES, "tracing mode")
    s_crit = check_s_crit(s_crit)
    min_points = check_min_points(min_points)
    if breakpoints.shape != slope.shape or slope.shape != dem.shape:
        raise FloodMeshError("breakpoints, slope and DEM rasters must have the same shape "
                             f"(got {breakpoints.shape}, {slope.shape}, {dem.shape})")
    if mode == "auto":
        valid = slope.values[np.isfinite(slope.values)]
        mode = "steep" if valid.size and np.median(valid) >= s_crit else "flat"
    bp = breakpoints.values.astype(bool)
    slope_values = np.where(np.isfinite(slope.values), slope.values, 0.0)
    neighbours = ndimage.convolve(bp.astype(np.int64), np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]]),
                                  mode="constant", cval=0)
    rows, cols = np.nonzero(bp)
    is_end = neighbours[rows, cols] == 1
    order = np.lexsort((-slope_values[rows, cols], ~is_end))
    flat_order = (rows * bp.shape[1] + cols)[order].astype(np.int64)
    cells, starts = _trace(bp, slope_values, flat_order, float(s_crit), mode == "steep")
    paths = [cells[starts[i]:starts[i + 1]] for i in range(len(starts) - 1)]
    paths = _drop_fringes([p for p in paths if len(p) >= min_points], bp.shape)
    components = _components(paths, bp.shape)
    lines = []
    for idx, component in zip(paths, components):
        r, c = np.divmod(idx, bp.shape[1])
        x, y = dem.cell_centres(r, c)
        lines.append(BreakLine(np.column_stack([x, y, dem.values[r, c]]), slope.values[r, c],
                               int(component)))
    return lines


def _components(paths: list[np.ndarray], shape) -> list[int]:
    """Component id (1, 2, …) of each path: paths whose cells touch (8-neighbourhood) share one."""
    from scipy import ndimage

    if not paths:
        return []
    traced = np.zeros(shape[0] * shape[1], bool)
    traced[np.concatenate(paths)] = True
    labels, _ = ndimage.label(traced.reshape(shape), structure=np.ones((3, 3), bool))
    return [int(labels.flat[path[0]]) for path in paths]


def _drop_fringes(paths: list[np.ndarray], shape) -> list[np.ndarray]:
    """Drop short paths whose every cell touches (8-neighbourhood) a path twice as long."""
    if not paths:
        return paths
    lengths = np.array([len(p) for p in paths], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)])
    keep = _fringe_keep(np.concatenate(paths), starts, shape[0], shape[1])
    return [p for p, k in zip(paths, keep) if k]


@numba.njit(cache=True)
def _fringe_keep(cells, starts, rows, cols):
    n_paths = starts.size - 1
    length_at = np.zeros(rows * cols, dtype=np.int64)
    owner = np.full(rows * cols, -1, dtype=np.int64)
    for k in range(n_paths):
        length = starts[k + 1] - starts[k]
        for i in range(starts[k], starts[k + 1]):
            if length > length_at[cells[i]]:
                length_at[cells[i]] = length
                owner[cells[i]] = k
    keep = np.ones(n_paths, dtype=np.bool_)
    for k in range(n_paths):
        length = starts[k + 1] - starts[k]
        beside = True
        for i in range(starts[k], starts[k + 1]):
            r, c = cells[i] // cols, cells[i] % cols
            touched = False
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    rr, cc = r + dr, c + dc
                    if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                        continue
                    other = owner[rr * cols + cc]
                    if other >= 0 and other != k and length_at[rr * cols + cc] >= 2 * length:
                        touched = True
            if not touched:
                beside = False
                break
        keep[k] = not beside
    return keep


@numba.njit(cache=True)
def _extend(start, trend_r, trend_c, bp, slope, used, links, s_crit, steep, path):
    """Grow a path from ``start`` (already in ``path[0]``); return its length."""
    rows, cols = bp.shape
    n = 1
    cur = start
    while True:
        cr, cc = cur // cols, cur % cols
        if n >= 2:
            back = path[max(0, n - 4)]
            tr, tc = cr - back // cols, cc - back % cols
        else:
            tr, tc = trend_r, trend_c
        has_trend = tr != 0 or tc != 0
        tnorm = np.sqrt(tr * tr + tc * tc) if has_trend else 1.0
        best, best_k = -1, -1
        best_score, best_turn = np.inf, np.inf
        for k in range(8):
            nr, nc = cr + DR[k], cc + DC[k]
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                continue
            if not bp[nr, nc] or used[nr, nc]:
                continue
            ds = abs(slope[nr, nc] - slope[cr, cc])
            if ds >= s_crit:
                continue
            turn = 0.0
            if has_trend:
                cos = (DR[k] * tr + DC[k] * tc) / (tnorm * np.sqrt(DR[k] ** 2 + DC[k] ** 2))
                if cos < -1e-9:
                    continue  # turns more than 90 degrees from the trend
                turn = 1.0 - cos
            if DR[k] != 0 and DC[k] != 0:
                # a diagonal step crosses the link between the two cells beside it
                side = cr * cols + nc  # (cr, nc) linked to (nr, cc) by the direction (DR, -DC)
                for j in range(8):
                    if DR[j] == DR[k] and DC[j] == -DC[k]:
                        if links[side] & (1 << j):
                            turn = np.inf
                if turn == np.inf:
                    continue
            score = slope[nr, nc] if not steep else ds
            if score < best_score - 1e-9 or (abs(score - best_score) <= 1e-9 and turn < best_turn - 1e-12):
                best, best_k, best_score, best_turn = nr * cols + nc, k, score, turn
        if best < 0:
            return n
        links[cur] |= 1 << best_k
        links[best] |= 1 << ((best_k + 4) % 8)
        used[best // cols, best % cols] = True
        path[n] = best
        n += 1
        cur = best


@numba.njit(cache=True)
def _trace(bp, slope, order, s_crit, steep):
    rows, cols = bp.shape
    used = np.zeros((rows, cols), dtype=np.bool_)
    links = np.zeros(rows * cols, dtype=np.uint8)
    n_bp = order.size
    cells = np.empty(2 * n_bp + 16, dtype=np.int64)
    starts = np.empty(n_bp + 1, dtype=np.int64)
    path_a = np.empty(n_bp + 1, dtype=np.int64)
    path_b = np.empty(n_bp + 1, dtype=np.int64)
    n_cells = 0
    n_lines = 0
    starts[0] = 0
    for k in range(n_bp):
        s = order[k]
        if used[s // cols, s % cols]:
            continue
        used[s // cols, s % cols] = True
        path_a[0] = s
        len_a = _extend(s, 0, 0, bp, slope, used, links, s_crit, steep, path_a)
        if len_a == 1:
            continue  # an isolated breakpoint opens no line
        # the second path from the opening point heads away from the first
        back_r = -(path_a[1] // cols - s // cols)
        back_c = -(path_a[1] % cols - s % cols)
        path_b[0] = s
        len_b = _extend(s, back_r, back_c, bp, slope, used, links, s_crit, steep, path_b)
        for i in range(len_b - 1, 0, -1):
            cells[n_cells] = path_b[i]
            n_cells += 1
        for i in range(len_a):
            cells[n_cells] = path_a[i]
            n_cells += 1
        n_lines += 1
        starts[n_lines] = n_cells
        # every further candidate of the opening point starts a line of its own
        while True:
            path_a[0] = s
            len_c = _extend(s, 0, 0, bp, slope, used, links, s_crit, steep, path_a)
            if len_c == 1:
                break
            for i in range(len_c):
                cells[n_cells] = path_a[i]
                n_cells += 1
            n_lines += 1
            starts[n_lines] = n_cells
    return cells[:n_cells].copy(), starts[:n_lines + 1].copy()
