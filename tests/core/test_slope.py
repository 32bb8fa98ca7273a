"""Slope methods (``core.steps.slope``) and the block processing behind them
(``core.engine.blocks``).

References: analytic planes and an analytic curved surface (exact gradients), and GDAL's own
``gdaldem slope`` (Horn and ZevenbergenThorne) on the real Merewether DEM.
"""
import numpy as np
import pytest
from affine import Affine
from numpy.testing import assert_allclose, assert_array_equal
from pyproj import CRS

from floodmesh.core.engine import blocks
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.io import read_raster
from floodmesh.core.raster import Grid
from floodmesh.core.steps.slope import SLOPE_METHODS, slope, slope_block

CRS_M = CRS.from_epsg(25832)
X0, Y0 = 500000.0, 6001000.0  # upper-left corner of the synthetic grids
NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1)]
SECOND_ORDER = ["sharpnack-akin", "one-over-distance", "wood", "zevenbergen-thorne", "ritter"]
G30 = 0.2  # gradient of the plane at 30 degrees to the x axis
PLANES = {
    "flat": (0.0, 0.0),
    "x": (0.1, 0.0),
    "y": (0.0, -0.2),
    "xy": (0.3, 0.4),
    "steep": (-1.5, 2.0),
    "30deg": (G30 * np.cos(np.radians(30)), G30 * np.sin(np.radians(30))),
    "45deg": (0.25, 0.25),
}


def analytic_grid(f, d, rows, cols):
    """Grid of z = f(local x, local y) sampled at the cell centres of a north-up grid."""
    grid = Grid(np.zeros((rows, cols)), Affine(d, 0.0, X0, 0.0, -d, Y0), CRS_M)
    x, y = grid.cell_centres(*np.indices((rows, cols)))
    return grid.with_values(f(x - X0, y - Y0))


def plane_grid(a, b, d=1.0, rows=12, cols=15):
    return analytic_grid(lambda x, y: a * x + b * y + 7.0, d, rows, cols)


def plane_degrees(method, a, b):
    """Exact slope of the plane z = a·x + b·y by ``method`` (degrees)."""
    if method != "max-slope":
        return np.degrees(np.arctan(np.hypot(a, b)))
    # max-slope: steepest of the 8 directional slopes; east = +col, north = -row.
    steepest = max(abs(a * dc - b * dr) / np.hypot(dr, dc) for dr, dc in NEIGHBOURS)
    return np.degrees(np.arctan(steepest))


def corners(shape):
    mask = np.zeros(shape, bool)
    mask[[0, 0, -1, -1], [0, -1, 0, -1]] = True
    return mask


@pytest.mark.parametrize("plane", PLANES)
@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_plane_exact_in_interior_and_along_edges(method, plane):
    """Every cell but the four corners: the exact plane slope, 1e-9 degrees."""
    a, b = PLANES[plane]
    dem = plane_grid(a, b)
    result = slope(dem, method)
    assert result.transform == dem.transform and result.crs == dem.crs
    expected = np.full(dem.shape, plane_degrees(method, a, b))
    keep = ~corners(dem.shape)
    assert_allclose(result.values[keep], expected[keep], rtol=0, atol=1e-9)


@pytest.mark.parametrize("plane", PLANES)
@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_plane_exact_at_corners(method, plane):
    """The four corner cells too: the module promises the exact slope up to the edge."""
    a, b = PLANES[plane]
    result = slope(plane_grid(a, b), method)
    expected = plane_degrees(method, a, b)
    assert_allclose(result.values[corners(result.shape)], expected, rtol=0, atol=1e-9)


def test_max_slope_reference_values():
    """The independent maximum: along x it is atan(a); at 45 degrees the diagonal wins."""
    assert plane_degrees("max-slope", 0.1, 0.0) == pytest.approx(np.degrees(np.arctan(0.1)))
    assert plane_degrees("max-slope", 0.25, 0.25) == pytest.approx(
        np.degrees(np.arctan(0.5 / np.sqrt(2))))
    assert plane_degrees("max-slope", 0.25, 0.25) > plane_degrees("sharpnack-akin", 0.25, 0.25) - 1e-12
    result = slope(plane_grid(0.1, 0.0), "max-slope")
    assert_allclose(result.values, np.degrees(np.arctan(0.1)), rtol=0, atol=1e-9)


