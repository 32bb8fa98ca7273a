"""Break lines a flood model can afford: clipped back from the domain edge, cut where they run
near other lines, vertices no closer than the spacing; and on the demo floodplain the mesh's
smallest triangle (and so the solver's time step) grows several times."""
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS

from floodmesh.core.raster import Grid
from floodmesh.core.steps.hydraulic_lines import (drop_spikes, lines_for_hydraulics,
                                                  split_at_folds, thin_vertices)
from floodmesh.core.steps.hydraulics import inradii
from floodmesh.core.steps.mesh import build_mesh, domain_from_dem
from floodmesh.core import io
from floodmesh.core.frontends.demo import synthetic_floodplain
from floodmesh.core.options import RunOptions
from floodmesh.core.chain.pipeline import run_pipeline


def test_a_line_crossing_itself_well_inside_is_split_at_the_crossing():
    """A loop that crosses itself with gentle turns (no fold to split it) far from the edge:
    its arms leave the crossing as separate lines, none crossing another, the loop kept a
    spacing clear of them (a whole self-crossing line made the PSLG node it there itself)."""
    domain = shapely.box(0, 0, 200, 200)
    t = np.linspace(-1.6, 1.6, 161)
    alpha = np.column_stack([30 * (t * t - 1) + 100, 30 * (t ** 3 - t) + 100, np.full(161, 5.0)])
    assert not shapely.is_simple(shapely.LineString(alpha))
    out, _ = lines_for_hydraulics([alpha], domain, spacing=1.0)
    geoms = [shapely.LineString(c[:, :2]) for c in out]
    assert len(geoms) == 3 and all(shapely.is_simple(geoms))
    assert not any(shapely.crosses(a, b) for i, a in enumerate(geoms) for b in geoms[i + 1:])
    assert np.allclose(out[0][-1, :2], (100.0, 100.0))  # an arm ends at the crossing


def test_lines_keep_clear_of_the_edge_and_of_other_lines():
    domain = shapely.box(0, 0, 100, 50)
    along_edge = np.array([[10, 0.4, 1], [90, 0.4, 1]])          # 0.4 m inside the edge
    # crosses the own line and the longer one at their heights, climbing 3 m between them
    crossing = np.array([[50, 5, 0], [50, 20, 0], [50, 30, 3], [50, 45, 3]])
    parallel = np.array([[20, 30.5, 3], [80, 30.5, 3]])          # 0.5 m from a longer line
    longer = np.array([[10, 30, 3], [90, 30, 3]])
    own = [np.array([[5, 20, 0], [95, 20, 0]])]
    out, stats = lines_for_hydraulics([along_edge, crossing, parallel, longer], domain,
                                      spacing=1.0, own_lines=own)
    geoms = [shapely.LineString(c[:, :2]) for c in out]
    assert all(shapely.distance(g, domain.exterior) >= 2.0 - 1e-9 for g in geoms)
    own_line = shapely.LineString(own[0][:, :2])
    # a spacing off the own line, or meeting it with an end (a junction), never beside it
    for g in geoms:
        gap = shapely.distance(g, own_line)
        ends = shapely.distance(shapely.points(np.asarray(g.coords)[[0, -1]]), own_line)
        assert gap >= 1.0 - 1e-9 or (gap < 1e-9 and ends.min() < 1e-9
                                     and shapely.length(shapely.intersection(g, own_line)) == 0)
    # the crossing line is cut where it crosses the own line and the longer line (3 pieces),
    # and its pieces' ends joined onto those lines, at the same points from either side; the
    # parallel one is merged away into the longer, which stays whole
    assert stats["cut_near_other_lines"] >= 2 and stats["clipped_at_edge"] >= 1
    crossing = [c for c in out if np.allclose(c[:, 0], 50)]
    assert len(crossing) == 3 and stats["ends_joined"] == 4
    assert sorted(float(y) for c in crossing for y in c[[0, -1], 1]) == pytest.approx(
        [5, 20, 20, 30, 30, 45])
    assert not any(np.allclose(c[:, 1], 30.5) for c in out)
    assert any(np.allclose(c[:, 1], 30) and np.ptp(c[:, 0]) == pytest.approx(80) for c in out)
    assert all(c.shape[1] == 3 for c in out)   # z kept (interpolated at the cuts)


