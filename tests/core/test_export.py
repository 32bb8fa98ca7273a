"""Solver exports (core.steps.export): boundaries, open sections, materials, and every file
read back by a reader written here from the format's published description (ADCIRC fort.14,
SCHISM hgrid.gr3, TELEMAC Selafin and .cli) or by our own 2DM reader; QGIS's readers (MDAL)
check the 2DM, Selafin and UGRID files in tests/qgis/test_export.py."""
import json
import struct
import subprocess
import sys
from pathlib import Path

import fiona
import numpy as np
import pytest
import shapely
from pyproj import CRS
from scipy.io import netcdf_file

from floodmesh.core.steps import export
from floodmesh.core import io
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.steps.mesh import boundary_loops, triangle_areas
from floodmesh.core.options import RunOptions, parse_formats
from floodmesh.core.chain.pipeline import OUTPUT_FILES, run_pipeline
from floodmesh.core.points import PointCloud

from ..conftest import UTM_ORIGIN, hole_mesh, plane_points, write_export_inputs, write_regions

X0, Y0 = UTM_ORIGIN
UTM32 = CRS.from_epsg(25832)
WEST_LINE = np.array([[X0, Y0 + 10.0], [X0, Y0 + 50.0]])   # an inflow section on the west edge
EAST_LINE = np.array([[X0 + 100.0, Y0 + 5.0], [X0 + 100.0, Y0 + 25.0]])
FLOODMESH = str(Path(sys.executable).parent / "floodmesh")


@pytest.fixture(scope="module")
def mesh():
    return hole_mesh()


def ring_area(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def edges_used_once(triangles):
    """Undirected edges that border exactly one triangle, as a set of sorted pairs."""
    e = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                triangles[:, [2, 0]]]), axis=1)
    pairs, counts = np.unique(e, axis=0, return_counts=True)
    return {tuple(p) for p in pairs[counts == 1].tolist()}


def steps(nodes_seq):
    return {tuple(sorted(p)) for p in zip(nodes_seq[:-1], nodes_seq[1:])}


# ---------------------------------------------------------------------------------------------
# boundary loops
def test_boundary_of_a_small_grid_in_order():
    """A 3 x 3 node grid (8 triangles): one counter-clockwise loop of the 8 rim nodes, from
    node 0, the centre node left out."""
    x, y = np.meshgrid([0.0, 1.0, 2.0], [0.0, 1.0, 2.0])
    nodes = np.column_stack([x.ravel(), y.ravel(), np.zeros(9)])
    tris = []
    for r in range(2):
        for c in range(2):
            a, b, d, e = 3 * r + c, 3 * r + c + 1, 3 * r + c + 3, 3 * r + c + 4
            tris += [[a, b, e], [a, e, d]]
    loops = boundary_loops(nodes, np.array(tris))
    assert len(loops) == 1
    assert loops[0].tolist() == [0, 1, 2, 5, 8, 7, 6, 3]


def test_boundary_of_a_mesh_with_a_hole(mesh):
    """Outer ring first (counter-clockwise, the rectangle's area), then the hole (clockwise,
    minus its area); together they walk every edge used by one triangle exactly once."""
    nodes, tris = mesh
    loops = boundary_loops(nodes, tris)
    assert len(loops) == 2
    outer, hole = loops
    assert ring_area(nodes[outer, :2]) == pytest.approx(100 * 60)
    assert ring_area(nodes[hole, :2]) == pytest.approx(-20 * 20)
    local = nodes[:, :2] - UTM_ORIGIN
    on_rect = np.isclose(local[outer, 0] % 100, 0) | np.isclose(local[outer, 1] % 60, 0)
    assert on_rect.all()
    h = local[hole]
    assert (np.isclose(h[:, 0], 40) | np.isclose(h[:, 0], 60) | np.isclose(h[:, 1], 20)
            | np.isclose(h[:, 1], 40)).all()
    walked = [steps(np.append(loop, loop[0])) for loop in loops]
    assert sum(len(w) for w in walked) == len(edges_used_once(tris))
    assert walked[0] | walked[1] == edges_used_once(tris)
    assert len(np.unique(np.concatenate(loops))) == sum(len(loop) for loop in loops)


def test_boundary_ignores_triangle_orientation(mesh):
    """Clockwise triangles give the same loops as counter-clockwise ones."""
    nodes, tris = mesh
    flipped = tris[:, [0, 2, 1]]
    for a, b in zip(boundary_loops(nodes, tris), boundary_loops(nodes, flipped)):
        np.testing.assert_array_equal(a, b)


def test_boundary_through_a_pinch_node():
    """Two squares touching at one corner: two counter-clockwise loops of four nodes, the shared
    corner in both."""
    nodes = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 1, 0], [2, 2, 0],
                      [1, 2, 0]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3], [2, 4, 5], [2, 5, 6]])
    loops = boundary_loops(nodes, tris)
    assert sorted(len(loop) for loop in loops) == [4, 4]
    assert all(2 in loop for loop in loops)
    assert all(ring_area(nodes[loop, :2]) == pytest.approx(1.0) for loop in loops)


