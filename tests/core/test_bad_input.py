"""Every kind of bad input through the command line: exit code 2, one line on stderr that names
the problem, no traceback, and no output file (the cases are in tests/bad_inputs.py)."""
import pytest

from floodmesh.core.frontends.cli import main

from ..bad_inputs import CASES


def cli_error(case, folder, capsys):
    """Run the case's command in this process; return (exit code, stderr lines)."""
    args = [str(a).replace("{out}", str(folder / "out")) for a in case.make(folder)]
    code = main(args)
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_one_line_and_exit_code_2(case, tmp_path, capsys):
    code, lines = cli_error(case, tmp_path, capsys)
    assert code == 2, lines
    assert len(lines) == 1, lines
    assert lines[0].startswith("floodmesh: error: ")
    assert case.words in lines[0]
    out = tmp_path / "out"
    assert not out.exists() or list(out.iterdir()) == [], "bad input left a file behind"


@pytest.mark.parametrize("args", [
    ["run"],
    ["run", "points.laz", "--out", "o", "--cell-size", "one"],
    ["run", "points.laz", "--out", "o", "--slope-method", "steepest"],
    ["mesh", "dem.tif", "--out", "m.2dm", "--max-triangles", "1.5"],
    ["frobnicate"],
])
def test_usage_errors_are_one_line_too(args, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(args)
    assert exit_.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("floodmesh: error: ")
    assert lines[0].endswith("--help)")
