"""CRSs as users give them: what the messages for feet tell the user to do."""
import numpy as np
import pytest

from floodmesh.core.frontends.cli import main

from ..bad_inputs import plane_xyz, slope_dem, write_tif


def floodmesh(args, capsys):
    """(exit code, stderr lines) of the command ``args`` run in this process."""
    code = main([str(a) for a in args])
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("kind, crs, words", [
    ("raster", "EPSG:2229", 'gdal_calc.py -A IN --calc "A*0.3048006" --outfile OUT'),  # US ft
    ("points", "EPSG:2994", 'filters.assign --filters.assign.value="Z = Z * 0.3048"'),  # ft
])
def test_feet_message_says_how_to_bring_z_to_metres(tmp_path, capsys, kind, crs, words):
    """Reprojecting x, y (gdalwarp, pdal's reprojection) leaves z in feet: the message also
    names the scaling of z, by the CRS's foot."""
    if kind == "points":
        path = tmp_path / "points.xyz"
        np.savetxt(path, plane_xyz(), fmt="%.3f")
        args = ["run", path, "--crs", crs]
    else:
        args = ["run", write_tif(tmp_path / "dem.tif", slope_dem(), crs=crs)]
    code, err = floodmesh([*args, "--out", tmp_path / "out"], capsys)
    assert code == 2 and len(err) == 1 and words in err[0], err