def test_overlapping_triangles_are_refused(mesh):
    nodes, tris = mesh
    with pytest.raises(FloodMeshError, match="overlap"):
        boundary_loops(nodes, np.concatenate([tris, tris[:1]]))


# ---------------------------------------------------------------------------------------------
# open sections
def test_open_section_picks_boundary_nodes_near_the_line(mesh):
    """The west line opens the west-edge nodes within 1 m of it, north to south (the way the
    counter-clockwise ring runs there); land runs from its last node round to its first."""
    nodes, tris = mesh
    boundary = export.mesh_boundary(nodes, tris, [WEST_LINE], snap=1.0)
    opens, lands = boundary.of_kind("open"), boundary.of_kind("land")
    assert len(opens) == 1 and len(lands) == 2           # the outer land and the island
    section = opens[0].nodes
    local = nodes[:, :2] - UTM_ORIGIN
    outer = boundary.loops[0]
    expected = {i for i in outer.tolist()
                if abs(local[i, 0]) < 1e-9 and 9.0 <= local[i, 1] <= 51.0}
    assert set(section.tolist()) == expected and len(expected) >= 3
    assert (np.diff(local[section, 1]) < 0).all()
    land = lands[0]
    assert not land.island and land.nodes[0] == section[-1] and land.nodes[-1] == section[0]
    assert len(section) + len(land.nodes) == len(outer) + 2
    assert lands[1].island and lands[1].closed
    assert boundary.loops[0][0] == section[0]            # numbering starts at the section


def test_two_sections_and_land_between(mesh):
    nodes, tris = mesh
    boundary = export.mesh_boundary(nodes, tris, [WEST_LINE, EAST_LINE], snap=1.0)
    outer = [s for s in boundary.segments if s.loop == 0]
    assert [s.kind for s in outer] == ["open", "land", "open", "land"]
    for a, b in zip(outer, outer[1:] + outer[:1]):
        assert a.nodes[-1] == b.nodes[0]                  # segments join end to end
    walked = set().union(*(steps(s.nodes) for s in outer))
    assert walked == steps(np.append(boundary.loops[0], boundary.loops[0][0]))


def test_a_line_round_the_whole_ring_opens_it_all(mesh):
    nodes, tris = mesh
    ring = np.array([[0, 0], [100, 0], [100, 60], [0, 60], [0, 0]], float) + UTM_ORIGIN
    boundary = export.mesh_boundary(nodes, tris, [ring], snap=0.5)
    first = boundary.segments[0]
    assert first.kind == "open" and first.closed and len(first.nodes) == len(boundary.loops[0])


@pytest.mark.parametrize("case", ["inside", "across"])
def test_a_line_that_touches_no_boundary_is_refused(mesh, case):
    """A line inside the mesh, and a line crossing the west edge right at one boundary node
    (one node makes no section), are refused."""
    nodes, tris = mesh
    local = nodes[:, :2] - UTM_ORIGIN
    if case == "inside":
        line = np.array([[30.0, 10.0], [30.0, 15.0]]) + UTM_ORIGIN
    else:
        west = [i for i in boundary_loops(nodes, tris)[0]
                if abs(local[i, 0]) < 1e-9 and 5 < local[i, 1] < 55]
        y = local[west[0], 1]
        line = np.array([[-5.0, y], [5.0, y]]) + UTM_ORIGIN
        d = shapely.distance(shapely.points(nodes[boundary_loops(nodes, tris)[0], :2]),
                             shapely.LineString(line))
        assert (d <= 0.2).sum() == 1
    with pytest.raises(FloodMeshError, match="fewer than two nodes.*snapping distance"):
        export.mesh_boundary(nodes, tris, [line], snap=0.2)


# ---------------------------------------------------------------------------------------------
# materials
def test_regions_set_material_ids_by_centroid(mesh):
    nodes, tris = mesh
    west = shapely.box(X0, Y0, X0 + 30, Y0 + 60)
    corner = shapely.box(X0, Y0, X0 + 10, Y0 + 10)
    mats = export.region_materials(nodes, tris, [(west, 5), (corner, 9)],
                                   np.ones(len(tris), np.int64))
    cx = nodes[tris][:, :, 0].mean(axis=1) - X0
    cy = nodes[tris][:, :, 1].mean(axis=1) - Y0
    expected = np.where((cx < 10) & (cy < 10), 9, np.where(cx < 30, 5, 1))
    np.testing.assert_array_equal(mats, expected)
    assert set(np.unique(mats)) == {1, 5, 9}


