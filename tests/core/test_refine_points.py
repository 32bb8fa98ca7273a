"""Refinement points put into the mesh: one a hair off a break line is left out, as one near a
vertex is (a DEM cell centre on a traced line made Triangle refine towards it without end)."""
import numpy as np
from affine import Affine
from pyproj import CRS

from floodmesh.core.steps.accuracy import residuals
from floodmesh.core.steps.mesh import build_mesh
from floodmesh.core.raster import Grid


def test_a_point_a_hair_off_a_break_line_is_not_inserted():
    x0, y1 = 500_000.0, 6_000_040.0
    rows, cols = np.mgrid[0:40, 0:40]
    dem = Grid(10.0 + 0.01 * cols + 0.0 * rows, Affine(1.0, 0, x0, 0, -1.0, y1),
               CRS.from_epsg(25832))
    # a line through cell centres; the refinement point sits 1e-9 m off it, between vertices
    line = np.array([[x0 + 5.5, y1 - 20.5, 10.05], [x0 + 30.5, y1 - 20.5 + 5.0, 10.30]])
    t = 0.44
    on = line[0, :2] + t * (line[1, :2] - line[0, :2])
    normal = np.array([-5.0, 25.0]) / np.hypot(5.0, 25.0)
    hair = np.r_[on + 1e-9 * normal, 10.2]
    clear = np.array([x0 + 20.5, y1 - 8.5, 10.2])  # far from the line: kept
    mesh = build_mesh(dem, [line], min_angle=25.0, max_area=20.0,
                      points=np.vstack([hair, clear]))
    xy = mesh.nodes[:, :2]
    assert len(np.unique(np.round(xy, 6), axis=0)) == len(xy)  # no nodes on one spot
    assert np.any(np.all(np.isclose(xy, clear[:2], atol=1e-9), axis=1))
    assert len(mesh.nodes) < 200
    assert np.isfinite(residuals(mesh, np.array([clear]))).all()
