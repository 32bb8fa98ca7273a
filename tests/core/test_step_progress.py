"""The steps as the library, the command line and QGIS's worker call them (``chain.files``):
long work tells its ``progress`` callable how far it is before it ends, and stops when
``cancelled`` says so, leaving no output. Counts of reports, never times."""
import pytest

from floodmesh.core.chain import files
from floodmesh.core.errors import Cancelled


@pytest.fixture(scope="module")
def chain(demo_points_file, tmp_path_factory):
    """The demo floodplain's steps up to the mesh, as files: {name: path}."""
    t = tmp_path_factory.mktemp("progress")
    paths = {name: t / name for name in ("dem.tif", "holdout.gpkg", "slope.tif", "bp.tif",
                                         "lines.gpkg", "simple.gpkg", "mesh.2dm")}
    files.grid(demo_points_file, paths["dem.tif"], cell_size=1.0, holdout=0.01,
               holdout_output=paths["holdout.gpkg"])
    files.slope(paths["dem.tif"], paths["slope.tif"])
    files.breakpoints(paths["slope.tif"], paths["bp.tif"])
    files.trace(paths["bp.tif"], paths["slope.tif"], paths["dem.tif"], paths["lines.gpkg"])
    files.simplify(paths["lines.gpkg"], paths["simple.gpkg"], method="douglas-peucker",
                   amount=0.9)
    files.mesh(paths["dem.tif"], paths["mesh.2dm"], breaklines=paths["simple.gpkg"])
    paths["points"] = demo_points_file
    return paths


STEPS = {
    "trace": lambda p, out, **kw: files.trace(p["bp.tif"], p["slope.tif"], p["dem.tif"],
                                              out / "lines.gpkg", **kw),
    "simplify": lambda p, out, **kw: files.simplify(p["lines.gpkg"], out / "simple.gpkg",
                                                    method="douglas-peucker", amount=0.9, **kw),
    "mesh": lambda p, out, **kw: files.mesh(p["dem.tif"], out / "mesh.2dm",
                                            breaklines=p["simple.gpkg"],
                                            triangles=out / "mesh.gpkg", **kw),
    "refine": lambda p, out, **kw: files.refine(p["dem.tif"], p["points"], out / "fine.2dm",
                                                breaklines=p["simple.gpkg"],
                                                check=p["holdout.gpkg"], max_rounds=2, **kw),
    "assess": lambda p, out, **kw: files.assess(p["mesh.2dm"], p["holdout.gpkg"],
                                                out / "res.gpkg", report=out / "accuracy.json",
                                                png=out / "pics", **kw),
    "export": lambda p, out, **kw: files.export(p["mesh.2dm"], out / "geo.slf",
                                                crs="EPSG:25832", **kw),
}


@pytest.mark.parametrize("step", STEPS)
def test_a_step_reports_its_progress_before_it_ends(chain, tmp_path, step):
    seen = []
    STEPS[step](chain, tmp_path, progress=seen.append)
    assert all(0 <= f <= 1 for f in seen), seen
    assert seen == sorted(seen), f"progress went back: {seen}"
    # the bar moves while the step works, not only when it is done
    assert len({f for f in seen if 0 < f < 1}) >= 3, seen
    assert seen[-1] == 1.0


@pytest.mark.parametrize("step", STEPS)
def test_a_step_stops_when_cancelled_and_writes_nothing(chain, tmp_path, step):
    asked = []

    def cancelled():  # Cancel pressed once the step has begun its work: on the second poll
        asked.append(True)
        return len(asked) >= 2

    with pytest.raises(Cancelled):
        STEPS[step](chain, tmp_path, cancelled=cancelled)
    assert len(asked) == 2
    assert not [p for p in tmp_path.rglob("*") if p.is_file()]


def test_the_bar_takes_out_rounding_but_not_a_step_back():
    """Shares of shares summed in another order round apart (Python 3.12's compensated sum()
    made a run's bar end at 0.9999999999999998 on Debian 13): such rounding is not told as a
    step back or as short of 100 %, while a real step back still shows."""
    from floodmesh.core.engine.progress import steady

    told = []
    tell = steady(told.append)
    for fraction in (0.1 + 0.75, 0.85, 0.5, 0.9999999999999998):
        tell(fraction)
    assert told == [0.1 + 0.75, 0.1 + 0.75, 0.5, 1.0]