def test_region_layer_with_and_without_a_field(tmp_path):
    path = tmp_path / "regions.gpkg"
    write_regions(path, [(shapely.box(X0, Y0, X0 + 10, Y0 + 10), 7),
                         (shapely.box(X0 + 50, Y0, X0 + 60, Y0 + 10), 3)])
    assert [m for _, m in io.read_regions(path, field="mat")] == [7, 3]
    assert [m for _, m in io.read_regions(path)] == [2, 3]
    with pytest.raises(FloodMeshError, match="no field 'nope'.*mat, label"):
        io.read_regions(path, field="nope")
    with pytest.raises(FloodMeshError, match="whole numbers"):
        io.read_regions(path, field="label")


# ---------------------------------------------------------------------------------------------
# SMS 2DM
def test_2dm_round_trip_with_materials_node_strings_and_element_elevations(mesh, tmp_path):
    """Our 2DM reader gives back the nodes (+ datum offset), triangles, material ids, element
    centre elevations and node strings (each boundary loop closed, then the open section)."""
    nodes, tris = mesh
    path = tmp_path / "mesh.2dm"
    regions = [(shapely.box(X0, Y0, X0 + 30, Y0 + 60), 4)]
    export.export_mesh(path, nodes, tris, open_lines=[WEST_LINE], regions=regions,
                       datum_offset=0.5, element_elevations=True)
    back = io.read_2dm(path)
    np.testing.assert_allclose(back.nodes[:, :2], nodes[:, :2], atol=0.5e-4)
    np.testing.assert_allclose(back.nodes[:, 2], nodes[:, 2] + 0.5, atol=0.5e-4)
    ccw = np.where((triangle_areas(nodes, tris) < 0)[:, None], tris[:, [0, 2, 1]], tris)
    np.testing.assert_array_equal(back.triangles, ccw)
    cx = nodes[tris][:, :, 0].mean(axis=1) - X0
    np.testing.assert_array_equal(back.materials, np.where(cx < 30, 4, 1))
    np.testing.assert_allclose(back.element_z, nodes[tris, 2].mean(axis=1) + 0.5, atol=0.5e-4)
    boundary = export.mesh_boundary(nodes, tris, [WEST_LINE])
    assert len(back.node_strings) == 3
    for string, loop in zip(back.node_strings, boundary.loops):
        np.testing.assert_array_equal(string, np.append(loop, loop[0]))
    np.testing.assert_array_equal(back.node_strings[2], boundary.of_kind("open")[0].nodes)
    text = path.read_text().splitlines()
    assert text[:2] == ["MESH2D", "NUM_MATERIALS_PER_ELEM 2"]
    ns = [line.split() for line in text if line.startswith("NS")]
    assert all(len(parts) <= 12 for parts in ns)
    ends = [parts for parts in ns if any(int(v) < 0 for v in parts[1:])]
    assert [int(parts[-1]) for parts in ends] == [1, 2, 3]   # the string's number follows


def test_2dm_without_element_elevations_has_one_material_column(mesh, tmp_path):
    nodes, tris = mesh
    path = tmp_path / "mesh.2dm"
    export.export_mesh(path, nodes, tris)
    lines = path.read_text().splitlines()
    assert lines[1] == "NUM_MATERIALS_PER_ELEM 1"
    assert all(len(line.split()) == 6 for line in lines if line.startswith("E3T"))
    back = io.read_2dm(path)
    assert back.element_z is None and (back.materials == 1).all()


# ---------------------------------------------------------------------------------------------
# TELEMAC: Selafin and .cli, read by a reader written from the Selafin description
def read_selafin(path):
    """Selafin as documented (TELEMAC-2D user manual, appendix 'Selafin format'): big-endian
    Fortran records (length, data, length); reals are 4 bytes for SERAFIN, 8 for SERAFIND."""
    data = Path(path).read_bytes()
    pos = 0

    def record():
        nonlocal pos
        (size,) = struct.unpack(">i", data[pos:pos + 4])
        body = data[pos + 4:pos + 4 + size]
        assert struct.unpack(">i", data[pos + 4 + size:pos + 8 + size])[0] == size
        pos += size + 8
        return body

    title = record().decode()
    real = ">f8" if title[72:80] == "SERAFIND" else ">f4"
    nbv1, nbv2 = np.frombuffer(record(), ">i4")
    names = [record().decode() for _ in range(nbv1 + nbv2)]
    iparam = np.frombuffer(record(), ">i4")
    if iparam[9] == 1:
        record()
    nelem, npoin, ndp, _ = np.frombuffer(record(), ">i4")
    ikle = np.frombuffer(record(), ">i4").reshape(nelem, ndp)
    ipobo = np.frombuffer(record(), ">i4")
    x, y = np.frombuffer(record(), real), np.frombuffer(record(), real)
    steps_ = []
    while pos < len(data):
        time = np.frombuffer(record(), real)[0]
        steps_.append((time, [np.frombuffer(record(), real) for _ in names]))
    return dict(title=title, names=names, iparam=iparam, ikle=ikle, ipobo=ipobo, x=x, y=y,
                steps=steps_)


def read_cli(path):
    rows = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    assert all(len(r) == 13 for r in rows)
    return rows


