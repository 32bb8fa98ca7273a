"""The modeller's own lines and domain, checked on entry: a zero-length line or repeated
vertices are left out with a note naming the feature (a zero-length line beside a good one ended
a run with a GEOS traceback after the mesh was built); a coordinate that is no number, or 3-D
lines crossing at two heights, are refused; a domain reaching beyond the data is clipped with a
note giving the area left out, and one narrower than a cell in places is meshed with a note
saying where. Every node on an own 3-D line takes the z along it, in every step."""
import json
import subprocess
import sys

import fiona
import pytest
import shapely.geometry
from pyproj import CRS

from ..conftest import write_regions


def _lines(path, features):
    schema = {"geometry": "LineString", "properties": {"name": "str"}}
    with fiona.open(path, "w", driver="GPKG", schema=schema,
                    crs_wkt=CRS.from_epsg(25832).to_wkt()) as dst:
        for name, coords in features:
            dst.write({"geometry": {"type": "LineString", "coordinates": coords},
                       "properties": {"name": name}})


def _run(points, out, *options):
    return subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run", str(points),
                           "--out", str(out), "--max-area", "400", *options],
                          capture_output=True, text=True, timeout=600)


def test_own_lines_and_domain_checked_on_entry(demo_points_file, tmp_path):
    from floodmesh.core import io

    dem = io.read_points(demo_points_file).xyz
    x0, y0 = dem[:, 0].min(), dem[:, 1].min()
    _lines(tmp_path / "own.gpkg", [
        ("point", [(x0 + 50, y0 + 50), (x0 + 50, y0 + 50)]),                 # zero length
        ("dyke", [(x0 + 60, y0 + 20), (x0 + 60, y0 + 20), (x0 + 60, y0 + 120)]),  # repeated
    ])
    domain = shapely.geometry.box(x0 - 100, y0 + 5, x0 + 150, y0 + 150)  # 100 m beyond the data
    write_regions(tmp_path / "domain.gpkg", [(domain, 1)])
    run = _run(demo_points_file, tmp_path / "out", "--lines", str(tmp_path / "own.gpkg"),
               "--boundary", str(tmp_path / "domain.gpkg"))
    assert run.returncode == 0, run.stderr[-3000:]
    assert "Traceback" not in run.stderr
    notes = json.loads((tmp_path / "out" / "report.json").read_text())["notes"]
    assert [n for n in notes if "own.gpkg" in n and "feature(s) 1 left out" in n], notes
    assert [n for n in notes if "domain.gpkg" in n and "has no data" in n], notes


def test_own_2d_lines_give_every_node_an_elevation(demo_points_file, tmp_path):
    """From the user's side: a structure line digitised in QGIS without Z (a 2-D LineString
    layer, which reads back with no z) across the demo floodplain. The run's mesh had nodes
    with no elevation (NaN in mesh.2dm: 55 of them, when found) where the terrain fits
    gave nodes on a line the line's z; a solver then breaks down at the first step. Every node
    has an elevation, and those on the line the terrain's there (within 0.3 m of the DEM)."""
    import numpy as np

    from floodmesh.core import io
    from floodmesh.core.raster import bilinear

    xyz = io.read_points(demo_points_file).xyz
    x0, y0 = xyz[:, 0].min(), xyz[:, 1].min()
    line = [(x0 + 40, y0 + 30), (x0 + 260, y0 + 170)]
    _lines(tmp_path / "own.gpkg", [("dyke", line)])
    run = _run(demo_points_file, tmp_path / "out", "--lines", str(tmp_path / "own.gpkg"))
    assert run.returncode == 0, run.stderr[-3000:]
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert np.isfinite(nodes[:, 2]).all()
    on_line = shapely.distance(shapely.geometry.LineString(line), shapely.points(nodes[:, :2]))
    on = nodes[on_line < 1e-3]
    assert len(on) >= 8
    dem = io.read_raster(tmp_path / "out" / "dem.tif")
    assert np.abs(on[:, 2] - bilinear(dem, on[:, 0], on[:, 1])).max() < 0.3