@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_cell_size_comes_from_the_transform(method):
    """The same plane at d = 2.5 m and d = 1 m has the same slope in degrees."""
    a, b = PLANES["30deg"]
    fine = slope(plane_grid(a, b, d=1.0), method).values
    coarse = slope(plane_grid(a, b, d=2.5), method).values
    assert_allclose(coarse, fine, rtol=0, atol=1e-9)
    assert_allclose(coarse[1:-1, 1:-1], plane_degrees(method, a, b), rtol=0, atol=1e-9)


@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_nodata_cell_gives_nodata_only_there(method):
    """A NaN cell is NaN in the slope; its neighbours stay exact, every other cell finite."""
    a, b = PLANES["xy"]
    dem = plane_grid(a, b)
    z = dem.values.copy()
    holes = [(5, 6), (0, 3), (11, 14)]
    for r, c in holes:
        z[r, c] = np.nan
    result = slope(dem.with_values(z), method).values
    nan_expected = np.zeros(z.shape, bool)
    nan_expected[tuple(np.array(holes).T)] = True
    assert_array_equal(np.isnan(result), nan_expected)
    neighbours = [(5 + dr, 6 + dc) for dr, dc in NEIGHBOURS]
    assert_allclose(result[tuple(np.array(neighbours).T)], plane_degrees(method, a, b),
                    rtol=0, atol=1e-9)


def wavy(x, y):
    return 5.0 * np.sin(x / 15.0) * np.cos(y / 11.0)


def wavy_degrees(x, y):
    dzdx = 5.0 / 15.0 * np.cos(x / 15.0) * np.cos(y / 11.0)
    dzdy = -5.0 / 11.0 * np.sin(x / 15.0) * np.sin(y / 11.0)
    return np.degrees(np.arctan(np.hypot(dzdx, dzdy)))


def interior_error(method, d):
    """Max |slope - analytic slope| over cell centres with local x in [15, 105], y in [-75, -15]."""
    dem = analytic_grid(wavy, d, int(round(90 / d)), int(round(120 / d)))
    x, y = dem.cell_centres(*np.indices(dem.shape))
    x, y = x - X0, y - Y0
    region = (x >= 15) & (x <= 105) & (y >= -75) & (y <= -15)
    err = np.abs(slope(dem, method).values - wavy_degrees(x, y))[region]
    assert np.isfinite(err).all()
    return err.max()


@pytest.mark.parametrize("method", SECOND_ORDER)
def test_second_order_convergence_on_curved_surface(method):
    """Halving d divides the interior error by about 4 (second order): ratio > 3."""
    e2, e1, e05 = (interior_error(method, d) for d in (2.0, 1.0, 0.5))
    assert e2 / e1 > 3, (e2, e1)
    assert e1 / e05 > 3, (e1, e05)
    assert e05 < 0.05


def test_max_slope_is_not_a_gradient_method():
    """Control for the convergence test: max-slope stays biased as d shrinks."""
    e1, e05 = interior_error("max-slope", 1.0), interior_error("max-slope", 0.5)
    assert e1 / e05 < 3


# ---------------------------------------------------------------------------------------------
# GDAL as independent reference
def gdal_slope(src_path, out_path, alg):
    from osgeo import gdal

    gdal.UseExceptions()
    gdal.DEMProcessing(str(out_path), str(src_path), "slope", alg=alg)
    ds = gdal.Open(str(out_path))
    band = ds.GetRasterBand(1)
    values = band.ReadAsArray().astype(np.float64)
    nodata = band.GetNoDataValue()
    if nodata is not None:
        values[values == nodata] = np.nan
    transform = Affine.from_gdal(*ds.GetGeoTransform())
    ds = None
    return values, transform


@pytest.mark.parametrize("method, alg", [("sharpnack-akin", "Horn"),
                                         ("zevenbergen-thorne", "ZevenbergenThorne")])
