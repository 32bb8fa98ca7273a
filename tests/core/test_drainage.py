"""Where water flows (floodmesh.core.steps.drainage): height above the nearest drainage on surfaces
whose drainage is known, and the flow size field in the chain."""
import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from floodmesh.core.steps.drainage import flow_area_for, flow_size, height_above_drainage
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.raster import Grid

from ..conftest import low_ground_triangles, swaled


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


def test_the_flow_area_refines_low_ground_where_the_terrain_needs_it_only(demo_points_file,
                                                                          tmp_path):
    """The user's side of issue 28 item 2: on the demo floodplain, whose low ground is a plane
    between its break lines, the default mesh has at most 10 % more nodes than --flow-area 0
    (it had 46 % more when every cell of low ground took the flow area); where that low ground
    has swales (15 cm, 6 m apart, a street's kerbs and gutters would do), its triangles take
    the flow area (23 m² on the 1 m grid, or a given one), while its plane half keeps the
    maximum area's."""
    from scipy.ndimage import binary_erosion

    from floodmesh.core import io
    from floodmesh.core.options import RunOptions
    from floodmesh.core.chain.pipeline import run_pipeline

    reports = {name: run_pipeline(demo_points_file, tmp_path / name, RunOptions(flow_area=area))
               for name, area in (("off", 0.0), ("default", None))}
    assert reports["default"]["nodes"] <= 1.10 * reports["off"]["nodes"]
    assert reports["default"]["flow_zone"]["low_ground_share"] > 0.2   # the river's floodplain
    assert reports["default"]["flow_zone"]["refined_share"] < 0.01
    dem, _ = swaled(io.read_raster(tmp_path / "off" / "dem.tif"))
    io.write_raster(tmp_path / "swaled.tif", dem)
    # the low ground of the swaled DEM, 5 m in from its edge, in the west and the east half
    low = binary_erosion(np.isfinite(flow_size(dem, flow_area=23.0).values), iterations=5)
    half = np.arange(dem.shape[1]) < dem.shape[1] // 2
    west, east = low & half, low & ~half
    largest = {}
    for name, area in (("off", 0.0), ("default", None), ("flow", 15.0)):
        report = run_pipeline(tmp_path / "swaled.tif", tmp_path / f"swaled-{name}",
                              RunOptions(flow_area=area))
        # nearly all swaled triangles (a few under coarse triangles too small to tell relief
        # from noise are left), and the largest plane one
        mesh = tmp_path / f"swaled-{name}" / "mesh.2dm"
        largest[name] = (np.quantile(low_ground_triangles(mesh, dem, west), 0.95),
                         low_ground_triangles(mesh, dem, east).max())
        if area is None:   # the lines thinned to the flow spacing near there only
            zone = report["flow_zone"]
            assert 0 < zone["refined_share"] < zone["low_ground_share"]
            assert zone["refined_share"] < zone["thinned_share"] < 0.9
    assert largest["flow"][0] <= 15 * 1.05 < largest["default"][0] <= 23 * 1.05
    # without the flow area the swales keep triangles twice the flow area's and more (over
    # 50 m² until the hinge fits' shorter windows localised more of the swales' kinks: 49 m²)
    assert largest["off"][0] > 2 * 23 and min(largest[name][1] for name in largest) > 50


def test_a_flow_area_mesh_over_the_limit_is_refused_naming_the_flow_area(demo_points_file,
                                                                        tmp_path):
    """The triangle and memory guard counts the flow area's triangles, not the maximum area's:
    on a DEM whose low ground needs the flow area (swales), a limit that the estimate at the
    maximum area meets (about 6,930 triangles) but that of a flow area of 5 m² does not is
    refused before Triangle refines, naming --flow-area, and leaves no output folder; the same
    limit with --flow-area 0 meshes."""
    from floodmesh.core import io
    from floodmesh.core.errors import FloodMeshError
    from floodmesh.core.options import RunOptions
    from floodmesh.core.chain.pipeline import run_pipeline

    run_pipeline(demo_points_file, tmp_path / "demo", RunOptions(flow_area=0.0))
    dem, _ = swaled(io.read_raster(tmp_path / "demo" / "dem.tif"))
    io.write_raster(tmp_path / "swaled.tif", dem)
    limit = 7300   # the estimate at the maximum area: about 6,930 triangles
    with pytest.raises(FloodMeshError, match=r"size field asks for triangles .*--flow-area"):
        run_pipeline(tmp_path / "swaled.tif", tmp_path / "flow",
                     RunOptions(max_triangles=limit, flow_area=5.0))
    assert not (tmp_path / "flow").exists()
    report = run_pipeline(tmp_path / "swaled.tif", tmp_path / "off-again",
                          RunOptions(max_triangles=limit, flow_area=0.0))
    assert report["triangles"] < limit


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


