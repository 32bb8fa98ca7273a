"""The report's pictures (floodmesh.core.report): valid PNGs, class colours where residuals of
each class are, NaN residuals, atomic writing."""
import numpy as np
import pytest
from matplotlib import colors
from matplotlib.image import imread

from floodmesh.core import report
from floodmesh.core.options import OUTSIDE_MESH_COLOUR, RESIDUAL_CLASS_COLOURS

from ..conftest import UTM_ORIGIN, hole_mesh


def colour_pixels(image, hex_colour, tol=2 / 255):
    """How many pixels of an RGB(A) image (floats 0–1) have the colour ``hex_colour``."""
    rgb = np.array(colors.to_rgb(hex_colour))
    return int((np.abs(image[:, :, :3] - rgb).max(axis=2) <= tol).sum())


def distinct_colours(image):
    return len(np.unique((image[:, :, :3] * 255).round().astype(np.uint8).reshape(-1, 3), axis=0))


def check_points(residuals_m, seed=0):
    """Points spread over hole_mesh()'s solid part (x 0–40 m) with the given residuals (z = TIN z
    plus the residual), as (n, 3) in UTM coordinates."""
    rng = np.random.default_rng(seed)
    n = len(residuals_m)
    local = np.column_stack([rng.uniform(2, 38, n), rng.uniform(2, 58, n)])
    z = 10.0 + 0.01 * local[:, 0] + 0.02 * local[:, 1] + np.asarray(residuals_m)
    return np.column_stack([local + UTM_ORIGIN, z])


@pytest.fixture
def classes_mix():
    """Residuals of all three classes and two NaN (outside the mesh)."""
    res = np.array([0.01, -0.03, 0.05, 0.0, -0.08] * 8 + [0.15, -0.2, 0.12] * 5
                   + [0.4, -0.6, 1.5] * 3 + [np.nan, np.nan])
    return res


def test_histogram_is_a_png_with_each_class_colour(tmp_path, classes_mix):
    path = report.write_residual_histogram(tmp_path / "h.png", classes_mix)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = imread(path)
    assert image.shape[0] >= 300 and image.shape[1] >= 500
    assert distinct_colours(image) > 10
    for colour in RESIDUAL_CLASS_COLOURS:
        assert colour_pixels(image, colour) > 50, colour


def test_histogram_without_large_residuals_has_no_red(tmp_path):
    """Control for the colour test: no residual over 25 cm, no red bar (so the test above can
    fail)."""
    image = imread(report.write_residual_histogram(tmp_path / "h.png",
                                                   np.array([0.02, -0.04, 0.12] * 10)))
    assert colour_pixels(image, RESIDUAL_CLASS_COLOURS[0]) > 50
    assert colour_pixels(image, RESIDUAL_CLASS_COLOURS[2]) == 0


def test_histogram_bins_have_the_class_edges():
    for top in (0.05, 0.4, 1.0, 2.0, 30.0):
        edges = report.histogram_bins_cm(np.array([-100 * top, 0.0, 100 * top]))
        assert {-25.0, -10.0, 10.0, 25.0} <= set(edges.tolist())
        assert edges[-1] >= min(100 * top, 250) and len(edges) <= 101


def test_histogram_all_outside_the_mesh(tmp_path):
    """All residuals NaN: still a picture, which says so, not an error."""
    image = imread(report.write_residual_histogram(tmp_path / "h.png", np.full(5, np.nan)))
    assert image.ndim == 3 and distinct_colours(image) > 2


def test_map_shows_each_class_where_it_occurs(tmp_path, classes_mix):
    nodes, triangles = hole_mesh()
    xyz = check_points(classes_mix)
    xyz[-2:, :2] = np.array([[50.0, 30.0], [-5.0, 5.0]]) + UTM_ORIGIN  # in the hole, outside
    from floodmesh.core.accuracy import residuals
    from floodmesh.core.mesh import Mesh

    res = residuals(Mesh(nodes, triangles, None), xyz)
    assert np.isnan(res[-2:]).all() and np.allclose(res[:-2], classes_mix[:-2])
    path = report.write_residual_map(tmp_path / "m.png", nodes, triangles, xyz, res)
    image = imread(path)
    assert image.shape[0] > 200 and distinct_colours(image) > 10
    for colour in (*RESIDUAL_CLASS_COLOURS, OUTSIDE_MESH_COLOUR):
        assert colour_pixels(image, colour) > 10, colour
    # only small residuals: no orange or red points
    small = report.write_residual_map(tmp_path / "s.png", nodes, triangles, xyz[:40],
                                      res[:40])
    image = imread(small)
    assert colour_pixels(image, RESIDUAL_CLASS_COLOURS[0]) > 10
    assert colour_pixels(image, RESIDUAL_CLASS_COLOURS[1]) == 0
    assert colour_pixels(image, RESIDUAL_CLASS_COLOURS[2]) == 0