def test_thin_vertices_keeps_the_ends_and_the_spacing():
    line = np.column_stack([[0, 0.3, 0.6, 1.2, 2.5, 2.9, 3.0], np.zeros(7)])
    thinned = thin_vertices(line, 1.0)
    assert thinned[0, 0] == 0 and thinned[-1, 0] == 3.0
    assert (np.diff(thinned[:, 0]) >= 1.0 - 1e-12).all()


def test_thinning_to_the_flow_spacing_keeps_what_the_terrain_needs():
    """Where water flows the lines thin to the flow spacing only where the chord past a vertex
    holds it within the tolerance (plan 0.25 m, height 5 cm here): an even straight line thins
    fully, a kerb (a 15 cm step in its height) keeps the vertices at the step, also near the
    line's end, and a corner its corner; a smooth bend, each vertex within the tolerance of its
    chord, thins."""
    x = np.arange(0, 41.0)
    even = np.column_stack([x, np.zeros_like(x), 0.01 * x])      # a plane rising 1 %
    args = dict(firm=1.0, tolerance=(0.25, 0.05))
    assert thin_vertices(even, 8.0, **args)[:, 0].tolist() == [0, 8, 16, 24, 32, 40]
    kerbed = even.copy()
    kerbed[20:, 2] += 0.15
    assert thin_vertices(kerbed, 8.0, **args)[:, 0].tolist() == [0, 8, 16, 19, 20, 28, 40]
    assert thin_vertices(kerbed, 8.0)[:, 0].tolist() == [0, 8, 16, 24, 32, 40]  # without it
    # a step within the spacing of the line's end stays too (the end once took it away)
    assert thin_vertices(kerbed[:23], 8.0, **args)[:, 0].tolist() == [0, 8, 16, 19, 20, 22]
    assert thin_vertices(kerbed[:23], 8.0)[:, 0].tolist() == [0, 8, 22]
    corner = np.vstack([np.column_stack([x[:21], np.zeros(21)]),
                        np.column_stack([np.full(20, 20.0), x[1:21]])])
    kept = thin_vertices(corner, 8.0, **args)[:, :2].tolist()
    assert kept == [[0, 0], [8, 0], [16, 0], [20, 0], [20, 8], [20, 20]]
    t = np.linspace(0, np.pi / 2, 81)
    arc = np.column_stack([20 * np.cos(t), 20 * np.sin(t), np.zeros_like(t)])
    assert len(thin_vertices(arc, 8.0, **args)) == len(thin_vertices(arc, 8.0))
    # never closer than the firm spacing, whatever the terrain
    zigzag = np.column_stack([x / 2, 0.3 * (np.arange(41) % 2), np.zeros_like(x)])
    assert np.hypot(*np.diff(thin_vertices(zigzag, 8.0, **args)[:, :2], axis=0).T).min() >= 1.0


def test_default_mesh_of_the_demo_affords_a_longer_time_step(demo_points_file, tmp_path):
    plain = run_pipeline(demo_points_file, tmp_path / "plain", RunOptions(min_spacing=0))
    default = run_pipeline(demo_points_file, tmp_path / "default", RunOptions())
    assert plain["hydraulic_lines"] is None and default["hydraulic_lines"]["spacing_m"] == 1.0
    h0, h1 = plain["hydraulics"], default["hydraulics"]
    assert h0["n_small_inradius_near_edge"] > 0 and h1["n_small_inradius"] == 0
    assert h1["cfl_time_step_s"] > 3 * h0["cfl_time_step_s"]
    assert default["n_missing_segments"] == 0 and default["n_below_min_angle"] == 0
    # the terrain error stays where it was (within a centimetre)
    assert default["rmse_m"] < plain["rmse_m"] + 0.01


