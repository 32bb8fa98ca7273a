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
least change of slope. Where that leaves a tie, the kernel widens: each tied candidate is scored
by the best breakpoint ahead of it (within ±45° of its direction) on the 5x5 ring, then on the
7x7 ring; a tie that survives both goes to the smallest turn, and only then to a random choice
seeded by ``seed`` and the cell, so results are reproducible.

Thinning keeps the interior cells of steep bands that run obliquely to the grid (they have a
non-breakpoint diagonal neighbour); traced on their own they give short lines across the band.
A short line every point of which lies next to a line at least twice as long adds nothing, and
is dropped. The same bands cut their edge lines at every step of the staircase: thinning leaves
a corner cell inside the band there, whose slope differs from the edge's by more than S_crit.
Pieces whose ends are grid neighbours and point at each other are therefore joined (``join``);
that joint is the one place where a line's slope may jump by S_crit or more.
"""
from __future__ import annotations

import gc
from contextlib import contextmanager

import numba
import numpy as np

from ..engine.progress import REPORTS, part, report
from ..errors import FloodMeshError
from ..options import (TRACING_MODES, check_choice, check_min_length, check_min_points,
                       check_s_crit, check_seed)
from ..points import line_list, xyz_array
from ..raster import Grid, one_place, step_grid, usable_dem

MODES = TRACING_MODES
# neighbour order: E, NE, N, NW, W, SW, S, SE as (row, col) offsets
DR = np.array([0, -1, -1, -1, 0, 1, 1, 1], dtype=np.int64)
DC = np.array([1, 1, 0, -1, -1, -1, 0, 1], dtype=np.int64)


class BreakLine:
    """One break line: ``coords`` (k, 3) x, y, z in metres, the slope (degrees) at each point,
    and the connected break-line system it belongs to (lines that touch share a component);
    ``bridged``, where localisation bridged a gap across another line (see
    ``joining.bridges``, ``localise._bridged``), per vertex whether it is one of such a
    bridge's (a segment between two such vertices crosses the gap)."""

    __slots__ = ("coords", "slopes", "component", "bridged")

    def __init__(self, coords: np.ndarray, slopes: np.ndarray, component: int = 0,
                 bridged: np.ndarray | None = None):
        self.coords, self.slopes, self.component = coords, slopes, component
        self.bridged = bridged

    def __repr__(self):
        return f"BreakLine({len(self.coords)} points, component {self.component})"

    @property
    def length(self) -> float:
        """Horizontal length in metres."""
        return float(np.hypot(*np.diff(self.coords[:, :2], axis=0).T).sum())


def as_breaklines(lines, what: str) -> list[BreakLine]:
    """The caller's ``lines``, BreakLines or (k, 3) arrays of x, y, z (m; taken as lines of no
    known slope), as BreakLines; other arrays are refused, naming ``what`` and the line."""
    return [line if isinstance(line, BreakLine) else
            _no_slopes(xyz_array(getattr(line, "coords", line), f"{what} {k + 1}"))
            for k, line in enumerate(line_list(lines, f"the {what}s"))]


def _no_slopes(coords: np.ndarray) -> BreakLine:
    return BreakLine(coords, np.full(len(coords), np.nan))


BREAKPOINTS_FIX = "give classify_breakpoints(slope, s_crit), 1 where a cell is a breakpoint"


def check_tracing(s_crit, mode, min_points, min_length, seed) -> tuple:
    """The tracing options checked (``options``' ranges): (S_crit, minimum points, minimum
    length, seed) as numbers."""
    check_choice(mode, MODES, "tracing mode")
    return (check_s_crit(s_crit), check_min_points(min_points), check_min_length(min_length),
            check_seed(seed))


