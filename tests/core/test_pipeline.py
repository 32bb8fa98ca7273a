"""The whole chain (core.chain.pipeline.run_pipeline) on the demo floodplain and real data."""
import json
import os

import fiona
import numpy as np
import pytest
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.errors import Cancelled
from floodmesh.core.chain.pipeline import OUTPUT_FILES, RunOptions, run_pipeline
from floodmesh.core.points import PointCloud

from ..conftest import REAL_DATA, plane_points

REPORT_KEYS = ("nodes", "triangles", "min_angle_deg", "max_area_m2", "rmse_m", "mean_m",
               "max_abs_residual_m", "n_holdout")


def _mesh_from_gpkg(path):
    """Triangles of mesh.gpkg as a (m, 3, 2) array of full-precision corner coordinates."""
    with fiona.open(path) as src:
        return np.array([[c[:2] for c in f["geometry"]["coordinates"][0][:3]] for f in src])


def _angles_and_areas(corners):
    """Interior angles (degrees) and signed areas of (m, 3, 2) triangles, computed here."""
    angles = []
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        v = corners[:, (k + 2) % 3] - corners[:, k]
        cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        angles.append(np.degrees(np.arctan2(np.abs(cross), (u * v).sum(axis=1))))
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    areas = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    return np.column_stack(angles), areas


def _residuals_from_gpkg(path):
    with fiona.open(path) as src:
        values = [f["properties"]["residual_m"] for f in src]
    return np.array([np.nan if v is None else v for v in values], float)


@pytest.fixture(scope="module")
def demo_run(demo_points_file, tmp_path_factory):
    """One run on the demo floodplain (2 points/m²) with 1 % held out, recording progress and log."""
    out = tmp_path_factory.mktemp("run1")
    fractions, steps = [], []
    report = run_pipeline(demo_points_file, out, RunOptions(holdout=0.01),
                          progress=fractions.append, log=steps.append)
    return out, report, fractions, steps


def test_all_outputs_written(demo_run):
    """All fourteen OUTPUT_FILES exist and no temporary (.partial, hidden) file is left behind."""
    out, _, _, _ = demo_run
    assert len(OUTPUT_FILES) == 14
    names = os.listdir(out)
    assert set(OUTPUT_FILES) <= set(names)
    assert [n for n in names if "partial" in n or n.startswith(".")] == []
    for name in OUTPUT_FILES:
        assert (out / name).stat().st_size > 0


def test_report_json(demo_run):
    """report.json holds the figures returned, with a seconds entry per step."""
    out, report, _, _ = demo_run
    written = json.loads((out / "report.json").read_text())
    for key in REPORT_KEYS:
        assert key in written
        assert written[key] == pytest.approx(report[key], rel=1e-12)
    assert isinstance(written["seconds"], dict)
    assert {"read", "grid", "slope", "breakpoints", "breaklines", "mesh", "assess", "write"} \
        <= set(written["seconds"])
    assert all(v >= 0 for v in written["seconds"].values())


def test_report_pictures(demo_run):
    """The run's residual histogram and map are PNGs listed in the report, the map with green
    points (most of the demo's residuals are under 10 cm)."""
    from matplotlib.image import imread

    from floodmesh.core.options import RESIDUAL_CLASS_COLOURS

    from .test_report import colour_pixels

    out, report, _, _ = demo_run
    assert {"residual_histogram.png", "residual_map.png"} <= set(report["files"])
    for name in ("residual_histogram.png", "residual_map.png"):
        image = imread(out / name)
        assert image.ndim == 3 and image.shape[0] > 200
        assert colour_pixels(image, RESIDUAL_CLASS_COLOURS[0]) > 20, name


def test_progress_and_log(demo_run):
    """Progress rises monotonically from above 0 to 1; the log names the steps in order (besides
    numba's compile, said where the cache is cold: the first run of an install)."""
    from floodmesh.core.engine.compiles import is_compile_message

    _, _, fractions, steps = demo_run
    steps = [step for step in steps if not is_compile_message(step)]
    assert fractions and all(0 < f <= 1 + 1e-12 for f in fractions)
    assert all(b >= a - 1e-12 for a, b in zip(fractions, fractions[1:]))
    assert fractions[-1] == pytest.approx(1.0)
    assert steps[0].startswith("read") and steps[-1].startswith("write")


