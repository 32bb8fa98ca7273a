"""User break lines that cross, touch, duplicate each other or meet at tiny angles, and DEMs with
large nodata holes (water): each gives a valid mesh and says what was repaired, through
``floodmesh mesh --breaklines`` and through build_mesh."""
import json

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.frontends.cli import main
from floodmesh.core.steps.mesh import build_mesh, mesh_quality, triangle_angles, triangle_areas
from floodmesh.core.raster import Grid

from ..conftest import swaled
from .test_mesh import ORIGIN, _covered_length, _edges, _line, _plane, _plane_dem

CASES = {
    # id: (lines in local coordinates, words the notes must hold or None for no note)
    "crossing": ([[(10, 10), (50, 50)], [(10, 50), (50, 10)]], "joined at 1 nodes"),
    "touching": ([[(10, 30), (50, 30)], [(30, 50), (30, 30)]], "joined at 1 nodes"),
    "duplicate": ([[(10, 20), (30, 25), (50, 40)]] * 2, "duplicated or ran along"),
    "overlapping": ([[(10, 30), (40, 30)], [(20, 30), (50, 30)]], "duplicated or ran along"),
    "nearly-identical": ([[(10, 20), (50, 40)], [(10.001, 20.0005), (50.001, 40.0005)]],
                         "duplicated or ran along"),
    "tiny-angle-at-a-shared-end": ([[(10, 30), (50, 30)], [(10, 30), (50, 33.5)]],
                                   "less than 60 degrees were shortened"),
    "crossing-at-a-tiny-angle": ([[(10, 29), (50, 31)], [(10, 31), (50, 29)]],
                                 "less than 60 degrees were shortened"),
    "outside-the-dem": ([[(10, 30), (50, 30)], [(70, 10), (90, 50)]], "wholly outside"),
    "one-point": ([[(10, 30), (50, 30)], [(20, 20)]], "fewer than 2 points"),
    "zigzag-self-crossing": ([[(10, 10), (50, 50), (50, 10), (10, 50)]], "joined at 1 nodes"),
    "clean": ([[(10, 20), (30, 25), (50, 40)]], None),
}


def _lines(case):
    return [_line(coords) for coords in CASES[case][0]]


def _check_mesh(nodes, triangles, min_angle=25.0, max_area=20.0):
    areas = triangle_areas(nodes, triangles)
    assert (areas > 0).all(), "a triangle is clockwise or degenerate"
    assert areas.max() <= max_area * (1 + 1e-9)
    assert triangle_angles(nodes, triangles).min() >= min_angle - 1e-6
    assert areas.sum() == pytest.approx(59.0 ** 2, rel=1e-9)
    assert np.isfinite(nodes).all()


@pytest.mark.parametrize("case", list(CASES))
def test_break_line_case_meshes_and_says_what_was_done(case):
    notes = []
    mesh = build_mesh(_plane_dem(), _lines(case), min_angle=25, max_area=20, note=notes.append)
    _check_mesh(mesh.nodes, mesh.triangles)
    q = mesh_quality(mesh, min_angle=25, max_area=20)
    assert q["n_below_min_angle"] == 0 and q["n_small_input_angles"] == 0
    words = CASES[case][1]
    if words is None:
        assert notes == []
    else:
        assert any(words in n for n in notes), notes
    # node z is the plane's; a vertex snapped to another line's takes that line's z (the
    # nearly identical lines differ by up to 0.1 mm here)
    local = mesh.nodes[:, :2] - ORIGIN
    np.testing.assert_allclose(mesh.nodes[:, 2], _plane(local[:, 0], local[:, 1]), atol=1e-4)


def test_touching_line_ends_on_a_node_of_the_other():
    mesh = build_mesh(_plane_dem(), _lines("touching"), min_angle=25, max_area=20)
    edges = _edges(mesh.triangles)
    for a, b in (((10, 30), (50, 30)), ((30, 50), (30, 30))):
        a, b = np.add(a, ORIGIN), np.add(b, ORIGIN)
        assert _covered_length(mesh.nodes, edges, a, b) == pytest.approx(np.hypot(*(b - a)))


def test_duplicate_lines_mesh_as_one():
    one = build_mesh(_plane_dem(), _lines("duplicate")[:1], min_angle=25, max_area=20)
    two = build_mesh(_plane_dem(), _lines("duplicate"), min_angle=25, max_area=20)
    np.testing.assert_array_equal(one.nodes, two.nodes)
    np.testing.assert_array_equal(one.triangles, two.triangles)


@pytest.mark.parametrize("case", ["crossing", "duplicate", "crossing-at-a-tiny-angle",
                                  "outside-the-dem"])