def test_own_lines_far_off_the_ground_are_named(demo_points_file, tmp_path):
    """From the user's side: own lines in a layer with Z, one digitised without heights (z 0,
    QGIS's default, some 20 m under the demo's floodplain), one with heights 0.4 m above the
    ground. The run goes on with both as given, and its notes name the first, with how far it
    lies from the ground and how to give it the DEM's z; the second is not named."""
    import numpy as np

    from floodmesh.core import io
    from floodmesh.core.frontends import demo

    xyz = io.read_points(demo_points_file).xyz
    x0, y0 = xyz[:, 0].min(), xyz[:, 1].min()
    along = np.linspace(0, 1, 6)[:, None]
    zero = np.column_stack([x0 + 40 + 200 * along, y0 + 30 + 120 * along, 0 * along])
    # apart from the first: crossing it 20 m higher would be refused
    raised = np.column_stack([x0 + 60 + 200 * along, y0 + 200 - 20 * along])
    raised = np.column_stack([raised, demo.ground_elevation(raised[:, 0] - demo.DEMO_ORIGIN[0],
                                                            raised[:, 1] - demo.DEMO_ORIGIN[1],
                                                            demo.DEMO) + 0.4])
    schema = {"geometry": "3D LineString", "properties": {"name": "str"}}
    with fiona.open(tmp_path / "own.gpkg", "w", driver="GPKG", schema=schema,
                    crs_wkt=CRS.from_epsg(25832).to_wkt()) as dst:
        for name, coords in (("no heights", zero), ("surveyed", raised)):
            dst.write({"geometry": {"type": "LineString", "coordinates": coords.tolist()},
                       "properties": {"name": name}})
    run = _run(demo_points_file, tmp_path / "out", "--lines", str(tmp_path / "own.gpkg"))
    assert run.returncode == 0, run.stderr[-3000:]
    notes = json.loads((tmp_path / "out" / "report.json").read_text())["notes"]
    named = [n for n in notes if n.startswith("own.gpkg: line(s)")]
    assert len(named) == 1 and "line(s) 1 lie -2" in named[0], notes
    assert "without Z" in named[0]


def test_hec_ras_breaklines_are_the_lines_the_mesh_honours(demo_points_file, tmp_path):
    """From the user's side: a domain with an own line across it, exported for HEC-RAS
    (``--formats gpkg``), which builds its own mesh from mesh.gpkg's ``breaklines`` layer. The
    layer left out the own line and held detected lines beyond the domain, few of whose
    vertices were mesh nodes. It holds the own line, nothing outside the domain, and every
    vertex is a node of the mesh with the node's z."""
    import numpy as np

    from floodmesh.core import io

    xyz = io.read_points(demo_points_file).xyz
    x0, y0 = xyz[:, 0].min(), xyz[:, 1].min()
    own = [(x0 + 40, y0 + 30), (x0 + 160, y0 + 110)]
    _lines(tmp_path / "own.gpkg", [("dyke", own)])
    domain = shapely.geometry.box(x0 + 20, y0 + 10, x0 + 200, y0 + 150)
    write_regions(tmp_path / "domain.gpkg", [(domain, 1)])
    run = _run(demo_points_file, tmp_path / "out", "--lines", str(tmp_path / "own.gpkg"),
               "--boundary", str(tmp_path / "domain.gpkg"), "--formats", "gpkg")
    assert run.returncode == 0, run.stderr[-3000:]
    with fiona.open(tmp_path / "out" / "mesh.gpkg", layer="breaklines") as src:
        lines = [np.asarray(f["geometry"]["coordinates"], float) for f in src]
    with fiona.open(tmp_path / "out" / "mesh.gpkg", layer="nodes") as src:
        nodes = np.array([f["geometry"]["coordinates"] for f in src], float)
    layer = shapely.MultiLineString([line[:, :2] for line in lines])
    assert shapely.LineString(own).difference(layer.buffer(0.1)).length < 1.0  # noded on a grid
    assert layer.difference(domain.buffer(1e-6)).length == 0
    vertices = np.concatenate(lines)
    index = {tuple(n[:2]): n[2] for n in nodes}
    assert all(tuple(v[:2]) in index and index[tuple(v[:2])] == v[2] for v in vertices)


def test_boundary_layer_named_as_qgis_names_it(tmp_path):
    """From the user's side: a GeoPackage holding ``buildings`` and then ``domain``, given as QGIS
    writes a layer's source (``file.gpkg|layername=domain``). The first layer (one house) was
    meshed silently; the mesh covers the named domain."""
    import numpy as np

    from floodmesh.core import io

    from ..bad_inputs import ORIGIN, layered_boundary, slope_dem, write_tif

    dem = write_tif(tmp_path / "dem.tif", slope_dem())
    boundary = f"{layered_boundary(tmp_path)}|layername=domain"
    run = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "mesh", str(dem),
                          "--boundary", boundary, "--out", str(tmp_path / "mesh.2dm")],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    nodes, _ = io.read_mesh_2dm(tmp_path / "mesh.2dm")
    assert np.ptp(nodes[:, 0]) > 40 and nodes[:, 0].min() - ORIGIN[0] < 6