def test_matches_gdal_on_real_dem(real_data, tmp_path, method, alg):
    """Interior cells (1-cell border and GDAL nodata dropped) agree with gdaldem to 1e-3 deg."""
    asc = real_data / "merewether_topography1.asc"
    dem = read_raster(asc, crs="EPSG:32756")
    assert dem.cell_size == pytest.approx(0.99993681, abs=1e-8)
    ours = slope(dem, method).values
    theirs, transform = gdal_slope(asc, tmp_path / f"{alg}.tif", alg)
    assert transform.almost_equals(dem.transform, precision=1e-9)
    assert theirs.shape == ours.shape
    ours, theirs = ours[1:-1, 1:-1], theirs[1:-1, 1:-1]
    compared = np.isfinite(theirs)
    assert compared.mean() > 0.9
    assert np.isfinite(ours[compared]).all()
    assert np.nanmax(theirs) > 20  # real relief, not a flat comparison
    assert_allclose(ours[compared], theirs[compared], rtol=0, atol=1e-3)


# ---------------------------------------------------------------------------------------------
# block processing
def box_sum(halo):
    """A (2·halo+1)² neighbourhood sum, NaN-aware, of a padded block."""
    def func(padded):
        rows, cols = padded.shape[0] - 2 * halo, padded.shape[1] - 2 * halo
        out = np.zeros((rows, cols))
        for dr in range(2 * halo + 1):
            for dc in range(2 * halo + 1):
                out += np.nan_to_num(padded[dr:dr + rows, dc:dc + cols]) * (1 + dr + 10 * dc)
        return out
    return func


@pytest.fixture
def random_dem():
    rng = np.random.default_rng(11)
    z = rng.normal(50.0, 3.0, size=(23, 17))
    z[rng.random(z.shape) < 0.05] = np.nan
    return z


@pytest.mark.parametrize("halo", [1, 2])
@pytest.mark.parametrize("block_rows", [1, 5, 7, 22, 23, 1000])
def test_map_overlap_blocks_equal_whole(random_dem, halo, block_rows):
    """Any block height gives the function applied to the whole NaN-padded raster."""
    func = box_sum(halo)
    whole = func(np.pad(random_dem, halo, constant_values=np.nan))
    blocked = blocks.map_overlap(random_dem, func, halo=halo, block_rows=block_rows)
    assert_array_equal(blocked, whole)


@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_slope_same_with_small_blocks(random_dem, method):
    """``slope`` (one block here) equals its kernel run through map_overlap in blocks of 7 rows."""
    dem = Grid(random_dem, Affine(2.0, 0.0, X0, 0.0, -2.0, Y0), CRS_M)
    assert dem.shape[0] < blocks.DEFAULT_BLOCK_ROWS

    small = blocks.map_overlap(random_dem, lambda padded: slope_block(padded, 2.0, method),
                               halo=1, block_rows=7)
    assert_array_equal(slope(dem, method).values, small)


def test_slope_across_default_block_boundaries():
    """A raster taller than two default blocks gives the same slope as one block of all rows."""
    rows = 2 * blocks.DEFAULT_BLOCK_ROWS + 5
    rng = np.random.default_rng(3)
    z = np.cumsum(rng.normal(0, 0.3, size=(rows, 6)), axis=0)
    z[blocks.DEFAULT_BLOCK_ROWS - 1, 2] = np.nan  # nodata just above a block boundary
    dem = Grid(z, Affine(1.0, 0.0, X0, 0.0, -1.0, Y0), CRS_M)

    whole = blocks.map_overlap(z, lambda padded: slope_block(padded, 1.0, "sharpnack-akin"),
                               halo=1, block_rows=10 * rows)
    assert_array_equal(slope(dem, "sharpnack-akin").values, whole)


def test_unknown_method_names_the_choices():
    with pytest.raises(FloodMeshError) as excinfo:
        slope(plane_grid(0.1, 0.0), "horn")
    message = str(excinfo.value)
    assert "'horn'" in message
    for name in SLOPE_METHODS:
        assert name in message
