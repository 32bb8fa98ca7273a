"""A survey sparser than its grid (issue 28's real samples: 0.1-0.4 ground points/m² gridded at
1 m, where the break lines followed the TIN's facets) is said so, with the cell size that
suits it; a survey of a point a cell or more says nothing."""
import pytest

from floodmesh.core import io
from floodmesh.core.chain.pipeline import run_pipeline
from floodmesh.core.frontends.demo import synthetic_floodplain
from floodmesh.core.options import RunOptions
from floodmesh.core.points import sparse_survey_note

from ..conftest import REAL_DATA


def test_the_note_gives_the_density_and_a_cell_of_one_point():
    # the Québec sample: 8,159 ground points over 62,752 cells of 1 m
    said = sparse_survey_note(8159, 62752, 1.0)
    assert "0.13 ground points/m²" in said and "about 3 m" in said and "--cell-size" in said
    assert "about 1.5 m" in sparse_survey_note(26000, 62000, 1.0)   # 0.42 a cell: Autzen's
    assert sparse_survey_note(62752, 62752, 1.0) is None      # a point a cell
    assert sparse_survey_note(31376, 62752, 1.0) is None      # half a point a cell: the bar
    assert sparse_survey_note(0, 62752, 1.0) is None          # a DEM: no points
    # the cell size counts: 0.13 points/m² on a 4 m grid is two points a cell
    assert sparse_survey_note(8159, 62752 // 16, 4.0) is None


def test_a_sparse_run_says_it_and_a_dense_one_does_not(tmp_path):
    notes = {}
    for density in (0.2, 2.0):
        points, classes = synthetic_floodplain(density=density, seed=3)
        io.write_points_las(tmp_path / f"{density}.laz", points, classes=classes)
        report = run_pipeline(tmp_path / f"{density}.laz", tmp_path / f"out{density}",
                              RunOptions())
        notes[density] = [n for n in report["notes"] if "ground points/m²" in n]
    assert len(notes[0.2]) == 1 and "about 2 m" in notes[0.2][0]
    assert notes[2.0] == []


@pytest.mark.skipif(not (REAL_DATA / "Topography.laz").is_file(), reason="../shared absent")
def test_the_quebec_sample_is_said_to_be_sparse(tmp_path):
    report = run_pipeline(REAL_DATA / "Topography.laz", tmp_path / "out", RunOptions())
    assert any("a cell size of about 3 m" in n for n in report["notes"])