def _bridge(x0, y0, dem_z, rise):
    """A road's line on the ground and a bridge deck's line ``rise`` m above it, crossing at
    (x0 + 150, y0 + 100); ``dem_z(x, y)`` the ground's z."""
    import numpy as np

    along = np.linspace(0, 1, 5)[:, None]
    road = np.column_stack([x0 + 100 + 100 * along, np.full_like(along, y0 + 100)])
    deck = np.column_stack([np.full_like(along, x0 + 150), y0 + 40 + 130 * along])
    road = np.column_stack([road, dem_z(road[:, 0], road[:, 1])])
    deck = np.column_stack([deck, np.full(len(deck), dem_z(x0 + 150, y0 + 100) + rise)])
    return road, deck


def _lines_3d(path, lines):
    schema = {"geometry": "3D LineString", "properties": {"name": "str"}}
    with fiona.open(path, "w", driver="GPKG", schema=schema,
                    crs_wkt=CRS.from_epsg(25832).to_wkt()) as dst:
        for k, coords in enumerate(lines):
            dst.write({"geometry": {"type": "LineString", "coordinates": coords.tolist()},
                       "properties": {"name": str(k)}})


def test_own_3d_lines_crossing_at_two_heights_are_refused(demo_points_file, tmp_path):
    """From the user's side: a road's line on the ground and a bridge deck's 7 m above it, one
    layer with Z, crossing (vertices 40 m apart: neither has a vertex at the crossing). The run
    meshed them without a word, the crossing's node at the ground and the deck's line running
    down to it: a 7 m spike. It stops, naming the crossing, both heights and the fixes, and
    writes nothing."""
    from floodmesh.core import io
    from floodmesh.core.frontends import demo

    xyz = io.read_points(demo_points_file).xyz
    x0, y0 = xyz[:, 0].min(), xyz[:, 1].min()

    def ground(x, y):
        return demo.ground_elevation(x - demo.DEMO_ORIGIN[0], y - demo.DEMO_ORIGIN[1], demo.DEMO)

    road, deck = _bridge(x0, y0, ground, 7.0)
    _lines_3d(tmp_path / "own.gpkg", [road, deck])
    run = _run(demo_points_file, tmp_path / "out", "--lines", str(tmp_path / "own.gpkg"))
    assert run.returncode == 2, run.stderr[-3000:]
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, lines
    assert (f"own.gpkg: features 1 and 2 cross at ({x0 + 150:.2f}, {y0 + 100:.2f}) at heights "
            f"{road[2, 2]:.2f} and {deck[0, 2]:.2f} m, 7.00 m apart") in lines[0], lines
    assert "Cut one line short of the crossing" in lines[0] and "without Z" in lines[0]
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


def test_own_3d_lines_meeting_at_one_height_are_meshed(tmp_path):
    """From the user's side: 3-D lines of one layer meeting at one height, as a modeller's
    lines do: a road crossing another (5 cm apart there, as two surveys agree), a lane ending
    on the road (a T-junction) and the road's continuation end to end. The mesh step takes
    them, with a node at each meeting point."""
    import numpy as np

    from floodmesh.core import io

    from ..bad_inputs import ORIGIN, slope_dem, write_tif

    dem = write_tif(tmp_path / "dem.tif", slope_dem())
    x0, y0 = ORIGIN

    def ground(x, y):
        return 10.0 + 0.05 * (np.asarray(x) - x0)  # the bank DEM west of its step

    def line(*xy, lift=0.0):
        xy = np.asarray(xy, float) + ORIGIN
        return np.column_stack([xy, ground(xy[:, 0], xy[:, 1]) + lift])

    lines = [line((5, 30), (25, 30)), line((25, 30), (28, 45)),  # the road, end to end
             line((15, 10), (15, 50), lift=0.05),                # a road crossing it
             line((10, 50), (10, 30))]                            # a lane ending on it
    _lines_3d(tmp_path / "own.gpkg", lines)
    run = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "mesh", str(dem),
                          "--lines", str(tmp_path / "own.gpkg"), "--out",
                          str(tmp_path / "mesh.2dm")], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    nodes, _ = io.read_mesh_2dm(tmp_path / "mesh.2dm")
    for x, y in ((15, 30), (10, 30), (25, 30)):
        near = np.hypot(nodes[:, 0] - x0 - x, nodes[:, 1] - y0 - y)
        assert near.min() < 0.01, (x, y)
        assert abs(nodes[near.argmin(), 2] - ground(x0 + x, 0)) < 0.2


