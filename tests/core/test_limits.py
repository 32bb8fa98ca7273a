"""Size guards (core.engine.limits): the estimates behind the refusals are close to what a run
really makes, and a refusal comes before the work, with the estimate."""
import json
import time

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.frontends.cli import main
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.engine.limits import (available_memory, check_memory, check_triangles,
                                          estimate_triangles, fits_in_memory, footprint)
from floodmesh.core.steps.mesh import PSLG, build_mesh, triangulate_pslg
from floodmesh.core.chain.pipeline import RunOptions, run_pipeline
from floodmesh.core.raster import Grid

from ..bad_inputs import plane_xyz, write_las


def test_available_memory_is_read():
    memory = available_memory()
    assert memory is not None and 10**8 < memory < 10**14


def test_footprint_of_uniform_points():
    """20 000 points on 50 x 50 m: 2500 m² within the bins' rounding, spacing 0.35 m."""
    area, spacing = footprint(plane_xyz()[:, :2])
    assert area == pytest.approx(2500, rel=0.1)
    assert spacing == pytest.approx(np.sqrt(2500 / 20_000), rel=0.05)


def test_footprint_leaves_out_a_void():
    """Points on the left half of a 100 x 50 m box only (water on the right): the area and the
    spacing are those of the half with data, not of the box."""
    rng = np.random.default_rng(2)
    xy = np.column_stack([rng.uniform(0, 50, 10_000), rng.uniform(0, 50, 10_000)])
    xy = np.vstack([xy, [[100.0, 0.0], [100.0, 50.0]]])  # two points far right stretch the box
    area, spacing = footprint(xy)
    assert area == pytest.approx(2500, rel=0.15)
    assert spacing == pytest.approx(0.5, rel=0.08)


@pytest.mark.parametrize("max_area", [2.0, 10.0, 50.0])
def test_triangle_estimate_is_close_to_triangle(max_area):
    """On a 100 x 100 m DEM without break lines the estimate is within 25 % of the triangles
    Triangle makes."""
    dem = Grid(np.zeros((101, 101)), Affine(1, 0, 5e5, 0, -1, 6e6), CRS.from_epsg(25832))
    mesh = build_mesh(dem, [], min_angle=25, max_area=max_area)
    estimate = estimate_triangles(100.0 * 100.0, max_area)
    assert estimate == pytest.approx(len(mesh.triangles), rel=0.25)


def test_memory_refusal_names_the_estimate():
    with pytest.raises(FloodMeshError) as err:
        check_memory(points=10**6, cells=10**7, memory=10**8, advice="do less")
    message = str(err.value)
    assert "1,000,000 points" in message and "10,000,000 grid cells" in message
    assert "about 0.8 GB of memory" in message and "but 0.1 GB is available" in message and "do less" in message
    assert check_memory(points=10, memory=10**8, advice="") > 0


def test_fits_in_memory_is_the_refusals_test_without_refusing():
    sizes = dict(points=10**6, cells=10**7, cell_bytes=100)
    need = check_memory(**sizes, memory=10**10, advice="")
    assert fits_in_memory(**sizes, memory=need) and not fits_in_memory(**sizes, memory=need - 1)
    with pytest.raises(FloodMeshError):
        check_memory(**sizes, memory=need - 1, advice="")


def test_triangle_limit_refusal_gives_the_area_that_fits():
    with pytest.raises(FloodMeshError, match=r"about 160,000 triangles .* at least 16 m²"):
        check_triangles(10_000.0, 0.1, 1000)
    with pytest.raises(FloodMeshError, match="of memory"):
        check_triangles(10_000.0, 0.1, 10**9, memory=10**6)


def test_triangulate_refuses_before_triangle_starts():
    """A 1 km square at 0.0001 m² would be 1.6e10 triangles: refused at once, not meshed."""
    square = PSLG(np.array([[0, 0], [1000, 0], [1000, 1000], [0, 1000]], float) + 5e5,
                  np.array([[0, 1], [1, 2], [2, 3], [3, 0]], np.int32), np.empty((0, 2)))
    start = time.perf_counter()
    with pytest.raises(FloodMeshError, match="more than the limit of 5,000,000"):
        triangulate_pslg(square, min_angle=25, max_area=1e-4)
    assert time.perf_counter() - start < 1.0


def test_build_mesh_refuses_above_max_triangles():
    dem = Grid(np.zeros((101, 101)), Affine(1, 0, 5e5, 0, -1, 6e6), CRS.from_epsg(25832))
    with pytest.raises(FloodMeshError, match="more than the limit of 100"):
        build_mesh(dem, [], min_angle=25, max_area=10, max_triangles=100)
    assert len(build_mesh(dem, [], max_area=10, max_triangles=5000).triangles) < 5000


def test_unclassified_las_is_used_whole_and_the_cli_says_so(tmp_path, capsys):
    """A LAS whose points are all class 1 (never ground-classified) is gridded whole, with a
    note on stderr and in the report."""
    path = write_las(tmp_path / "unclassified.laz", plane_xyz(), classes=1)
    notes = []
    assert len(io.read_points(path, note=notes.append)) == 20_000
    assert len(notes) == 1 and "not classified" in notes[0]
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--max-area", "20"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    # its notes: with a cold numba cache the run also says what it compiles
    assert [line for line in err if line.startswith("floodmesh: note:")] == [
        f"floodmesh: note: {notes[0]}"]
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["notes"] == notes
    assert report["n_holdout"] == 20


def test_pipeline_refuses_a_large_mesh_before_gridding(tmp_path):
    """The run's up-front triangle estimate (from the points' footprint) refuses before the grid
    step starts, with the estimate."""
    path = write_las(tmp_path / "p.laz", plane_xyz())
    steps = []
    with pytest.raises(FloodMeshError, match=r"about 4\d,\d{3} triangles .* limit of 1,000"):
        run_pipeline(path, tmp_path / "out", RunOptions(max_area=0.1, max_triangles=1000),
                     log=steps.append)
    assert steps == ["read..."]
    assert not (tmp_path / "out").exists()  # the run's folder appears only when complete