def test_selafin_and_cli(mesh, tmp_path):
    """Double precision X, Y (UTM centimetres survive), BOTTOM = z + offset, 1-based IKLE, and a
    boundary numbering IPOBO that the .cli follows line by line: K = 1, 2, … and IPOBO(N) = K;
    open-section nodes free (4 4 4), the rest solid walls (2 2 2)."""
    nodes, tris = mesh
    path = tmp_path / "geo.slf"
    written = export.export_mesh(path, nodes, tris, open_lines=[WEST_LINE], datum_offset=-2.0,
                                 title="river reach")
    assert written == [path, tmp_path / "geo.cli"]
    slf = read_selafin(path)
    assert slf["title"].startswith("river reach") and slf["title"].endswith("SERAFIND")
    assert slf["names"] == ["BOTTOM          M               "]
    np.testing.assert_array_equal(slf["ikle"], tris + 1)
    np.testing.assert_array_equal(slf["x"], nodes[:, 0])
    np.testing.assert_array_equal(slf["y"], nodes[:, 1])
    assert len(slf["steps"]) == 1 and slf["steps"][0][0] == 0.0
    np.testing.assert_allclose(slf["steps"][0][1][0], nodes[:, 2] - 2.0, rtol=0, atol=1e-12)
    ipobo = slf["ipobo"]
    n_boundary = len(edges_used_once(tris))         # one boundary node per boundary edge
    assert ipobo.max() == n_boundary and (ipobo > 0).sum() == n_boundary
    rows = read_cli(tmp_path / "geo.cli")
    assert [int(r[12]) for r in rows] == list(range(1, n_boundary + 1))
    for r in rows:
        assert ipobo[int(r[11]) - 1] == int(r[12])
    boundary = export.mesh_boundary(nodes, tris, [WEST_LINE])
    open_nodes = set((boundary.of_kind("open")[0].nodes + 1).tolist())
    for r in rows:
        codes = (r[0], r[1], r[2], r[7])
        assert codes == (("4",) * 4 if int(r[11]) in open_nodes else ("2",) * 4)
    assert sum(int(r[11]) in open_nodes for r in rows) == len(open_nodes) >= 3
    # numbering follows the boundary: consecutive K are neighbours along a boundary edge
    by_k = np.argsort(ipobo[ipobo > 0])
    numbered = np.nonzero(ipobo > 0)[0][by_k]
    loops = boundary_loops(nodes, tris)
    outer = numbered[:len(loops[0])]
    assert steps(np.append(outer, outer[0])) <= edges_used_once(tris)


# ---------------------------------------------------------------------------------------------
# ADCIRC fort.14 and SCHISM hgrid.gr3, read by a parser written from ADCIRC's description
def read_fort14(path):
    """fort.14 as the ADCIRC manual lays it out: AGRID; NE NP; NP lines JN X Y DP; NE lines
    JE NHY NM1 NM2 NM3; NOPE; NETA; per open segment NVDLL [IBTYPEE] and NVDLL node lines;
    NBOU; NVEL; per flow segment NVELL IBTYPE and NVELL node lines. Numbers are read
    list-directed: the leading values of a line, anything after them ignored."""
    lines = iter(Path(path).read_text().splitlines())

    def ints(count):
        values = next(lines).replace(",", " ").split()
        return [int(v) for v in values[:count]]

    grid = {"agrid": next(lines)}
    ne, np_ = ints(2)
    table = [next(lines).split() for _ in range(np_)]
    grid["jn"] = [int(r[0]) for r in table]
    grid["xyd"] = np.array([[float(v) for v in r[1:4]] for r in table])
    grid["elements"] = np.array([ints(5) for _ in range(ne)])
    nope, = ints(1)
    neta, = ints(1)
    grid["open"] = []
    for _ in range(nope):
        head = next(lines).split()
        grid["open"].append([ints(1)[0] for _ in range(int(head[0]))])
    nbou, = ints(1)
    nvel, = ints(1)
    grid["land"] = []
    for _ in range(nbou):
        nvell, ibtype = ints(2)
        grid["land"].append((ibtype, [ints(1)[0] for _ in range(nvell)]))
    grid["neta_ok"] = neta == sum(map(len, grid["open"]))
    grid["nvel_ok"] = nvel == sum(len(n) for _, n in grid["land"])
    grid["rest"] = [line for line in lines if line.strip()]
    return grid