def test_mesh_bounds_and_accuracy(demo_run):
    """Report: min angle >= 25, max area <= 100, no violations, RMSE < 0.15 m; the angles and areas
    recomputed from mesh.gpkg agree."""
    out, report, _, _ = demo_run
    assert report["min_angle_deg"] >= 25
    assert report["max_area_m2"] <= 100
    assert report["n_below_min_angle"] == 0 and report["n_above_max_area"] == 0
    assert report["rmse_m"] < 0.15
    angles, areas = _angles_and_areas(_mesh_from_gpkg(out / "mesh.gpkg"))
    assert len(areas) == report["triangles"]
    assert angles.min() >= 25 - 1e-6
    assert (areas > 0).all() and areas.max() <= 100 * (1 + 1e-9)


def test_dem_and_mesh_files_match_report(demo_run):
    """dem.tif has the report's grid shape and valid cells; mesh.2dm the report's node and triangle
    counts, with node z inside the DEM's range."""
    out, report, _, _ = demo_run
    dem = io.read_raster(out / "dem.tif")
    assert dem.shape == (report["grid"]["rows"], report["grid"]["cols"])
    assert int(np.isfinite(dem.values).sum()) == report["grid"]["valid_cells"]
    assert dem.cell_size == report["grid"]["cell_size_m"] == 1.0
    nodes, triangles = io.read_mesh_2dm(out / "mesh.2dm")
    assert len(nodes) == report["nodes"] and len(triangles) == report["triangles"]
    assert np.nanmin(dem.values) - 0.01 <= nodes[:, 2].min()
    assert nodes[:, 2].max() <= np.nanmax(dem.values) + 0.01


def test_residuals_file(demo_run):
    """residuals.gpkg holds n_holdout points with residual_m; their RMSE and NaN count are the
    report's."""
    out, report, _, _ = demo_run
    res = _residuals_from_gpkg(out / "residuals.gpkg")
    assert report["n_holdout"] == len(res) == 1440  # 1 % of 144 000 ground points
    assert int(np.isnan(res).sum()) == report["n_outside_mesh"]
    inside = res[np.isfinite(res)]
    assert np.sqrt(np.mean(inside ** 2)) == pytest.approx(report["rmse_m"], rel=1e-9)
    assert np.abs(inside).max() == pytest.approx(report["max_abs_residual_m"], rel=1e-9)


def test_same_inputs_give_identical_mesh(demo_run, demo_points_file, tmp_path):
    """A second run with the same input and seed writes a byte-identical mesh.2dm."""
    out, _, _, _ = demo_run
    run_pipeline(demo_points_file, tmp_path, RunOptions(holdout=0.01))
    assert (tmp_path / "mesh.2dm").read_bytes() == (out / "mesh.2dm").read_bytes()


def test_cancel_at_once(demo_points_file, tmp_path):
    """cancelled() true from the start raises Cancelled and writes no mesh (no file at all)."""
    with pytest.raises(Cancelled):
        run_pipeline(demo_points_file, tmp_path, RunOptions(holdout=0.01), cancelled=lambda: True)
    assert not (tmp_path / "mesh.2dm").exists()
    assert os.listdir(tmp_path) == []


def test_cancel_before_writing(tmp_path):
    """Cancelling after the assessment (just before the write step) leaves no output files."""
    points = tmp_path / "plane.laz"
    io.write_points_las(points, PointCloud(plane_points(size=40.0, density=2.0),
                                           CRS.from_epsg(25832)))
    out = tmp_path / "out"
    seen = []
    with pytest.raises(Cancelled):
        run_pipeline(points, out, RunOptions(holdout=0.05), log=seen.append,
                     cancelled=lambda: any(s.startswith("assess") for s in seen))
    assert [s for s in seen if not s.startswith("note: ")][-1].startswith("assess")
    assert not out.exists() or os.listdir(out) == []  # the folder is made only when complete


# ---------------------------------------------------------------------------------------------
# real data
def _real(name):
    path = REAL_DATA / name
    if not path.is_file():
        pytest.skip(f"{path} is not beside this checkout")
    return path


@pytest.fixture(scope="module")
def merewether_run(tmp_path_factory):
    path = _real("merewether_topography1.asc")
    out = tmp_path_factory.mktemp("merewether")
    return out, run_pipeline(path, out, RunOptions())


@pytest.fixture(scope="module")
def topography_run(tmp_path_factory):
    path = _real("Topography.laz")
    out = tmp_path_factory.mktemp("topography")
    # 0.5 % of the 8159 ground points: 41 check points (the default 0.1 % would give 8, too
    # few for the FEMA/NSSDA test, and is refused)
    return out, run_pipeline(path, out, RunOptions(cell_size=2.0, holdout=0.005))


