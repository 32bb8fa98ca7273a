"""Every kind of bad input through QGIS (processing.run, as the dialog, the Modeler and scripts
run an algorithm): a QgsProcessingException whose message is the command line's, word for word,
and no output left behind. The cases are in tests/bad_inputs.py."""
import pytest
from qgis.core import QgsProcessingException

from floodmesh.core.cli import main

from ..bad_inputs import CASES, BadInput

QGIS_CASES = [c for c in CASES if c.qgis is not None]
# parameter values QGIS checks before the run (checkParameterValues) come back with this prefix
BEFORE_RUN = "Unable to execute algorithm\n"


def test_most_cases_reach_qgis():
    assert len(QGIS_CASES) >= len(CASES) - 1


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