def test_map_has_equal_aspect(tmp_path):
    """hole_mesh() is 100 x 60 m: the picture is wider than tall."""
    nodes, triangles = hole_mesh()
    image = imread(report.write_residual_map(tmp_path / "m.png", nodes, triangles,
                                             check_points([0.0]), np.array([0.0])))
    assert image.shape[1] > 1.3 * image.shape[0]


def test_map_draws_the_edges_up_to_its_limit(tmp_path, monkeypatch):
    """The mesh's faint grey edges are drawn while there are at most MAP_EDGES of them; above,
    none (the title says how many), so the map's memory does not grow with the mesh."""
    nodes, triangles = hole_mesh()
    xyz = check_points([0.0])

    def grey_pixels(name):
        image = imread(report.write_residual_map(tmp_path / name, nodes, triangles, xyz,
                                                 np.array([0.0])))[:, :, :3]
        return int(((image.max(axis=2) - image.min(axis=2) < 0.02)
                    & (image.mean(axis=2) > 0.6) & (image.mean(axis=2) < 0.9)).sum())

    edges = len(report.mesh_edges(triangles))
    monkeypatch.setattr(report, "MAP_EDGES", edges)
    drawn = grey_pixels("drawn.png")
    monkeypatch.setattr(report, "MAP_EDGES", edges - 1)
    assert drawn > 4 * grey_pixels("bare.png")  # text and frame are the rest


def test_mesh_edges_are_unique():
    triangles = np.array([[0, 1, 2], [2, 1, 3]])
    assert report.mesh_edges(triangles).tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]


def test_failed_write_leaves_no_file(tmp_path):
    """A figure that fails while being rendered (bad mathtext) leaves neither the PNG nor a
    temporary file, and an existing PNG stays as it was."""
    broken = report.new_figure(4, 3)
    broken.add_subplot().set_title(r"$\frac{$")
    with pytest.raises(ValueError):
        report.save_png(broken, tmp_path / "new.png")
    assert list(tmp_path.iterdir()) == []
    good = report.write_residual_histogram(tmp_path / "h.png", np.array([0.0, 0.1]))
    before = good.read_bytes()
    with pytest.raises(ValueError):
        report.save_png(broken, good)
    assert good.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["h.png"]


def test_write_report_pngs(tmp_path, classes_mix):
    nodes, triangles = hole_mesh()
    paths = report.write_report_pngs(tmp_path, nodes, triangles, check_points(classes_mix),
                                     classes_mix)
    assert [p.name for p in paths] == [report.HISTOGRAM_PNG, report.MAP_PNG]
    assert all(imread(p).ndim == 3 for p in paths)


def test_an_interrupt_while_drawing_waits_until_the_pictures_are_written(tmp_path, classes_mix):
    """Ctrl-C inside matplotlib left broken paths that crashed a later draw (SIGSEGV on Debian
    13): the interrupt comes just after both pictures instead, and the handler is restored."""
    import signal

    nodes, triangles = hole_mesh()
    raised = []

    def interrupt(signum, frame):
        raised.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.002)  # drawing takes far longer
        with pytest.raises(KeyboardInterrupt):
            report.write_report_pngs(tmp_path, nodes, triangles, check_points(classes_mix),
                                     classes_mix)
        assert signal.getsignal(signal.SIGALRM) is interrupt
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert raised == [signal.SIGALRM]
    assert all(imread(tmp_path / name).ndim == 3 for name in (report.HISTOGRAM_PNG, report.MAP_PNG))