@pytest.mark.parametrize("fmt", ["14", "gr3"])
def test_fort14_and_gr3_read_back(mesh, tmp_path, fmt):
    """Depth is minus (elevation + datum offset); elements and nodes as given; counts NETA and
    NVEL add up; the open segment is the west section; open and land segments together walk
    every boundary edge once; ADCIRC closes the island (first node repeated, IBTYPE 21, the
    mainland 20), SCHISM does not (flags 0 and 1)."""
    nodes, tris = mesh
    path = tmp_path / f"grid.{fmt}"
    export.export_mesh(path, nodes, tris, open_lines=[WEST_LINE], datum_offset=1.25)
    grid = read_fort14(path)
    n, m = len(nodes), len(tris)
    assert grid["jn"] == list(range(1, n + 1)) and grid["rest"] == []
    np.testing.assert_allclose(grid["xyd"][:, :2], nodes[:, :2], atol=0.5e-4)
    np.testing.assert_allclose(grid["xyd"][:, 2], -(nodes[:, 2] + 1.25), atol=0.5e-4)
    assert (grid["xyd"][:, 2] < 0).all()                   # dry land above the datum
    np.testing.assert_array_equal(grid["elements"][:, 0], np.arange(1, m + 1))
    assert (grid["elements"][:, 1] == 3).all()
    np.testing.assert_array_equal(grid["elements"][:, 2:] - 1, tris)
    assert grid["neta_ok"] and grid["nvel_ok"]
    boundary = export.mesh_boundary(nodes, tris, [WEST_LINE])
    assert len(grid["open"]) == 1
    np.testing.assert_array_equal(np.array(grid["open"][0]) - 1, boundary.of_kind("open")[0].nodes)
    (main_type, main), (island_type, island) = grid["land"]
    assert main[0] == grid["open"][0][-1] and main[-1] == grid["open"][0][0]
    if fmt == "14":
        assert (main_type, island_type) == (20, 21) and island[0] == island[-1]
        island_steps = steps(np.array(island) - 1)
    else:
        assert (main_type, island_type) == (0, 1) and island[0] != island[-1]
        island_steps = steps(np.append(island, island[0]) - 1)
    walked = [steps(np.array(grid["open"][0]) - 1), steps(np.array(main) - 1), island_steps]
    assert sum(len(w) for w in walked) == len(edges_used_once(tris))
    assert set().union(*walked) == edges_used_once(tris)


@pytest.mark.parametrize("fmt", ["14", "gr3"])
def test_all_land_boundary(mesh, tmp_path, fmt):
    """No open section: ADCIRC gets one mainland segment closed by repeating its first node;
    SCHISM, which wants no closed exterior segment, two land segments linked end to end."""
    nodes, tris = mesh
    path = tmp_path / f"grid.{fmt}"
    export.export_mesh(path, nodes, tris)
    grid = read_fort14(path)
    assert grid["open"] == [] and grid["nvel_ok"]
    outer = boundary_loops(nodes, tris)[0] + 1
    if fmt == "14":
        assert [t for t, _ in grid["land"]] == [20, 21]
        assert grid["land"][0][1] == np.append(outer, outer[0]).tolist()
    else:
        (t1, a), (t2, b), (t3, _) = grid["land"]
        assert (t1, t2, t3) == (0, 0, 1)
        assert a[-1] == b[0] and b[-1] == a[0] and a[:-1] + b[:-1] == outer.tolist()


# ---------------------------------------------------------------------------------------------
# UGRID netCDF
def test_ugrid_netcdf(mesh, tmp_path):
    """UGRID-1.0 topology with node x/y/z, 1-based face and edge connectivity (Euler: E = V + F
    - 1 + holes) and a CRS variable naming EPSG:25832 in the attributes MDAL and D-Flow FM
    read."""
    nodes, tris = mesh
    path = tmp_path / "mesh_net.nc"
    export.export_mesh(path, nodes, tris, crs="EPSG:25832", datum_offset=0.3)
    with netcdf_file(path, "r", mmap=False) as nc:
        v = nc.variables
        topo = v["mesh2d"]
        assert topo.cf_role == b"mesh_topology" and topo.topology_dimension == 2
        assert topo.node_coordinates == b"mesh2d_node_x mesh2d_node_y"
        faces = v[topo.face_node_connectivity.decode()]
        assert faces.start_index == 1 and faces._FillValue == -999
        np.testing.assert_array_equal(faces[:] - 1, tris)
        np.testing.assert_array_equal(v["mesh2d_node_x"][:], nodes[:, 0])
        np.testing.assert_array_equal(v["mesh2d_node_y"][:], nodes[:, 1])
        z = v["mesh2d_node_z"]
        assert (z.standard_name, z.mesh, z.location) == (b"altitude", b"mesh2d", b"node")
        np.testing.assert_allclose(z[:], nodes[:, 2] + 0.3, rtol=0, atol=1e-12)
        edges = v[topo.edge_node_connectivity.decode()][:]
        assert len(edges) == len(nodes) + len(tris) - 1 + 1
        assert {tuple(e) for e in (np.sort(edges, axis=1) - 1).tolist()} >= edges_used_once(tris)
        gm = v[v["mesh2d_node_x"].grid_mapping.decode()]
        assert gm.epsg == 25832 and gm.EPSG_code == b"EPSG:25832"
        assert CRS.from_wkt(gm.wkt.decode()) == UTM32
        assert gm.grid_mapping_name == b"transverse_mercator"
        # the two dummy scalars are written, not left as whatever memory scipy had
        assert topo.getValue() == 0 and gm.getValue() == 0
    again = tmp_path / "again_net.nc"
    export.export_mesh(again, nodes, tris, crs="EPSG:25832", datum_offset=0.3)
    assert again.read_bytes() == path.read_bytes()


