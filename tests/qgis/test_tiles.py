"""Tiles in real QGIS: Grid LiDAR points and LiDAR to mesh given several LAZ tiles grid them on a
Dask cluster of threads inside QGIS (processing.run) and inside qgis_process, to the DEM of one
file of the same points."""
import json
import subprocess

import numpy as np
import pytest
from qgis.core import QgsProcessingContext, QgsProcessingFeedback

from floodmesh.core import io

from ..conftest import survey_tiles


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    return survey_tiles(tmp_path_factory.mktemp("survey"), density=2.0)


def test_grid_and_mesh_tiles_through_processing(processing, survey, tmp_path):
    tiles = [str(p) for p in sorted((survey / "tiles").glob("*.laz"))]
    feedback = QgsProcessingFeedback()
    progress = []
    feedback.progressChanged.connect(progress.append)
    result = processing.run("floodmesh:gridpoints", {
        "TILES": tiles, "CELL_SIZE": 1.0, "WORKERS": 2, "OUTPUT": str(tmp_path / "tiles.tif")},
        context=QgsProcessingContext(), feedback=feedback)
    processing.run("floodmesh:gridpoints", {
        "INPUT": str(survey / "single.laz"), "CELL_SIZE": 1.0,
        "OUTPUT": str(tmp_path / "single.tif")},
        context=QgsProcessingContext(), feedback=QgsProcessingFeedback())
    tiled = io.read_raster(result["OUTPUT"])
    single = io.read_raster(tmp_path / "single.tif")
    assert tiled.transform == single.transform
    np.testing.assert_array_equal(tiled.values, single.values)
    assert progress and max(progress) == pytest.approx(100)
    with pytest.raises(Exception, match="an input file, tiles or a folder of tiles, not several"):
        processing.run("floodmesh:gridpoints", {
            "INPUT": str(survey / "single.laz"), "TILES": tiles, "CELL_SIZE": 1.0,
            "OUTPUT": str(tmp_path / "both.tif")},
            context=QgsProcessingContext(), feedback=QgsProcessingFeedback())


def test_qgis_process_meshes_tiles(qgis_process, survey, tmp_path):
    exe, env = qgis_process
    tiles = sorted((survey / "tiles").glob("*.laz"))
    out = tmp_path / "headless"
    run = subprocess.run(
        [exe, "run", "floodmesh:lidartomesh", "--json", "--",
         *[f"TILES={p}" for p in tiles], "MAX_AREA=200", "HOLDOUT=0.01",
         f"OUTPUT_FOLDER={out}"], env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    results = json.loads(run.stdout[run.stdout.index("{"):])["results"]
    report = json.loads((out / "report.json").read_text())
    assert results["NODES"] == report["nodes"] > 100
    # held out as one file of the tiles' points holds them out: 1 % of them
    assert report["holdout_source"] == "LiDAR points withheld from gridding"
    assert report["n_holdout"] == round(0.01 * report["n_points"])
    assert len(report["input"]) == len(tiles)


def test_an_unreadable_tile_is_named_or_left_out_in_qgis(processing, survey, tmp_path):
    """A truncated LAZ in a tile folder: refused naming it and the option; with "Tiles: leave
    out unreadable tiles" the grid is made from the others, with a note naming it."""
    import shutil

    folder = tmp_path / "delivery"
    shutil.copytree(survey / "tiles", folder)
    broken = sorted(folder.glob("*.laz"))[0]
    broken.write_bytes(broken.read_bytes()[:len(broken.read_bytes()) // 2])
    parameters = {"TILE_FOLDER": str(folder), "CELL_SIZE": 1.0, "WORKERS": 1,
                  "OUTPUT": str(tmp_path / "dem.tif")}
    with pytest.raises(Exception, match=f"{broken.name}.*leave out unreadable tiles"):
        processing.run("floodmesh:gridpoints", parameters, context=QgsProcessingContext(),
                       feedback=QgsProcessingFeedback())
    assert not (tmp_path / "dem.tif").exists()
    feedback = QgsProcessingFeedback()
    result = processing.run("floodmesh:gridpoints", {**parameters, "SKIP_UNREADABLE": True},
                            context=QgsProcessingContext(), feedback=feedback)
    assert io.read_raster(result["OUTPUT"]).values.size > 0
    assert broken.name in feedback.textLog()