def planes(noise=0.0, swales=0.0, seed=0):
    """A 80 x 80 m plane rising 1 % east and 0.5 % north, 1 m cells, with independent noise
    (m) and swales (amplitude m, 6 m apart, across x)."""
    jj, ii = np.meshgrid(np.arange(80) + 0.5, np.arange(80) + 0.5)
    z = 0.01 * jj + 0.005 * (80 - ii) + swales * np.sin(2 * np.pi * jj / 6.0)
    return grid(z + np.random.default_rng(seed).normal(0, noise, z.shape) if noise else z)


def test_dem_noise_is_the_cells_independent_noise_and_zero_on_a_plane():
    from floodmesh.core.steps.drainage import dem_noise

    assert dem_noise(planes()) < 1e-9
    for sigma in (0.02, 0.05, 0.15):
        assert dem_noise(planes(noise=sigma)) == pytest.approx(sigma, rel=0.06)


def test_relief_no_triangle_follows_is_told_from_noise():
    """``misfit_triangles`` flags the triangles of a 100 m² mesh over swales of 10 cm under
    5 cm of noise, none over the same noisy plane (a plane's misfit is noise alone, which the
    margin keeps from passing by chance), and none for a node set 50 cm off (the triangle's
    plane, not its nodes, is what the relief is measured against)."""
    from floodmesh.core.steps.drainage import misfit_triangles
    from floodmesh.core.steps.mesh import build_mesh

    mesh = build_mesh(planes(), [], max_area=100.0)
    everywhere = np.ones((80, 80), bool)
    flat, sigma = misfit_triangles(planes(noise=0.05), everywhere, mesh.nodes, mesh.triangles)
    assert sigma == pytest.approx(0.05, rel=0.1) and flat.mean() < 0.02
    swaled, _ = misfit_triangles(planes(noise=0.05, swales=0.1), everywhere, mesh.nodes,
                                 mesh.triangles)
    assert swaled.mean() > 0.9
    nodes = mesh.nodes.copy()
    nodes[len(nodes) // 2, 2] += 0.5
    offset, _ = misfit_triangles(planes(), everywhere, nodes, mesh.triangles)
    assert not offset.any()
    # only the cells asked about: the swales' west half
    west = everywhere.copy()
    west[:, 40:] = False
    half, _ = misfit_triangles(planes(swales=0.1), west, mesh.nodes, mesh.triangles)
    assert not half[:, 40:].any() and half[:, :35].mean() > 0.9


def test_the_dem_rounding_a_line_s_kink_is_not_relief_to_refine():
    """A DEM rounds the kink a break line carries over the cell or so beside it (TIN gridding
    does): that is the line's, not relief a shallow flood follows between lines. Cells beside a
    line (a 6 cm ridge along it here) are left out of the test: given the line, nothing is
    refined; not told of it, the triangles along it are."""
    from floodmesh.core.steps.drainage import flow_refined
    from floodmesh.core.steps.mesh import build_mesh

    dem = planes()
    x, y = dem.cell_centres(*np.indices(dem.shape))
    line = np.array([[40.0, y.min(), 0.0], [40.0, y.max(), 0.0]])   # across the whole grid
    dem = dem.with_values(dem.values + 0.06 * (np.abs(x - 40.0) < 1.0))
    mesh = build_mesh(dem, [line], max_area=100.0)
    flow = dem.with_values(np.full(dem.shape, 23.0, np.float32))
    builds = []

    def build(size, spacing, note, **progress_cancelled):
        builds.append(size)
        return mesh

    _, _, told = flow_refined(build, None, flow, None, dem, lines=[line])
    assert told["refined_share"] == 0 and len(builds) == 1
    _, _, untold = flow_refined(build, None, flow, None, dem)
    assert untold["refined_share"] > 0.05 and len(builds) == 3
