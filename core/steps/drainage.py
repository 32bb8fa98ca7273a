"""Where water flows, from the terrain alone: the height above the nearest drainage (HAND,
Rennó et al. 2008; Nobre et al. 2011) on a DEM, and a size field that puts smaller triangles on
low ground near the drainage lines, the ground a flood reaches first (streets, valley floors,
floodplains), and leaves dry hillsides to the break lines.

The smaller triangles go only where the mesh without them misses the terrain of that low
ground (``flow_refined``): a triangle whose DEM cells depart from its plane by more than
``FLOW_TERRAIN_TOLERANCE`` beyond the DEM's own noise (a street's kerbs and gutters, a
floodplain's swales: relief a shallow flood follows) is refined; low ground that the mesh
already follows (a plane floodplain between its break lines) keeps its triangles, as extra
nodes there change neither the terrain nor the flood.

Drainage by priority flood (Barnes et al. 2014): cells leave a heap lowest first, starting from
the grid's edge and the edge of its data; each cell drains to the neighbour that reached it, so
depressions fill and drain over their rims. Cells draining ``channel_area`` m² or more are the
drainage lines; HAND is a cell's height above the drainage cell its path reaches first.
"""
from __future__ import annotations

import heapq

import numba
import numpy as np

from ..engine.progress import part, poll, report
from ..raster import Grid
from .sizing import finer

CHANNEL_AREA = 5000.0  # m²: a cell draining this much is on a drainage line
FLOW_AREA_CELLS = 23.0  # the default flow area, in cells: 23 m² at 1 m (see flow_area_for)
FLOW_TERRAIN_TOLERANCE = 0.01  # m: RMS relief within a triangle, noise taken out
NOISE_MARGIN = 4.0  # standard errors of a triangle's mean square misfit that noise may reach
MIN_CELLS = 12  # cells of a triangle to tell its relief from noise


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


def dem_noise(dem: Grid, cells: np.ndarray | None = None) -> float:
    """The DEM's noise (m, one standard deviation) from the departure of each cell from the
    mean of its 3x3 neighbourhood (zero on a plane; (8/9)·σ² for independent noise), by the
    median absolute departure over ``cells`` (a mask; all valid cells if None), so that real
    relief in a few cells does not count as noise."""
    # lazy: SciPy loads only when this runs
    from scipy.ndimage import uniform_filter

    z = np.asarray(dem.values, float)
    valid = np.isfinite(z)
    if not valid.any():
        return 0.0
    filled = np.where(valid, z, np.nanmean(z))
    departure = np.abs(filled - uniform_filter(filled, 3, mode="nearest"))
    keep = valid if cells is None else valid & cells
    if not keep.any():
        return 0.0
    return float(1.4826 * np.median(departure[keep]) / np.sqrt(8 / 9))


