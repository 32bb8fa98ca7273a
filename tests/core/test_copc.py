"""Cloud-optimised input (issue 29): COPC files as tiles, and one COPC file larger than memory
read in spatial windows (its octree nodes that reach each window), gridded to the DEM of the
same points as one LAZ file, with no re-tiling. The COPC files are written by tests/copc.py
and read back by laspy's own COPC reader."""
from pathlib import Path

import numpy as np
import pytest

from floodmesh.core import io
from floodmesh.core.chain.pipeline import run_pipeline
from floodmesh.core.chain.source import POINT_TILES, POINTS, open_source
from floodmesh.core.engine import tiles
from floodmesh.core.options import RunOptions
from floodmesh.core.points import PointCloud

from ..conftest import survey_tiles
from ..copc import write_copc


def _sorted(xyz):
    return xyz[np.lexsort(xyz.T[::-1])]


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """The test survey as one LAZ file, as one COPC file of the same points, and its four
    tiles as COPC files."""
    root = survey_tiles(tmp_path_factory.mktemp("copc"))
    whole = io.read_points(root / "single.laz")
    write_copc(root / "reach.copc.laz", whole.xyz, crs_wkt=whole.crs.to_wkt())
    (root / "copc_tiles").mkdir()
    for tile in sorted((root / "tiles").glob("*.laz")):
        points = io.read_points(tile)
        write_copc(root / "copc_tiles" / f"{tile.stem}.copc.laz", points.xyz,
                   crs_wkt=points.crs.to_wkt())
    return root


def test_copc_tiles_grid_to_the_dem_of_their_las_tiles(survey, tmp_path):
    options = RunOptions()  # the default holdout too: drawn by place, not by tile name or order
    copc = run_pipeline(survey / "copc_tiles", tmp_path / "copc", options)
    las = run_pipeline(survey / "tiles", tmp_path / "las", options)
    assert copc["n_points"] == las["n_points"]
    assert io.read_raster(tmp_path / "copc" / "dem.tif").values.tobytes() == \
        io.read_raster(tmp_path / "las" / "dem.tif").values.tobytes()
    # the same points in octree order give the same mesh: the holdout and the terrain fits
    # draw their samples by place, not by index or tile name (draws by index gave 1,472 against
    # 1,539 nodes without a holdout, 1,466 against 1,504 with the default one)
    assert copc["nodes"] == las["nodes"]
    assert (tmp_path / "copc" / "mesh.2dm").read_bytes() == \
        (tmp_path / "las" / "mesh.2dm").read_bytes()


def test_a_copc_file_gives_the_mesh_of_its_las_file(survey, tmp_path):
    """One file of the survey, as a LAZ file in its flight lines' order and as a COPC file in
    octree order, with the default options: the same check points and the same mesh."""
    copc = run_pipeline(survey / "reach.copc.laz", tmp_path / "copc", RunOptions())
    las = run_pipeline(survey / "single.laz", tmp_path / "las", RunOptions())
    assert copc["n_holdout"] == las["n_holdout"] > 0
    checks = [_sorted(io.read_points_vector(tmp_path / name / "residuals.gpkg"))
              for name in ("copc", "las")]
    assert np.array_equal(*checks)
    assert (tmp_path / "copc" / "mesh.2dm").read_bytes() == \
        (tmp_path / "las" / "mesh.2dm").read_bytes()


def test_a_copc_file_that_fits_is_one_point_file(survey):
    assert open_source(survey / "reach.copc.laz").kind == POINTS


def test_windows_of_a_copc_file_hold_every_point_once(survey, monkeypatch):
    monkeypatch.setattr(tiles, "WINDOW_POINTS", 40_000)
    found, _, _ = tiles.check_point_tiles([survey / "reach.copc.laz"])
    assert len(found) >= 6 and all(tiles._WINDOW in t.path for t in found)
    parts = [tiles._read_raw(Path(t.path))[:2] for t in found]
    assert all(len(xyz) for xyz, _ in parts)
    whole = io.read_points(survey / "reach.copc.laz").xyz
    np.testing.assert_array_equal(_sorted(np.concatenate([xyz for xyz, _ in parts])),
                                  _sorted(whole))
    # read in memory, window after window, as the tiles of a delivery are
    read = tiles.read_point_tiles([survey / "reach.copc.laz"], 1.0)
    assert read.n_tiles == len(found) and read.n_points == len(whole)


def test_a_copc_file_larger_than_memory_runs_in_windows_to_the_one_files_mesh(survey, tmp_path,
                                                                             monkeypatch):
    """More points than memory holds: the COPC file becomes its windows, gridded on a local
    cluster; with the default options the run gives the check points, DEM, break lines and mesh
    of one LAZ file of the same points to the byte (in the windows' order: the terrain fits'
    sums follow the order of the points, the lines' coordinates to round-off)."""
    monkeypatch.setattr(tiles, "WINDOW_POINTS", 40_000)
    copc = survey / "reach.copc.laz"
    windows, crs, _ = tiles.check_point_tiles([copc])
    in_order = tmp_path / "in_order.laz"
    io.write_points_las(in_order, PointCloud(np.concatenate(
        [tiles._read_raw(Path(w.path))[0] for w in windows]), crs))
    monkeypatch.setattr(tiles, "fits_in_memory", lambda **sizes: False)  # too many points
    assert open_source(copc).kind == POINT_TILES
    options = RunOptions(workers=2)
    windowed = run_pipeline(copc, tmp_path / "windowed", options)
    single = run_pipeline(in_order, tmp_path / "single", options)
    assert "read back" in windowed["seconds"]  # gridded on the cluster, the points read back
    assert windowed["n_points"] == single["n_points"] == len(io.read_points(copc))
    assert windowed["n_holdout"] == single["n_holdout"] > 0
    assert np.array_equal(*[_sorted(io.read_points_vector(tmp_path / name / "residuals.gpkg"))
                            for name in ("windowed", "single")])
    assert io.read_raster(tmp_path / "windowed" / "dem.tif").values.tobytes() == \
        io.read_raster(tmp_path / "single" / "dem.tif").values.tobytes()
    for name in ("mesh.2dm", "breaklines.gpkg"):
        assert (tmp_path / "windowed" / name).read_bytes() == \
            (tmp_path / "single" / name).read_bytes(), name