def test_a_domain_narrower_than_a_cell_is_named(tmp_path):
    """From the user's side: a model domain of a 20 m square and, drawn on with it, a strip
    0.5 m wide and 30 m long on a DEM of 1 m cells (a slip of the mouse, or a ditch drawn as
    the domain). It was meshed without a word: triangles of a fraction of a cell there, on
    terrain the DEM holds one height a cell across. It is meshed, and a note names the strip:
    where, how long, and the fixes; the square alone gets no such note."""
    import shapely.affinity

    from ..bad_inputs import ORIGIN, slope_dem, write_tif

    dem = write_tif(tmp_path / "dem.tif", slope_dem())
    square = shapely.geometry.box(5, 5, 25, 25)
    strip = shapely.geometry.box(25, 15, 55, 15.5)
    notes = {}
    for name, domain in (("strip", shapely.union_all([square, strip])), ("square", square)):
        write_regions(tmp_path / f"{name}.gpkg", [(shapely.affinity.translate(domain, *ORIGIN),
                                                   1)])
        run = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "mesh",
                              str(dem), "--boundary", str(tmp_path / f"{name}.gpkg"), "--out",
                              str(tmp_path / f"{name}.2dm")], capture_output=True, text=True,
                             timeout=600)
        assert run.returncode == 0, run.stderr[-3000:]
        assert (tmp_path / f"{name}.2dm").is_file()
        notes[name] = [line for line in run.stderr.splitlines() if "narrower" in line]
    assert not notes["square"], notes
    assert len(notes["strip"]) == 1, notes
    x, y = ORIGIN[0] + 40, ORIGIN[1] + 15.25
    assert (f"strip.gpkg: the model domain is narrower than a cell (1 m) along some 30 m, "
            f"around ({x:.2f}, {y:.2f})") in notes["strip"][0]
    assert "widen the domain there, or grid with smaller cells" in notes["strip"][0]


def test_nodes_on_an_own_3d_line_take_its_height_in_every_step(tmp_path):
    """From the user's side: a bridge deck's 3-D line, 8 m above the bank DEM and rising 2 m
    over its 50 m (a vertex at each end), meshed in small triangles (max area 2 m²), which
    split it into some 30 segments, with a break line (``--breaklines``) crossing it between
    both lines' vertices. The mesh step, refine and ``run --node-elevation dem`` gave the
    deck's nodes between its vertices the DEM's z (10.98 m under a deck at 18.60 m), a dip of
    8 m in the deck. Every node on the deck has the z along it (within 1 mm), the crossing's
    too, in every step, as run's terrain fits (its default) gave them before."""
    import numpy as np

    from floodmesh.core import io

    from ..bad_inputs import ORIGIN, slope_dem, write_tif, write_xyz

    values = slope_dem()
    dem = write_tif(tmp_path / "dem.tif", values)
    x0, y0 = ORIGIN
    deck = np.array([[x0 + 20, y0 + 5, 18.0], [x0 + 20, y0 + 55, 20.0]])
    _lines_3d(tmp_path / "own.gpkg", [deck])
    crossing = np.array([[x0 + 5, y0 + 30, 10.25], [x0 + 12, y0 + 30, 10.6],
                         [x0 + 28, y0 + 30, 11.4]])  # on the ground: 10 + 0.05 (x - x0)
    _lines_3d(tmp_path / "detected.gpkg", [crossing])
    rows, cols = np.mgrid[0:values.shape[0], 0:values.shape[1]]
    write_xyz(tmp_path / "cells.xyz", np.column_stack([x0 + cols.ravel() + 0.5,
                                                       y0 + values.shape[0] - rows.ravel() - 0.5,
                                                       values.ravel()]))
    common = ["--lines", str(tmp_path / "own.gpkg"), "--max-area", "2"]
    commands = {
        "mesh": ["mesh", dem, "--breaklines", tmp_path / "detected.gpkg", *common,
                 "--out", tmp_path / "mesh.2dm"],
        "refine": ["refine", dem, "--points", tmp_path / "cells.xyz", "--crs", "EPSG:25832",
                   *common, "--out", tmp_path / "refine.2dm"],
        "run": ["run", dem, *common, "--out", tmp_path / "run"],
        "run-dem": ["run", dem, *common, "--node-elevation", "dem", "--out", tmp_path / "dem"]}
    meshes = {"mesh": "mesh.2dm", "refine": "refine.2dm", "run": "run/mesh.2dm",
              "run-dem": "dem/mesh.2dm"}
    for name, args in commands.items():
        done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli",
                               *map(str, args)], capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, (name, done.stderr[-3000:])
        nodes, _ = io.read_mesh_2dm(tmp_path / meshes[name])
        on = nodes[shapely.distance(shapely.geometry.LineString(deck[:, :2]),
                                    shapely.points(nodes[:, :2])) < 1e-3]
        assert len(on) >= 20, name
        along = 18.0 + 2.0 * (on[:, 1] - y0 - 5) / 50
        assert np.abs(on[:, 2] - along).max() < 1e-3, (name, on[np.abs(on[:, 2] - along) > 1e-3])
        if name == "mesh":
            assert np.hypot(on[:, 0] - x0 - 20, on[:, 1] - y0 - 30).min() < 1e-3  # the crossing


