"""Terrain fits on analytic surfaces: a noisy hinge (bank top) whose crest line is known, and a
noisy plane whose elevation is known."""
import numpy as np
import pytest

from floodmesh.core.steps.localise import (estimate_noise, fit_node_elevations, fit_window,
                                           localise_breaklines)

ANGLE = np.radians(35.0)  # the crest runs at 35° to the grid, the hard case for the tracer
TANGENT = np.array([np.cos(ANGLE), np.sin(ANGLE)])
NORMAL = np.array([-np.sin(ANGLE), np.cos(ANGLE)])


def hinge(xy):
    """Flat to the right of the crest line through (50, 50), a 1:2 bank to its left."""
    u = (xy - 50.0) @ NORMAL
    return 10.0 + 0.5 * np.maximum(u, 0.0) + 0.002 * (xy @ TANGENT)


def noisy_points(surface, *, density=9.0, noise=0.05, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 100, (int(density * 100 * 100), 2))
    return np.column_stack([xy, surface(xy) + rng.normal(0, noise, len(xy))])


@pytest.mark.parametrize("density, noise, bound", [(9.0, 0.05, 0.10), (2.0, 0.15, 0.30)])
def test_crest_localised_on_a_noisy_hinge(density, noise, bound):
    points = noisy_points(hinge, density=density, noise=noise)
    window = fit_window(points, 100 * 100, 1.0)
    assert window.noise == pytest.approx(noise, rel=0.25)
    # a traced line: the crest's staircase, 0.3–0.6 m off it to either side
    s = np.arange(-25, 26, 4.0)
    offset = np.where(np.arange(len(s)) % 2, 0.6, -0.3)
    xy = 50.0 + s[:, None] * TANGENT + offset[:, None] * NORMAL
    line = np.column_stack([xy, hinge(xy)])
    [moved], [confidence], [kink] = localise_breaklines([line], points, window)
    off = np.abs((moved[:, :2] - 50.0) @ NORMAL)
    assert np.isfinite(confidence).mean() > 0.8
    # the bound: 90 % of the vertices within it, half of them within a third of it
    assert np.median(off) < bound / 3 and np.percentile(off, 90) < bound
    assert np.median(np.abs(offset)) > 2 * np.median(off)
    # z from the fit: the crest's true height, with much less than the noise
    assert np.median(np.abs(moved[:, 2] - hinge(moved[:, :2]))) < 0.3 * noise
    assert np.nanmedian(confidence) == pytest.approx(noise, rel=0.3)
    assert np.nanmin(kink) > 0.3  # the bank's foot as the hinge sees it: a toe (slope rises)


def test_no_kink_no_move():
    """On a plane there is no hinge: the vertices stay where they were."""
    points = noisy_points(lambda xy: 5.0 + 0.05 * xy[:, 0])
    xy = 50.0 + np.arange(-20, 21, 4.0)[:, None] * TANGENT
    line = np.column_stack([xy, np.zeros(len(xy))])
    window = fit_window(points, 1e4, 1.0)
    [moved], [confidence], [kink] = localise_breaklines([line], points, window)
    assert np.isnan(confidence).mean() > 0.8
    assert np.abs(moved[:, :2] - xy).max(axis=1).mean() < 0.05


def test_node_elevations_take_the_noise_out_on_a_plane():
    def plane(xy):
        return 3.0 + 0.01 * xy[:, 0] - 0.02 * xy[:, 1]

    noise = 0.05
    points = noisy_points(plane, noise=noise, seed=1)
    rng = np.random.default_rng(2)
    xy = rng.uniform(10, 90, (500, 2))
    noisy = np.column_stack([xy, plane(xy) + rng.normal(0, noise, len(xy))])
    line = np.array([[20.0, 20.0, 1.0], [80.0, 20.0, 2.0]])  # a line with its own z
    noisy[0, :2] = (50.0, 20.0)
    z, counts = fit_node_elevations(noisy, points, [line], 1.5, on_line=0.05)
    assert z[0] == pytest.approx(1.5)  # on the line: z along it
    error = z[1:] - plane(xy[1:])
    assert counts["plane_fitted"] >= 490
    assert np.sqrt(np.mean(error ** 2)) < 0.25 * noise