def misfit_triangles(dem: Grid, cells: np.ndarray, nodes: np.ndarray, triangles: np.ndarray, *,
                     tolerance: float = FLOW_TERRAIN_TOLERANCE, margin: float = NOISE_MARGIN,
                     block_cells: int = 1 << 20) -> tuple[np.ndarray, float]:
    """(a mask of ``cells`` (a cell mask of ``dem``), true where the triangle of the mesh
    (``nodes`` (n, 2+), ``triangles``) holding the cell has relief that no plane follows: its
    cells of the mask depart from their least-squares plane by more than ``tolerance`` m RMS
    beyond the DEM's noise σ; the noise, m). Beyond the noise: the triangle's mean square
    departure (over n − 3 degrees of freedom) less σ² exceeds both ``tolerance``² and
    ``margin`` standard errors of that mean (σ²·√(2/(n − 3))), so a noisy plane does not pass
    by chance. The plane, not the triangle's own nodes: noise at a node is the node fit's to
    take out, not a reason for smaller triangles. The cells go in blocks of rows of about
    ``block_cells``: the memory is ten sums a triangle and 12 B a cell of the mask."""
    # lazy: numba loads only when this runs
    from .._kernels.mesh import Locator

    mask = cells & np.isfinite(dem.values)
    flagged = np.zeros(cells.shape, bool)
    if not mask.any():
        return flagged, 0.0
    sigma = dem_noise(dem, cells)
    values = np.asarray(dem.values)
    nodes = np.asarray(nodes, float)
    corners = nodes[triangles]
    centre = corners[:, :, :2].mean(axis=1)
    base = np.nan_to_num(corners[:, :, 2].mean(axis=1)) if nodes.shape[1] > 2 else np.zeros(
        len(triangles))
    locator = Locator(nodes, triangles)
    # per triangle: n, Σu, Σv, Σuu, Σuv, Σvv, Σz, Σuz, Σvz, Σzz (u, v from its centre, z from
    # its nodes' mean height: the sums stay small beside the departures they give)
    sums = np.zeros((10, len(triangles)))
    rows_per_block = max(1, block_cells // max(cells.shape[1], 1))
    held = []
    for r0 in range(0, cells.shape[0], rows_per_block):
        rows, cols = np.nonzero(mask[r0:r0 + rows_per_block])
        rows += r0
        x, y = dem.cell_centres(rows, cols)
        k = locator(np.column_stack([x, y]))[0]
        inside = k >= 0
        rows, cols, k = rows[inside], cols[inside], k[inside]
        held.append((rows * cells.shape[1] + cols, k.astype(np.int32)))
        u, v = x[inside] - centre[k, 0], y[inside] - centre[k, 1]
        z = values[rows, cols].astype(float) - base[k]
        for i, w in enumerate((None, u, v, u * u, u * v, v * v, z, u * z, v * z, z * z)):
            sums[i] += np.bincount(k, w, minlength=len(triangles))
    n, su, sv, suu, suv, svv, sz, suz, svz, szz = sums
    normal = np.stack([np.stack([n, su, sv], -1), np.stack([su, suu, suv], -1),
                       np.stack([sv, suv, svv], -1)], -2)
    right = np.stack([sz, suz, svz], -1)
    # a plane and a mean square from at least MIN_CELLS cells (a triangle smaller than that
    # is smaller than any flow area's too)
    solvable = (n >= MIN_CELLS) & (np.abs(np.linalg.det(normal)) > 1e-9 * np.maximum(n, 1) ** 3)
    coefficients = np.zeros((len(triangles), 3))
    coefficients[solvable] = np.linalg.solve(normal[solvable], right[solvable][..., None])[..., 0]
    # the least-squares plane's residual sum of squares: Σz² less the fitted part
    residual = np.maximum(szz - (coefficients * right).sum(-1), 0.0)
    dof = np.maximum(n - 3, 1)
    excess = residual / dof - sigma ** 2
    rough = solvable & (excess > np.maximum(tolerance ** 2, margin * sigma ** 2 * np.sqrt(2 / dof)))
    for flat, k in held:
        flagged.ravel()[flat] = rough[k]
    return flagged, sigma


def flow_refined(build, size: Grid | None, flow: Grid | None, spacing: Grid | None, dem: Grid,
                 *, lines=(), note=None, progress=None, cancelled=None):
    """(mesh, size field, figures or None): ``build(size, spacing, note, progress=,
    cancelled=)``, a Mesh of that size field with its break lines thinned to the flow spacing
    ``spacing`` (a Grid, see ``flow_spacing``; None: not thinned), its repairs told to ``note``,
    its share of the work to ``progress`` (0–1), ``cancelled`` polled (see ``build_mesh``).
    Without a flow size
    ``flow`` (see ``flow_size``), that mesh without the spacing; with one, first that mesh,
    whose triangles with relief that no plane follows (``misfit_triangles`` on the flow zone,
    but the cells a cell or less from one of its ``lines``, (k, 2+) arrays, where the DEM
    rounds the kink the line carries) then take the flow size, and the lines the flow spacing
    within a flow triangle's side of them, and only there. Figures: the shares of the DEM's
    valid cells in the flow zone, refined and thinned, the DEM's noise and the tolerance (m).
    ``note`` hears the notes of the mesh returned only, not those of a first mesh built again
    (the same repairs of nearly the same lines). ``progress`` hears the whole: the first mesh
    takes all of it without a flow size, else half, the mesh refined in the flow zone the rest."""
    notes = []

    def build_told(size, spacing, shares):
        notes.clear()
        return build(size, spacing, notes.append, progress=part(progress, *shares),
                     cancelled=cancelled)

    result = _flow_refined(build_told, size, flow, spacing, dem, lines, cancelled)
    report(progress, None, 1.0)  # also where the first mesh needed no refining
    for message in notes if note else ():
        note(message)
    return result


def _flow_refined(build, size, flow, spacing, dem: Grid, lines, cancelled=None):
    """``flow_refined``; ``build(size, spacing, shares)`` tells its notes itself, and its
    progress as the ``shares`` (start, end) of the whole."""
    # lazy: SciPy loads only when this runs
    from scipy.ndimage import binary_dilation

    terrain = build(size, None, (0.0, 1.0 if flow is None else 0.5))
    if flow is None:
        return terrain, size, None
    poll(cancelled)
    zone = np.isfinite(np.asarray(flow.values, float))
    flagged, sigma = misfit_triangles(dem, zone & ~_beside(lines, dem), terrain.nodes,
                                      terrain.triangles)
    valid = max(int(np.isfinite(dem.values).sum()), 1)
    figures = {"low_ground_share": float(zone.sum() / valid),
               "refined_share": float(flagged.sum() / valid), "thinned_share": 0.0,
               "dem_noise_m": sigma, "tolerance_m": FLOW_TERRAIN_TOLERANCE}
    if not flagged.any():
        return terrain, size, figures
    size = finer(size, _only(flow, flagged))
    if spacing is not None:  # the spacing is the flow triangle's side (see flow_spacing)
        side = np.nanmax(spacing.values) / dem.cell_size
        near = binary_dilation(flagged, iterations=max(1, int(round(side))))
        spacing = _only(spacing, near)
        figures["thinned_share"] = float((near & np.isfinite(spacing.values)).sum() / valid)
    poll(cancelled)
    return build(size, spacing, (0.5, 1.0)), size, figures


def _beside(lines, dem: Grid) -> np.ndarray:
    """The cells of ``dem`` that ``lines`` ((k, 2+) arrays) touch, and their neighbours."""
    # lazy: GDAL's rasteriser and SciPy load only when this runs
    import shapely
    from rasterio.features import rasterize
    from scipy.ndimage import binary_dilation

    shapes = [shapely.LineString(np.asarray(c, float)[:, :2]) for c in lines if len(c) >= 2]
    if not shapes:
        return np.zeros(dem.shape, bool)
    touched = rasterize(((line, 1) for line in shapes), out_shape=dem.shape,
                        transform=dem.transform, all_touched=True, dtype="uint8") > 0
    return binary_dilation(touched)


def _only(grid: Grid, cells: np.ndarray) -> Grid:
    """``grid`` on ``cells`` (a mask), NaN elsewhere."""
    return grid.with_values(np.where(cells, grid.values, np.nan).astype(np.float32))
