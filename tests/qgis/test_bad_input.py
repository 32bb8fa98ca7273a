"""Every kind of bad input through QGIS (processing.run, as the dialog, the Modeler and scripts
run an algorithm): a QgsProcessingException whose message is the command line's, word for word,
and no output left behind. The cases are in tests/bad_inputs.py."""
import pytest
from qgis.core import QgsProcessingException

from floodmesh.core.frontends.cli import main

from ..bad_inputs import CASES, BadInput

QGIS_CASES = [c for c in CASES if c.qgis is not None]
# parameter values QGIS checks before the run (checkParameterValues) come back with this prefix
BEFORE_RUN = "Unable to execute algorithm\n"


def test_most_cases_reach_qgis():
    # command line only: a .laz name for grid's GeoTIFF, a LoG sigma beyond the data, a CRS
    # given as a name (QGIS's CRS parameter passes a code or WKT), a vertical CRS alone (QGIS
    # 3.22's CRS parameter takes none: the input then has no CRS), what QGIS has no parameter for
    # (assess's pictures folder, two cases, and series) and a GeoPackage's layer by name (two)
    assert len(QGIS_CASES) >= len(CASES) - 9


@pytest.mark.parametrize("case", QGIS_CASES, ids=[c.id for c in QGIS_CASES])
def test_bad_input_is_a_processing_exception_with_the_cli_message(case, processing, tmp_path,
                                                                  capsys):
    args = [str(a).replace("{out}", str(tmp_path / "out")) for a in case.make(tmp_path)]
    assert main(args) == 2
    message = capsys.readouterr().err.strip().removeprefix("floodmesh: error: ")

    folder = tmp_path  # the same input files, written again
    algorithm, parameters = case.qgis(folder)
    with pytest.raises(QgsProcessingException) as raised:
        processing.run(algorithm, parameters)
    got = str(raised.value).removeprefix(BEFORE_RUN)
    assert case.words in got
    assert BadInput.stable(got) == BadInput.stable(message)
    out = folder / "qgis-out"
    assert not out.exists() or list(out.iterdir()) == []


def test_build_mesh_says_what_it_repaired_in_the_break_lines(processing, tmp_path, feedback_log):
    """Crossing and duplicated break lines through Build mesh: a mesh, and the repairs in the
    algorithm's log as warnings, in core's words."""
    import numpy as np
    from pyproj import CRS

    from floodmesh.core import io
    from floodmesh.core.steps.mesh import build_mesh

    from ..bad_inputs import write_tif, slope_dem

    dem = write_tif(tmp_path / "dem.tif", slope_dem())
    x0, y0 = 412_000.0, 5_652_000.0
    cross = [np.array([[x0 + 10, y0 + 10, 11], [x0 + 50, y0 + 50, 13]]),
             np.array([[x0 + 10, y0 + 50, 11], [x0 + 50, y0 + 10, 13]])]
    lines = cross + cross[:1]
    io.write_lines_gpkg(tmp_path / "lines.gpkg", lines, CRS.from_epsg(25832))
    expected = []
    build_mesh(io.read_raster(dem), io.read_lines_gpkg(tmp_path / "lines.gpkg"),
               note=expected.append)
    assert len(expected) == 2
    result = processing.run("floodmesh:buildmesh", {
        "DEM": str(dem), "BREAKLINES": str(tmp_path / "lines.gpkg"),
        "OUTPUT": str(tmp_path / "mesh.2dm")}, feedback=feedback_log)
    assert result["TRIANGLE_COUNT"] > 0 and (tmp_path / "mesh.2dm").exists()
    assert feedback_log.warnings == expected