def test_node_planes_fit_closer_where_a_fold_no_line_carries_bends_them():
    """Nodes 0.5-1.5 m from a crest that no break line carries (a fold where features cross):
    a plane over 3 m straddles the fold and sits low; where its residual stands above the
    noise, the fit is made again within half the radius. Nodes on plain ground keep the wide
    fit (their z the same to the bit)."""
    points = noisy_points(hinge, density=9.0, noise=0.05, seed=6)
    rng = np.random.default_rng(7)
    u = rng.uniform(0.5, 1.5, 200) * rng.choice([-1, 1], 200)
    xy = 50.0 + rng.uniform(-20, 20, 200)[:, None] * TANGENT + u[:, None] * NORMAL
    far = 50.0 + rng.uniform(-20, 20, 200)[:, None] * TANGENT - 10 * NORMAL
    nodes = np.column_stack([np.vstack([xy, far]), np.zeros(400)])
    wide, _ = fit_node_elevations(nodes, points, [], 3.0, on_line=0.05)
    closer, _ = fit_node_elevations(nodes, points, [], 3.0, on_line=0.05, noise=0.05)
    truth = hinge(nodes[:, :2])

    def rms(z):
        return np.sqrt(np.mean((z[:200] - truth[:200]) ** 2))

    assert rms(closer) < 0.6 * rms(wide)
    assert np.mean(closer[200:] == wide[200:]) > 0.9  # plain ground: mostly untouched


def test_fits_in_chunks_give_the_same_numbers_as_all_at_once(monkeypatch):
    """Node and hinge fits go FIT_CHUNK centres at a time so that their memory stays bounded
    whatever the mesh: chunks of 7 give the same numbers, bit for bit, as one chunk of all."""
    from floodmesh.core.steps import localise

    points = noisy_points(hinge, seed=4)
    window = fit_window(points, 100 * 100, 1.0)
    rng = np.random.default_rng(5)
    nodes = np.column_stack([rng.uniform(5, 95, (200, 2)), np.zeros(200)])
    line = 50.0 + np.arange(-25, 26, 2.0)[:, None] * TANGENT
    line = np.column_stack([line, hinge(line)])
    results = []
    for chunk in (10**6, 7):
        monkeypatch.setattr(localise, "FIT_CHUNK", chunk)
        z, _ = fit_node_elevations(nodes, points, [line], 1.5, on_line=0.05)
        [moved], [confidence], [kink] = localise_breaklines([line], points, window)
        results.append((z, moved, confidence, kink))
    for once, chunked in zip(*results):
        assert np.array_equal(once, chunked, equal_nan=True)
    assert np.isfinite(results[0][2]).sum() > 10 and np.isfinite(results[0][0]).all()


def test_noise_estimate():
    points = noisy_points(hinge, noise=0.10, seed=3)
    assert estimate_noise(points, 9.0) == pytest.approx(0.10, rel=0.15)


def test_noise_estimate_of_the_same_points_in_another_order_is_the_same():
    points = noisy_points(hinge, noise=0.10, seed=3)
    shuffled = points[np.random.default_rng(1).permutation(len(points))]
    assert estimate_noise(shuffled, 9.0) == pytest.approx(estimate_noise(points, 9.0), rel=1e-9)


def test_noise_estimate_of_a_reach_across_its_bounding_box():
    """A reach at 45° fills a fifth of its bounding box: the places drawn outside it are drawn
    again, and the estimate is the noise's."""
    points = noisy_points(hinge, noise=0.10, seed=3)
    diagonal = np.abs(points[:, 0] - points[:, 1]) < 10
    assert diagonal.mean() < 0.25
    assert estimate_noise(points[diagonal], 9.0) == pytest.approx(0.10, rel=0.15)


def test_chain_fits_the_terrain_on_the_demo_floodplain(demo_points_file, tmp_path):
    """run_pipeline with the fits (the defaults) against the chain without them, scored on the
    demo's TRUE surface: a lower true RMSE with no more nodes; report.json states the fits."""
    from floodmesh.core.frontends import demo
    from floodmesh.core import io
    from floodmesh.core.steps.accuracy import tin_elevation
    from floodmesh.core.steps.mesh import Mesh
    from floodmesh.core.options import RunOptions
    from floodmesh.core.chain.pipeline import run_pipeline

    rng = np.random.default_rng(0)
    local = rng.uniform((2, 2), (demo.WIDTH - 2, demo.HEIGHT - 2), (20_000, 2))
    truth = demo.ground_elevation(local[:, 0], local[:, 1])
    result = {}
    for name, options in (("fitted", RunOptions(holdout=0.01)),
                          ("plain", RunOptions(holdout=0.01, localise=False,
                                               node_elevation="dem", conforming=True))):
        report = run_pipeline(demo_points_file, tmp_path / name, options)
        nodes, triangles = io.read_mesh_2dm(tmp_path / name / "mesh.2dm")
        z = tin_elevation(Mesh(nodes, triangles, None), *(local + demo.DEMO_ORIGIN).T)
        result[name] = len(nodes), float(np.sqrt(np.nanmean((z - truth) ** 2))), report
    (n_fit, rmse_fit, report), (n_plain, rmse_plain, _) = result["fitted"], result["plain"]
    assert n_fit <= n_plain and rmse_fit < 0.7 * rmse_plain
    fit = report["terrain_fit"]
    assert fit["node_radius"] > 0 and fit["half_width"] > 0 and 0.03 < fit["noise"] < 0.08
    assert fit["vertices_localised"] > 0.7 * fit["vertices"]
    assert fit["nodes"]["plane_fitted"] > 0.3 * report["nodes"]


