"""Where water flows (floodmesh.core.steps.drainage): height above the nearest drainage on surfaces
whose drainage is known, and the flow size field in the chain."""
import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from floodmesh.core.steps.drainage import flow_area_for, flow_size, height_above_drainage
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.raster import Grid


def grid(z):
    return Grid(np.asarray(z, float), Affine(1.0, 0, 0, 0, -1.0, 100.0),
                CRS.from_epsg(32756))


def valley(pit=False):
    """A valley along row 50 falling 0.1 % to x = 0, sides rising 10 % from its thalweg."""
    jj, ii = np.meshgrid(np.arange(100) + 0.5, np.arange(101) + 0.5)
    z = 0.001 * jj + 0.1 * np.abs(ii - 50.5)
    if pit:  # a 0.5 m deep pit on the thalweg: it fills and drains over its rim
        z[48:53, 58:63] -= 0.5
    return z


def test_hand_of_a_valley_is_the_height_above_its_thalweg():
    hand, drained = height_above_drainage(grid(valley()), channel_area=500.0)
    rows = np.abs(np.arange(101) - 50)[:, None] + np.zeros(100)
    cols = np.arange(100)[None, :] + np.zeros((101, 1))
    # a path down a side runs diagonally (D8) and meets the thalweg as many cells downstream as
    # it starts from it (0.1 % lower each); nearer the grid's west edge it leaves the grid
    # first: not low ground, NaN
    meets = (cols > rows + 1) & (rows < 49) & (cols < 99)   # the east edge's cells: outlets
    assert np.abs(hand.values - 0.1 * rows)[meets].max() < 0.001 * 50 + 1e-4
    assert np.isnan(hand.values[(cols < rows - 1) & (rows > 1)]).all()
    # the thalweg drains the valley above it: about half of the grid at its foot
    assert drained.values[50, 1] > 0.4 * 101 * 100


def test_a_pit_fills_and_drains_over_its_rim():
    hand, drained = height_above_drainage(grid(valley(pit=True)), channel_area=500.0)
    # the water reaching the pit goes on down the valley: the thalweg below it drains as much
    # as without the pit
    _, plain = height_above_drainage(grid(valley()), channel_area=500.0)
    assert drained.values[50, 20] == pytest.approx(plain.values[50, 20], rel=0.01)
    # the pit lies on the drainage line, its floor below it: low ground
    assert (hand.values[48:53, 58:63] <= 0.11).all() and hand.values[48:53, 58:63].min() < -0.4


def test_flow_size_is_the_flow_area_on_low_ground_only():
    field = flow_size(grid(valley()), flow_area=20.0, height=1.0, channel_area=500.0)
    v = field.values[:, 20:-1]   # the east edge's cells are outlets
    rows = np.abs(np.arange(101) - 50)
    assert (v[rows <= 9] == 20).all()       # 0.9 m or less above the thalweg
    assert np.isnan(v[rows >= 11]).all()    # 1.1 m or more


def test_the_flow_area_is_23_cells_by_default_and_0_turns_it_off():
    from floodmesh.core.options import RunOptions

    assert flow_area_for(None, 1.0) == 23.0 and flow_area_for(None, 0.5) == 5.75
    assert flow_area_for(30.0, 1.0) == 30.0 and flow_area_for(0.0, 1.0) is None
    RunOptions(flow_area=0.0)
    with pytest.raises(FloodMeshError, match="flow area must be 0"):
        RunOptions(flow_area=-5.0)


def test_run_flow_area_puts_triangles_of_that_size_on_the_low_ground(demo_points_file,
                                                                     tmp_path):
    from floodmesh.core import io
    from floodmesh.core.steps.mesh import triangle_areas
    from floodmesh.core.options import RunOptions
    from floodmesh.core.chain.pipeline import run_pipeline

    largest = {}
    for name, area in (("off", 0.0), ("default", None), ("flow", 20.0)):
        run_pipeline(demo_points_file, tmp_path / name, RunOptions(flow_area=area))
        nodes, tri = io.read_mesh_2dm(tmp_path / name / "mesh.2dm")
        dem = io.read_raster(tmp_path / name / "dem.tif")
        low = flow_size(dem, flow_area=20.0).values
        centre = nodes[tri][:, :, :2].mean(axis=1)
        rows, cols = ~dem.transform * (centre[:, 0], centre[:, 1])
        zone = np.isfinite(low[cols.astype(int), rows.astype(int)])
        assert zone.mean() > 0.2                  # the river and its low floodplain
        largest[name] = np.abs(triangle_areas(nodes, tri))[zone].max()
    # the default: 23 cells of the demo's 1 m grid
    assert largest["flow"] <= 20.0 * 1.05 < largest["default"] <= 23.0 * 1.05 < largest["off"]



