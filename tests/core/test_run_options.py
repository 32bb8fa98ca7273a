"""RunOptions as a library user builds them from a config file or argv: text where the chain wants
a switch, a number, a list of formats or of classes."""
import pytest

from floodmesh.core import FloodMeshError, RunOptions


@pytest.mark.parametrize("name", ["refine", "localise", "conforming", "zero_crossings",
                                  "processes"])
@pytest.mark.parametrize("value", ["False", "True", "", 0, None])
def test_a_switch_must_be_true_or_false(name, value):
    # refine="False" is truthy: it used to run the refinement, a different mesh and no word
    with pytest.raises(FloodMeshError, match=f"{name} must be True or False.*{name}=False"):
        RunOptions(**{name: value})


def test_numbers_given_as_text_are_converted_like_the_steps_convert_them():
    # cell_size="1.0" used to pass validate() and fail with a TypeError in the chain
    given = RunOptions(cell_size="1.0", max_area="50", flow_area="10", min_spacing="1",
                       misfit_passes="1", seed="3", keep_every="4", max_gap="12.5")
    assert given == RunOptions(cell_size=1.0, max_area=50.0, flow_area=10.0, min_spacing=1.0,
                               misfit_passes=1, seed=3, keep_every=4, max_gap=12.5)
    assert type(given.cell_size) is float and type(given.misfit_passes) is int


@pytest.mark.parametrize("kw, words", [
    (dict(cell_size="one"), "cell_size must be a number, got 'one'"),
    (dict(flow_area=[10]), "flow_area must be a number"),
    (dict(min_spacing="nan"), "min_spacing must be a number, got NaN"),
    (dict(cell_size=True), "cell_size must be a number, got True"),
    (dict(seed="1.5"), "random seed must be a whole number"),
    (dict(misfit_passes="9"), "from 0 (off) to 8, got 9"),
])
def test_text_that_is_no_number_is_refused_naming_the_field(kw, words):
    with pytest.raises(FloodMeshError, match=words.replace("(", r"\(").replace(")", r"\)")):
        RunOptions(**kw)


def test_formats_and_classes_as_text_are_read_as_the_command_line_reads_them():
    assert RunOptions(formats="slf").formats == ("slf",)  # was "unknown mesh format 's'"
    assert RunOptions(formats="2dm, .SLF").formats == ("2dm", "slf")
    assert RunOptions(classes="2,9").classes == (2, 9)  # was "got 2, ,, 9"
    assert RunOptions(classes=2).classes == (2,)  # was a TypeError
    assert RunOptions(classes=[2, 9]).classes == (2, 9)


@pytest.mark.parametrize("kw, words", [
    (dict(formats="shp"), "unknown mesh format 'shp'"),
    (dict(classes="ground"), "comma-separated class numbers"),
    (dict(classes=2.5), "list of class numbers 0-255, got 2.5"),
])
def test_bad_formats_and_classes_are_named(kw, words):
    with pytest.raises(FloodMeshError, match=words):
        RunOptions(**kw)


@pytest.mark.parametrize("name", ["seed", "keep_every", "min_points", "max_triangles",
                                  "misfit_passes", "workers"])
def test_an_integer_field_takes_a_whole_number_as_a_number_or_as_text(name):
    # seed="3.0" was 3 but seed=3.0 was refused (and keep_every=3.0 stayed a float)
    for value in (3.0, "3.0", "3", 3):
        given = getattr(RunOptions(**{name: value}), name)
        assert given == 3 and type(given) is int, value
    for value in (3.5, "3.5"):
        with pytest.raises(FloodMeshError, match=r"whole number.*got 3\.5"):
            RunOptions(**{name: value})


def test_the_command_line_takes_integers_by_the_same_rule(tmp_path, capsys):
    from floodmesh.core.frontends.cli import main

    missing = tmp_path / "missing.laz"
    with pytest.raises(SystemExit):
        main(["run", str(missing), "--out", str(tmp_path / "out"), "--seed", "3.5"])
    assert capsys.readouterr().err.strip() == (
        "floodmesh: error: argument --seed: must be a whole number, got 3.5 "
        "(see floodmesh run --help)")
    assert main(["run", str(missing), "--out", str(tmp_path / "out"), "--seed", "3.0",
                 "--misfit-passes", "1.0"]) == 2  # --seed 3.0 was "invalid int value"
    err = capsys.readouterr().err
    assert "missing.laz" in err and "--seed" not in err, err