def test_the_misfit_pass_leaves_the_edge_band_to_the_edge_nodes(tmp_path):
    """The misfit pass split triangles within the 2 m band the lines keep clear of the domain
    edge, and its splits made the smallest triangles there (0.31 m on the demo), where a flood
    flows in and out: 91 % of the demo levee flood's time steps. Now the band has none under
    half a metre, and the held-out error is the same."""
    points, classes = synthetic_floodplain()  # `floodmesh demo`'s survey
    io.write_points_las(tmp_path / "demo.laz", points, classes=classes)
    report = run_pipeline(tmp_path / "demo.laz", tmp_path / "out", RunOptions())
    h = report["hydraulics"]
    assert h["edge_band_m"] == 2.0 and h["min_inradius_near_edge_m"] > 0.5
    assert report["rmse_m"] < 0.058  # 5.7 cm, as with the splits


def test_the_pieces_of_a_cut_line_stay_a_spacing_apart():
    """A line grazing another's buffer is cut into two pieces a hair apart; they may not keep
    two nodes 0.2 m apart (found on Merewether)."""
    longer = np.array([[0, 0, 0], [40, 0, 0]])
    grazing = np.array([[0, 5, 0], [20, 0.99, 0], [40, 5, 0]])  # dips 1 cm into the buffer
    out, _ = lines_for_hydraulics([longer, grazing], None, spacing=1.0)
    ends = [c[[0, -1], :2] for c in out[1:]]
    gaps = [np.hypot(*(a - b)) for i, e in enumerate(ends) for f in ends[i + 1:]
            for a in e for b in f]
    assert len(out) == 3 and min(gaps) >= 1.0 - 1e-9


def test_a_first_flood_sets_the_size_field_and_the_flow_zone():
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.steps.hydraulic_lines import flood_size_field, wet_zone
    from floodmesh.core.raster import Grid

    depth = np.zeros((40, 60))
    depth[10:20, 10:30] = 0.3   # wet: 20 × 10 m at 1 m cells
    grid = Grid(depth.astype(np.float32), Affine(1, 0, 0, 0, -1, 40), CRS.from_epsg(32756))
    size = flood_size_field(grid, wet_area=8.0, margin=2.0)
    wet = np.isfinite(size.values)
    assert (size.values[wet] == 8.0).all() and wet[10:20, 10:30].all()
    assert wet.sum() == pytest.approx((20 + 4) * (10 + 4) - 4 * 4 + 4 * 3, rel=0.15)
    zone = wet_zone(grid, margin=0.0)
    assert zone.area == pytest.approx(200.0)
    line = np.array([[0, 25, 0], [60, 25, 0]])   # through the wet block (y 20–30)
    out, _ = lines_for_hydraulics([line], None, spacing=1.0, within=zone)
    assert len(out) == 1 and out[0][0, 0] == pytest.approx(10) and out[0][-1, 0] == \
        pytest.approx(30)


def test_flow_spacing_thins_lines_to_the_flow_zone_triangle_side():
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.raster import Grid

    # a 1 m grid, x < 50 in the flow zone with a spacing of 6 m, no limit elsewhere
    values = np.full((20, 100), np.nan, np.float32)
    values[:, :50] = 6.0
    zone = Grid(values, Affine(1.0, 0, 0, 0, -1.0, 20.0), CRS.from_epsg(32756))
    line = np.column_stack([np.arange(0.0, 100.0, 1.5), np.full(67, 10.0), np.zeros(67)])
    short = np.array([[10, 2, 0], [11, 2.5, 0], [13, 3, 0]])   # 3.2 m long, in the zone
    (out,), _ = lines_for_hydraulics([line, short], None, spacing=1.0, flow_spacing=zone)
    steps = np.diff(out[:, 0])
    wet, dry = out[1:, 0] < 50, out[:-1, 0] >= 50
    assert (steps[wet] >= 6.0 - 1e-9).all() and (steps[dry] == 1.5).all()
    assert out[0, 0] == 0 and out[-1, 0] == line[-1, 0]     # the ends stay
    # without the field the spacing is the plain one and the short line stays
    plain, _ = lines_for_hydraulics([line, short], None, spacing=1.0)
    assert len(plain) == 2 and len(plain[0]) == len(line)


