"""Gridding: LiDAR points to a DEM by linear (TIN) interpolation at cell centres.

Cells are aligned to whole multiples of the cell size d. A cell gets the elevation of the plane
of the Delaunay triangle holding its centre; cells outside the data, or under a triangle with an
edge longer than ``max_gap`` (water, buildings, voids), stay NaN instead of being bridged by long
thin triangles.

The grid is made in square tiles of ``TILE`` cells or larger, each from the points of the tile and a
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

from .._kernels.delaunay import delaunay_in_sweep_order
from .._kernels.points import extent
from ..engine.arrays import without_huge_pages
from ..engine.limits import MIN_GAP_IN_SPACINGS, check_memory, footprint
from ..errors import Cancelled, FloodMeshError
from ..options import check_cell_size, check_max_gap
from ..points import PointCloud
from ..raster import Grid

TILE = 256  # the least tile side (cells); larger where there are tiles enough for the threads


def grid_points_linear(points: PointCloud, cell_size: float, *, max_gap: float | None = None,
                       progress=None, cancelled=None, workers: int | None = None,
                       plan: dict | None = None) -> Grid:
    """DEM of cell size ``cell_size`` (m) by linear interpolation on the points' Delaunay TIN.

    ``max_gap`` (m, default 10 cell sizes) is the longest triangle edge bridged; wider gaps become
    nodata. Duplicate points are harmless (the triangulation skips them). Progress and
    cancellation are polled per tile. ``plan``: what ``check_grid`` returned for these points
    and arguments, where the caller checked them already (the points' footprint is a pass over
    all of them).
    """
    cell_size = check_cell_size(cell_size)
    plan = plan if plan is not None else check_grid(points, cell_size, max_gap)
    max_gap, rows, cols, x0, y1 = (plan[k] for k in ("max_gap", "rows", "cols", "x0", "y1"))
    values = grid_window(points.xyz, cell_size, max_gap, x0, y1, rows, cols, progress=progress,
                         cancelled=cancelled, workers=workers)
    if not np.isfinite(values).any():
        raise FloodMeshError(
            f"no grid cell is covered by the points at a gap limit of {max_gap} m; the points are "
            "too sparse for this cell size: raise the cell size or the max gap")
    if progress:
        progress(1.0)
    transform = Affine(cell_size, 0.0, x0, 0.0, -cell_size, y1)
    return Grid(values, transform, points.crs)


def halo_width(cell_size: float, max_gap: float) -> float:
    """Metres of neighbouring points a window of cells needs so that every TIN triangle that
    can cover one of its cells is formed as in one global TIN."""
    return max(max_gap, 4 * cell_size)


def grid_window(xyz: np.ndarray, cell_size: float, max_gap: float, x0: float, y1: float,
                rows: int, cols: int, *, progress=None, cancelled=None,
                workers: int | None = None) -> np.ndarray:
    """Cell values (rows, cols; NaN where no triangle covers) of the window whose upper-left
    corner is (x0, y1), by linear interpolation on the TIN of ``xyz``. Points up to
    ``halo_width`` beyond the window are used; points farther out are ignored."""
    values = np.full((rows, cols), np.nan)
    workers = workers or os.cpu_count() or 1
    # tiles as large as keep two for each thread: a tile's halo is work done twice (12 % of
    # the points at 256 cells, 1 m cells and a 10 m halo; 6 % at 512)
    side = TILE
    while math.ceil(rows / (2 * side)) * math.ceil(cols / (2 * side)) >= 2 * workers:
        side *= 2
    tiles = [(r, c) for r in range(0, rows, side) for c in range(0, cols, side)]
    halo = halo_width(cell_size, max_gap)
    # Points sorted once into buckets about a halo wide, row-major: a tile and its halo are
    # then a few contiguous slices, one per bucket row.
    per_tile = max(1, min(8 * side // TILE, int(side * cell_size // halo)))
    bucket_size = side * cell_size / per_tile
    n_brows = math.ceil(rows / side) * per_tile
    n_bcols = math.ceil(cols / side) * per_tile

    def grid_tile(tile):
        r0, c0 = tile
        if cancelled is not None and cancelled():
            raise Cancelled()
        x_lo, x_hi = c0 * cell_size - halo, (c0 + side) * cell_size + halo
        y_lo, y_hi = r0 * cell_size - halo, (r0 + side) * cell_size + halo
        local, local_z = _tile_points(
            xy, z, bounds, n_bcols, max(0, int(y_lo // bucket_size)),
            min(n_brows - 1, int(y_hi // bucket_size)), max(0, int(x_lo // bucket_size)),
            min(n_bcols - 1, int(x_hi // bucket_size)), x_lo, x_hi, y_lo, y_hi)
        if len(local) < 3:
            return
        swept, ids, triangles = delaunay_in_sweep_order(local)
        if len(triangles):
            _rasterise_tin(swept, local_z[ids], triangles, values, r0, min(rows, r0 + side),
                           c0, min(cols, c0 + side), float(cell_size), float(max_gap))

    with ThreadPoolExecutor(max_workers=workers) as pool, without_huge_pages():
        xy, z, bounds = _bucket_sort(xyz, float(x0), float(y1), bucket_size, n_brows, n_bcols,
                                     pool, workers)
        for done, _ in enumerate(pool.map(grid_tile, tiles), start=1):
            if progress:
                progress(done / len(tiles))
    return values


def check_grid(points: PointCloud, cell_size: float, max_gap: float | None = None, *,
               memory: int | None = None) -> dict:
    """Check, before any cell is allocated, that a grid of ``cell_size`` suits the points: at
    least 3 cells each way, a max gap (default 10 cells) that bridges the point spacing, and
    memory for the points and the cells. Returns the grid's layout
    (``rows``, ``cols``, ``x0``, ``y1``, ``max_gap``) and the points' ``area`` (m²) and
    ``spacing`` (m)."""
    xyz = points.xyz
    bounds = extent(xyz[:, 0], xyz[:, 1])
    area, _ = footprint(xyz[:, :2], bounds)
    return check_layout(bounds, len(xyz), area, cell_size, max_gap, memory=memory)


def check_layout(bounds, n_points: int, area: float, cell_size: float,
                 max_gap: float | None = None, *, memory: int | None = None,
                 memory_points: int | None = None, memory_cells: int | None = None,
                 advice: str | None = None) -> dict:
    """``check_grid`` for points known by their ``bounds`` (xmin, ymin, xmax, ymax), count and
    covered ``area`` (m²), as tiles are; the memory is checked for ``memory_points`` and
    ``memory_cells`` (default: all the points and cells)."""
    cell_size = check_cell_size(cell_size)
    max_gap = check_max_gap(max_gap)
    default_gap = max_gap is None
    if default_gap:
        max_gap = 10.0 * cell_size
    xmin, ymin, xmax, ymax = bounds
    x0 = math.floor(xmin / cell_size) * cell_size
    y1 = math.ceil(ymax / cell_size) * cell_size
    cols = max(1, math.ceil((xmax - x0) / cell_size))
    rows = max(1, math.ceil((y1 - ymin) / cell_size))
    spacing = math.sqrt(area / n_points)
    if rows < 3 or cols < 3:
        raise FloodMeshError(
            f"the data covers only {xmax - xmin:.2f} x {ymax - ymin:.2f} m, fewer than 3 cells of "
            f"{cell_size:g} m each way; choose a smaller cell size (the points are about "
            f"{spacing:.2g} m apart)")
    if max_gap < MIN_GAP_IN_SPACINGS * spacing:
        fix = (f"give a cell size of at least {MIN_GAP_IN_SPACINGS * spacing / 10:.2g} m (the "
               f"point spacing, {spacing:.2g} m, is a good choice) or a larger max gap"
               if default_gap else
               f"give a max gap of at least {MIN_GAP_IN_SPACINGS * spacing:.2g} m, or leave it "
               "out (10 cells)")
        raise FloodMeshError(
            f"the points are about {spacing:.2g} m apart ({n_points:,} points over "
            f"{area:,.0f} m²), so gaps of at most {max_gap:.2g} m "
            f"({'10 cells of ' + format(cell_size, 'g') + ' m' if default_gap else 'max gap'}) "
            f"would leave most grid cells empty: {fix}")
    check_memory(points=n_points if memory_points is None else memory_points,
                 cells=rows * cols if memory_cells is None else memory_cells, memory=memory,
                 advice=advice or f"give a cell size larger than {cell_size:g} m, or split the "
                                  "data into tiles")
    return {"rows": rows, "cols": cols, "x0": float(x0), "y1": float(y1), "max_gap": max_gap,
            "area": area, "spacing": spacing}


def _bucket_sort(xyz, x0, y1, size, n_rows, n_cols, pool, workers):
    """Local coordinates (x − x0, y1 − y: y down, keeping the digits that UTM magnitudes would
    cost) and z, counting-sorted (stably) into row-major buckets of ``size`` metres;
    ``bounds[k]`` is the first point of bucket k. Each of ``workers`` threads of ``pool``
    counts and places its own share of the points."""
    n = len(xyz)
    parts = np.linspace(0, n, workers + 1).astype(np.int64)
    bucket = np.empty(n, np.int32)
    counts = np.zeros((workers, n_rows * n_cols), np.int64)
    list(pool.map(lambda t: _bucket_counts(xyz, parts[t], parts[t + 1], x0, y1, size, n_rows,
                                           n_cols, bucket, counts[t]), range(workers)))
    bounds = np.concatenate([[0], np.cumsum(counts.sum(axis=0))])
    fill = bounds[:-1] + np.cumsum(counts, axis=0) - counts  # each share's first places
    xy, z = np.empty((n, 2)), np.empty(n)
    list(pool.map(lambda t: _bucket_fill(xyz, parts[t], parts[t + 1], x0, y1, bucket, fill[t],
                                         xy, z), range(workers)))
    return xy, z, bounds


@numba.njit(cache=True, nogil=True)
def _bucket_counts(xyz, start, stop, x0, y1, size, n_rows, n_cols, bucket, counts):
    """The bucket of points ``start``..``stop``-1 into ``bucket``, counted into ``counts``."""
    for p in range(start, stop):
        r = min(max(int((y1 - xyz[p, 1]) // size), 0), n_rows - 1)
        c = min(max(int((xyz[p, 0] - x0) // size), 0), n_cols - 1)
        bucket[p] = r * n_cols + c
        counts[r * n_cols + c] += 1


@numba.njit(cache=True, nogil=True)
def _bucket_fill(xyz, start, stop, x0, y1, bucket, fill, xy, z):
    """Points ``start``..``stop``-1 placed in their buckets from the places ``fill``."""
    for p in range(start, stop):
        k = fill[bucket[p]]
        fill[bucket[p]] += 1
        xy[k, 0] = xyz[p, 0] - x0
        xy[k, 1] = y1 - xyz[p, 1]
        z[k] = xyz[p, 2]


@numba.njit(cache=True, nogil=True)
def _tile_points(xy, z, bounds, n_cols, row0, row1, col0, col1, x_lo, x_hi, y_lo, y_hi):
    """(xy, z) of the bucketed points of bucket rows row0..row1 and columns col0..col1 that lie
    within x_lo..x_hi, y_lo..y_hi, in bucket order."""
    size = 0
    for i in range(row0, row1 + 1):
        size += bounds[i * n_cols + col1 + 1] - bounds[i * n_cols + col0]
    local, local_z = np.empty((size, 2)), np.empty(size)
    k = 0
    for i in range(row0, row1 + 1):
        for p in range(bounds[i * n_cols + col0], bounds[i * n_cols + col1 + 1]):
            if x_lo <= xy[p, 0] <= x_hi and y_lo <= xy[p, 1] <= y_hi:
                local[k, 0], local[k, 1], local_z[k] = xy[p, 0], xy[p, 1], z[p]
                k += 1
    return local[:k], local_z[:k]


@numba.njit(cache=True, nogil=True)
def _rasterise_tin(xy, z, simplices, out, row0, row1, col0, col1, d, max_gap):
    """Linear interpolation of each triangle onto the cell centres it covers within rows
    row0..row1-1 and columns col0..col1-1 of ``out`` (local coordinates, y down)."""
    max_gap2 = max_gap * max_gap
    eps = 1e-9
    for t in range(simplices.shape[0]):
        a, b, c = simplices[t, 0], simplices[t, 1], simplices[t, 2]
        xa, ya, xb, yb, xc, yc = xy[a, 0], xy[a, 1], xy[b, 0], xy[b, 1], xy[c, 0], xy[c, 1]
        # most triangles of dense points cover no cell centre: that is tested first
        j0 = max(col0, int(math.ceil(min(xa, xb, xc) / d - 0.5)))
        j1 = min(col1 - 1, int(math.floor(max(xa, xb, xc) / d - 0.5)))
        if j0 > j1:
            continue
        i0 = max(row0, int(math.ceil(min(ya, yb, yc) / d - 0.5)))
        i1 = min(row1 - 1, int(math.floor(max(ya, yb, yc) / d - 0.5)))
        if i0 > i1:
            continue
        if ((xb - xa) ** 2 + (yb - ya) ** 2 > max_gap2 or (xc - xb) ** 2 + (yc - yb) ** 2 > max_gap2
                or (xa - xc) ** 2 + (ya - yc) ** 2 > max_gap2):
            continue
        det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
        if abs(det) < 1e-12:
            continue
        for i in range(i0, i1 + 1):
            y = (i + 0.5) * d
            for j in range(j0, j1 + 1):
                x = (j + 0.5) * d
                l1 = ((yb - yc) * (x - xc) + (xc - xb) * (y - yc)) / det
                l2 = ((yc - ya) * (x - xc) + (xa - xc) * (y - yc)) / det
                l3 = 1.0 - l1 - l2
                if l1 >= -eps and l2 >= -eps and l3 >= -eps:
                    out[i, j] = l1 * z[a] + l2 * z[b] + l3 * z[c]