def test_a_line_hopping_from_crest_to_toe_is_cut():
    """A traced line that follows a bank's crest, hops across the 3 m wide bank and goes on along
    its toe (the staircase of an oblique band) is cut at the hop; the kink beside each half is
    found (``_companions``) and joined to it: two lines, the crest and the toe, each along the
    whole bank."""
    from floodmesh.core.steps.breaklines import BreakLine
    from floodmesh.core.steps.localise import localise_traced

    def bank(xy):
        u = (xy - 50.0) @ NORMAL
        return 10.0 - 0.5 * np.clip(u, 0.0, 3.0)  # crest at u = 0, toe at u = 3

    points = noisy_points(bank)
    s = np.arange(-24, 25, 4.0)
    u = np.where(s < 0, 0.3, 2.7)
    xy = 50.0 + s[:, None] * TANGENT + u[:, None] * NORMAL
    line = BreakLine(np.column_stack([xy, bank(xy)]), np.full(len(s), 20.0))
    pieces, confidence, counts = localise_traced([line], points, fit_window(points, 1e4, 1.0),
                                                 join_gap=10.0)
    assert counts["hop_segments_cut"] == 1 and len(pieces) == len(confidence) == 2
    for piece, at in zip(pieces, (0.0, 3.0)):
        off = (piece.coords[:, :2] - 50.0) @ NORMAL - at
        assert np.abs(off).max() < 0.15
        along = (piece.coords[:, :2] - 50.0) @ TANGENT
        assert along.min() < -23 and along.max() > 23


def test_a_loop_without_a_kink_keeps_its_course():
    """Thinning drops unmoved vertices only over short stretches along the line: a closed loop
    on a plane (no kink anywhere, its ends 1 m apart) keeps its whole length."""
    from floodmesh.core.steps.breaklines import BreakLine
    from floodmesh.core.steps.localise import localise_traced

    points = noisy_points(lambda xy: 5.0 + 0.3 * xy[:, 0])
    square = [(30, 30), (70, 30), (70, 70), (30, 70), (30, 31)]
    xy = np.concatenate([np.linspace(a, b, 10, endpoint=False)
                         for a, b in zip(square[:-1], square[1:])] + [[square[-1]]])
    line = BreakLine(np.column_stack([xy, 5.0 + 0.3 * xy[:, 0]]), np.full(len(xy), 16.7))
    [out], _, counts = localise_traced([line], points, fit_window(points, 1e4, 1.0))
    assert counts["vertices_localised"] == 0
    assert out.length == pytest.approx(line.length, rel=1e-6)


@pytest.mark.parametrize("density, noise", [(16.0, 0.05), (9.0, 0.0), (25.0, 0.0)])
def test_dense_or_clean_points_do_not_shrink_the_fit_window_below_eight_cells(density, noise):
    # the window holds 40 + 800·noise points but covers at least 8 cells: with fewer (2.5 cells
    # at 16 points/m², 4.4 at 9 points/m² without noise) the corpus's meshes lost up to a third
    # of their efficiency (benchmarks/RESULTS.md, "The evaluation corpus")
    window = fit_window(noisy_points(hinge, density=density, noise=noise), 100 * 100, 1.0)
    assert 4 * window.half_width * window.half_length >= 8.0 - 1e-9
    assert window.node_radius >= np.sqrt(8.0 / np.pi) - 1e-9


def test_the_reference_survey_keeps_its_own_window():
    # 9 points/m² and 5 cm: (40 + 800·σ)/9 ≈ 8.9 cells, above the least window: unchanged
    window = fit_window(noisy_points(hinge, density=9.0, noise=0.05), 100 * 100, 1.0)
    wanted = (40 + 800 * window.noise) / window.density
    assert wanted > 8.0
    assert window.half_width == pytest.approx(min(1.5, np.sqrt(wanted) / 2))


def test_a_toe_beside_a_traced_crest_is_found():
    """A bank 3 m wide (crest at u = 0, toe at u = 3) whose band the tracer followed along its
    crest only: the toe, which no traced line follows, comes out as a line of its own, on the
    toe, along most of the bank."""
    from floodmesh.core.steps.breaklines import BreakLine
    from floodmesh.core.steps.localise import localise_traced

    def bank(xy):
        u = (xy - 50.0) @ NORMAL
        return 10.0 - 0.27 * np.clip(u, 0.0, 3.0)  # 15°: just over S_crit, a narrow band

    points = noisy_points(bank)
    s = np.arange(-30, 31, 2.0)
    xy = 50.0 + s[:, None] * TANGENT + 0.3 * NORMAL
    line = BreakLine(np.column_stack([xy, bank(xy)]), np.full(len(s), 15.0))
    pieces, _, counts = localise_traced([line], points, fit_window(points, 1e4, 1.0))
    assert counts["companions_found"] >= 1
    at = [np.median((p.coords[:, :2] - 50.0) @ NORMAL) for p in pieces]
    toes = [p for p, u in zip(pieces, at) if abs(u - 3.0) < 0.5]
    assert sum(p.length for p in toes) > 0.8 * line.length
    off = np.abs(np.concatenate([(p.coords[:, :2] - 50.0) @ NORMAL for p in toes]) - 3.0)
    # a 15° bank, a weaker kink than 1:2: a line localised on the toe itself scatters as much
    assert np.median(off) < 0.1 and off.max() < 0.35
    assert all(abs(u) < 0.15 or abs(u - 3.0) < 0.15 for u in at)