def test_drop_spikes_removes_sharp_turns_only_where_asked():
    from floodmesh.core.steps.hydraulic_lines import drop_spikes

    # a hairpin at x = 10 (the line turns back at about 11°) and a right angle at (20, 2)
    line = np.array([[0, 0], [10, 0], [0, 2], [20, 2], [20, 10]], float)
    out = drop_spikes(line)
    assert [10, 0] not in out.tolist() and [20, 2] in out.tolist()
    assert out[0].tolist() == [0, 0] and out[-1].tolist() == [20, 10]
    assert len(drop_spikes(line, where=np.zeros(5, bool))) == 5


def _numpy_thin(coords, spacing, firm=None, tolerance=None):
    """thin_vertices as NumPy defined it before its loop was compiled: the reference."""
    spacing = np.broadcast_to(np.asarray(spacing, float), (len(coords),))
    keep = [0]
    for i in range(1, len(coords) - 1):
        gap = np.hypot(*(coords[i, :2] - coords[keep[-1], :2]))
        if gap >= spacing[i] or (tolerance is not None and gap >= firm and not _numpy_holds(
                coords[[keep[-1], i, i + 1]], tolerance)):
            keep.append(i)
    while len(keep) > 1:
        gap = np.hypot(*(coords[-1, :2] - coords[keep[-1], :2]))
        if gap >= max(spacing[-1], spacing[keep[-1]]) or (
                tolerance is not None and gap >= firm
                and not _numpy_holds(coords[[keep[-2], keep[-1], keep[-1] + 1]], tolerance)):
            break
        keep.pop()
    return coords[keep + [len(coords) - 1]]