def test_netcdf_and_gpkg_need_a_crs(mesh, tmp_path):
    nodes, tris = mesh
    for name in ("mesh.nc", "mesh.gpkg"):
        with pytest.raises(FloodMeshError, match="--crs"):
            export.export_mesh(tmp_path / name, nodes, tris)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# GeoPackage
def test_geopackage_layers(mesh, tmp_path):
    """triangles (PolygonZ, with material), nodes (PointZ, id and z), boundary (LineStringZ,
    open/land) and breaklines, each in the mesh's CRS."""
    nodes, tris = mesh
    path = tmp_path / "mesh.gpkg"
    line = np.array([[X0 + 5, Y0 + 5, 11.0], [X0 + 20, Y0 + 30, 12.0]])
    export.export_mesh(path, nodes, tris, crs=UTM32, open_lines=[WEST_LINE], breaklines=[line],
                       regions=[(shapely.box(X0, Y0, X0 + 30, Y0 + 60), 3)])
    assert fiona.listlayers(path) == ["triangles", "nodes", "boundary", "breaklines"]
    expected = {"triangles": ("3D Polygon", len(tris)), "nodes": ("3D Point", len(nodes)),
                "boundary": ("3D LineString", 3), "breaklines": ("3D LineString", 1)}
    for layer, (geometry, count) in expected.items():
        with fiona.open(path, layer=layer) as src:
            assert src.schema["geometry"] == geometry and len(src) == count
            assert CRS.from_wkt(src.crs_wkt) == UTM32
    with fiona.open(path, layer="nodes") as src:
        feats = list(src)
    assert [f["properties"]["id"] for f in feats] == list(range(1, len(nodes) + 1))
    np.testing.assert_allclose([f["properties"]["z"] for f in feats], nodes[:, 2])
    with fiona.open(path, layer="boundary") as src:
        kinds = [f["properties"]["kind"] for f in src]
    assert kinds == ["open", "land", "land"]
    with fiona.open(path, layer="triangles") as src:
        mats = {f["properties"]["material"] for f in src}
    assert mats == {1, 3}


# ---------------------------------------------------------------------------------------------
# every format: same input, same bytes; formats by name and extension
def test_same_input_gives_identical_files(mesh, tmp_path):
    nodes, tris = mesh
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        export.export_formats(tmp_path / run / "mesh", nodes, tris, "2dm,slf,14,gr3,nc",
                              crs="EPSG:25832", open_lines=[WEST_LINE], element_elevations=True)
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert names == ["mesh.14", "mesh.2dm", "mesh.cli", "mesh.gr3", "mesh.nc", "mesh.prj",
                     "mesh.slf"]
    for name in names:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_format_names_and_extensions():
    assert parse_formats("2dm, SLF,.nc,2dm") == ("2dm", "slf", "nc")
    assert export.format_of("out/fort.14") == "14" and export.format_of("hgrid.gr3") == "gr3"
    assert export.format_of("x.txt", "gpkg") == "gpkg"
    with pytest.raises(FloodMeshError, match="unknown mesh format 'msh'.*2dm, slf, 14, gr3, nc"):
        parse_formats("2dm,msh")
    with pytest.raises(FloodMeshError, match=r"extension '\.msh'.*\.2dm \.slf \.14 \.gr3 \.nc"):
        export.format_of("mesh.msh")
    with pytest.raises(FloodMeshError, match="unknown mesh format"):
        RunOptions(formats=("selafin",))


def test_a_failed_export_leaves_no_file(mesh, tmp_path):
    """A mesh node in no triangle is refused before anything is written."""
    nodes, tris = mesh
    extra = np.vstack([nodes, [X0 + 200, Y0, 0.0]])
    with pytest.raises(FloodMeshError, match="1 mesh nodes belong to no triangle"):
        export.export_mesh(tmp_path / "mesh.slf", extra, tris)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# command line and the whole chain
def floodmesh(*args):
    return subprocess.run([FLOODMESH, *map(str, args)], capture_output=True, text=True,
                          timeout=300)


@pytest.fixture
def mesh_files(tmp_path):
    write_export_inputs(tmp_path, material=6)
    return tmp_path