def test_an_own_3d_line_crossing_detected_lines_keeps_its_height_in_run(tmp_path):
    """From the user's side: a deck's 3-D line 7 m above the bank DEM, across the bank's
    detected crest and toe lines, in a run that keeps every detected line (``--min-spacing
    0``). The crossing's node, snapped to a 5 cm grid and so nearer the toe's line than the
    deck's, took the toe's z in the run's terrain fits (11.46 m under a deck at 19.02 m),
    while ``--node-elevation dem`` and the mesh step gave it the deck's. Every node within
    5 cm of the deck has the deck's z there, both ways."""
    import numpy as np

    from floodmesh.core import io

    from ..bad_inputs import ORIGIN, slope_dem, write_tif

    dem = write_tif(tmp_path / "dem.tif", slope_dem())
    x0, y0 = ORIGIN
    deck = np.array([[x0 + 5, y0 + 20.44, 18.0], [x0 + 55, y0 + 20.54, 20.0]])
    _lines_3d(tmp_path / "own.gpkg", [deck])
    line = shapely.geometry.LineString(deck)
    for name, extra in (("plane", []), ("dem", ["--node-elevation", "dem"])):
        done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run",
                               str(dem), "--lines", str(tmp_path / "own.gpkg"), "--min-spacing",
                               "0", "--out", str(tmp_path / name), *extra],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, (name, done.stderr[-3000:])
        detected = io.read_lines_gpkg(tmp_path / name / "breaklines.gpkg")
        assert sum(line.crosses(shapely.geometry.LineString(c[:, :2])) for c in detected) >= 2
        nodes, _ = io.read_mesh_2dm(tmp_path / name / "mesh.2dm")
        points = shapely.points(nodes[:, :2])
        on = shapely.distance(line, points) < 0.05
        assert on.sum() >= 10, name
        along = shapely.get_z(shapely.line_interpolate_point(
            line, shapely.line_locate_point(line, points[on])))
        assert np.abs(nodes[on, 2] - along).max() < 1e-3, (name, nodes[on][:, 2] - along)