def trace_breaklines(breakpoints: Grid, slope: Grid, dem: Grid, s_crit: float, *,
                     mode: str = "auto", min_points: int = 3, min_length: float = 0.0,
                     join: bool = True, seed: int = 0, crests: bool = True,
                     note=None, progress=None, cancelled=None) -> list[BreakLine]:
    """Join thinned breakpoints into break lines (see the module docstring for the rules), and
    with ``crests`` add the crest lines of ridges and the bed lines of troughs too narrow for
    their sides to be traced apart (``narrow_crest_cells``), traced by the same rules.

    ``mode`` is "flat", "steep" or "auto" (steep when the median slope of the DEM is at least
    S_crit). Lines with fewer than ``min_points`` points or shorter than ``min_length`` metres
    are dropped. ``join`` joins pieces end to end across the corners that thinning leaves on
    bands oblique to the grid (see ``_join_fragments``); without it every line obeys the slope
    continuity rule strictly. ``seed`` settles ties that the 7x7 kernel leaves. DEM cells no
    ground has (-9999, inf) are nodata (``raster.usable_dem``, ``note`` told). ``progress``
    hears the share done as the breakpoints open lines, batch by batch, ``cancelled`` is polled
    between the batches.
    """
    s_crit, min_points, min_length, seed = check_tracing(s_crit, mode, min_points, min_length,
                                                         seed)
    if breakpoints.shape != slope.shape or slope.shape != dem.shape:
        raise FloodMeshError("breakpoints, slope and DEM rasters must have the same shape "
                             f"(got {breakpoints.shape}, {slope.shape}, {dem.shape})")
    dem = usable_dem(dem, "the DEM", note)
    step_grid(slope, "the slope", "slope", "give terrain_slope(dem)")
    step_grid(breakpoints, "the breakpoints grid", "breakpoints", BREAKPOINTS_FIX)
    marks = breakpoints.values
    if not ((marks == 0) | (marks == 1)).all():
        raise FloodMeshError(f"the breakpoints grid holds {np.nanmin(marks):g} to "
                             f"{np.nanmax(marks):g}, not 0 and 1: {BREAKPOINTS_FIX}")
    for grid, what in ((slope, "the slope"), (breakpoints, "the breakpoints grid")):
        one_place(grid, dem, what, "the DEM", "give the DEM's own slope and breakpoints")
    if mode == "auto":
        valid = slope.values[np.isfinite(slope.values)]  # a copy: the median may sort it
        mode = "steep" if valid.size and np.median(valid, overwrite_input=True) >= s_crit \
            else "flat"
        del valid
    # the tracer reads slope only at the cells it traces: breakpoints, where it is finite
    # (slope >= S_crit), and crest cells, which have a height all round
    slope_values = np.ascontiguousarray(slope.values, dtype=np.float64)
    lines = _traced(breakpoints.values, slope, slope_values, dem, s_crit, mode == "steep",
                    min_points, min_length, join, seed,
                    progress=part(progress, 0.0, 0.8 if crests else 1.0), cancelled=cancelled)
    if not crests:
        return lines
    crest_cells = narrow_crest_cells(dem, s_crit)
    report(progress, cancelled, 0.85)
    narrow = _traced(crest_cells, slope, slope_values, dem, s_crit,
                     mode == "steep", min_points,
                     max(min_length, CREST_MIN_LENGTH * dem.cell_size), join, seed,
                     progress=part(progress, 0.85, 1.0), cancelled=cancelled)
    first = 1 + max((line.component for line in lines), default=-1)
    for line in narrow:
        line.component += first
    return lines + narrow


# A narrow crest: a cell at least as high as its neighbours across it, whose ground falls on
# both sides by CREST_FALL of S_crit's rise at the far reach (a crest a metre wide with sides of
# 3 m falls a little less than its sides' slope there), a fall already CREST_START under way at
# the mid reach, where a crest 3 m wide is still flat (its edges are the breakpoints' lines).
# Heights are averaged over three cells along the crest first: a straight crest keeps its
# profile, noise loses 40 %. Chosen on crests a metre wide with sides of 1-3 m at seven angles
# to the grid, plains of 10-20 cm of noise a cell and the corpus's levees and channels at four
# angles (tests/core/test_narrow_crests.py), then checked on the whole evaluation corpus
CREST_REACH = ((2, 3), (1, 2))  # (mid, far) cells out: on the axes, on the diagonals
CREST_FALL = 0.75
CREST_START = 0.3
CREST_MIN_LENGTH = 5  # cells: shorter crests are left to the breakpoints' lines
CREST_STRIP = 1024  # rows looked at a time