def _numpy_holds(abc, tolerance):
    ab = abc[2, :2] - abc[0, :2]
    t = np.clip((abc[1:2, :2] - abc[0, :2]) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    plan = np.hypot(*(abc[0, :2] + t[:, None] * ab - abc[1:2, :2]).T)
    height = np.abs(abc[0, 2] + t * (abc[2, 2] - abc[0, 2]) - abc[1:2, 2])
    return bool((plan <= tolerance[0]).all() and (height <= tolerance[1]).all())


def _numpy_unspiked(coords, where, min_angle=60.0):
    keep, i = list(range(len(coords))), 1
    while i < len(keep) - 1:
        a, b, c = (coords[keep[j], :2] for j in (i - 1, i, i + 1))
        u, v = a - b, c - b
        cos = u @ v / max(np.hypot(*u) * np.hypot(*v), 1e-12)
        if where[keep[i]] and cos > np.cos(np.radians(min_angle)):
            del keep[i]
            i = max(1, i - 1)
        else:
            i += 1
    return coords[keep]


def test_compiled_thinning_and_spikes_are_the_numpy_definitions_to_the_bit():
    """Random walks at UTM magnitudes with steps from centimetres to metres, spacings per
    vertex, with and without the chord tolerance; spikes with and without ``where``."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        n = int(rng.integers(2, 80))
        coords = (np.array([400_000.0, 5_600_000.0, 30.0])
                  + np.cumsum(rng.normal(0, 10 ** rng.uniform(-2, 0.5), (n, 3)), axis=0))
        spacing = rng.uniform(0.2, 3.0, n)
        tolerance = (float(rng.uniform(0.05, 0.5)), float(rng.uniform(0.01, 0.1)))
        assert np.array_equal(thin_vertices(coords, spacing), _numpy_thin(coords, spacing))
        assert np.array_equal(thin_vertices(coords, spacing, firm=0.3, tolerance=tolerance),
                              _numpy_thin(coords, spacing, 0.3, tolerance))
        where = rng.random(n) < 0.7
        assert np.array_equal(drop_spikes(coords, where), _numpy_unspiked(coords, where))
        assert np.array_equal(drop_spikes(coords), _numpy_unspiked(coords, np.ones(n, bool)))


def test_a_line_folding_back_on_itself_leaves_no_sliver():
    """A traced line that runs out and back 0.4-0.6 m beside itself (a narrow embankment's crest
    traced down and up again, found on the corpus) is two lines: the shorter arm merges into
    the longer, as it would into any other line, and the mesh's smallest triangle (the flood
    model's time step) is no longer a sliver between the arms."""
    dem = Grid(np.zeros((60, 80)), Affine(1, 0, 0, 0, -1, 60), CRS.from_epsg(32633))
    fold = np.array([[10, 30, 1], [25, 30, 1], [40, 30, 1], [25, 30.4, 1], [12, 30.6, 1]])
    out, stats = lines_for_hydraulics([fold], None, spacing=1.0)
    assert stats["lines_in"] == 1 and len(out) == 1
    assert out[0][:, :2].tolist() == [[10, 30], [25, 30], [40, 30]]
    as_traced, kept = (build_mesh(dem, lines, max_area=100) for lines in ([fold], out))
    assert inradii(as_traced.nodes, as_traced.triangles).min() < 0.2
    assert inradii(kept.nodes, kept.triangles).min() > 1.0


def test_split_at_folds_cuts_only_where_a_line_turns_back():
    zigzag = np.array([[0, 0], [10, 0], [0, 1], [10, 2], [20, 2], [20, 12]], float)
    pieces = split_at_folds(zigzag)
    assert [p.tolist() for p in pieces] == [[[0, 0], [10, 0]], [[10, 0], [0, 1]],
                                            [[0, 1], [10, 2], [20, 2], [20, 12]]]
    assert len(split_at_folds(zigzag, min_angle=3.0)) == 1
    assert len(split_at_folds(zigzag[:2])) == 1


def test_a_line_running_into_another_ends_on_it_not_a_spacing_short():
    """A line that runs into a longer one (a bank into a road embankment) is cut a spacing
    short of it, and that gap between the cut end and the other line held the mesh's smallest
    triangles (found on the corpus's crossings, where they set the flood model's time step);
    the cut end now joins the other line, the z along it."""
    dem = Grid(np.zeros((60, 80)), Affine(1, 0, 0, 0, -1, 60), CRS.from_epsg(32633))
    bar = np.array([[5, 30, 2], [75, 30, 4]])
    stem = np.array([[40, 5, 1], [40, 18, 2], [40, 29.6, 2.9]])  # rising to the bar's 3 m
    out, stats = lines_for_hydraulics([bar, stem], None, spacing=1.0)
    joined = [c for c in out if np.allclose(c[:, 0], 40)][0]
    assert stats["ends_joined"] == 1
    assert joined[-1].tolist() == pytest.approx([40, 30, 3])
    gap_left = [bar, np.array([[40, 5, 1], [40, 18, 1], [40, 29, 1]])]  # cut, as before
    as_before, now = (build_mesh(dem, lines, max_area=100) for lines in (gap_left, out))
    assert inradii(as_before.nodes, as_before.triangles).min() < 0.4
    assert inradii(now.nodes, now.triangles).min() > 0.6
    # a line 2 m below the bar where it ends 0.4 m short of it meets a wall, not the bar
    below = np.array([[40, 5, 1], [40, 18, 1], [40, 29.6, 1]])
    _, stats = lines_for_hydraulics([bar, below], None, spacing=1.0)
    assert stats["ends_joined"] == 0
    # a line meeting another at a glancing angle keeps its gap (the PSLG's corner rule)
    glancing = np.array([[10, 20, 1], [40, 29.2, 1]])
    _, stats = lines_for_hydraulics([bar, glancing], None, spacing=1.0)
    assert stats["ends_joined"] == 0


def test_a_line_clipped_at_the_edge_leaves_no_stub_beside_it():
    """A bank running out of the domain is clipped the clearance (2 m) inside the edge; where
    that cut falls 1.5 m past the bank's last vertex, the stub between them (no terrain: the
    cut's point is interpolated) held the smallest triangle by the edge, which set 87 % of a
    flood's time steps at the corpus's outflow. The line now ends at its vertex."""
    dem = Grid(np.zeros((50, 100)), Affine(1, 0, 0, 0, -1, 50), CRS.from_epsg(32633))
    domain = domain_from_dem(dem)  # the cells' centres: x from 0.5
    bank = np.array([[50, 25, 1], [30, 20, 1], [4.0, 15, 1], [-5, 13.5, 1]])
    out, stats = lines_for_hydraulics([bank], domain, spacing=1.0)
    assert stats["clipped_at_edge"] == 1 and len(out) == 1
    assert out[0].tolist() == [[50, 25, 1], [30, 20, 1], [4.0, 15, 1]]
    stub = np.array([[50, 25, 1], [30, 20, 1], [4.0, 15, 1], [2.5, 14.75, 1]])  # as before
    as_before, now = (build_mesh(dem, lines, max_area=100, domain=domain)
                      for lines in ([stub], out))
    assert inradii(as_before.nodes, as_before.triangles).min() < 0.6
    assert inradii(now.nodes, now.triangles).min() > 1.2
    # a clip further from the vertex (3 m) keeps its end there: the line reaches the edge
    far = np.array([[50, 25, 1], [30, 20, 1], [5.5, 15, 1], [-5, 13.5, 1]])
    out, _ = lines_for_hydraulics([far], domain, spacing=1.0)
    assert out[0][-1, 0] == pytest.approx(2.5) and len(out[0]) == 4


def test_a_bridge_on_low_ground_is_left_out_of_the_mesh_lines_and_kept_on_high_ground():
    """A line bridged across a crossing (vertices 3-6 a bridge's) loses the bridge's segments
    where they lie on low ground (x < 10 here) and keeps them, and the rest, elsewhere."""
    from floodmesh.core.steps.hydraulic_lines import without_wet_bridges

    x = np.arange(0.0, 20.0, 2.0)  # vertices at x = 0, 2, ..., 18
    line = np.column_stack([x, np.full(len(x), 5.0), np.zeros(len(x))])
    bridged = np.zeros(len(x), bool)
    bridged[3:7] = True  # x = 6 … 12: segments 6-8, 8-10, 10-12 are the bridge's
    values = np.full((10, 20), np.nan, np.float32)
    values[:, :10] = 3.0  # low ground west of x = 10
    low = Grid(values, Affine(1.0, 0, 0, 0, -1.0, 10.0), CRS.from_epsg(32633))
    pieces = without_wet_bridges([line, line], [bridged, None], low)
    assert [list(p[:, 0]) for p in pieces] == [[0, 2, 4, 6], [10, 12, 14, 16, 18], list(x)]
    assert without_wet_bridges([line], [bridged], None)[0] is line  # no low ground known


def test_a_wall_gives_no_node_a_height_between_its_foot_and_top(tmp_path):
    """A DEM with a 10 m wall (a quay or a quarry face) across an embankment and a channel:
    the embankment's toe line ends at the wall's foot, the wall's top edge is a line too. No
    mesh node may take a height the ground around it does not have (the toe's end joined onto
    the top edge gave a 40 m segment a 10 m ramp; a traced line stepping up the wall did the
    same): every node lies within 1 m of the range of the DEM's 3 x 3 cells around it."""
    import rasterio

    rows, cols = 200, 300
    x, y = np.meshgrid(np.arange(cols) + 0.5, rows - np.arange(rows) - 0.5)
    z = (20.0 + 0.01 * x + np.clip((6.0 - np.abs(y - 90.0)) / 4.0, 0, 1) * 1.5
         - np.clip((7.5 - np.abs(x - 80.0)) / 3.0, 0, 1) * 2.0 + np.where(x > 200, 10.0, 0.0))
    dem = tmp_path / "wall.tif"
    with rasterio.open(dem, "w", driver="GTiff", width=cols, height=rows, count=1,
                       dtype="float32", crs="EPSG:25832",
                       transform=Affine(1, 0, 500_000, 0, -1, 5_600_200)) as dst:
        dst.write(z.astype("float32"), 1)
    run_pipeline(dem, tmp_path / "out", RunOptions(max_area=100.0))
    nodes, _ = io.read_mesh_2dm(tmp_path / "out" / "mesh.2dm")
    col = np.clip((nodes[:, 0] - 500_000).astype(int), 1, cols - 2)
    row = np.clip((5_600_200 - nodes[:, 1]).astype(int), 1, rows - 2)
    around = np.stack([z[row + i, col + j] for i in (-1, 0, 1) for j in (-1, 0, 1)])
    above, below = nodes[:, 2] - around.max(axis=0), around.min(axis=0) - nodes[:, 2]
    assert max(above.max(), below.max()) < 1.0, (above.max(), below.max())