def test_a_2d_own_line_listed_first_leaves_a_3d_line_its_height_at_their_crossing(tmp_path):
    """From the user's side: one layer of own lines (a GeoPackage whose features may have Z or
    not, as QGIS saves a layer of mixed lines) holding a road digitised without Z and a bridge
    deck's 3-D line 8 m above the bank DEM, crossing it between both lines' vertices. With the
    road listed first, the crossing's node took the DEM's z (the road's) in the mesh step and
    the run: a dip of 8 m in the deck. It takes the deck's z in either order, in every step."""
    import numpy as np

    from floodmesh.core import io

    from ..bad_inputs import ORIGIN, slope_dem, write_tif

    dem = write_tif(tmp_path / "dem.tif", slope_dem())
    x0, y0 = ORIGIN
    road = [[x0 + 5, y0 + 30], [x0 + 33, y0 + 30]]
    deck = [[x0 + 20, y0 + 5, 18.0], [x0 + 20, y0 + 55, 20.0]]
    crossing = (x0 + 20, y0 + 30, 19.0)
    schema = {"geometry": "Unknown", "properties": {"name": "str"}}
    for order in ((road, deck), (deck, road)):
        own = tmp_path / f"own{len(order[0][0])}.gpkg"
        with fiona.open(own, "w", driver="GPKG", schema=schema,
                        crs_wkt=CRS.from_epsg(25832).to_wkt()) as dst:
            for coords in order:
                dst.write({"geometry": {"type": "LineString", "coordinates": coords},
                           "properties": {"name": str(len(coords[0]))}})
        for step, out, mesh in (("mesh", ["--out", tmp_path / "mesh.2dm"], "mesh.2dm"),
                                ("run", ["--out", tmp_path / "run"], "run/mesh.2dm")):
            done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", step,
                                   str(dem), "--lines", str(own), "--max-area", "4",
                                   *map(str, out)], capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, (step, done.stderr[-3000:])
            nodes, _ = io.read_mesh_2dm(tmp_path / mesh)
            near = np.hypot(nodes[:, 0] - crossing[0], nodes[:, 1] - crossing[1])
            assert near.min() < 1e-3, (step, near.min())
            assert abs(nodes[near.argmin(), 2] - crossing[2]) < 1e-3, (
                step, len(order[0][0]), nodes[near.argmin()])


def test_an_own_line_is_named_by_its_feature_id_as_qgis_shows_it(tmp_path):
    """A layer whose first feature was deleted (fid 2 and 3 left) named its second feature,
    fid 3, 'feature 2': the modeller, looking for fid 2 in QGIS's attribute table, was sent to
    the line without the fault."""
    import sqlite3

    import numpy as np
    from affine import Affine

    from floodmesh.core import io
    from floodmesh.core.raster import Grid

    x0, y0 = 412_000.0, 5_652_000.0
    io.write_raster(tmp_path / "dem.tif", Grid(np.full((60, 60), 10.0),
                                               Affine(1, 0, x0, 0, -1, y0 + 60),
                                               CRS.from_epsg(25832)))
    _lines(tmp_path / "own.gpkg", [
        ("gone", [(x0 + 5, y0 + 10), (x0 + 40, y0 + 10)]),
        ("good", [(x0 + 5, y0 + 20), (x0 + 40, y0 + 20)]),
        ("bad", [(x0 + 5, y0 + 30), (float("nan"), y0 + 30), (x0 + 40, y0 + 30)])])
    with sqlite3.connect(tmp_path / "own.gpkg") as db:  # as QGIS saves a deletion
        db.execute("DELETE FROM own WHERE fid = 1")
    done = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "mesh",
                           str(tmp_path / "dem.tif"), "--lines", str(tmp_path / "own.gpkg"),
                           "--out", str(tmp_path / "m.2dm")], capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert "own.gpkg: feature 3, vertex 2 of 3, has an x of nan, not a number" in done.stderr


def test_own_3d_lines_crossing_at_two_heights_are_refused_by_the_library_step_too():
    """From a library user's side: build_mesh(own_lines=[road, deck]) with a deck's line 7 m
    above the road's where they cross. The file's reader refused them, but the step meshed them
    without a word, the crossing's node taking the road's z and the deck a 7 m spike. It refuses
    them as the reader does, naming them by their place in own_lines; lines crossing at one
    height are meshed."""
    import numpy as np
    from affine import Affine

    from floodmesh.core import FloodMeshError, Grid, build_mesh

    from ..bad_inputs import ORIGIN

    x0, y0 = ORIGIN
    dem = Grid(np.full((240, 300), 10.0), Affine(1, 0, x0, 0, -1, y0 + 240), crs="EPSG:25832")
    road, deck = _bridge(x0, y0, lambda x, y: np.full(np.shape(x), 10.0), 7.0)
    with pytest.raises(FloodMeshError) as error:
        build_mesh(dem, [], own_lines=[road, deck], max_area=200)
    message = str(error.value)
    assert "\n" not in message and message.startswith(
        f"own_lines[0] and own_lines[1] cross at ({x0 + 150:.2f}, {y0 + 100:.2f}) at heights "
        "10.00 and 17.00 m, 7.00 m apart"), message
    assert "Cut one line short of the crossing" in message
    level = deck.copy()
    level[:, 2] = 10.0
    mesh = build_mesh(dem, [], own_lines=[road, level], max_area=200)
    assert np.allclose(mesh.nodes[:, 2], 10.0)