def narrow_crest_cells(dem: Grid, s_crit: float) -> np.ndarray:
    """Cells (uint8, 1 on a crest) on the crest of a ridge, or the bed of a trough, too narrow
    to hold two break lines a cell apart: along one of the four grid directions the cell is at
    least as high as its two neighbours (as low, for a trough), the cells at the far reach of
    ``CREST_REACH`` on both sides lie lower by ``CREST_FALL`` of S_crit's rise over that
    distance (higher), and those at the mid reach already ``CREST_START`` of that fall lower;
    heights averaged over the cell and its two neighbours across that direction.
    An embankment with a crest a metre wide and sides of 1-3 m has its slope breaks within a
    cell or two of one another: its breakpoints form one band, whose lines hop between crest
    and toe. In strips of ``CREST_STRIP`` rows (and their reach), so that the kernel's
    float64 copies stay small whatever the DEM."""
    # lazy: numba loads only when this runs
    from .._kernels.lines import narrow_crests

    rise = CREST_FALL * np.tan(np.radians(check_s_crit(s_crit))) * dem.cell_size
    reach = np.array(CREST_REACH, np.int64)
    halo = int(reach.max()) + 1
    z = np.asarray(dem.values)
    rows = z.shape[0]
    found = np.empty(z.shape, np.uint8)
    for top in range(0, rows, CREST_STRIP):
        bottom = min(rows, top + CREST_STRIP)
        first, last = max(0, top - halo), min(rows, bottom + halo)
        strip = np.empty((last - first, z.shape[1]), np.uint8)
        narrow_crests(np.ascontiguousarray(z[first:last], np.float64), rise, CREST_START, reach,
                      strip)
        found[top:bottom] = strip[top - first:bottom - first]
    return found


def _traced(cells_traced: np.ndarray, slope: Grid, slope_values: np.ndarray, dem: Grid,
            s_crit: float, steep: bool, min_points: int, min_length: float, join: bool,
            seed: int, *, progress=None, cancelled=None) -> list[BreakLine]:
    """``trace_breaklines``' lines through the marked cells ``cells_traced`` alone, its
    arguments checked and its mode settled (``steep``); ``slope_values``: ``slope``'s values
    as float64, which the tracer reads."""
    bp = np.ascontiguousarray(cells_traced, dtype=np.bool_)
    cells, starts = _trace(bp, slope_values, _opening_order(bp, slope_values), float(s_crit),
                           steep, np.uint64(seed & 0xFFFFFFFFFFFFFFFF),
                           progress=part(progress, 0.0, 0.9), cancelled=cancelled)
    if join:
        cells, starts = _join_fragments(cells, starts, *bp.shape)
    cells, starts = _select(cells, starts, np.diff(starts) >= max(min_points, 2))
    cells, starts = _select(cells, starts, _fringe_keep(cells, starts, *bp.shape))
    rows, cols = np.divmod(cells, bp.shape[1])
    x, y = dem.cell_centres(rows, cols)
    if min_length > 0:
        step = np.hypot(np.diff(x), np.diff(y))
        step[starts[1:-1] - 1] = 0.0  # no step between one line's end and the next's start
        length = np.add.reduceat(np.append(step, 0.0), starts[:-1]) if len(cells) else step
        cells, starts = _select(cells, starts, length >= min_length - 1e-9)
        rows, cols = np.divmod(cells, bp.shape[1])
        x, y = dem.cell_centres(rows, cols)
    components = _components(cells, starts, *bp.shape)
    coords = np.column_stack([x, y, dem.values.ravel()[cells]])
    slopes = slope.values.ravel()[cells]
    with _collector_paused():  # a million small objects would trigger it dozens of times
        return [BreakLine(coords[a:b], slopes[a:b], k)
                for a, b, k in zip(starts[:-1].tolist(), starts[1:].tolist(), components.tolist())]


@numba.njit(cache=True)
def _end_cells(cells, first, last, at_start, n, out):
    """The last ``n`` cells (fewer on short paths) up to one end of cells[first:last], ending at
    the end cell; returns how many were written into ``out``."""
    m = min(n, last - first)
    for i in range(m):
        out[i] = cells[first + m - 1 - i] if at_start else cells[last - m + i]
    return m


