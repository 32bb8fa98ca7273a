"""Laplacian of Gaussian: exact on quadratic surfaces (∇²z known analytically), zero on planes,
and breakpoints where an embankment's slope breaks (lobes) or at its mid-slope (zero crossings)."""
import numpy as np
import pytest
from affine import Affine
from numpy.testing import assert_allclose
from pyproj import CRS

from floodmesh.core.steps.breakpoints import log_breakpoints
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.raster import Grid
from floodmesh.core.steps.slope import laplacian_of_gaussian

D = 0.5
CRS_M = CRS.from_epsg(25832)


def surface(f, rows=120, cols=130):
    yy, xx = np.mgrid[0:rows, 0:cols] * D
    return Grid(f(xx, yy), Affine(D, 0, 0, 0, -D, rows * D), CRS_M), xx


@pytest.mark.parametrize("kernel, sigma", [("pratt", 0.0), ("pratt", 1.0), ("pratt", 2.0),
                                           ("analytic", 0.5), ("analytic", 1.0),
                                           ("analytic", 2.0)])
def test_exact_on_quadratic_surfaces(kernel, sigma):
    """z = a(x−x0)² + b(y−y0)² + c·xy has ∇²z = 2a + 2b everywhere; the response is −3d²/8·∇²z."""
    a, b, c = 0.3, -0.1, 0.05
    dem, _ = surface(lambda x, y: a * (x - 20) ** 2 + b * (y - 15) ** 2 + c * x * y)
    response = laplacian_of_gaussian(dem, sigma, kernel=kernel).values
    finite = np.isfinite(response)
    assert finite.mean() > 0.5
    assert_allclose(response[finite], -3 * D * D / 8 * (2 * a + 2 * b), atol=1e-9)


@pytest.mark.parametrize("kernel, sigma", [("pratt", 1.0), ("analytic", 1.0)])
def test_zero_on_planes_and_nodata_within_reach_of_edges_and_holes(kernel, sigma):
    dem, _ = surface(lambda x, y: 0.2 * x - 0.1 * y + 5)
    values = dem.values.copy()
    values[40, 45] = np.nan
    response = laplacian_of_gaussian(dem.with_values(values), sigma, kernel=kernel).values
    reach = int(np.ceil(4 * sigma / D)) + (1 if kernel == "pratt" else 0)
    assert np.isnan(response[:reach]).all() and np.isnan(response[:, -reach:]).all()
    assert np.isnan(response[40, 45 - reach:45 + reach + 1]).all()
    assert np.isfinite(response[reach + 1:-reach - 1, reach + 1:40 - reach - 1]).all()
    assert_allclose(response[np.isfinite(response)], 0.0, atol=1e-9)


def embankment(x):
    """Flat to x = 20 m, a 1:2 side up to a crest at x = 24 m, flat at 2 m beyond."""
    return np.clip((x - 20) * 0.5, 0.0, 2.0)


def test_lobes_mark_toe_and_crest():
    dem, xx = surface(lambda x, y: embankment(x))
    bp = log_breakpoints(laplacian_of_gaussian(dem, 1.0), 0.01).values
    columns = np.unique(np.nonzero(bp[20:60])[1]) * D + D / 2
    # the thinned outline of the band around the toe (20 m) and the crest (24 m)
    assert set(np.round(columns - D / 2, 1)) == {19.0, 21.0, 23.0, 25.0}
    assert bp.sum() > 0 and (bp[20:60, :] == bp[20]).all()  # straight lines along y


def test_zero_crossings_mark_mid_slope():
    dem, _ = surface(lambda x, y: embankment(x))
    response = laplacian_of_gaussian(dem, 1.0)
    bp = log_breakpoints(response, 0.005, zero_crossings=True).values
    assert set(np.nonzero(bp[40])[0] * D) == {22.0}
    # a higher sensitivity than the response's jump across zero finds nothing
    assert log_breakpoints(response, 1.0, zero_crossings=True).values.sum() == 0


def test_bad_parameters():
    dem, _ = surface(lambda x, y: x)
    with pytest.raises(FloodMeshError, match="sigma"):
        laplacian_of_gaussian(dem, -1.0)
    with pytest.raises(FloodMeshError, match="at least one cell"):
        laplacian_of_gaussian(dem, 0.2, kernel="analytic")
    with pytest.raises(FloodMeshError, match="kernel"):
        laplacian_of_gaussian(dem, 1.0, kernel="sobel")
    with pytest.raises(FloodMeshError, match="sensitivity"):
        log_breakpoints(dem, -0.1)