def test_export_command(mesh, mesh_files):
    """floodmesh export: the format from the extension, open boundaries and regions from
    layers (their CRS taken for the netCDF file), --format forcing a format."""
    t = mesh_files
    nodes, tris = mesh
    run = floodmesh("export", t / "mesh.2dm", t / "out.2dm", "--open-boundaries", t / "open.gpkg",
                    "--regions", t / "regions.gpkg", "--material-field", "mat")
    assert run.returncode == 0, run.stderr
    back = io.read_2dm(t / "out.2dm")
    assert set(np.unique(back.materials)) == {1, 6} and len(back.node_strings) == 3
    run = floodmesh("export", t / "mesh.2dm", t / "out.nc", "--open-boundaries", t / "open.gpkg")
    assert run.returncode == 0, run.stderr
    with netcdf_file(t / "out.nc", "r", mmap=False) as nc:
        assert nc.variables["projected_coordinate_system"].epsg == 25832
    run = floodmesh("export", t / "mesh.2dm", t / "hgrid", "--format", "gr3", "--datum-offset", 2)
    assert run.returncode == 0, run.stderr
    grid = read_fort14(t / "hgrid")
    np.testing.assert_allclose(grid["xyd"][:, 2], -(nodes[:, 2] + 2), atol=0.5e-4)


def test_export_takes_the_crs_from_the_meshs_prj_sidecar(mesh, mesh_files, tmp_path):
    """A 2DM has no CRS: write_mesh_2dm puts it into mesh.prj, read_2dm returns it, and the
    export of a CRS-carrying format needs no --crs then."""
    t = mesh_files
    nodes, tris = mesh
    io.write_mesh_2dm(tmp_path / "own.2dm", nodes, tris, crs=UTM32)
    assert CRS.from_wkt(io.read_2dm(tmp_path / "own.2dm").crs).to_epsg() == 25832
    assert (tmp_path / "own.prj").is_file()
    run = floodmesh("export", tmp_path / "own.2dm", t / "out.nc")
    assert run.returncode == 0, run.stderr
    with netcdf_file(t / "out.nc", "r", mmap=False) as nc:
        assert nc.variables["projected_coordinate_system"].epsg == 25832
    assert io.read_2dm(t / "mesh.2dm").crs is None  # no sidecar: as before


@pytest.mark.parametrize("args, words", [
    (["{t}/mesh.2dm", "{t}/out.msh"], "extension '.msh'"),
    (["{t}/mesh.2dm", "{t}/out.2dm", "--format", "telemac"], "unknown mesh format 'telemac'"),
    (["{t}/regions.gpkg", "{t}/out.slf"], "not an SMS 2DM mesh"),
    (["{t}/missing.2dm", "{t}/out.slf"], "does not exist"),
    (["{t}/mesh.2dm", "{t}/out.nc"], "--crs"),
    (["{t}/mesh.2dm", "{t}/out.slf", "--open-boundaries", "{t}/open.gpkg", "--snap", "0.5",
      "--crs", "EPSG:25832", "--regions", "{t}/far.gpkg"], "far.gpkg does not exist"),
])
def test_export_command_errors_are_one_line(mesh_files, args, words):
    t = mesh_files
    run = floodmesh("export", *[a.format(t=t) for a in args])
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("floodmesh: error:") and words in lines[0]
    assert not any(p.name.startswith("out") for p in t.iterdir())


def test_export_command_refuses_a_line_off_the_boundary(mesh_files):
    t = mesh_files
    io.write_lines_gpkg(t / "inside.gpkg", [np.array([[X0 + 30, Y0 + 10, 0], [X0 + 30, Y0 + 15, 0]])],
                        UTM32, layer="open")
    run = floodmesh("export", t / "mesh.2dm", t / "out.slf", "--open-boundaries", t / "inside.gpkg")
    assert run.returncode == 2
    assert "open boundary line 1 touches the mesh boundary at fewer than two nodes" in run.stderr
    assert not (t / "out.slf").exists() and not (t / "out.cli").exists()


def test_run_writes_the_formats_beside_mesh_2dm(tmp_path):
    """run_pipeline with formats writes mesh.<ext> for each (mesh.cli with mesh.slf), all with
    the mesh's node and triangle counts, and report.json lists every file."""
    points = PointCloud(plane_points(size=40.0, density=2.0), UTM32)
    src = tmp_path / "plane.laz"
    io.write_points_las(src, points)
    out = tmp_path / "out"
    report = run_pipeline(src, out, RunOptions(holdout=0.02, formats=("2dm", "slf", "14", "gr3",
                                                                      "nc", "gpkg")))
    names = {p.name for p in out.iterdir()}
    exported = {"mesh.slf", "mesh.cli", "mesh.14", "mesh.gr3", "mesh.nc"}
    assert names == set(OUTPUT_FILES) | exported
    assert set(json.loads((out / "report.json").read_text())["files"]) == names
    n, m = report["nodes"], report["triangles"]
    back = io.read_2dm(out / "mesh.2dm")
    assert (len(back.nodes), len(back.triangles)) == (n, m) and len(back.node_strings) == 1
    slf = read_selafin(out / "mesh.slf")
    assert (len(slf["x"]), len(slf["ikle"])) == (n, m)
    grid = read_fort14(out / "mesh.14")
    assert (len(grid["jn"]), len(grid["elements"])) == (n, m)
    layers = {"triangles", "nodes", "boundary"} | ({"breaklines"} if report["n_breaklines"]
                                                   else set())
    assert set(fiona.listlayers(out / "mesh.gpkg")) == layers
    with fiona.open(out / "mesh.gpkg", layer="triangles") as src_:
        assert len(src_) == m and {"area_m2", "min_angle_deg"} <= set(src_.schema["properties"])
    assert triangle_areas(back.nodes, back.triangles).min() > 0