@numba.njit(cache=True)
def _turns_ok(seq, m, cols, backwards):
    """The tracing trend rule along seq[:m] (read backwards if asked): no step turns more than
    90° from the direction over the (up to) three steps before it."""
    for i in range(1, m - 1):
        here = seq[m - 1 - i] if backwards else seq[i]
        back = seq[m - 1 - max(0, i - 3)] if backwards else seq[max(0, i - 3)]
        ahead = seq[m - 2 - i] if backwards else seq[i + 1]
        tr, tc = here // cols - back // cols, here % cols - back % cols
        sr, sc = ahead // cols - here // cols, ahead % cols - here % cols
        if tr * sr + tc * sc < 0:
            return False
    return True


@numba.njit(cache=True)
def _root(parent, a):
    """Union–find: the root of ``a``, halving the path on the way."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@numba.njit(cache=True)
def _crosses_link(links, cell, k, cols):
    """Whether a diagonal step from ``cell`` in direction ``k`` crosses the link between the
    two cells beside it: (r, c + dc) linked to (r + dr, c) by the direction (dr, -dc)."""
    if DR[k] == 0 or DC[k] == 0:
        return False
    side = cell + DC[k]
    for j in range(8):
        if DR[j] == DR[k] and DC[j] == -DC[k] and links[side] & (1 << j):
            return True
    return False


@numba.njit(cache=True)
def _add_link(links, a, b, k):
    """Record the link from cell ``a`` to its neighbour ``b`` in direction ``k``: bit k of a's
    links and bit k + 4 (the opposite direction) of b's."""
    links[a] |= 1 << k
    links[b] |= 1 << ((k + 4) % 8)


@numba.njit(cache=True)
def _join_fragments(cells, starts, rows, cols):
    """Join paths end to end where an end cell is a grid neighbour of another path's end cell,
    the two ends point at each other (their chords over six steps within 45°) and the joined
    line keeps the trend rule across the joint.

    Thinning leaves a corner cell inside the band at every step of a band that runs obliquely
    to the grid; its slope differs from the edge's by more than S_crit, so the tracer ends the
    line there. Joining the pieces restores one line per feature. Closest, straightest joins go
    first; no path joins itself, and an opening point shared by several paths joins nothing."""
    in_paths, end_cell, end_at = _path_ends(cells, starts, rows, cols)
    cost, end_a, end_b, direction = _joint_candidates(cells, starts, rows, cols, in_paths,
                                                      end_cell, end_at)
    links = _path_links(cells, starts, rows, cols)
    partner = _chosen_joints(cost, end_a, end_b, direction, end_cell, links, cols)
    return _walk_chains(cells, starts, partner)


@numba.njit(cache=True)
def _path_ends(cells, starts, rows, cols):
    """Per cell, how many paths hold it; per path end (2k: path k's start, 2k + 1: its end), its
    cell; per cell, the end in it (-1: none)."""
    n_paths = starts.size - 1
    in_paths = np.zeros(rows * cols, dtype=np.int32)
    for i in range(cells.size):
        in_paths[cells[i]] += 1
    end_cell = np.empty(2 * n_paths, dtype=np.int64)
    end_at = np.full(rows * cols, -1, dtype=np.int32)  # the end in a cell that is in one path
    for k in range(n_paths):
        end_cell[2 * k] = cells[starts[k]]
        end_cell[2 * k + 1] = cells[starts[k + 1] - 1]
        end_at[end_cell[2 * k]] = 2 * k
        end_at[end_cell[2 * k + 1]] = 2 * k + 1
    return in_paths, end_cell, end_at