def _assert_valid_mesh(out, report):
    nodes, triangles = io.read_mesh_2dm(out / "mesh.2dm")
    assert len(nodes) == report["nodes"] > 1000
    assert len(triangles) == report["triangles"]
    assert np.isfinite(nodes).all()
    assert np.unique(triangles).size == len(nodes)
    angles, areas = _angles_and_areas(_mesh_from_gpkg(out / "mesh.gpkg"))
    assert (areas > 0).all(), "triangles not counter-clockwise or degenerate"
    assert areas.max() <= 100 * (1 + 1e-9)
    assert report["all_counter_clockwise"] is True and report["n_above_max_area"] == 0
    dem = io.read_raster(out / "dem.tif")
    assert np.nanmin(dem.values) - 0.01 <= nodes[:, 2].min()
    assert nodes[:, 2].max() <= np.nanmax(dem.values) + 0.01
    xmin, ymin, xmax, ymax = dem.bounds
    assert (nodes[:, 0] >= xmin).all() and (nodes[:, 0] <= xmax).all()
    assert (nodes[:, 1] >= ymin).all() and (nodes[:, 1] <= ymax).all()
    return angles, areas


def test_real_merewether_dem(merewether_run):
    """The 1 m ASCII DEM (UTM 56S from its .prj) runs through: a valid mesh inside the DEM, the
    report's counts, and check points at DEM cell centres assessed."""
    out, report = merewether_run
    _assert_valid_mesh(out, report)
    assert report["grid"]["rows"] == 416 and report["grid"]["cols"] == 321
    assert CRS.from_user_input(report["crs"]) == CRS.from_epsg(32756)
    assert report["n_holdout"] >= 30 and report["n_outside_mesh"] < report["n_holdout"]
    assert report["n_breaklines"] > 0
    assert report["rmse_m"] < 0.5
    assert report["terrain_fit"]["points"] == "DEM cell centres"


def test_real_topography_laz(topography_run):
    """Topography.laz (0.9 points/m², lakes) at 2 m cells: a valid mesh within the area bound,
    with nodata cells over the lakes left out of the mesh."""
    out, report = topography_run
    _assert_valid_mesh(out, report)
    assert report["grid"]["cell_size_m"] == 2.0
    assert report["grid"]["valid_cells"] < report["grid"]["rows"] * report["grid"]["cols"]
    assert report["n_points"] == 8159
    assert report["terrain_fit"]["points"] == "LiDAR points gridded"
    assert report["max_area_m2"] <= 100


@pytest.mark.parametrize("run", ["merewether_run", "topography_run"])
def test_real_data_meets_angle_bound(run, request):
    """On real data every triangle, recomputed from mesh.gpkg, has all angles >= 25 degrees, and the
    report counts no violation."""
    out, report = request.getfixturevalue(run)
    angles, _ = _angles_and_areas(_mesh_from_gpkg(out / "mesh.gpkg"))
    smallest = angles.min(axis=1)
    assert smallest.min() >= 25 - 1e-6, (
        f"{int((smallest < 25 - 1e-6).sum())} triangles below 25 degrees, smallest "
        f"{smallest.min():.2f}")
    assert report["min_angle_deg"] == pytest.approx(smallest.min(), abs=1e-9)
    assert report["n_below_min_angle"] == 0


@pytest.fixture(scope="module")
def bar_run(demo_points_file, tmp_path_factory):
    """A run on the demo floodplain with its bar's fractions and its log in one list, in the
    order told."""
    events = []
    run_pipeline(demo_points_file, tmp_path_factory.mktemp("bar") / "out",
                 RunOptions(holdout=0.01), progress=lambda f: events.append(f),
                 log=lambda m: events.append(m))
    return events


def _told_within(events, step):
    """The fractions told between the log's ``step`` ("mesh...") and the next step's name, or
    the end (its notes and numba's compile messages are no step)."""
    from floodmesh.core.engine.compiles import is_compile_message

    start = events.index(step) + 1
    end = next((k for k in range(start, len(events)) if isinstance(events[k], str)
                and not events[k].startswith("note: ") and not is_compile_message(events[k])),
               len(events))
    return [f for f in events[start:end] if not isinstance(f, str)]


