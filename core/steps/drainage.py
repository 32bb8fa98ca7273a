"""Where water flows, from the terrain alone: the height above the nearest drainage (HAND,
Rennó et al. 2008; Nobre et al. 2011) on a DEM, and a size field that puts smaller triangles on
low ground near the drainage lines, the ground a flood reaches first (streets, valley floors,
floodplains), and leaves dry hillsides to the break lines.

Drainage by priority flood (Barnes et al. 2014): cells leave a heap lowest first, starting from
the grid's edge and the edge of its data; each cell drains to the neighbour that reached it, so
depressions fill and drain over their rims. Cells draining ``channel_area`` m² or more are the
drainage lines; HAND is a cell's height above the drainage cell its path reaches first.
"""
from __future__ import annotations

import heapq

import numba
import numpy as np

from ..raster import Grid

CHANNEL_AREA = 5000.0  # m²: a cell draining this much is on a drainage line
FLOW_AREA_CELLS = 23.0  # the default flow area, in cells: 23 m² at 1 m (see flow_area_for)


def flow_area_for(flow_area: float | None, cell_size: float) -> float | None:
    """The flow zone's triangle area (m²) of an option: None gives the default, 23 cells
    (23 m² on a 1 m grid, an equilateral side of 7.3 cells: a street or a valley floor gets a
    few triangles across it); 0 turns it off (returns None)."""
    if flow_area is None:
        return FLOW_AREA_CELLS * cell_size ** 2
    return float(flow_area) if flow_area > 0 else None


@numba.njit(cache=True, nogil=True)
def _priority_flood(z, index_type):
    """(order, parent, filled): cells in the order they leave the heap (lowest first), the
    flat index each drains to (-1: an outlet at the edge), both of ``index_type`` (int32 where
    the grid allows: 4 B a cell each), and the depression-filled surface."""
    ny, nx = z.shape
    n = ny * nx
    filled = z.ravel().copy()
    parent = np.full(n, -1, index_type)
    seen = np.zeros(n, np.bool_)
    order = np.empty(n, index_type)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for i in range(ny):
        for j in range(nx):
            k = i * nx + j
            if not np.isfinite(filled[k]):
                seen[k] = True
                continue
            edge = i == 0 or j == 0 or i == ny - 1 or j == nx - 1
            if not edge:
                for di in (-1, 0, 1):
                    for dj in (-1, 0, 1):
                        if not np.isfinite(z[i + di, j + dj]):
                            edge = True
            if edge:
                seen[k] = True
                heapq.heappush(heap, (filled[k], np.int64(k)))
    count = 0
    while len(heap) > 0:
        level, k = heapq.heappop(heap)
        order[count] = k
        count += 1
        i, j = k // nx, k % nx
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                a, b = i + di, j + dj
                if (di == 0 and dj == 0) or a < 0 or b < 0 or a >= ny or b >= nx:
                    continue
                m = a * nx + b
                if seen[m]:
                    continue
                seen[m] = True
                parent[m] = k
                filled[m] = max(filled[m], level)
                heapq.heappush(heap, (filled[m], m))
    return order[:count], parent, filled


@numba.njit(cache=True, nogil=True)
def _hand(z, order, parent, cell_area, channel_area):
    n = z.size
    flat = z.ravel()
    drained = np.full(n, cell_area)
    for t in range(len(order) - 1, -1, -1):   # highest first: pass the area down
        k = order[t]
        if parent[k] >= 0:
            drained[parent[k]] += drained[k]
    base = np.full(n, np.nan)
    for t in range(len(order)):               # lowest first: the drainage a path meets first
        k = order[t]
        if drained[k] >= channel_area:
            base[k] = flat[k]
        elif parent[k] >= 0:
            base[k] = base[parent[k]]   # NaN: it leaves the grid before any drainage line
    for k in range(n):  # HAND in place of the bases: 8 B a cell less than a new array
        base[k] = flat[k] - base[k]
    return base, drained


def height_above_drainage(dem: Grid, *, channel_area: float) -> tuple[Grid, Grid]:
    """(HAND m, drained area m²) on ``dem``'s cells; NaN where the DEM has no data. Cells
    draining ``channel_area`` m² or more are drainage lines (HAND 0); NaN too where a cell's
    path leaves the grid before it meets one (a hillside at the edge is not low ground)."""
    z = np.asarray(dem.values, float)
    # some 25 B a cell at the peak (the flood's surface and heap, then the areas and HAND)
    order, parent, filled = _priority_flood(z, np.int32 if z.size < 2 ** 31 else np.int64)
    del filled
    hand, drained = _hand(z, order, parent, dem.cell_size ** 2, float(channel_area))
    del order, parent
    valid = np.isfinite(z).ravel()
    hand[~valid] = np.nan
    drained[~valid] = np.nan
    return (dem.with_values(hand.reshape(z.shape).astype(np.float32)),
            dem.with_values(drained.reshape(z.shape).astype(np.float32)))


def flow_size(dem: Grid, *, flow_area: float, height: float = 1.0,
              channel_area: float = CHANNEL_AREA, hand: Grid | None = None) -> Grid:
    """A size field (local maximum triangle areas, m²; NaN: no limit): ``flow_area`` on the
    ground less than ``height`` m above a drainage line draining ``channel_area`` m² or more
    (``hand``: that HAND grid of ``dem``, when already computed)."""
    if hand is None:
        hand, _ = height_above_drainage(dem, channel_area=channel_area)
    low = np.nan_to_num(np.asarray(hand.values, float), nan=np.inf) <= height
    return dem.with_values(np.where(low, float(flow_area), np.nan).astype(np.float32))


def flow_spacing(dem: Grid, *, flow_area: float, height: float = 3.0,
                 channel_area: float = CHANNEL_AREA, hand: Grid | None = None) -> Grid:
    """Break-line spacing (m) where a flood may go: the side of an equilateral triangle of
    ``flow_area`` on the ground less than ``height`` m above a drainage line (wider than the
    flow zone of ``flow_size``: water rises above it, and a short segment anywhere wet sets the
    time step), NaN elsewhere (see ``hydraulic_lines``)."""
    zone = flow_size(dem, flow_area=flow_area, height=height, channel_area=channel_area,
                     hand=hand)
    return zone.with_values(np.sqrt(4 / np.sqrt(3) * np.asarray(zone.values, float))
                            .astype(np.float32))
