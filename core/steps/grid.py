"""Gridding: LiDAR points to a DEM by linear (TIN) interpolation at cell centres.

Cells are aligned to whole multiples of the cell size d. A cell gets the elevation of the plane
of the Delaunay triangle holding its centre; cells outside the data, or under a triangle with an
edge longer than ``max_gap`` (water, buildings, voids), stay NaN instead of being bridged by long
thin triangles.

The grid is made in square tiles, each from the points of the tile and a halo around it: a few
point spacings wide where a check proves every tile cell's triangle one of the global TIN's,
else at least ``max_gap`` wide, so every triangle that can cover a tile cell is formed as in one
global TIN; tiles run in parallel threads and could stream from disk.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from affine import Affine

from .._kernels.delaunay import average_repeats, circumcentre, delaunay_in_sweep_order
from .._kernels.points import extent_on_threads, hull_candidates, monotone_chain
from ..engine.arrays import without_huge_pages
from ..engine.limits import MIN_GAP_IN_SPACINGS, check_memory, footprint
from ..engine.nearest import cell_of
from ..engine.progress import poll
from ..errors import FloodMeshError
from ..options import check_cell_size, check_max_gap
from ..points import PointCloud, check_spread, step_cloud
from ..raster import Grid, check_cells_across

FULL_TILE = 256  # the least tile side (cells) with full halos; larger where there are tiles
# enough for the threads
NEAR_TILE_POINTS = 120_000  # points a tile with a near halo is sized for, its side in cells the
# nearest power of two from 16 to 512 (128 cells of 1 m at 9 points/m², 32 of 5 m)
NEAR_HALO_SPACINGS = 6.0  # the near halo, in mean point spacings (2 m at 9 points/m²)
FULL_SHARE = 0.75  # a tile by a bucket of fewer points than this share of the median bucket's
# (a void, water, the data's edge) takes the full halo at once


def grid_points_linear(points: PointCloud, cell_size: float, *, max_gap: float | None = None,
                       progress=None, cancelled=None, workers: int | None = None,
                       plan: dict | None = None, note=None) -> Grid:
    """DEM of cell size ``cell_size`` (m) by linear interpolation on the points' Delaunay TIN.

    ``max_gap`` (m, default 10 cell sizes) is the longest triangle edge bridged; wider gaps become
    nodata. Duplicate points are harmless (the triangulation skips them). Progress and
    cancellation are polled per tile. ``plan``: what ``check_grid`` returned for these points
    and arguments, where the caller checked them already (the points' footprint is a pass over
    all of them). Points without a finite x, y, z or with a z no ground has are left out, as
    the readers leave them out (``points.step_cloud``; ``note`` is told), and a CRS the readers
    refuse is refused; without a ``plan``, points on one line or at one place are refused, as
    the readers refuse them (``points.check_spread``).
    """
    cell_size = check_cell_size(cell_size)
    xyz = step_cloud(points, "the point cloud", note, least=3)
    if xyz is not points.xyz:  # converted (a view, of an array numba made), or some left out:
        # the caller's plan, made for them all, holds only where none were
        points, plan = PointCloud(xyz, points.crs), plan if len(xyz) == len(points.xyz) else None
    if plan is None:  # the readers' check (points.clean_points) first: points spread over an
        # area, not on one line, which no cell size or gap would grid
        check_spread(xyz[:, :2], "the points")
        plan = check_grid(points, cell_size, max_gap)
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
                workers: int | None = None, known: tuple | None = None,
                extent: tuple | None = None):
    """Cell values (rows, cols; NaN where no triangle covers) of the window whose upper-left
    corner is (x0, y1), by linear interpolation on the TIN of ``xyz``. Points up to
    ``halo_width`` beyond the window are triangulated; points farther out only check that a
    triangle is the whole TIN's (its circle empty of them).

    ``known`` (xmin, ymin, xmax, ymax, m): ``xyz`` are the survey's points within this box
    only (a block of tiles), not all of them, and all lie within ``extent`` (the same order).
    A triangle is then the whole TIN's only if its circle is empty of the points beyond the
    box too, which were not given: returns (the values, the box the given points must fill for
    every cell to be decided): ``known`` itself, or a larger box where the circle of a
    triangle that gave a cell reaches past it within ``extent`` (grid again with the points
    within it).

    Each tile is triangulated with the points of a halo around it, and a triangle whose
    circumcircle stays inside the halo's box is one of the TIN of all the points (its circle is
    empty of them all). On dense points the halo is a few point spacings (near), and every cell
    of the tile must lie in such a triangle; a tile that fails (a void, water, the data's edge)
    is triangulated again with a halo of ``max_gap`` (full), as are at once the tiles by a
    bucket of markedly fewer points than most. The full halo holds the corners of every
    triangle of the whole TIN with edges of at most ``max_gap`` that covers a tile cell; a
    short triangle of the tile whose circle reaches past the box is kept only where no point
    past the box lies in the circle (else the whole TIN has a long one there: NaN)."""
    values = np.full((rows, cols), np.nan)
    if len(xyz) < 3:
        return values if known is None else (values, tuple(known))
    # the box of the given points in local coordinates (x - x0, y1 - y: x0, x1, y0, y1), and
    # the box of the circles of the triangles that gave cells and reach past it
    inf, clipped = np.inf, known is not None

    def local(box):
        return (np.array([-inf, inf, -inf, inf]) if box is None else
                np.array([box[0] - x0, box[2] - x0, y1 - box[3], y1 - box[1]], float))
    limits, within = local(known), local(extent)
    workers = workers or os.cpu_count() or 1
    halo = halo_width(cell_size, max_gap)
    near = NEAR_HALO_SPACINGS * math.sqrt(rows * cols * cell_size ** 2 / max(len(xyz), 1))
    if near <= halo / 2:
        side = near_tile_side(rows, cols, cell_size, len(xyz), workers)
    else:
        # tiles as large as keep two for each thread: a full halo is work done twice (12 % of
        # the points at 256 cells, 1 m cells and a 10 m halo; 6 % at 512)
        near, side = halo, FULL_TILE
        while math.ceil(rows / (2 * side)) * math.ceil(cols / (2 * side)) >= 2 * workers:
            side *= 2
    tiles = [(r, c) for r in range(0, rows, side) for c in range(0, cols, side)]
    # Points sorted once into buckets about a halo wide, row-major: a tile and its halo are
    # then a few contiguous slices, one per bucket row.
    per_tile = max(1, min(8 * side // FULL_TILE, int(side * cell_size // halo)))
    bucket_size = side * cell_size / per_tile
    n_brows = math.ceil(rows / side) * per_tile
    n_bcols = math.ceil(cols / side) * per_tile

    def triangulated(r0, c0, reach, checked, past):
        """Rasterise the tile at (r0, c0) from the TIN of its points and those within ``reach``
        metres around it; with ``checked``, returns how many of its cells are not proven to be
        the whole TIN's (``_rasterise_tin``; ``past``: the box of its circles past the given
        points', updated)."""
        x_lo, x_hi = c0 * cell_size - reach, (c0 + side) * cell_size + reach
        y_lo, y_hi = r0 * cell_size - reach, (r0 + side) * cell_size + reach
        r1, c1 = min(rows, r0 + side), min(cols, c0 + side)
        local, local_z = _tile_points(
            xy, z, bounds, n_bcols, *bucket_span(x_lo, x_hi, y_lo, y_hi), x_lo, x_hi, y_lo, y_hi)
        if len(local) < 3:
            return (r1 - r0) * (c1 - c0) if checked else 0
        swept, ids, triangles = delaunay_in_sweep_order(local)
        # a side of the box beyond every point needs no check: no point lies past it (where
        # all the points were given)
        box = ((x_lo if x_lo > data[0] or clipped else -np.inf),
               (x_hi if x_hi < data[1] or clipped else np.inf),
               (y_lo if y_lo > data[2] or clipped else -np.inf),
               (y_hi if y_hi < data[3] or clipped else np.inf))
        # points at one place (overlapping flight lines, tiles merged twice): their mean z, in
        # the copy that indexing by ``ids`` makes
        return _rasterise_tin(swept, average_repeats(swept, local_z[ids]), triangles, values,
                              r0, r1, c0, c1, float(cell_size), float(max_gap), checked,
                              np.array(box), hull, xy, bounds, n_bcols, bucket_size, limits,
                              within, past)

    def bucket_span(x_lo, x_hi, y_lo, y_hi):
        """Rows and columns (first, last) of the buckets that hold a box's points (the
        buckets as ``_bucket_counts`` numbers them)."""
        return (cell_of(y_lo, 0.0, bucket_size, n_brows), cell_of(y_hi, 0.0, bucket_size, n_brows),
                cell_of(x_lo, 0.0, bucket_size, n_bcols), cell_of(x_hi, 0.0, bucket_size, n_bcols))

    def grid_tile(tile):
        """Grid the tile at (r0, c0); the box of its circles past the given points'."""
        r0, c0 = tile
        poll(cancelled)
        if near < halo:
            brow0, brow1, bcol0, bcol1 = bucket_span(
                c0 * cell_size - near, (c0 + side) * cell_size + near,
                r0 * cell_size - near, (r0 + side) * cell_size + near)
            past = limits.copy()
            if (density[brow0:brow1 + 1, bcol0:bcol1 + 1].min() >= full_density
                    and not triangulated(r0, c0, near, True, past)):
                return past
            values[r0:r0 + side, c0:c0 + side] = np.nan
        past = limits.copy()
        triangulated(r0, c0, halo, False, past)
        return past

    with ThreadPoolExecutor(max_workers=workers) as pool, without_huge_pages():
        xy, z, bounds = _bucket_sort(xyz, float(x0), float(y1), bucket_size, n_brows, n_bcols,
                                     pool, workers)
        # points per bucket area within the window (edge buckets reach past it)
        inside = np.outer(_inside_share(n_brows, bucket_size, rows * cell_size),
                          _inside_share(n_bcols, bucket_size, cols * cell_size))
        density = np.diff(bounds).reshape(n_brows, n_bcols) / np.where(inside > 0, inside, 1)
        density[inside == 0] = np.inf  # past the window: only halo points, no cells
        finite = density[np.isfinite(density) & (density > 0)]
        full_density = FULL_SHARE * np.median(finite) if len(finite) else np.inf
        hull = _local_hull(xyz, x0, y1)
        data = (hull[:, 0].min(), hull[:, 0].max(), hull[:, 1].min(), hull[:, 1].max())
        needed = limits.copy()
        for done, past in enumerate(pool.map(grid_tile, tiles), start=1):
            needed[::2], needed[1::2] = (np.minimum(needed[::2], past[::2]),
                                         np.maximum(needed[1::2], past[1::2]))
            if progress:
                progress(done / len(tiles))
    if not clipped:
        return values
    # in world coordinates, the sides that do not grow as given
    return values, (x0 + needed[0] if needed[0] < limits[0] else known[0],
                    y1 - needed[3] if needed[3] > limits[3] else known[1],
                    x0 + needed[1] if needed[1] > limits[1] else known[2],
                    y1 - needed[2] if needed[2] < limits[2] else known[3])


def near_tile_side(rows: int, cols: int, cell_size: float, n_points: int, workers: int) -> int:
    """The side (cells) of the tiles with a near halo: small enough that a tile's triangulation
    stays in cache (449 ns a point at 2.5 M points a tile, 364 ns at 0.2 M), as many as keep
    two for each thread, large enough that the near halo adds little (6 % of the points at
    128 cells of 1 m, 9 points/m²). Gridding 9 M points at 5 m cells: 2.70 s in tiles of 128
    cells, 2.24 s in tiles of 32."""
    density = n_points / max(rows * cols * cell_size ** 2, 1e-9)
    side = 2 ** min(9, max(4, round(math.log2(math.sqrt(NEAR_TILE_POINTS / density)
                                                / cell_size))))
    while side > 16 and math.ceil(rows / side) * math.ceil(cols / side) < 2 * workers:
        side //= 2
    return side


def _local_hull(xyz, x0, y1) -> np.ndarray:
    """The convex hull of the points in local coordinates (x - x0, y1 - y), anticlockwise there."""
    # the few candidates' rows once (a mask over all the points, twice, took 30 ms)
    keep = np.flatnonzero(hull_candidates(xyz[:, 0], xyz[:, 1], numba.get_num_threads()))
    x, y = xyz[keep, 0] - x0, y1 - xyz[keep, 1]
    order = np.lexsort((y, x))
    return monotone_chain(x[order], y[order])


def _inside_share(n_buckets: int, size: float, length: float) -> np.ndarray:
    """The share of each of ``n_buckets`` buckets of ``size`` m, from 0, that lies within
    ``length`` m."""
    return np.clip((length - size * np.arange(n_buckets)) / size, 0.0, 1.0)


def check_grid(points: PointCloud, cell_size: float, max_gap: float | None = None, *,
               memory: int | None = None) -> dict:
    """Check, before any cell is allocated, that a grid of ``cell_size`` suits the points: as
    many cells each way as a DEM needs to be meshed (``raster.check_cells_across``), a max gap
    (default 10 cells) that bridges the point spacing, and memory for the points and the cells.
    Returns the grid's layout
    (``rows``, ``cols``, ``x0``, ``y1``, ``max_gap``) and the points' ``area`` (m²) and
    ``spacing`` (m)."""
    xyz = points.xyz
    bounds = extent_on_threads(xyz[:, 0], xyz[:, 1], numba.get_num_threads())
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
    check_cells_across((cols, rows), (xmax - xmin, ymax - ymin), cell_size, "the data",
                       f"choose a smaller cell size (the points are about {spacing:.2g} m apart)")
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
    """The bucket of points ``start``..``stop``-1 into ``bucket``, counted into ``counts``
    (``cell_of``: Python's exact ``//`` made this pass 0.4 s of CPU for 9 M points, ten times
    the rest)."""
    for p in range(start, stop):
        r = cell_of(y1 - xyz[p, 1], 0.0, size, n_rows)
        c = cell_of(xyz[p, 0] - x0, 0.0, size, n_cols)
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
def _rasterise_tin(xy, z, simplices, out, row0, row1, col0, col1, d, max_gap, near, box, hull,
                   points, bounds, n_bcols, bucket_size, limits, extent, past):
    """Linear interpolation of each triangle of the tile's TIN onto the cell centres it covers
    within rows row0..row1-1 and columns col0..col1-1 of ``out`` (local coordinates, y down),
    made from all the ``points`` (bucketed: ``bounds``, ``n_bcols``, ``bucket_size``) inside
    ``box`` (x0, x1, y0, y1; infinite on sides beyond every point).

    A triangle whose circumcircle lies in the box is one of the TIN of all the points (its
    circle is empty of all of them). With a ``near`` box, returns how many cells are not proven
    so: cells under other triangles, and cells no triangle covers inside the points' convex
    ``hull`` (anticlockwise (h, 2)). With a box ``max_gap`` around the tile, every triangle of
    the whole TIN whose edges are at most ``max_gap`` and which covers a tile cell is among
    the tile's; a short triangle of the tile whose circle reaches past the box is then the
    whole TIN's only if no point past the box lies in the circle, else its cells are under a
    longer triangle of the whole TIN, and stay NaN; returns 0.

    ``points`` are those within ``limits`` (x0, x1, y0, y1; infinite where all are given) of
    all within ``extent``: the box ``past`` (the same order, starting as ``limits``) grows to
    hold the circles (within ``extent``) of the triangles that give cells (with ``near``,
    those proven) and reach past ``limits``, which the points beyond may make no triangles of
    the whole TIN."""
    max_gap2 = max_gap * max_gap
    eps = 1e-9
    covered = np.zeros((row1 - row0, col1 - col0) if near else (0, 0), np.bool_)
    unproven = 0
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
        # the corners in x, y order: a cell's value is then the same to the bit whichever
        # tiling formed the triangle (the sweep starts each triangle at another corner)
        if (xb, yb) < (xa, ya):
            a, b, xa, ya, xb, yb = b, a, xb, yb, xa, ya
        if (xc, yc) < (xb, yb):
            b, c, xb, yb, xc, yc = c, b, xc, yc, xb, yb
            if (xb, yb) < (xa, ya):
                a, b, xa, ya, xb, yb = b, a, xb, yb, xa, ya
        det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
        if abs(det) < 1e-12:
            continue
        short = not ((xb - xa) ** 2 + (yb - ya) ** 2 > max_gap2
                     or (xc - xb) ** 2 + (yc - yb) ** 2 > max_gap2
                     or (xa - xc) ** 2 + (ya - yc) ** 2 > max_gap2)
        if not (short or near):
            continue
        ux, uy, r = _circumcircle(xa, ya, xb, yb, xc, yc)
        inside = (ux - r >= box[0] and ux + r <= box[1] and uy - r >= box[2]
                  and uy + r <= box[3])
        if short and not (near or inside) and not _empty_past(points, bounds, n_bcols,
                                                              bucket_size, ux, uy, r, box):
            continue
        gave = False
        for i in range(i0, i1 + 1):
            y = (i + 0.5) * d
            for j in range(j0, j1 + 1):
                x = (j + 0.5) * d
                l1 = ((yb - yc) * (x - xc) + (xc - xb) * (y - yc)) / det
                l2 = ((yc - ya) * (x - xc) + (xa - xc) * (y - yc)) / det
                l3 = 1.0 - l1 - l2
                if l1 >= -eps and l2 >= -eps and l3 >= -eps:
                    if short:
                        out[i, j] = l1 * z[a] + l2 * z[b] + l3 * z[c]
                        gave = True
                    if near and not covered[i - row0, j - col0]:
                        covered[i - row0, j - col0] = True
                        unproven += not inside
        # a circle past the given points' box: the cells it gave are decided only by the
        # points beyond, which the caller is to give
        if gave and (inside or not near) and (ux - r < limits[0] or ux + r > limits[1]
                                              or uy - r < limits[2] or uy + r > limits[3]):
            cx0, cx1, cy0, cy1 = _circle_within(ux, uy, r, extent)
            if cx0 <= cx1 and cy0 <= cy1:
                past[0], past[1] = min(past[0], cx0), max(past[1], cx1)
                past[2], past[3] = min(past[2], cy0), max(past[3], cy1)
    if near:
        for i in range(row1 - row0):
            for j in range(col1 - col0):
                if not covered[i, j] and _in_convex(hull, (col0 + j + 0.5) * d,
                                                    (row0 + i + 0.5) * d):
                    unproven += 1
    return unproven


@numba.njit(cache=True, nogil=True)
def _circle_within(ux, uy, r, box):
    """The bounds (x0, x1, y0, y1) of the part of the circle (ux, uy, r) within ``box`` (the
    same order); x0 > x1 where none is."""
    y = min(max(uy, box[2]), box[3])  # the box's nearest to the centre, each way
    x = min(max(ux, box[0]), box[1])
    half_width = math.sqrt(max(r * r - (y - uy) ** 2, 0.0))
    half_height = math.sqrt(max(r * r - (x - ux) ** 2, 0.0))
    if (x - ux) ** 2 + (y - uy) ** 2 > r * r:
        return 1.0, 0.0, 1.0, 0.0
    return (max(ux - half_width, box[0]), min(ux + half_width, box[1]),
            max(uy - half_height, box[2]), min(uy + half_height, box[3]))


@numba.njit(cache=True, nogil=True, inline="always")
def _circumcircle(xa, ya, xb, yb, xc, yc):
    """Centre and radius of the circle through three points, the radius a little enlarged
    (1e-9 relative and absolute) so that rounding errs on the side of a larger circle."""
    ux, uy = circumcentre(xa, ya, xb, yb, xc, yc)
    return ux, uy, math.hypot(ux - xa, uy - ya) * (1.0 + 1e-9) + 1e-9


@numba.njit(cache=True, nogil=True)
def _empty_past(points, bounds, n_bcols, bucket_size, ux, uy, r, box):
    """Whether no bucketed point outside ``box`` lies strictly inside the circle (ux, uy, r),
    the radius taken a little short for rounding."""
    n_brows = (bounds.shape[0] - 1) // n_bcols
    r_in = r * (1.0 - 2e-9) - 2e-9
    for i in range(cell_of(uy - r, 0.0, bucket_size, n_brows),
                   cell_of(uy + r, 0.0, bucket_size, n_brows) + 1):
        for j in range(cell_of(ux - r, 0.0, bucket_size, n_bcols),
                       cell_of(ux + r, 0.0, bucket_size, n_bcols) + 1):
            # the bucket's square (the edge buckets also hold the points past the window),
            # a hair wider: ``cell_of`` rounds the quotient, so a point a rounding below a
            # bucket's edge may be in it
            x0 = -np.inf if j == 0 else (j - 1e-9 * (j + 1)) * bucket_size
            x1 = np.inf if j == n_bcols - 1 else (j + 1 + 1e-9 * (j + 2)) * bucket_size
            y0 = -np.inf if i == 0 else (i - 1e-9 * (i + 1)) * bucket_size
            y1 = np.inf if i == n_brows - 1 else (i + 1 + 1e-9 * (i + 2)) * bucket_size
            if box[0] <= x0 and x1 <= box[1] and box[2] <= y0 and y1 <= box[3]:
                continue  # all its points are in the box
            if (min(max(ux, x0), x1) - ux) ** 2 + (min(max(uy, y0), y1) - uy) ** 2 >= r_in * r_in:
                continue  # the circle does not reach it
            for p in range(bounds[i * n_bcols + j], bounds[i * n_bcols + j + 1]):
                px, py = points[p, 0], points[p, 1]
                if box[0] <= px <= box[1] and box[2] <= py <= box[3]:
                    continue
                if (px - ux) ** 2 + (py - uy) ** 2 < r_in * r_in:
                    return False
    return True


@numba.njit(cache=True, nogil=True)
def _in_convex(polygon, x, y):
    """Whether (x, y) lies inside or on the anticlockwise convex ``polygon`` (h, 2)."""
    h = polygon.shape[0]
    if h < 3:
        return True  # too few vertices to tell: inside, the safe side
    for k in range(h):
        ax, ay = polygon[k, 0], polygon[k, 1]
        bx, by = polygon[(k + 1) % h, 0], polygon[(k + 1) % h, 1]
        if (bx - ax) * (y - ay) - (by - ay) * (x - ax) < 0.0:
            return False
    return True
