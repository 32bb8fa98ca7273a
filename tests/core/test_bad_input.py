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


@pytest.mark.parametrize("command", ["run", "grid"])
@pytest.mark.parametrize("classes, words", [
    ("ground", "LAS classes must be comma-separated class numbers 0-255, got 'ground'"),
    ("2,300", "LAS classes are whole numbers 0-255, got 300"),
])
def test_las_classes_other_than_class_numbers_are_refused(command, classes, words, tmp_path,
                                                          capsys):
    """--classes takes comma-separated LAS class numbers 0-255 and says so: a name gave
    'invalid <lambda> value', and a class out of range was left out without a word."""
    from floodmesh.core.errors import FloodMeshError
    from floodmesh.core.options import RunOptions

    with pytest.raises(SystemExit) as exit_:
        main([command, "points.laz", "--out", str(tmp_path / "out"), "--cell-size", "1",
              "--classes", classes])
    assert exit_.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "e.g. 2 (ground)" in lines[0], lines
    with pytest.raises(FloodMeshError, match="0-255, got 300"):  # the library's options
        RunOptions(classes=(2, 300))
