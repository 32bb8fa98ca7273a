"""DEMs whose band stores its elevations packed, value = stored · scale + offset (GDAL's band
scale and offset; whole centimetres in an Int16 or Int32 band, a NetCDF's scale_factor and
add_offset), as QGIS shows them: every step takes the elevations, not the stored numbers.

References: the analytic plane the DEM samples, and GDAL itself (``gdal_translate -unscale``,
then ``gdaldem slope``)."""
import numpy as np
import pytest
import rasterio
from affine import Affine
from numpy.testing import assert_allclose

from floodmesh.core import io
from floodmesh.core.frontends.cli import main

from ..bad_inputs import ORIGIN, UTM

ROWS, COLS = 40, 60
GX, GY = 0.05, 0.02  # the plane's rise per metre east and north: 3.08°, no break anywhere
TRUE_SLOPE_DEG = np.degrees(np.arctan(np.hypot(GX, GY)))
NODATA = -32768


def plane_m(offset=0.0):
    """The plane (m) at the cell centres: 12 m at the upper-left cell, a 4 x 4 hole of nodata."""
    rows, cols = np.mgrid[0:ROWS, 0:COLS].astype(float)
    z = 12.0 + GX * cols - GY * rows + offset
    z[20:24, 30:34] = np.nan
    return z


def write_packed(path, metres, *, scale=0.01, offset=0.0, x0=ORIGIN[0]):
    """``metres`` stored as Int16 (stored · scale + offset), nodata -32768, as GDAL packs them."""
    stored = np.where(np.isnan(metres), NODATA, np.round((metres - offset) / scale))
    with rasterio.open(path, "w", driver="GTiff", width=metres.shape[1],
                       height=metres.shape[0], count=1, dtype="int16", crs=UTM, nodata=NODATA,
                       transform=Affine(1.0, 0, x0, 0, -1.0, ORIGIN[1] + metres.shape[0])) as dst:
        dst.write(stored.astype("int16"), 1)
        dst.scales, dst.offsets = (scale,), (offset,)
    return path


@pytest.mark.parametrize("scale, offset", [(0.01, 0.0), (0.001, 100.0)])
def test_a_packed_dem_is_read_in_metres(tmp_path, scale, offset):
    """The library reads a packed DEM as its elevations (stored · scale + offset, to half a
    step), its nodata still nodata (not -327.68 m)."""
    metres = plane_m(offset)
    dem = io.read_input(write_packed(tmp_path / "dem.tif", metres, scale=scale, offset=offset))
    assert_allclose(dem.values, metres, rtol=0, atol=scale / 2 + 1e-9)
    np.testing.assert_array_equal(np.isnan(dem.values), np.isnan(metres))


def test_the_slope_command_gives_the_packed_dems_slope_as_gdal_gives_it_unpacked(tmp_path):
    """``floodmesh slope`` on a DEM packed in centimetres: the plane's slope in degrees (it gave
    79° instead of 3.1°, the stored centimetres taken for metres), the slope GDAL gives of the
    DEM unpacked by ``gdal_translate -unscale`` (Horn, interior cells)."""
    from osgeo import gdal

    gdal.UseExceptions()
    packed = write_packed(tmp_path / "dem.tif", plane_m())
    out = tmp_path / "slope.tif"
    assert main(["slope", str(packed), "--method", "sharpnack-akin", "--out", str(out)]) == 0
    ours = io.read_raster(out, elevations=False).values
    finite = np.isfinite(ours)
    np.testing.assert_array_equal(finite, np.isfinite(plane_m()))
    assert_allclose(ours[finite], TRUE_SLOPE_DEG, rtol=0, atol=0.01)

    unpacked = tmp_path / "unpacked.tif"
    gdal.Translate(str(unpacked), str(packed), unscale=True, outputType=gdal.GDT_Float32)
    gdal.DEMProcessing(str(tmp_path / "gdal.tif"), str(unpacked), "slope", alg="Horn")
    theirs = io.read_raster(tmp_path / "gdal.tif", elevations=False).values
    both = np.isfinite(theirs)
    assert both.sum() > 0.8 * both.size
    assert_allclose(ours[both], theirs[both], rtol=0, atol=1e-3)


def test_a_run_on_a_packed_dem_meshes_its_elevations(tmp_path):
    """``floodmesh run`` on a DEM packed in centimetres: the mesh's nodes at the plane's
    elevations (not 1200 m for 12 m) and no break line on a 3° plane."""
    packed = write_packed(tmp_path / "dem.tif", plane_m())
    assert main(["run", str(packed), "--out", str(tmp_path / "out")]) == 0
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    x, y = nodes[:, 0] - ORIGIN[0] - 0.5, ORIGIN[1] + ROWS - 0.5 - nodes[:, 1]
    assert_allclose(nodes[:, 2], 12.0 + GX * x - GY * y, rtol=0, atol=0.01)
    assert io.read_lines_gpkg(tmp_path / "out" / "breaklines.gpkg") == []


def test_packed_dem_tiles_are_merged_in_metres_and_tiles_packed_apart_refused(tmp_path, capsys):
    """DEM tiles packed alike are meshed at their elevations; tiles packed by different scales
    are refused in one line that names both and the fix."""
    metres = plane_m()
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    write_packed(tiles / "west.tif", metres[:, :30])
    write_packed(tiles / "east.tif", metres[:, 30:], x0=ORIGIN[0] + 30)
    assert main(["run", str(tiles), "--out", str(tmp_path / "out")]) == 0
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    x, y = nodes[:, 0] - ORIGIN[0] - 0.5, ORIGIN[1] + ROWS - 0.5 - nodes[:, 1]
    assert_allclose(nodes[:, 2], 12.0 + GX * x - GY * y, rtol=0, atol=0.01)

    write_packed(tiles / "east.tif", metres[:, 30:], scale=0.001, offset=10.0,
                 x0=ORIGIN[0] + 30)
    capsys.readouterr()
    assert main(["run", str(tiles), "--out", str(tmp_path / "out2")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "east.tif" in err and "west.tif" in err and "0.001" in err and "offset" in err
    assert "gdal_translate -unscale -ot Float32" in err
    assert not (tmp_path / "out2").exists()