def _bank_crest_in_two_pieces(**options):
    """localise_traced (join gap 2 m, bridge gap 12 m, ``options``) of a bank 3 m wide (15°)
    whose crest the tracer followed in two pieces 8 m apart and whose toe it missed: the toe is
    probed for (``_companions``) and both gaps are bridged (``_bridges_fitted``)."""
    from floodmesh.core.steps.breaklines import BreakLine
    from floodmesh.core.steps.localise import localise_traced

    def bank(xy):
        return 10.0 - 0.27 * np.clip((xy - 50.0) @ NORMAL, 0.0, 3.0)

    points = noisy_points(bank)
    lines = []
    for s in (np.arange(-30, -3, 2.0), np.arange(5, 31, 2.0)):
        xy = 50.0 + s[:, None] * TANGENT + 0.3 * NORMAL
        lines.append(BreakLine(np.column_stack([xy, bank(xy)]), np.full(len(s), 15.0)))
    return localise_traced(lines, points, fit_window(points, 1e4, 1.0), join_gap=2.0,
                           bridge_gap=12.0, **options)


def test_the_bar_moves_while_companions_are_probed_and_gaps_bridged():
    """Localising lines (``localise_traced``, a run's "localise") tells its progress along the
    probes for kinks beside the lines and the bridges' fits, not only by stages after the
    line-by-line pass (0.6 of the step): there it told 0.75, 0.85, 0.95 and 1 alone."""
    told = []
    _, _, counts = _bank_crest_in_two_pieces(progress=told.append)
    assert counts["companions_found"] >= 1 and counts["gaps_bridged"] >= 1  # the case holds
    late = [f for f in told if f >= 0.6]
    assert late == sorted(late) and told[-1] == 1.0, told
    assert len(set(late)) >= 12 and max(np.diff(late)) <= 0.1 + 1e-9, told


@pytest.mark.parametrize("pressed, stage_end", [(0.6, 0.75), (0.85, 0.95)])
def test_cancel_while_companions_are_probed_or_gaps_bridged_stops_there(pressed, stage_end):
    """Cancel pressed while the probes beside the lines (past 0.6 of the step) or the bridges
    (past 0.85) are fitted is honoured before they end: it waited for the stage's end."""
    from floodmesh.core.errors import Cancelled

    told = []
    with pytest.raises(Cancelled):
        _bank_crest_in_two_pieces(progress=told.append,
                                  cancelled=lambda: any(f > pressed for f in told))
    assert max(told) < stage_end, told


@pytest.mark.parametrize("noise", [0.05, 0.15])
def test_no_companion_beside_a_lone_crest(noise):
    """A crest with plain ground on either side (the hinge of ``hinge``), surveyed with noise:
    the search for a kink beside it finds none, and the crest stays one line."""
    from floodmesh.core.steps.breaklines import BreakLine
    from floodmesh.core.steps.localise import localise_traced

    points = noisy_points(hinge, noise=noise, seed=3)
    s = np.arange(-30, 31, 2.0)
    xy = 50.0 + s[:, None] * TANGENT
    line = BreakLine(np.column_stack([xy, hinge(xy)]), np.full(len(s), 26.6))
    pieces, _, counts = localise_traced([line], points, fit_window(points, 1e4, 1.0))
    assert counts["companions_found"] == 0 and len(pieces) == 1



def _hinge_search(u, v, z, half_width=1.5, steps=24):
    """``_hinge_offset``'s (offset, step) on a window, and the SSE of fitting the hinge point
    by point (``_hinge_sse``) at every one of its offsets."""
    from floodmesh.core.steps.localise import _hinge_fixed, _hinge_offset, _hinge_sse

    m = len(u)
    fixed = _hinge_fixed(v, z, m)
    beta, a, b = np.zeros(4), np.empty((4, 4)), np.empty(4)
    reach = 0.7 * half_width
    direct = np.array([_hinge_sse(u, v, z, m, -reach + 2 * reach * j / steps, fixed, beta, a, b)
                       for j in range(steps + 1)])
    return _hinge_offset(u, v, z, m, half_width, steps, fixed, beta, a, b), direct


