"""The ahead-of-time raster kernels (``core._kernels.aot``): the same values as numba's kernels of
the same source, and a ``floodmesh slope`` process that never imports numba."""
import shutil
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from floodmesh.core._kernels import aot as compiled, raster as raster_kernels
from floodmesh.core import io
from floodmesh.core.raster import HIGHEST_GROUND_M, LOWEST_GROUND_M
from floodmesh.core.steps.slope import SLOPE_METHODS

from .test_streaming import rough_dem


@pytest.fixture(scope="module")
def aot():
    if not compiled.ahead_of_time():
        if shutil.which("gcc") is None:
            pytest.skip("no C compiler: the numba kernels serve")
        pytest.importorskip("numba.pycc", reason="this numba has no ahead-of-time compiler")
        # numba.pycc builds through numpy.distutils, which numpy 2 dropped for Python >= 3.12
        # (Debian 13): there the numba kernels serve
        pytest.importorskip("numpy.distutils",
                            reason="numba's ahead-of-time compiler needs numpy.distutils")
    assert compiled.build(), "the ahead-of-time build failed with a C compiler present"
    return compiled._module()


def ragged_block(seed=3, shape=(61, 77)):
    """Float32 terrain with NaN holes, a nodata sentinel and ±inf cells."""
    rng = np.random.default_rng(seed)
    z = (rng.random(shape) * 4 + np.linspace(0, 30, shape[1])).astype(np.float32)
    z[rng.random(shape) < 0.08] = np.nan
    z[rng.random(shape) < 0.02] = -9999.0
    z[3, 5], z[7, 9] = np.inf, -np.inf
    return z


@pytest.mark.parametrize("method", SLOPE_METHODS)
def test_ahead_of_time_slope_equals_numba(aot, method):
    padded = ragged_block()
    padded[padded == -9999.0] = np.nan
    code = SLOPE_METHODS[method][0]
    ours = np.empty((59, 75), np.float32)
    jit = np.empty_like(ours)
    aot.slope_f32(padded, ours, 0.5, code, 0.5 * np.sqrt(2))
    raster_kernels.slope_kernel(padded, jit, 0.5, code, 0.5 * np.sqrt(2))
    assert np.isfinite(ours).sum() > 3000
    assert_array_equal(ours, jit)


def test_ahead_of_time_nodata_conversions_equal_numba(aot):
    block = ragged_block()
    block[20, 30] = block[40, 10] = 12000.0  # no ground's: NaN, and counted
    view, jit_view = block[2:50, 3:60].copy(), block[2:50, 3:60].copy()  # the padded buffer
    tag = np.float32(-9999.0)
    ground = np.float32(LOWEST_GROUND_M), np.float32(HIGHEST_GROUND_M)
    seen, jit_seen = np.array([0.0, np.inf, -np.inf]), np.array([0.0, np.inf, -np.inf])
    assert aot.missing_to_nan_f32(view, tag, tag, *ground, 1, seen) \
        == raster_kernels.missing_to_nan(jit_view, tag, tag, *ground, 1, jit_seen)
    assert_array_equal(view, jit_view)
    assert_array_equal(seen, jit_seen)
    assert list(seen) == [2, 12000.0, 12000.0]
    assert not np.isin(view, [-9999.0, np.inf, -np.inf]).any() and np.isnan(view).any()
    values = np.ascontiguousarray(view)
    assert_array_equal(aot.nan_to_value_f32(values.copy(), np.float32(-9999.0)),
                       raster_kernels.nan_to_value(values.copy(), np.float32(-9999.0)))


def test_slope_command_starts_without_numba(aot, tmp_path):
    """Importing numba and loading its cache would cost 0.6 s of CPU per run, pyproj 0.1 s."""
    io.write_raster(tmp_path / "dem.tif", rough_dem())
    script = ("import sys; from floodmesh.core.frontends import cli; "
              f"code = cli.main(['slope', {str(tmp_path / 'dem.tif')!r}, '--out', "
              f"{str(tmp_path / 's.tif')!r}]); print(code, 'numba' in sys.modules, 'pyproj' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            check=True)
    assert result.stdout.split()[-3:] == ["0", "False", "False"]
    assert (tmp_path / "s.tif").exists()