def test_run_command_formats_option(tmp_path):
    xyz = tmp_path / "points.xyz"
    np.savetxt(xyz, plane_points(size=30.0, density=2.0), fmt="%.3f")
    bad = floodmesh("run", xyz, "--out", tmp_path / "bad", "--crs", "EPSG:25832",
                    "--formats", "2dm,fem")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "unknown mesh format 'fem'" in bad.stderr
    good = floodmesh("run", xyz, "--out", tmp_path / "out", "--crs", "EPSG:25832",
                     "--formats", "gr3,nc", "--holdout", 0.05)
    assert good.returncode == 0, good.stderr
    assert (tmp_path / "out" / "mesh.gr3").is_file() and (tmp_path / "out" / "mesh.nc").is_file()
    assert not (tmp_path / "out" / "mesh.slf").exists()


def test_every_format_is_written_in_spatial_order(demo_points_file, tmp_path):
    """A mesh refined through break lines and a size field comes out of Triangle numbered all
    over the domain; a solver sweeps triangles and their neighbours each time step, so every
    file numbers nodes and triangles along the ground: a triangle's nodes lie close in the
    node list (on the demo their index spread was 30 % of the nodes, 2.4 % in order)."""
    out = tmp_path / "out"
    report = run_pipeline(demo_points_file, out, RunOptions(formats=("2dm", "slf", "14", "nc")))
    n = report["nodes"]
    spread = lambda t: float(np.mean(t.max(axis=1) - t.min(axis=1)))  # noqa: E731
    with netcdf_file(out / "mesh.nc", mmap=False) as nc:
        ugrid = np.array(nc.variables["mesh2d_face_nodes"][:], np.int64) - 1
    triangles = {"2dm": io.read_2dm(out / "mesh.2dm").triangles,
                 "slf": read_selafin(out / "mesh.slf")["ikle"] - 1,
                 "14": read_fort14(out / "mesh.14")["elements"][:, 2:] - 1, "nc": ugrid}
    for fmt, t in triangles.items():
        assert len(t) == report["triangles"] and spread(t) < 0.06 * n, (fmt, spread(t) / n)
    # and the triangles follow one another along the ground: consecutive centres are close
    nodes = io.read_2dm(out / "mesh.2dm").nodes
    centres = nodes[triangles["2dm"]][:, :, :2].mean(axis=1)
    step = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert np.median(step) < 2 * np.sqrt(np.median(triangle_areas(nodes, triangles["2dm"])))


def test_export_of_2d_break_lines_gives_them_the_mesh_z_and_says_a_crs_over_the_prj(tmp_path):
    """`floodmesh export MESH x.gpkg --breaklines L` with a 2-D line layer (as drawn in QGIS):
    HEC-RAS takes the lines' z as terrain, so each vertex gets the mesh's TIN z there (they
    were NaN). And --crs over a mesh whose .prj names another CRS is said in a note."""
    from floodmesh.core.steps.accuracy import tin_elevation
    from floodmesh.core.steps.mesh import Mesh

    nodes, tris = write_export_inputs(tmp_path, 2)
    io.write_prj(tmp_path / "mesh.prj", UTM32)
    x0, y0 = UTM_ORIGIN
    drawn = np.array([[x0 + 5, y0 + 5], [x0 + 20, y0 + 30], [x0 + 45, y0 + 53]])
    with fiona.open(tmp_path / "drawn.gpkg", "w", driver="GPKG", crs=UTM32.to_wkt(),
                    schema={"geometry": "LineString", "properties": {}}) as dst:
        dst.write({"geometry": {"type": "LineString", "coordinates": drawn.tolist()},
                   "properties": {}})
    out = tmp_path / "out.gpkg"
    result = subprocess.run([FLOODMESH, "export", tmp_path / "mesh.2dm", out, "--breaklines",
                             tmp_path / "drawn.gpkg"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    with fiona.open(out, layer="breaklines") as src:
        written = np.array(next(iter(src))["geometry"]["coordinates"])
    want = tin_elevation(Mesh(nodes, tris, UTM32), drawn[:, 0], drawn[:, 1])
    assert np.isfinite(want).all()
    np.testing.assert_allclose(written[:, 2], want, atol=1e-3)  # the 2DM keeps 0.1 mm

    other = subprocess.run([FLOODMESH, "export", tmp_path / "mesh.2dm", tmp_path / "o.gpkg",
                            "--crs", "EPSG:25833"], capture_output=True, text=True)
    assert other.returncode == 0, other.stderr
    assert "mesh mesh.2dm is in ETRS89 / UTM zone 32N, but the CRS given is used" in other.stderr