@pytest.mark.parametrize("seed", range(8))
def test_hinge_offset_search_matches_the_least_squares_fit_at_each_offset(seed):
    """The offset search (each offset's SSE from binned sums, the (a, b) block eliminated; the
    near-least ones fitted again point by point) chooses and refines the offset that fitting
    the hinge point by point at every offset gives (``_hinge_sse``: two passes over the points
    and a 4 x 4 solve an offset), to the bit: on noisy windows over a kink, on a plane, on a
    window half empty, and on DEM cell centres, whose lattice makes near-ties."""
    rng = np.random.default_rng(seed)
    half_width, steps = 1.5, 24
    m = int(rng.integers(12, 300))
    u = rng.uniform(-half_width, half_width, m)
    if seed == 4:  # cell centres of a 0.5 m DEM, the line along a row
        u = np.repeat(np.arange(-1.25, 1.5, 0.5), 8)
        m = len(u)
    if seed == 5:
        u = np.abs(u)  # no point left of the middle: offsets there have < 4 on a side
    v = rng.uniform(-3.0, 3.0, m) if seed != 4 else np.tile(np.arange(-1.75, 2.0, 0.5), 6)
    kink = rng.uniform(-0.8, 0.8) if seed % 3 else 0.0
    slope = 0.0 if seed == 3 else rng.uniform(0.1, 0.6)
    noise = 0.0 if seed in (4, 7) else 0.05  # noiseless: exact fits, SSEs near zero
    z = 0.02 * v + slope * np.maximum(u - kink, 0.0) + rng.normal(0.0, noise, m)
    z -= z.mean()
    (u0, best_j), direct = _hinge_search(u, v, z, half_width, steps)
    assert best_j == int(np.argmin(direct))
    reach = 0.7 * half_width
    j, h = best_j, 2 * reach / steps
    expected = -reach + h * j
    if 0 < j < steps and np.isfinite(direct[j - 1]) and np.isfinite(direct[j + 1]):
        curv = direct[j - 1] - 2 * direct[j] + direct[j + 1]
        if curv > 0:
            expected += 0.5 * h * (direct[j - 1] - direct[j + 1]) / curv
    assert u0 == expected  # to the bit


@pytest.mark.parametrize("rows", [3, 4, 6, 9])
def test_hinge_offset_search_breaks_ties_as_the_direct_fit_does(rows):
    """An exact plane on DEM cell centres: every offset fits it, each SSE zero but for rounding,
    so the offset chosen is decided by the rounding of the fits. The search keeps the one that
    fitting point by point at every offset keeps."""
    u, v = (g.ravel() for g in np.meshgrid(np.arange(-1.45, 1.5, 0.1),
                                           np.arange(rows) * 0.5 - 0.25 * rows))
    z = 0.1 * u + 0.02 * v
    z -= z.mean()
    (u0, best_j), direct = _hinge_search(u, v, z)
    assert direct.max() < 1e-12  # every offset fits
    assert best_j == int(np.argmin(direct))


def _embankment(xy, centreline, height=1.2, crest=1.5, toe=4.5):
    """An embankment ``height`` m high along ``centreline`` (a shapely line): crest ``crest``
    m and toes ``toe`` m to either side of it."""
    import shapely

    d = shapely.distance(shapely.points(xy), centreline)
    return height * np.clip((toe - d) / (toe - crest), 0.0, 1.0)


def _toe_under_a_road():
    """A bank's toe crossed at right angles by a road embankment 1.2 m high (9 m at its base),
    surveyed at 2 points/m² with 5 cm of noise, and a line traced along the toe (a staircase
    0.3–0.4 m off it, vertices a metre apart, z on the ground)."""
    import shapely

    road = shapely.LineString([50.0 - 40 * NORMAL, 50.0 + 40 * NORMAL])

    def ground(xy):
        return hinge(xy) + _embankment(xy, road)

    points = noisy_points(ground, density=2.0, noise=0.05, seed=3)
    s = np.arange(-20, 21, 1.0)
    xy = 50.0 + s[:, None] * TANGENT + np.where(np.arange(len(s)) % 2, 0.4, -0.3)[:, None] * NORMAL
    return ground, points, s, np.column_stack([xy, ground(xy)])


def test_a_toe_crossing_an_embankment_keeps_its_height_on_sparse_points():
    """Where a road crosses the toe, the ground bends along the line, which a hinge fit over the
    window's full length (12 m along at 2 points/m²) flattens by decimetres or fails; the fits
    that misfit beyond the noise are repeated over shorter windows and find the toe over the
    road at its height."""
    ground, points, s, line = _toe_under_a_road()
    window = fit_window(points, 100 * 100, 1.0)
    assert window.half_length > 5  # sparse: a long window
    [moved], [confidence], _ = localise_breaklines([line], points, window)
    on_road = np.abs(s) <= 6.0
    fitted = np.isfinite(confidence)
    assert fitted[on_road].mean() >= 0.7
    error = moved[:, 2] - ground(moved[:, :2])
    assert np.abs(error[on_road & fitted]).max() < 0.25


