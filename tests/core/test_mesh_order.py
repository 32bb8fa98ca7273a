"""The mesh numbered for a solver (issue 28, item 5): ``build_mesh`` hands back Triangle's mesh
renumbered along the ground (``in_spatial_order``: triangles in Z order of their centres, nodes
as the triangles first use them), the same mesh, with neighbours close in the node and
triangle lists, and the files carry that order."""
import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.chain.pipeline import run_pipeline
from floodmesh.core.options import RunOptions
from floodmesh.core.raster import Grid
from floodmesh.core.steps import mesh as mesh_step
from floodmesh.core.steps.mesh import in_spatial_order, triangle_areas
from floodmesh.core.steps.refine import refine_mesh


@pytest.fixture(scope="module")
def demo_run(demo_points_file, tmp_path_factory):
    """The demo run's folder and each mesh ``build_mesh`` made in it: (Triangle's numbering,
    the numbering delivered)."""
    out = tmp_path_factory.mktemp("order") / "out"
    made = []

    def recorded(mesh):
        made.append((mesh, in_spatial_order(mesh)))
        return made[-1][1]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mesh_step, "in_spatial_order", recorded)
        run_pipeline(demo_points_file, out, RunOptions(formats=("2dm",)))
    return out, made


def edge_gaps(triangles):
    """|i - j| (in the node list) over the mesh's edges, each edge once."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    edges = np.unique(edges, axis=0)
    return edges[:, 1] - edges[:, 0]


def neighbour_gaps(triangles):
    """|i - j| (in the triangle list) over pairs of triangles that share an edge."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(triangles)), 3)
    order = np.lexsort(edges.T[::-1])
    edges, owner = edges[order], owner[order]
    shared = np.flatnonzero((edges[1:] == edges[:-1]).all(axis=1))
    return np.abs(owner[shared + 1] - owner[shared])


def as_rings(nodes, triangles):
    """Each triangle as its corners' (x, y) in their order, from the lowest corner: the same
    set for the same triangles in the same orientation, however numbered."""
    rings = set()
    for ring in np.round(nodes[triangles][:, :, :2], 6).tolist():
        start = ring.index(min(ring))
        rings.add(tuple(map(tuple, ring[start:] + ring[:start])))
    return rings


def test_the_numbered_mesh_is_the_mesh_triangle_made(demo_run):
    """Same triangles (as corner coordinates, counter-clockwise), same input segments, same
    elevation at every node, no node lost; the numbering is the one ``build_mesh`` returns."""
    _, made = demo_run
    assert made
    for raw, ordered in made:
        assert len(ordered.nodes) == len(raw.nodes)
        assert len(ordered.triangles) == len(raw.triangles)
        assert as_rings(ordered.nodes, ordered.triangles) == as_rings(raw.nodes, raw.triangles)
        assert triangle_areas(ordered.nodes, ordered.triangles).min() > 0
        pairs = lambda m: {frozenset(map(tuple, np.round(m.nodes[s, :2], 6).tolist()))  # noqa: E731
                           for s in m.segments}
        assert len(ordered.segments) == len(raw.segments) and pairs(ordered) == pairs(raw)
        z = lambda m: dict(zip(map(tuple, np.round(m.nodes[:, :2], 6).tolist()),  # noqa: E731
                               m.nodes[:, 2]))
        assert z(ordered) == z(raw)
        again = in_spatial_order(ordered)  # the order depends on the geometry only
        np.testing.assert_array_equal(again.nodes, ordered.nodes)
        np.testing.assert_array_equal(again.triangles, ordered.triangles)
        np.testing.assert_array_equal(again.segments, ordered.segments)


def test_neighbours_lie_close_in_the_node_and_triangle_lists(demo_run):
    """On the demo the mean node-index gap over edges was 373 in Triangle's numbering and 30
    in order (node bandwidth 1,734 and 708 of 1,847 nodes), the mean triangle-index gap
    between neighbours 679 and 34: at least five times closer, both."""
    _, made = demo_run
    raw, ordered = made[-1]
    assert edge_gaps(ordered.triangles).mean() < edge_gaps(raw.triangles).mean() / 5
    assert neighbour_gaps(ordered.triangles).mean() < neighbour_gaps(raw.triangles).mean() / 5
    assert edge_gaps(ordered.triangles).max() < edge_gaps(raw.triangles).max()
    # and three neighbours in four within 8 places of each other (Triangle's: one in six)
    assert (neighbour_gaps(ordered.triangles) <= 8).mean() > 0.6


def test_the_2dm_is_written_in_that_order(demo_run):
    """mesh.2dm, read back, holds the nodes and triangles in the order ``build_mesh`` gave
    them (the node elevations are the terrain fit's, written after)."""
    out, made = demo_run
    back = io.read_2dm(out / "mesh.2dm")
    written = [ordered for _, ordered in made if len(ordered.triangles) == len(back.triangles)
               and np.array_equal(ordered.triangles, back.triangles)]
    assert written, "mesh.2dm's triangles are in no order build_mesh returned"
    np.testing.assert_allclose(back.nodes[:, :2], written[-1].nodes[:, :2], atol=1e-3)
    assert edge_gaps(back.triangles).mean() < 0.05 * len(back.nodes)


def test_the_refined_mesh_is_in_order_too():
    """Refinement meshes again each round (``build_mesh`` with the points it inserts): the mesh
    it returns is numbered along the ground as well (ordering it again changes nothing)."""
    x0, y0 = 500_000.0, 6_000_000.0
    centres = np.arange(80) + 0.5
    cx, cy = np.meshgrid(x0 + centres, y0 + 80 - centres)
    dem = Grid(10 + 2 * np.exp(-((cx - x0 - 40) ** 2 + (cy - y0 - 40) ** 2) / 200),
               Affine(1, 0, x0, 0, -1, y0 + 80), CRS.from_epsg(25832))
    xy = np.random.default_rng(0).uniform([x0 + 1, y0 + 1], [x0 + 79, y0 + 79], (3000, 2))
    points = np.column_stack([xy, 10 + 2 * np.exp(-((xy - [x0 + 40, y0 + 40]) ** 2).sum(1) / 200)])
    mesh, rounds = refine_mesh(dem, [], points, min_angle=25, max_area=100, lower=0.02,
                               upper=0.05, max_rounds=3)
    assert len(rounds) >= 2 and rounds[-1].nodes > rounds[0].nodes
    again = in_spatial_order(mesh)
    np.testing.assert_array_equal(again.nodes, mesh.nodes)
    np.testing.assert_array_equal(again.triangles, mesh.triangles)
    assert edge_gaps(mesh.triangles).mean() < 0.05 * len(mesh.nodes)
