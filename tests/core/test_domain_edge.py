"""The domain edge around data gaps (core.steps.mesh.domain_from_dem, core.outline): straight
runs within the tolerance of the cell-centre outline instead of a staircase of cell edges, and a
mesh that keeps its angle bound along it."""
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS

from floodmesh.core.steps.mesh import (boundary_loops, build_mesh, domain_from_dem, edge_tolerance,
                                       mesh_quality, triangle_areas, user_domain)
from floodmesh.core.raster import Grid

ORIGIN = (500_000.0, 6_000_000.0)
N = 80  # cells each way


def _gappy_dem(d):
    """A plane of N x N cells of d m with no data in a circle (a lake, radius 14 cells) and in a
    diagonal corner (x + y < 25 cells): both rasterise to staircases of cell edges."""
    y, x = (np.mgrid[0:N, 0:N] + 0.5) * d
    z = 10 + 0.02 * x + 0.01 * y
    z[(np.hypot(x - 45 * d, y - 40 * d) < 14 * d) | (x + y < 25 * d)] = np.nan
    return Grid(z, Affine(d, 0, ORIGIN[0], 0, -d, ORIGIN[1] + N * d), CRS.from_epsg(25832))


def _cell_centre_outline(dem):
    """The data as the method sees it, built here from the cells: the squares between four
    valid cell centres."""
    d = dem.cell_size
    valid = np.isfinite(dem.values)
    four = valid[:-1, :-1] & valid[1:, :-1] & valid[:-1, 1:] & valid[1:, 1:]
    rows, cols = np.nonzero(four)
    x0 = dem.transform.c + (cols + 0.5) * d
    y0 = dem.transform.f - (rows + 1.5) * d
    return shapely.union_all(shapely.box(x0, y0, x0 + d, y0 + d))


def _boundary_edges(mesh):
    """(k, 2) vectors of the mesh's boundary edges, m."""
    loops = boundary_loops(mesh.nodes, mesh.triangles)
    pairs = np.concatenate([np.column_stack([loop, np.roll(loop, -1)]) for loop in loops])
    return mesh.nodes[pairs[:, 1], :2] - mesh.nodes[pairs[:, 0], :2]


def _staircase_share(mesh, d):
    """The share of boundary edges that are axis-parallel and shorter than three cells."""
    edges = _boundary_edges(mesh)
    parallel = (np.abs(edges) < 1e-6 * d).any(axis=1)
    return float((parallel & (np.hypot(*edges.T) < 3 * d)).mean())


def _farthest(points_of, geometry, d):
    """Largest distance (m) from the boundary of ``points_of`` (densified) to ``geometry``."""
    xy = shapely.get_coordinates(shapely.segmentize(points_of.boundary, d / 20))
    return float(shapely.distance(shapely.points(xy), geometry).max())


@pytest.mark.parametrize("d", [1.0, 2.0])
def test_the_edge_around_a_lake_and_a_diagonal_corner_has_no_staircase(d):
    dem = _gappy_dem(d)
    mesh = build_mesh(dem, [], domain=domain_from_dem(dem))
    # the cell-centre outline as the domain: the staircase the modeller had to digitise away
    stairs = build_mesh(dem, [], domain=_cell_centre_outline(dem))
    assert _staircase_share(stairs, d) > 0.5
    assert _staircase_share(mesh, d) <= 0.05


@pytest.mark.parametrize("d, tolerance", [(1.0, None), (2.0, None), (1.0, 0.4), (1.0, 5.0)])
def test_the_edge_stays_within_the_tolerance_of_the_data(d, tolerance):
    dem = _gappy_dem(d)
    data = _cell_centre_outline(dem)
    domain = domain_from_dem(dem, tolerance=tolerance)
    allowed = min(d / 2 if tolerance is None else tolerance, d / 2) * (1 + 1e-9)
    assert domain.is_valid and domain.geom_type == "Polygon" and len(domain.interiors) == 1
    assert _farthest(domain, data.boundary, d) <= allowed  # no vertex or edge off the data
    assert _farthest(data, domain.boundary, d) <= allowed  # no stretch of the data cut off
    beyond = domain.difference(data)  # nodes there get z from cells within a cell
    assert beyond.is_empty or _farthest(beyond, data, d) <= allowed
    assert abs(domain.area - data.area) < 0.01 * data.area


@pytest.mark.parametrize("d", [1.0, 2.0])
def test_the_mesh_keeps_its_angle_bound_along_the_edge(d):
    dem = _gappy_dem(d)
    mesh = build_mesh(dem, [], domain=domain_from_dem(dem))
    quality = mesh_quality(mesh, min_angle=25.0, max_area=100.0)
    assert quality["min_angle_deg"] >= 25.0 - 1e-6
    assert quality["n_below_min_angle"] == 0 and quality["n_small_input_angles"] == 0
    assert quality["smallest_input_angle_deg"] >= 60.0
    # no small triangles along the edge: none smaller than along the staircase of cells
    stairs = build_mesh(dem, [], domain=_cell_centre_outline(dem))

    def smallest_at_the_edge(m):
        on_edge = np.zeros(len(m.nodes), bool)
        on_edge[np.concatenate(boundary_loops(m.nodes, m.triangles))] = True
        at_edge = on_edge[m.triangles].any(axis=1)
        return float(np.abs(triangle_areas(m.nodes, m.triangles[at_edge])).min())

    assert smallest_at_the_edge(mesh) >= smallest_at_the_edge(stairs)


def test_a_run_straightens_its_edge_within_its_own_tolerance():
    dem = _gappy_dem(1.0)
    assert edge_tolerance("keep-every", 4, 1.0) == 0.5  # no tolerance given ahead: Δ = d/2
    assert edge_tolerance("douglas-peucker", 0.3, 1.0) == 0.3  # α·Δ as given
    assert edge_tolerance("spline", 0.2, 2.0) == 0.2
    tight = domain_from_dem(dem, tolerance=0.2)
    assert _farthest(tight, _cell_centre_outline(dem).boundary, 1.0) <= 0.2 + 1e-9
    # a user's polygon over the whole DEM is clipped to the same straightened edge
    everything = shapely.box(*np.add(ORIGIN, (-5, -5)), *np.add(ORIGIN, (N + 5, N + 5)))
    assert shapely.equals(user_domain(everything, dem, tolerance=0.2), tight)


def test_areas_enclosed_by_parts_touching_at_corners_are_not_meshed():
    """Two parts that touch at two corners leave a gap that is no part's hole: Triangle reaches
    it from no hole point nor from the hull, so it needs one of its own."""
    u_shape = shapely.union_all([shapely.box(0, 0, 20, 4), shapely.box(0, 0, 4, 20),
                                 shapely.box(16, 0, 20, 20)])
    lid = shapely.box(4, 20, 16, 30)  # touches the U's arms at (4, 20) and (16, 20) only
    domain = shapely.affinity.translate(shapely.MultiPolygon([u_shape, lid]), *ORIGIN)
    assert domain.is_valid
    z = np.full((40, 40), 5.0)
    dem = Grid(z, Affine(1.0, 0, ORIGIN[0] - 5, 0, -1.0, ORIGIN[1] + 35), CRS.from_epsg(25832))
    mesh = build_mesh(dem, [], domain=domain, max_area=4.0)
    centroids = mesh.nodes[mesh.triangles][:, :, :2].mean(axis=1)
    assert shapely.contains_xy(domain, centroids[:, 0], centroids[:, 1]).all()
    assert np.isclose(np.abs(triangle_areas(mesh.nodes, mesh.triangles)).sum(), domain.area)