def test_a_localised_line_follows_the_ground_over_an_embankment():
    """From the user's side: the toe line out of ``localise_traced`` (what the mesh is built
    on) runs over the road at the ground's height, instead of a chord at the toe's height
    where fits failed (1.2 m under the road's crest)."""
    import shapely

    from floodmesh.core.steps.breaklines import BreakLine
    from floodmesh.core.steps.localise import localise_traced

    ground, points, s, line = _toe_under_a_road()
    out, _, _ = localise_traced([BreakLine(line, np.full(len(s), 20.0))], points,
                                fit_window(points, 1e4, 1.0), max_gap=20.0)
    for piece in out:
        path = shapely.LineString(piece.coords)
        at = shapely.get_coordinates(shapely.line_interpolate_point(
            path, np.arange(0.0, path.length, 0.5)), include_z=True)
        assert np.abs(at[:, 2] - ground(at[:, :2])).max() < 0.3
    covered = shapely.union_all([shapely.LineString(p.coords[:, :2]) for p in out])
    assert shapely.LineString(line[:, :2]).buffer(1.0).intersection(covered).length > 38


def test_unmoved_vertices_stay_where_a_crest_turns():
    """A run of vertices the fit did not move is dropped, but for the corner of a crest line
    (the kinks on either side crests): the raster's staircase goes, and so does the turn of a
    toe line (where a toe turns from a river into a tributary) or of a line that hops from a
    crest to a toe (cut there anyway)."""
    from floodmesh.core.steps.localise import _failed_fits_left_out

    x = np.arange(0.0, 11.0)
    coords = np.column_stack([x, np.zeros(11), np.full(11, 5.0)])
    coords[3, 1] = 0.4                               # the raster's staircase: goes
    coords[9:, 0], coords[9:, 1] = 8.0, x[9:] - 6.0  # a right-angle corner at vertex 8
    moved = np.zeros(11, bool)
    moved[[0, 1, 10]] = True
    crest = np.where(moved, -0.5, np.nan)
    keep = _failed_fits_left_out(coords, moved, 20.0, 2.0, crest)
    assert keep[[0, 1, 8, 10]].all() and not keep[[2, 3, 4, 5, 6, 7, 9]].any()
    for kink in (-crest, np.where(np.arange(11) == 10, 0.5, crest)):  # a toe; a hop
        assert not _failed_fits_left_out(coords, moved, 20.0, 2.0, kink)[2:10].any()
    # on a long stretch without fits, the traced course is kept whole
    assert _failed_fits_left_out(coords, moved, 5.0, 2.0, crest)[1:].all()


def test_a_second_trace_goes_and_a_crests_other_edge_a_cell_away_stays():
    """Of lines along one kink (1 m cells), the longest stays; a shorter crest within a
    quarter cell of it goes, a crest 1 m beside it (the other edge of a 1 m crest), a toe
    along it and a crest that leaves it after a third of its length stay."""
    from floodmesh.core.steps.localise import (SECOND_TRACE_SHARE, SECOND_TRACE_WITHIN,
                                               _second_traces_left_out)

    def piece(x0, x1, y, kink=-0.3, bend=0.0):
        x = np.arange(x0, x1 + 0.5, 1.0)
        coords = np.column_stack([x, y + bend * np.maximum(x - (x0 + (x1 - x0) / 3), 0),
                                  np.zeros(len(x))])
        n = len(x)
        return (coords, np.full(n, 20.0), 0, np.full(n, 0.05), np.full(n, kink),
                np.zeros(n, bool))

    pieces = [piece(0, 60, 0.0), piece(5, 50, 0.15), piece(5, 50, 1.0),
              piece(5, 50, 0.1, kink=0.3), piece(5, 50, 0.1, bend=0.5)]
    kept = _second_traces_left_out(pieces, SECOND_TRACE_WITHIN, SECOND_TRACE_SHARE)
    assert [any(k is p for k in kept) for p in pieces] == [True, False, True, True, True]