@numba.njit(cache=True)
def _joint_candidates(cells, starts, rows, cols, in_paths, end_cell, end_at):
    """The possible joints: pairs of ends of two paths, in neighbouring cells held by one path
    each, that face each other and keep the trend rule across the joint. Returns per joint its
    cost (step length plus how far the ends are from facing), its two ends and the step's
    direction from the first end's cell; each pair once."""
    n_ends = end_cell.size
    reach = 7  # cells per end for the chord (six steps)
    tail_a = np.empty(reach, dtype=np.int64)
    tail_b = np.empty(reach, dtype=np.int64)
    joint = np.empty(8, dtype=np.int64)
    cand_cost = np.empty(8 * n_ends)
    cand_a = np.empty(8 * n_ends, dtype=np.int64)
    cand_b = np.empty(8 * n_ends, dtype=np.int64)
    cand_dir = np.empty(8 * n_ends, dtype=np.int64)
    n_cand = 0
    for e in range(n_ends):
        k = e // 2
        if starts[k + 1] - starts[k] < 2 or in_paths[end_cell[e]] > 1:
            continue
        na = _end_cells(cells, starts[k], starts[k + 1], e % 2 == 0, reach, tail_a)
        r, c = end_cell[e] // cols, end_cell[e] % cols
        for j in range(8):
            rr, cc = r + DR[j], c + DC[j]
            if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                continue
            target = rr * cols + cc
            if in_paths[target] != 1 or end_at[target] < 0:
                continue
            f = end_at[target]
            m = f // 2
            if m <= k or starts[m + 1] - starts[m] < 2:
                continue  # each pair once, no self-joins
            nb = _end_cells(cells, starts[m], starts[m + 1], f % 2 == 0, reach, tail_b)
            facing = _facing(tail_a, na, tail_b, nb, cols)
            if facing < np.sqrt(0.5) - 1e-9:
                continue
            if not _joint_keeps_trend(tail_a, na, tail_b, nb, joint, cols):
                continue
            cand_cost[n_cand] = np.sqrt(DR[j] ** 2 + DC[j] ** 2) + (1.0 - facing)
            cand_a[n_cand], cand_b[n_cand], cand_dir[n_cand] = e, f, j
            n_cand += 1
    return cand_cost[:n_cand], cand_a[:n_cand], cand_b[:n_cand], cand_dir[:n_cand]


@numba.njit(cache=True)
def _chord(tail, n, cols):
    """(rows, cols) from the first to the last of the cells tail[:n]."""
    return tail[n - 1] // cols - tail[0] // cols, tail[n - 1] % cols - tail[0] % cols


@numba.njit(cache=True)
def _facing(tail_a, na, tail_b, nb, cols):
    """How squarely two path ends (their last cells, each up to its end cell) point at each
    other: the cosine between one end's chord and the other's reversed."""
    ur, uc = _chord(tail_a, na, cols)
    un = np.sqrt(ur * ur + uc * uc)
    vr, vc = _chord(tail_b, nb, cols)
    return -(ur * vr + uc * vc) / (un * np.sqrt(vr * vr + vc * vc))


@numba.njit(cache=True)
def _joint_keeps_trend(tail_a, na, tail_b, nb, joint, cols):
    """Whether the line joined across two ends keeps the trend rule, read in both directions,
    over the four cells on each side of the joint (``joint``: room for eight cells)."""
    n_joint = 0
    for q in range(max(0, na - 4), na):
        joint[n_joint] = tail_a[q]
        n_joint += 1
    for q in range(nb - 1, max(-1, nb - 5), -1):
        joint[n_joint] = tail_b[q]
        n_joint += 1
    return _turns_ok(joint, n_joint, cols, False) and _turns_ok(joint, n_joint, cols, True)


@numba.njit(cache=True)
def _path_links(cells, starts, rows, cols):
    """The links between successive cells of the paths, as in _trace: bit k of a cell's links
    is set where it links to its neighbour k."""
    links = np.zeros(rows * cols, dtype=np.uint8)
    for k in range(starts.size - 1):
        for i in range(starts[k], starts[k + 1] - 1):
            a, b = cells[i], cells[i + 1]
            for q in range(8):
                if b // cols - a // cols == DR[q] and b % cols - a % cols == DC[q]:
                    _add_link(links, a, b, q)
    return links


