"""Cheap hydraulic checks of a mesh (inradius, CFL time step, small triangles at the edge and at
crossings of own and detected lines) and the repair of boundary fans that ANUGA cannot take."""
import numpy as np
import pytest

from floodmesh.core.engine.arrays import boundary_edges
from floodmesh.core.flood.model import merge_wall_fans
from floodmesh.core.steps.hydraulics import (cfl_time_step, collinear_wall_stencils,
                                             hydraulic_checks, inradii)
from floodmesh.core.steps.mesh import triangle_areas


def fan_mesh():
    """Node a fans over three straight wall segments w0–w1–w2–w3 (y = 0): the middle
    triangle's centroid and its neighbours' lie on one line (y = 1/3)."""
    nodes = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [1.5, 1, 0], [3, 2, 0],
                      [0, 2, 0]], float)
    triangles = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 5, 4], [4, 5, 6], [0, 4, 6]])
    return nodes, triangles


def test_inradius_and_time_step_of_known_triangles():
    nodes = np.array([[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0, 3, 0], [4, 0, 0]])
    r = inradii(nodes, np.array([[0, 1, 2], [0, 4, 3]]))
    assert r[0] == pytest.approx(1 / (2 * np.sqrt(3)))
    assert r[1] == pytest.approx(1.0)  # 3-4-5 right triangle: (3 + 4 − 5) / 2
    assert cfl_time_step(r, depth=1.0) == pytest.approx(r[0] / np.sqrt(9.81))


def test_checks_find_the_small_triangle_at_the_edge_and_the_crossing():
    nodes, triangles = fan_mesh()
    nodes = np.vstack([nodes, [[1.5, 0.05, 0]]])   # a sliver against the wall
    triangles = np.vstack([np.delete(triangles, 1, axis=0), [[1, 7, 4], [7, 2, 4], [1, 2, 7]]])
    report = hydraulic_checks(nodes, triangles, own_lines=[np.array([[1.5, -1], [1.5, 3]])],
                              detected_lines=[np.array([[0, 0.05], [3, 0.05]])])
    assert report["n_small_inradius"] == 1 and report["n_small_inradius_near_edge"] == 1
    assert report["min_inradius_m"] < 0.05
    assert report["min_edge_at_domain_edge_m"] == pytest.approx(np.hypot(0.5, 0.05))
    assert report["min_node_distance_to_edge_m"] == pytest.approx(0.05)
    assert report["n_own_detected_crossings"] == 1
    assert report["min_edge_at_crossings_m"] == pytest.approx(np.hypot(0.5, 0.05))
    assert report["cfl_slowdown_vs_uniform"] > 5


def test_boundary_fans_are_merged_without_changing_the_boundary():
    nodes, triangles = fan_mesh()
    assert collinear_wall_stencils(nodes, triangles).tolist() == [1]
    merged, dropped = merge_wall_fans(nodes, triangles)
    assert dropped == 1 and len(merged) == len(triangles) - 1
    assert not collinear_wall_stencils(nodes, merged).size
    assert (triangle_areas(nodes, merged) > 0).all()
    assert triangle_areas(nodes, merged).sum() == pytest.approx(
        triangle_areas(nodes, triangles).sum())
    assert len(boundary_edges(merged)) == len(boundary_edges(triangles)) - 1


def test_crest_lowering_along_own_lines_against_the_dem():
    """A ridge z = 2 − |x − 5.5| on a 1 m DEM: a mesh with a node on the crest keeps it, one
    whose nodes straddle it cuts it by up to 0.5 m (bilinear DEM: exact on cell centres)."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.steps.hydraulics import crest_lowering
    from floodmesh.core.raster import Grid

    x = np.arange(10) + 0.5
    dem = Grid(np.tile(2 - np.abs(x - 5.5), (10, 1)), Affine(1, 0, 0, 0, -1, 10),
               CRS.from_epsg(32756))
    crest = [np.array([[5.5, 2.0], [5.5, 8.0]])]

    def mesh(columns):
        xs, ys = np.meshgrid(columns, [0.5, 9.5])
        nodes = np.column_stack([xs.ravel(), ys.ravel(), 2 - np.abs(xs.ravel() - 5.5)])
        k = len(columns)
        triangles = [[i, i + 1, k + i + 1] for i in range(k - 1)] + \
                    [[i, k + i + 1, k + i] for i in range(k - 1)]
        return nodes, np.array(triangles)

    kept = crest_lowering(*mesh([0.5, 3.5, 5.5, 7.5, 9.5]), crest, dem)
    cut = crest_lowering(*mesh([0.5, 5.0, 6.0, 9.5]), crest, dem)
    assert abs(kept["crest_max_lowering_m"]) < 1e-9
    assert cut["crest_max_lowering_m"] == pytest.approx(0.5, abs=0.01)


def test_the_inner_node_nearest_the_domain_edge_is_found():
    """On a 1 m lattice of 30 x 20 m, one inner node moved to 0.3 m off the left edge and one
    0.45 m below the top edge: the report gives 0.3 m, the distance to the nearest boundary
    edge, not to a boundary node (its neighbours on the edge are over 1 m away)."""
    from scipy.spatial import Delaunay

    yy, xx = np.mgrid[0:21, 0:31].astype(float)
    xy = np.column_stack([xx.ravel(), yy.ravel()])
    xy[5 * 31 + 1] = (0.3, 5.5)
    xy[19 * 31 + 7] = (7.5, 19.55)
    nodes = np.column_stack([xy, np.zeros(len(xy))])
    triangles = Delaunay(xy).simplices
    report = hydraulic_checks(nodes, triangles)
    assert report["min_node_distance_to_edge_m"] == pytest.approx(0.3, abs=1e-12)