def test_a_run_traces_each_kink_of_an_embankment_at_45_degrees_once(tmp_path, monkeypatch):
    """From the user's side: LiDAR (9 points/m², 5 cm noise) of an embankment (1.5 m high, 3 m
    crest, 1:2 sides) at 45° to the grid. The break-line layer holds four lines, one on each
    crest edge and toe; the tracer follows a 45° band from both of its sides, and the hinge
    fits moved both traces onto one crest edge: six lines, each crest edge two pieces."""
    import shapely

    from floodmesh.core import io
    from floodmesh.core.chain import pipeline
    from floodmesh.core.frontends import demo
    from floodmesh.core.options import RunOptions
    from floodmesh.core.steps import localise
    from floodmesh.core.steps.validation import score_breaklines

    along = 200 * np.array([np.cos(np.radians(45)), np.sin(np.radians(45))])
    plain = demo.Floodplain({  # the river south of the area: ground_elevation needs one
        "river": (shapely.LineString([(-50, -40), (350, -40)]), demo.Profile(-2.0, 4.0, 8.0)),
        "embankment": (shapely.LineString([(150, 120) - along, (150, 120) + along]),
                       demo.Profile(1.5, 1.5, 4.5))}, terrace=None)
    points, classes = demo.synthetic_floodplain(density=9.0, seed=2, floodplain=plain)
    io.write_points_las(tmp_path / "points.laz", points, classes=classes)
    truth = [shapely.affinity.translate(g, *demo.DEMO_ORIGIN)
             for g in demo.true_breaklines(plain)]

    def score(out):
        report = pipeline.run_pipeline(tmp_path / "points.laz", tmp_path / out, RunOptions())
        lines = io.read_lines_gpkg(tmp_path / out / "breaklines.gpkg")
        return (score_breaklines(lines, truth, 2.0),
                report["terrain_fit"]["second_traces_left_out"])

    now, left_out = score("now")
    monkeypatch.setattr(localise, "SECOND_TRACE_SHARE", 2.0)  # never
    before, _ = score("before")
    # when written: 4 lines, 1 piece each, recall 0.999; before: 6 lines, 2, 2, 2 and 1 pieces
    assert now["n_traced"] == 4 and now["pieces"] == [1, 1, 1, 1] and left_out == 2
    assert before["n_traced"] == 6 and max(before["pieces"]) == 2
    assert now["recall"] >= before["recall"] - 0.002


def test_pieces_join_between_their_fitted_ends_and_a_free_end_keeps_its_course():
    """Two pieces of one straight crest, each ending in a traced run the fit did not move,
    bent 1.5 m to either side of the line (what noise does to a trace beyond its last kink
    found): measured between their traced ends they lie 3 m apart across the line and stay two
    lines; measured between their fitted ends they join, the bent runs at the joint go, and
    the free ends keep theirs."""
    from floodmesh.core.steps.joining import join_pieces
    from floodmesh.core.steps.localise import _fitted_span, _tails_given_back

    a = np.array([[0.0, 0, 5], [5, 0, 5], [10, 0, 5], [15, 0, 5], [17, 1.0, 5], [19, 1.5, 5]])
    b = np.array([[20.0, -1.5, 5], [21, -1.0, 5], [22, 0, 5], [27, 0, 5], [32, 0, 5]])
    fitted_a = np.array([False, True, True, True, False, False])  # a free end unfitted too
    fitted_b = np.array([False, False, True, True, True])
    assert len(join_pieces([a, b], [-1, -1], max_gap=10.0, lateral=1.0)) == 2
    spans = [_fitted_span(a, fitted_a, 12.0), _fitted_span(b, fitted_b, 12.0)]
    assert spans == [(1, 4), (2, 5)]
    chains = join_pieces([a[1:4], b[2:5]], [-1, -1], max_gap=10.0, lateral=1.0)
    [chain] = _tails_given_back(chains, spans, [len(a), len(b)])
    line = np.concatenate([((a, b)[k][::-1] if reverse else (a, b)[k])[first:stop]
                           for k, reverse, first, stop in chain])
    if line[0, 0] > line[-1, 0]:
        line = line[::-1]
    assert line[:, 0].tolist() == [0, 5, 10, 15, 22, 27, 32]  # a's first vertex kept
    # an unfitted run longer than the limit is the line's own traced course: it stays
    assert _fitted_span(a, fitted_a, 3.0) == (0, 6)
    assert _fitted_span(b, np.zeros(5, bool), 12.0) == (0, 5)


def _embankment_at_15_degrees_scored(tmp_path, density: float = 9.0):
    """A run's break lines scored against the true ones (``score_breaklines`` within 2 m, and
    ``"height_errors"``: |mesh - true ground| (m) every metre along the true lines), as a
    function of the output folder's name: LiDAR (``density`` points/m², 15 cm noise, seed 6)
    of an embankment (1.5 m high, 3 m crest, 1:2 sides) at 15° to the grid."""
    import shapely

    from floodmesh.core import io
    from floodmesh.core.chain import pipeline
    from floodmesh.core.frontends import demo
    from floodmesh.core.options import RunOptions
    from floodmesh.core.steps.accuracy import tin_elevation
    from floodmesh.core.steps.mesh import Mesh
    from floodmesh.core.steps.validation import score_breaklines

    along = 200 * np.array([np.cos(np.radians(15)), np.sin(np.radians(15))])
    plain = demo.Floodplain({  # the river south of the area: ground_elevation needs one
        "river": (shapely.LineString([(-50, -40), (350, -40)]), demo.Profile(-2.0, 4.0, 8.0)),
        "embankment": (shapely.LineString([(150, 120) - along, (150, 120) + along]),
                       demo.Profile(1.5, 1.5, 4.5))}, terrace=None)
    points, classes = demo.synthetic_floodplain(density=density, noise=0.15, seed=6,
                                                floodplain=plain)
    io.write_points_las(tmp_path / "points.laz", points, classes=classes)
    truth = [shapely.affinity.translate(g, *demo.DEMO_ORIGIN)
             for g in demo.true_breaklines(plain)]
    along_truth = np.concatenate([shapely.get_coordinates(shapely.line_interpolate_point(
        g, np.arange(0.0, g.length, 1.0))) for g in truth])
    local = along_truth - demo.DEMO_ORIGIN

    def score(out):
        pipeline.run_pipeline(tmp_path / "points.laz", tmp_path / out, RunOptions())
        result = score_breaklines(io.read_lines_gpkg(tmp_path / out / "breaklines.gpkg"),
                                  truth, 2.0)
        mesh = Mesh(*io.read_mesh_2dm(tmp_path / out / "mesh.2dm"), points.crs)
        result["height_errors"] = np.abs(
            tin_elevation(mesh, along_truth[:, 0], along_truth[:, 1])
            - demo.ground_elevation(local[:, 0], local[:, 1], plain))
        return result

    return score