def test_the_bar_moves_inside_tracing_and_simplifying(bar_run):
    """A whole run (`floodmesh run`, LiDAR to mesh) tells its bar along the tracer's and the
    simplifier's work, as their own steps do, not only when each has ended: between the log's
    "breaklines..." and the next step, and "simplify..." and the next, the bar moves several
    times (counted, not timed)."""
    for step in ("breaklines...", "simplify..."):
        inside = _told_within(bar_run, step)
        assert len(inside) >= 3 and all(a <= b for a, b in zip(inside, inside[1:])), (step,
                                                                                      inside)


def test_the_bar_moves_inside_meshing_refining_and_writing(bar_run):
    """After the break lines, a run's longest stretch (meshing with the flow zone's second
    mesh, the misfit pass's mesh, the files) moves the bar too, not only as each ends: several
    distinct fractions inside each of these steps, never back, within 0–1, up to 1 at the
    end."""
    fractions = [f for f in bar_run if not isinstance(f, str)]
    assert all(0 <= f <= 1 for f in fractions), fractions
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    for step in ("mesh...", "refine...", "write..."):
        inside = _told_within(bar_run, step)
        assert len(set(inside)) >= 3, (step, inside)


def test_the_bar_stays_within_the_whole_with_the_laplacian_of_gaussian(tmp_path):
    """The Laplacian of Gaussian's run takes a step more (the first-order slope the tracer
    follows): the bar still ends at 100 %, never past it (it showed 105 %)."""
    points = tmp_path / "plane.laz"
    io.write_points_las(points, PointCloud(plane_points(size=40.0, density=2.0),
                                           CRS.from_epsg(25832)))
    told = []
    run_pipeline(points, tmp_path / "out", RunOptions(holdout=0.05, slope_method="log"),
                 progress=told.append)
    assert all(0 <= f <= 1 for f in told) and told == sorted(told) and told[-1] == 1.0, told


def test_the_bar_moves_inside_localising_and_the_first_refinement_round(bar_run):
    """The hinge fits that put the lines onto the ground ("localise") move the bar while they
    work (it told only their end), and the first refinement round, which fits the node z of the
    run's first mesh and measures its misfit, moves it too: no jump inside the refine step of
    more than a fifth of the step (the first round's half jumped at once, 61 -> 72 %)."""
    assert len(set(_told_within(bar_run, "localise..."))) >= 5, bar_run
    before = [f for f in bar_run[:bar_run.index("refine...")] if not isinstance(f, str)][-1:]
    told = before + _told_within(bar_run, "refine...")
    assert max(np.diff(told)) <= (told[-1] - told[0]) / 5, told


def test_the_bar_moves_inside_the_fit_window(bar_run):
    """Sizing the fit window from the points' noise ("fit window", the plane fits at 400
    places) moves the bar along its fits, never back (it told only its end)."""
    inside = _told_within(bar_run, "fit window...")
    assert len(set(inside)) >= 4 and inside == sorted(inside), inside


def test_the_bar_moves_inside_node_elevations(demo_points_file, tmp_path):
    """A run without the misfit pass fits its mesh's node z on local planes ("node
    elevations"): the bar moves inside that step too (it told only its end), never back,
    within 0–1, up to 1 at the end."""
    events = []
    run_pipeline(demo_points_file, tmp_path / "out", RunOptions(holdout=0.01, misfit_passes=0),
                 progress=events.append, log=events.append)
    fractions = [f for f in events if not isinstance(f, str)]
    assert all(0 <= f <= 1 for f in fractions), fractions
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert len(set(_told_within(events, "node elevations..."))) >= 4, events


@pytest.mark.parametrize("step", ["mesh...", "localise...", "node elevations..."])
def test_cancel_as_a_step_begins_stops_there(demo_points_file, tmp_path, step):
    """Cancel pressed as the mesh step (a big run's longest), the hinge fits ("localise") or
    the node z's plane fits ("node elevations", a run without the misfit pass) begin is
    honoured inside the step: the run stops with Cancelled, the bar moves no further and no
    later step starts, and no output folder nor staging folder is left."""
    events = []

    def cancelled():
        return step in events

    out = tmp_path / "out"
    options = RunOptions(holdout=0.01, misfit_passes=0 if step == "node elevations..." else 1)
    with pytest.raises(Cancelled):
        run_pipeline(demo_points_file, out, options, cancelled=cancelled,
                     progress=lambda f: events.append(f), log=lambda m: events.append(m))
    from floodmesh.core.engine.compiles import is_compile_message

    after = [e for e in events[events.index(step) + 1:]
             if not isinstance(e, str) or not (e.startswith("note: ") or is_compile_message(e))]
    assert after == [], after
    assert os.listdir(tmp_path) == []