def test_break_line_case_through_the_command(case, tmp_path, capsys):
    dem, lines = tmp_path / "dem.tif", tmp_path / "lines.gpkg"
    io.write_raster(dem, _plane_dem())
    io.write_lines_gpkg(lines, [line for line in _lines(case) if len(line) >= 2],
                        CRS.from_epsg(25832))
    assert main(["mesh", str(dem), "--breaklines", str(lines), "--max-area", "20",
                 "--out", str(tmp_path / "mesh.2dm")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err and all(line.startswith("floodmesh: note: ") for line in err)
    assert any(CASES[case][1] in line for line in err)
    nodes, triangles = io.read_mesh_2dm(tmp_path / "mesh.2dm")
    _check_mesh(nodes, triangles)


# ---------------------------------------------------------------------------------------------
# nodata holes (water)
def _lake_dem():
    """A 120 x 100 m DEM with a large irregular lake (about a third of it) holding an island,
    a bay open to the east edge, and scattered single nodata cells."""
    rows, cols = 100, 120
    yy, xx = np.mgrid[0:rows, 0:cols] + 0.5
    z = 0.02 * xx + 0.01 * yy + 5.0
    lake = ((xx - 50) / 32) ** 2 + ((yy - 50) / 26) ** 2 + 0.15 * np.sin(xx / 4) < 1
    island = ((xx - 48) / 7) ** 2 + ((yy - 52) / 6) ** 2 < 1
    bay = (xx > 95) & (np.abs(yy - 20) < 6)
    z[(lake & ~island) | bay] = np.nan
    rng = np.random.default_rng(3)
    z[rng.integers(0, rows, 15), rng.integers(0, cols, 15)] = np.nan
    return Grid(z, Affine(1.0, 0, ORIGIN[0], 0, -1.0, ORIGIN[1] + rows), CRS.from_epsg(25832))


def test_large_nodata_lake_with_an_island_meshes_around_the_water():
    dem = _lake_dem()
    mesh = build_mesh(dem, [], min_angle=25, max_area=20)
    areas = triangle_areas(mesh.nodes, mesh.triangles)
    assert (areas > 0).all() and triangle_angles(mesh.nodes, mesh.triangles).min() >= 25 - 1e-6
    centroids = mesh.nodes[mesh.triangles][:, :, :2].mean(axis=1)
    row, col = dem.fractional_index(centroids[:, 0], centroids[:, 1])
    cell = dem.values[np.round(row).astype(int), np.round(col).astype(int)]
    # no triangle's centroid lies on water (beyond the half cell the outline may cut)
    assert np.isfinite(cell).mean() > 0.99
    # the island is meshed, the lake around it is not
    island = np.hypot((centroids[:, 0] - ORIGIN[0] - 48) / 7,
                      (ORIGIN[1] + 100 - centroids[:, 1] - 52) / 6) < 0.5
    assert island.sum() > 3
    assert areas.sum() < 0.75 * 119 * 99
    assert np.isfinite(mesh.nodes[:, 2]).all()


def test_lake_dem_runs_through_the_whole_chain(tmp_path, capsys):
    path = tmp_path / "lake.tif"
    io.write_raster(path, _lake_dem())
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--max-area", "20"]) == 0
    nodes, triangles = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    assert len(triangles) > 300 and (triangle_areas(nodes, triangles) > 0).all()


def test_line_meeting_another_at_a_sharp_angle_is_shortened_not_dropped():
    """A long line ending on another at 20° keeps all but the end near the meeting point (the
    angle rule used to leave out its whole segment)."""
    lines = [_line([(5, 30), (55, 30)]), _line([(30, 30), (55, 30 + 25 * np.tan(np.radians(20)))])]
    notes = []
    mesh = build_mesh(_plane_dem(), lines, min_angle=25, max_area=20, note=notes.append)
    _check_mesh(mesh.nodes, mesh.triangles)
    assert mesh_quality(mesh, min_angle=25, max_area=20)["n_below_min_angle"] == 0
    assert any("shortened near the meeting point" in n for n in notes), notes
    edges = _edges(mesh.triangles)
    # the line's ends as the mesh has them (snapped to the PSLG's grid)
    a, b = (mesh.nodes[np.argmin(np.hypot(*(mesh.nodes[:, :2] - end).T)), :2]
            for end in (lines[1][0, :2], lines[1][-1, :2]))
    # ends 2·snap (0.5 m) off the other line: 1.46 m of the 26.6 m inside the 59 m domain less
    length = np.hypot(*(b - a))
    assert _covered_length(mesh.nodes, edges, a, b) > length - 2.5


def _swaled_valley():
    """A 200 x 101 m valley falling 0.5 % east, its sides rising 5 %, with swales on its west
    half's low ground (``swaled``): relief the flow area refines, so the mesh is built twice."""
    east, north = np.meshgrid(np.arange(200) + 0.5, np.arange(101) + 0.5)
    z = 0.005 * east + 0.05 * np.abs(north - 50.5)
    dem = Grid(z.astype(np.float32), Affine(1.0, 0, ORIGIN[0], 0, -1.0, ORIGIN[1] + 101),
               CRS.from_epsg(25832))
    return swaled(dem)[0]


@pytest.mark.parametrize("front_end", ["run", "Build mesh"])
def test_a_repair_is_said_once_when_the_flow_area_meshes_again(front_end, tmp_path, capsys):
    """Two crossing lines of the user's on a valley whose swales the flow area refines: the
    mesh is built again with smaller triangles there, and the join is said once (on stderr and
    in report.json for run; QGIS's Build mesh, which asks for the flow area, as well), not once
    for each mesh built."""
    from floodmesh.core.chain import files

    dem, lines = tmp_path / "dem.tif", tmp_path / "lines.gpkg"
    io.write_raster(dem, _swaled_valley())
    io.write_lines_gpkg(lines, [_line([(20, 30), (80, 70)]), _line([(20, 70), (80, 30)])],
                        CRS.from_epsg(25832))
    if front_end == "run":
        out = tmp_path / "out"
        assert main(["run", str(dem), "--lines", str(lines), "--out", str(out)]) == 0
        notes = [line.removeprefix("floodmesh: note: ")
                 for line in capsys.readouterr().err.splitlines() if "note: " in line]
        assert notes == json.loads((out / "report.json").read_text())["notes"]
        assert json.loads((out / "report.json").read_text())["flow_zone"]["refined_share"] > 0
    else:
        notes = []
        files.mesh(dem, tmp_path / "mesh.2dm", user_lines=lines, flow_area=None,
                   note=notes.append)
    assert [n for n in notes if "joined" in n] == [
        "break lines were joined at 1 nodes where they cross or touch one another or the boundary"]
    assert len(set(notes)) == len(notes), notes