def test_a_run_joins_a_noisy_embankments_pieces(tmp_path, monkeypatch):
    """From the user's side: LiDAR (9 points/m², 15 cm noise) of an embankment (1.5 m high,
    3 m crest, 1:2 sides) at 15° to the grid. Its four kinks come out in at most ten pieces;
    measured for joins and bridges at their traced ends, where the noise bent the trace off
    the kink, the pieces of one line lay too far apart across it, and stayed sixteen (7, 1, 4,
    4)."""
    from floodmesh.core.steps import localise

    score = _embankment_at_15_degrees_scored(tmp_path)
    now = score("now")
    monkeypatch.setattr(localise, "_fitted_span", lambda coords, fitted, tail: (0, len(coords)))
    before = score("before")
    # when written: pieces 4, 1, 3, 1, recall 0.984 (1, 1, 2, 1 since the bridges' second
    # pass); before: 7, 1, 4, 4, recall 0.984
    assert sum(now["pieces"]) <= 10 and sum(before["pieces"]) >= 14
    assert now["recall"] >= before["recall"] - 0.002


def test_a_run_keeps_a_noisy_embankments_crest_where_a_gap_in_it_was_bridged(tmp_path,
                                                                             monkeypatch):
    """From the user's side: LiDAR (2 points/m², 15 cm noise) of an embankment at 15°, whose
    lines the fits lose for a stretch and bridges carry across. The mesh follows the true
    ground along the embankment's four lines to within 0.7 m everywhere (when written: 0.56 m
    at most, 2 metres of line over 0.5 m off). A bridge was marked as a crossing's even where
    it crossed no other line, and the mesh, which leaves crossings out on low ground, dropped
    the crest there: 0.83 m off, 9 metres over 0.5 m. (Since the simplification keeps a line's
    part beyond a merge, ``_restore_beside_merges``, that crest's pieces are longer and the
    mesh 0.56 m off at most even then: the control takes that out too.)"""
    from floodmesh.core.steps import localise, simplify

    score = _embankment_at_15_degrees_scored(tmp_path, density=2.0)
    now = score("now")["height_errors"]
    monkeypatch.setattr(localise, "_crosses_another", lambda *args: True)
    monkeypatch.setattr(simplify, "_restore_beside_merges",  # merged, nothing given back
                        lambda lines, positions, masks, min_distance, cancelled=None:
                        simplify._merged(positions, masks, min_distance))
    before = score("before")["height_errors"]
    assert np.nanmax(now) < 0.7 and np.sum(now > 0.5) <= 4
    assert np.nanmax(before) > 0.75 and np.sum(before > 0.5) >= 8


def test_a_run_bridges_a_noisy_embankments_pieces_between_their_fitted_ends(tmp_path,
                                                                              monkeypatch):
    """From the user's side: LiDAR (9 points/m², 15 cm noise) of the embankment at 15°. Its
    four kinks come out in five pieces (1, 1, 2, 1); with the gaps that the fits fail along
    (over 10 m, the join gap) bridged only between the pieces' traced ends, nine (4, 1, 3, 1):
    beyond their last kinks found the traces bend off the crest with the noise."""
    from floodmesh.core.steps import localise

    score = _embankment_at_15_degrees_scored(tmp_path)
    now = score("now")
    first = localise._bridged  # the first pass alone: between the traced ends
    monkeypatch.setattr(localise, "_bridged", lambda pieces, make, gap, lateral, tail: first(
        pieces, make, gap, lateral, tail) if tail == 0 else (pieces, 0))
    before = score("before")
    assert sum(now["pieces"]) <= 6 and sum(before["pieces"]) >= 9
    assert now["recall"] >= before["recall"]
