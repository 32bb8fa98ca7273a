"""Gridding: LiDAR points to a DEM by linear (TIN) interpolation at cell centres.

Cells are aligned to whole multiples of the cell size d. A cell gets the elevation of the plane
of the Delaunay triangle holding its centre; cells outside the data, or under a triangle with an
edge longer than ``max_gap`` (water, buildings, voids), stay NaN instead of being bridged by long
thin triangles.

The grid is made in tiles of ``TILE`` x ``TILE`` cells, each from the points of the tile and a
halo around it (at least ``max_gap`` wide, so every triangle that can cover a tile cell is
formed as in one global TIN); tiles run in parallel threads and could stream from disk.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from affine import Affine

from .delaunay import delaunay
from .errors import Cancelled, FloodMeshError
from .points import PointCloud
from .raster import Grid

MAX_CELLS = 400_000_000
TILE = 256


def grid_points_linear(points: PointCloud, cell_size: float, *, max_gap: float | None = None,
                       progress=None, cancelled=None, workers: int | None = None) -> Grid:
    """DEM of cell size ``cell_size`` (m) by linear interpolation on the points' Delaunay TIN.

    ``max_gap`` (m, default 10 cell sizes) is the longest triangle edge bridged; wider gaps become
    nodata. Duplicate points are harmless (the triangulation skips them). Progress and
    cancellation are polled per tile.
    """
    if not cell_size > 0 or not math.isfinite(cell_size):
        raise FloodMeshError(f"cell size must be a positive number of metres, got {cell_size}")
    if max_gap is None:
        max_gap = 10.0 * cell_size
    if not max_gap > 0:
        raise FloodMeshError(f"max gap must be positive, got {max_gap}")
    xyz = points.xyz
    xmin, ymin = xyz[:, 0].min(), xyz[:, 1].min()
    xmax, ymax = xyz[:, 0].max(), xyz[:, 1].max()
    x0 = math.floor(xmin / cell_size) * cell_size
    y1 = math.ceil(ymax / cell_size) * cell_size
    cols = max(1, math.ceil((xmax - x0) / cell_size))
    rows = max(1, math.ceil((y1 - ymin) / cell_size))
    if rows * cols > MAX_CELLS:
        raise FloodMeshError(
            f"a {cell_size} m grid over {xmax - xmin:.0f} x {ymax - ymin:.0f} m needs {rows * cols:,} "
            f"cells (limit {MAX_CELLS:,}); choose a larger cell size or split the data into tiles")
    if rows < 3 or cols < 3:
        raise FloodMeshError(
            f"the data covers only {xmax - xmin:.2f} x {ymax - ymin:.2f} m, fewer than 3 cells of "
            f"{cell_size} m each way; choose a smaller cell size")
    # local coordinates, y down: Delaunay and the barycentric weights keep their digits
    xy = np.column_stack([xyz[:, 0] - x0, y1 - xyz[:, 1]])
    values = np.full((rows, cols), np.nan)
    tiles = [(r, c) for r in range(0, rows, TILE) for c in range(0, cols, TILE)]
    halo = max(max_gap, 4 * cell_size)
    # points bucketed by tile, so each tile gathers its halo from the 3x3 tiles around it
    tile_size = TILE * cell_size
    n_tile_rows, n_tile_cols = math.ceil(rows / TILE), math.ceil(cols / TILE)
    bucket = (np.clip(np.floor(xy[:, 1] / tile_size).astype(np.int64), 0, n_tile_rows - 1)
              * n_tile_cols
              + np.clip(np.floor(xy[:, 0] / tile_size).astype(np.int64), 0, n_tile_cols - 1))
    order = np.argsort(bucket, kind="stable")
    bounds = np.searchsorted(bucket[order], np.arange(n_tile_rows * n_tile_cols + 1))
    reach = max(1, math.ceil(halo / tile_size))

    def grid_tile(tile):
        r0, c0 = tile
        if cancelled is not None and cancelled():
            raise Cancelled()
        tr, tc = r0 // TILE, c0 // TILE
        pick = np.concatenate([
            order[bounds[i * n_tile_cols + j]:bounds[i * n_tile_cols + j + 1]]
            for i in range(max(0, tr - reach), min(n_tile_rows, tr + reach + 1))
            for j in range(max(0, tc - reach), min(n_tile_cols, tc + reach + 1))])
        local = xy[pick]
        inside = ((local[:, 0] >= c0 * cell_size - halo)
                  & (local[:, 0] <= (c0 + TILE) * cell_size + halo)
                  & (local[:, 1] >= r0 * cell_size - halo)
                  & (local[:, 1] <= (r0 + TILE) * cell_size + halo))
        pick = pick[inside]
        if len(pick) < 3:
            return
        triangles = delaunay(xy[pick])
        if len(triangles):
            _rasterise_tin(xy[pick], xyz[pick, 2], triangles, values, r0, min(rows, r0 + TILE),
                           c0, min(cols, c0 + TILE), float(cell_size), float(max_gap))

    with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        for done, _ in enumerate(pool.map(grid_tile, tiles), start=1):
            if progress:
                progress(done / len(tiles))
    if not np.isfinite(values).any():
        raise FloodMeshError(
            f"no grid cell is covered by the points at a gap limit of {max_gap} m; the points are "
            "too sparse for this cell size: raise the cell size or the max gap")
    if progress:
        progress(1.0)
    transform = Affine(cell_size, 0.0, x0, 0.0, -cell_size, y1)
    return Grid(values, transform, points.crs)


@numba.njit(cache=True, nogil=True)
def _rasterise_tin(xy, z, simplices, out, row0, row1, col0, col1, d, max_gap):
    """Linear interpolation of each triangle onto the cell centres it covers within rows
    row0..row1-1 and columns col0..col1-1 of ``out`` (local coordinates, y down)."""
    max_gap2 = max_gap * max_gap
    eps = 1e-9
    for t in range(simplices.shape[0]):
        a, b, c = simplices[t, 0], simplices[t, 1], simplices[t, 2]
        xa, ya, xb, yb, xc, yc = xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1]
        if ((xb - xa) ** 2 + (yb - ya) ** 2 > max_gap2 or (xc - xb) ** 2 + (yc - yb) ** 2 > max_gap2
                or (xa - xc) ** 2 + (ya - yc) ** 2 > max_gap2):
            continue
        det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
        if abs(det) < 1e-12:
            continue
        j0 = max(col0, int(math.ceil(min(xa, xb, xc) / d - 0.5)))
        j1 = min(col1 - 1, int(math.floor(max(xa, xb, xc) / d - 0.5)))
        i0 = max(row0, int(math.ceil(min(ya, yb, yc) / d - 0.5)))
        i1 = min(row1 - 1, int(math.floor(max(ya, yb, yc) / d - 0.5)))
        for i in range(i0, i1 + 1):
            y = (i + 0.5) * d
            for j in range(j0, j1 + 1):
                x = (j + 0.5) * d
                l1 = ((yb - yc) * (x - xc) + (xc - xb) * (y - yc)) / det
                l2 = ((yc - ya) * (x - xc) + (xa - xc) * (y - yc)) / det
                l3 = 1.0 - l1 - l2
                if l1 >= -eps and l2 >= -eps and l3 >= -eps:
                    out[i, j] = l1 * z[a] + l2 * z[b] + l3 * z[c]