def test_a_flow_area_mesh_over_the_limit_is_refused_naming_the_flow_area(demo_points_file,
                                                                        tmp_path):
    """The triangle and memory guard counts the flow area's triangles, not the maximum area's:
    a limit that the estimate at the maximum area meets (about 5,100 triangles) but the flow
    area's does not (about 5,700) is refused before Triangle refines, naming --flow-area, and
    leaves no output folder; the same limit with --flow-area 0 meshes."""
    from floodmesh.core.errors import FloodMeshError
    from floodmesh.core.options import RunOptions
    from floodmesh.core.chain.pipeline import run_pipeline

    with pytest.raises(FloodMeshError, match=r"size field asks for triangles .*--flow-area"):
        run_pipeline(demo_points_file, tmp_path / "flow", RunOptions(max_triangles=5400))
    assert not (tmp_path / "flow").exists()
    report = run_pipeline(demo_points_file, tmp_path / "off",
                          RunOptions(max_triangles=5400, flow_area=0.0))
    assert report["triangles"] < 5400


def test_no_line_segment_where_water_flows_is_shorter_than_its_triangles(demo_points_file,
                                                                        tmp_path, monkeypatch):
    """A short break-line segment where water goes makes the smallest wet triangle, which sets
    the flood model's time step: with the flow spacing none is shorter than the flow zone's
    triangle side on the demo's detected lines, but where the terrain needs its vertex (the
    chord past it misses the line by more than the tolerance; without the tolerance, none)."""
    from floodmesh.core import io
    from floodmesh.core.steps.drainage import flow_spacing
    from floodmesh.core.steps import hydraulic_lines
    from floodmesh.core.steps.hydraulic_lines import _spacing_at, lines_for_hydraulics
    from floodmesh.core.options import RunOptions
    from floodmesh.core.chain.pipeline import run_pipeline

    run_pipeline(demo_points_file, tmp_path, RunOptions(min_spacing=0.0))
    dem = io.read_raster(tmp_path / "dem.tif")
    lines = [np.asarray(c, float) for c in io.read_lines_gpkg(tmp_path / "breaklines.gpkg")]
    side = flow_spacing(dem, flow_area=20.0)
    assert np.nanmax(side.values) == pytest.approx(np.sqrt(4 / np.sqrt(3) * 20.0), rel=1e-6)
    plain, _ = lines_for_hydraulics(lines, None, spacing=1.0)
    out, _ = lines_for_hydraulics(lines, None, spacing=1.0, flow_spacing=side)
    monkeypatch.setattr(hydraulic_lines, "FLOW_PLAN_TOLERANCE", np.inf)   # thinned regardless
    monkeypatch.setattr(hydraulic_lines, "FLOW_HEIGHT_TOLERANCE", np.inf)
    strict, _ = lines_for_hydraulics(lines, None, spacing=1.0, flow_spacing=side)

    def short(coords):   # segments shorter than the spacing at their end vertex
        return sum(int((np.hypot(*np.diff(c[:, :2], axis=0).T)
                        < _spacing_at(side, c, 1.0)[1:] - 1e-6).sum()) for c in coords)

    assert short(plain) > 50 and short(strict) == 0 and 0 < short(out) < short(plain) / 2


def test_a_size_field_on_another_grid_combines_with_the_flow_area():
    """A user's size-field raster (here a 2 m grid with a 10 m² half) and the flow area on the
    DEM's 1 m grid: the finer of the two on the DEM's cells (the chain failed on the shapes)."""
    from floodmesh.core.steps.sizing import finer

    dem = grid(valley())
    user = Grid(np.where(np.arange(50)[None, :] < 25, 10.0, np.nan) + np.zeros((51, 1)),
                Affine(2.0, 0, 0, 0, -2.0, 100.0), dem.crs)
    both = finer(user, flow_size(dem, flow_area=20.0, channel_area=500.0)).values
    assert both.shape == dem.shape
    assert (both[:, :50] == 10).all()                       # the user's 10 m² west half
    assert (both[50, 50:99] == 20).all() and np.isnan(both[0, 50:]).all()   # the flow zone
