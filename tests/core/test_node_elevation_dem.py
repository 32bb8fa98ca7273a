"""``run --node-elevation dem`` as the method says (docs/method.md, 7b): the nodes off the break
lines take z bilinear from the DEM, those on the lines the lines' z. Reference: SciPy's
bilinear interpolation between the cell centres of the run's dem.tif, read with rasterio."""
import numpy as np
import rasterio
import shapely
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial import cKDTree

from floodmesh.core import io
from floodmesh.core.frontends.cli import main


def test_nodes_off_the_lines_are_bilinear_from_the_dem_and_on_them_the_lines_z(
        demo_points_file, tmp_path):
    out = tmp_path / "out"
    assert main(["run", str(demo_points_file), "--out", str(out), "--node-elevation", "dem"]) == 0
    nodes, _ = io.read_mesh_2dm(out / "mesh.2dm")
    with rasterio.open(out / "dem.tif") as src:
        z, t = src.read(1, masked=True).filled(np.nan).astype(float), src.transform
    x_centres = t.c + (np.arange(z.shape[1]) + 0.5) * t.a
    y_centres = t.f + (np.arange(z.shape[0]) + 0.5) * t.e
    bilinear = RegularGridInterpolator((y_centres[::-1], x_centres), z[::-1],
                                       bounds_error=False)(nodes[:, [1, 0]])
    lines = io.read_lines_gpkg(out / "breaklines.gpkg")
    assert len(lines) > 5
    # off the lines: more than a cell from every line (the mesh's lines are the layer's, thinned)
    # (and beside no nodata cell, where SciPy gives NaN and FloodMesh weighs the others)
    off = (shapely.distance(shapely.MultiLineString([line[:, :2] for line in lines]),
                            shapely.points(nodes[:, :2])) > t.a) & np.isfinite(bilinear)
    assert off.sum() > len(nodes) / 3
    np.testing.assert_allclose(nodes[off, 2], bilinear[off], rtol=0, atol=2e-4)  # 2DM's 0.1 mm
    # on the lines: the nodes at the layer's vertices carry the vertex's z, not the DEM's
    vertices = np.concatenate(lines)
    distance, nearest = cKDTree(vertices[:, :2]).query(nodes[:, :2])
    at = distance < 1e-3
    assert at.sum() >= 10
    np.testing.assert_allclose(nodes[at, 2], vertices[nearest[at], 2], rtol=0, atol=2e-4)
    assert np.abs(nodes[at, 2] - bilinear[at]).max() > 0.01  # the lines' z is not the DEM's