@numba.njit(cache=True)
def _chosen_joints(cost, end_a, end_b, direction, end_cell, links, cols):
    """The joints made, cheapest first: per end, the end it is joined to (-1: none). No end
    joins twice, no chain closes on itself and a diagonal joint crosses no link; each joint
    made is added to ``links``."""
    partner = np.full(end_cell.size, -1, dtype=np.int64)
    chain = np.arange(end_cell.size // 2)  # union-find over paths, to keep chains free of cycles
    for t in np.argsort(cost, kind="mergesort"):
        e, f = end_a[t], end_b[t]
        if partner[e] >= 0 or partner[f] >= 0:
            continue
        a, b = _root(chain, e // 2), _root(chain, f // 2)
        if a == b:
            continue
        j = direction[t]
        here = end_cell[e]
        if _crosses_link(links, here, j, cols):  # a diagonal joint must not cross a link
            continue
        _add_link(links, here, end_cell[f], j)
        chain[max(a, b)] = min(a, b)
        partner[e], partner[f] = f, e
    return partner


@numba.njit(cache=True)
def _walk_chains(cells, starts, partner):
    """The joined lines as (cells, starts): each chain of joined paths walked from a free end,
    a path read backwards where the walk enters it at its end."""
    n_paths = starts.size - 1
    out = np.empty(cells.size, dtype=np.int64)
    out_starts = np.empty(n_paths + 1, dtype=np.int64)
    out_starts[0] = 0
    done = np.zeros(n_paths, dtype=np.bool_)
    n_out, n_lines = 0, 0
    for k in range(n_paths):
        if done[k] or (partner[2 * k] >= 0 and partner[2 * k + 1] >= 0):
            continue
        e = 2 * k if partner[2 * k] < 0 else 2 * k + 1  # the free end starts the chain
        while True:
            m = e // 2
            done[m] = True
            if e % 2 == 0:
                for i in range(starts[m], starts[m + 1]):
                    out[n_out] = cells[i]
                    n_out += 1
            else:
                for i in range(starts[m + 1] - 1, starts[m] - 1, -1):
                    out[n_out] = cells[i]
                    n_out += 1
            far = e + 1 if e % 2 == 0 else e - 1
            if partner[far] < 0:
                break
            e = partner[far]
        n_lines += 1
        out_starts[n_lines] = n_out
    return out[:n_out].copy(), out_starts[:n_lines + 1].copy()


@contextmanager
def _collector_paused():
    """Pause Python's cyclic garbage collector (BreakLines hold no reference cycles)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def _opening_order(bp: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """Flat indices of the breakpoints in the order they open lines: line ends (one breakpoint
    neighbour) first, then by descending slope; equal keys in raster order."""
    flat = np.flatnonzero(bp)
    ends = _neighbour_count(bp, flat) == 1
    key = np.where(ends, 1000.0, 0.0) + slope.ravel()[flat]  # slopes are at most 90 degrees
    return flat[np.argsort(-key, kind="stable")].astype(np.int64)


@numba.njit(cache=True)
def _neighbour_count(bp, flat):
    rows, cols = bp.shape
    count = np.zeros(flat.size, dtype=np.int64)
    for i in range(flat.size):
        r, c = flat[i] // cols, flat[i] % cols
        for k in range(8):
            rr, cc = r + DR[k], c + DC[k]
            if 0 <= rr < rows and 0 <= cc < cols and bp[rr, cc]:
                count[i] += 1
    return count


def _select(cells: np.ndarray, starts: np.ndarray, keep: np.ndarray):
    """The paths (``cells`` split at ``starts``) for which ``keep`` is true."""
    lengths = np.diff(starts)[keep]
    mask = np.repeat(keep, np.diff(starts))
    return cells[mask], np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)


@numba.njit(cache=True)
def _components(cells, starts, rows, cols):
    """Component id (1, 2, … in order of first appearance) of each path: paths whose cells touch
    (8-neighbourhood) share one. Union–find over the traced cells."""
    owner = np.full(rows * cols, -1, dtype=np.int32)
    n_paths = starts.size - 1
    parent = np.arange(n_paths)
    for k in range(n_paths):
        for i in range(starts[k], starts[k + 1]):
            owner[cells[i]] = k
    for k in range(n_paths):
        for i in range(starts[k], starts[k + 1]):
            r, c = cells[i] // cols, cells[i] % cols
            for j in range(8):
                rr, cc = r + DR[j], c + DC[j]
                if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                    continue
                other = owner[rr * cols + cc]
                if other >= 0:
                    a, b = _root(parent, k), _root(parent, other)
                    if a != b:
                        parent[max(a, b)] = min(a, b)
    label = np.zeros(n_paths, dtype=np.int64)
    ids = np.zeros(n_paths, dtype=np.int64)
    n_ids = 0
    for k in range(n_paths):
        a = _root(parent, k)
        if ids[a] == 0:
            n_ids += 1
            ids[a] = n_ids
        label[k] = ids[a]
    return label


@numba.njit(cache=True)
def _fringe_keep(cells, starts, rows, cols):
    n_paths = starts.size - 1
    length_at = np.zeros(rows * cols, dtype=np.int32)
    owner = np.full(rows * cols, -1, dtype=np.int32)
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


TIE = 1e-9  # scores closer than this (degrees) are a tie


@numba.njit(cache=True)
def _ring_score(cr, cc, k, ring, bp, slope, used, steep):
    """Best score among the free breakpoints on the square ring ``ring`` cells from (cr, cc)
    that lie within ±45° of direction ``k``; inf where there are none."""
    rows, cols = bp.shape
    best = np.inf
    dnorm = np.sqrt(DR[k] ** 2 + DC[k] ** 2)
    for dr in range(-ring, ring + 1):
        for dc in range(-ring, ring + 1):
            if max(abs(dr), abs(dc)) != ring:
                continue
            rr, cc2 = cr + dr, cc + dc
            if rr < 0 or rr >= rows or cc2 < 0 or cc2 >= cols:
                continue
            if not bp[rr, cc2] or used[rr, cc2]:
                continue
            cos = (dr * DR[k] + dc * DC[k]) / (np.sqrt(dr * dr + dc * dc) * dnorm)
            if cos < np.sqrt(0.5) - 1e-9:
                continue
            score = abs(slope[rr, cc2] - slope[cr, cc]) if steep else slope[rr, cc2]
            best = min(best, score)
    return best


@numba.njit(cache=True)
def _seeded_pick(seed, cell, n):
    """A reproducible choice among ``n``: splitmix64 of the seed and the cell."""
    z = seed + np.uint64(cell) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return int(z % np.uint64(n))


@numba.njit(cache=True)
def _extend(start, trend_r, trend_c, bp, slope, used, links, s_crit, steep, seed, path):
    """Grow a path from ``start`` (already in ``path[0]``); return its length."""
    cols = bp.shape[1]
    n = 1
    cur = start
    cand_k = np.empty(8, dtype=np.int64)
    cand_score = np.empty(8)
    cand_turn = np.empty(8)
    while True:
        cr, cc = cur // cols, cur % cols
        if n >= 2:
            back = path[max(0, n - 4)]
            tr, tc = cr - back // cols, cc - back % cols
        else:
            tr, tc = trend_r, trend_c
        n_cand = _step_candidates(cur, tr, tc, bp, slope, used, links, s_crit, steep,
                                  cand_k, cand_score, cand_turn)
        if n_cand == 0:
            return n
        best_k = _chosen_step(cur, n_cand, cand_k, cand_score, cand_turn, bp, slope, used,
                              steep, seed)
        best = (cr + DR[best_k]) * cols + cc + DC[best_k]
        _add_link(links, cur, best, best_k)
        used[best // cols, best % cols] = True
        path[n] = best
        n += 1
        cur = best


@numba.njit(cache=True)
def _step_candidates(cur, tr, tc, bp, slope, used, links, s_crit, steep, cand_k, cand_score,
                     cand_turn):
    """The steps the tracing rules allow from ``cur`` to a free neighbouring breakpoint: slope
    change under S_crit, at most 90° from the trend (tr, tc) (none: (0, 0)), no diagonal across
    a link. Their directions, 3x3 kernel scores and turns go into ``cand_k``, ``cand_score``
    and ``cand_turn``; returns how many."""
    rows, cols = bp.shape
    cr, cc = cur // cols, cur % cols
    has_trend = tr != 0 or tc != 0
    tnorm = np.sqrt(tr * tr + tc * tc) if has_trend else 1.0
    n_cand = 0
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
        if _crosses_link(links, cur, k, cols):  # a diagonal step across another link
            continue
        cand_k[n_cand] = k
        cand_score[n_cand] = ds if steep else slope[nr, nc]
        cand_turn[n_cand] = turn
        n_cand += 1
    return n_cand


@numba.njit(cache=True)
def _chosen_step(cur, n_cand, cand_k, cand_score, cand_turn, bp, slope, used, steep, seed):
    """The direction of the step taken from ``cur`` among the ``n_cand`` candidates: the 3x3
    kernel's choice, then the 5x5 and 7x7 rings' for its ties, then the smallest turn, then a
    seeded random choice. Overwrites the candidate arrays."""
    cols = bp.shape[1]
    cr, cc = cur // cols, cur % cols
    n_tied = n_cand
    for ring in range(1, 4):
        if ring > 1:
            for i in range(n_tied):
                cand_score[i] = _ring_score(cr, cc, cand_k[i], ring, bp, slope, used, steep)
        best = np.inf
        for i in range(n_tied):
            best = min(best, cand_score[i])
        m = 0
        for i in range(n_tied):
            if cand_score[i] <= best + TIE:
                cand_k[m], cand_turn[m] = cand_k[i], cand_turn[i]
                m += 1
        n_tied = m
        if n_tied == 1:
            break
    if n_tied > 1:  # then the smallest turn, then a seeded random choice
        least = np.inf
        for i in range(n_tied):
            least = min(least, cand_turn[i])
        m = 0
        for i in range(n_tied):
            if cand_turn[i] <= least + 1e-12:
                cand_k[m] = cand_k[i]
                m += 1
        n_tied = m
    return cand_k[0] if n_tied == 1 else cand_k[_seeded_pick(seed, cur, n_tied)]


def _trace(bp, slope, order, s_crit, steep, seed, *, progress=None, cancelled=None):
    """(cells, starts): the paths the breakpoints ``bp`` open in ``order``, their flat cells
    one after another, path k from starts[k] to starts[k + 1]; traced in some ``REPORTS``
    batches of opening points, ``progress`` told the share done and ``cancelled`` polled between
    them (the same paths as in one: the batches share the tracer's state)."""
    rows, cols = bp.shape
    n_bp = order.size
    used = np.zeros((rows, cols), dtype=np.bool_)
    links = np.zeros(rows * cols, dtype=np.uint8)
    cells = np.empty(2 * n_bp + 16, dtype=np.int64)
    starts = np.zeros(n_bp + 1, dtype=np.int64)
    paths = np.empty((2, n_bp + 1), dtype=np.int64)
    counts = np.zeros(2, dtype=np.int64)  # cells and paths so far
    batch = max(1, -(-n_bp // REPORTS))
    for k in range(0, n_bp, batch):
        report(progress, cancelled, k / max(n_bp, 1))
        _trace_batch(bp, slope, order[k:k + batch], s_crit, steep, seed, used, links, cells,
                     starts, paths, counts)
    report(progress, cancelled, 1.0)
    return cells[:counts[0]].copy(), starts[:counts[1] + 1].copy()


@numba.njit(cache=True)
def _trace_batch(bp, slope, order, s_crit, steep, seed, used, links, cells, starts, paths,
                 counts):
    """``_trace`` of the opening points ``order``, after those before them: the state
    (``used``, ``links``, the paths so far in ``cells`` and ``starts``, their ``counts``) goes
    on from one batch to the next."""
    rows, cols = bp.shape
    path_a, path_b = paths[0], paths[1]
    n_cells, n_lines = counts[0], counts[1]
    for k in range(order.size):
        s = order[k]
        if used[s // cols, s % cols]:
            continue
        used[s // cols, s % cols] = True
        path_a[0] = s
        len_a = _extend(s, 0, 0, bp, slope, used, links, s_crit, steep, seed, path_a)
        if len_a == 1:
            continue  # an isolated breakpoint opens no line
        # the second path from the opening point heads away from the first
        back_r = -(path_a[1] // cols - s // cols)
        back_c = -(path_a[1] % cols - s % cols)
        path_b[0] = s
        len_b = _extend(s, back_r, back_c, bp, slope, used, links, s_crit, steep, seed, path_b)
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
            len_c = _extend(s, 0, 0, bp, slope, used, links, s_crit, steep, seed, path_a)
            if len_c == 1:
                break
            for i in range(len_c):
                cells[n_cells] = path_a[i]
                n_cells += 1
            n_lines += 1
            starts[n_lines] = n_cells
    counts[0], counts[1] = n_cells, n_lines
