"""The report's pictures (floodmesh.core.io.report): valid PNGs, class colours where residuals of
each class are, NaN residuals, atomic writing; the hillshade and the break lines over it, and
report.html (floodmesh.core.io.report_html) of a run: its figures those of report.json, its images
embedded PNGs, its text escaped, the case without a holdout."""
import json
from pathlib import Path
from html.parser import HTMLParser

import numpy as np
import pytest
from matplotlib import colors
from matplotlib.image import imread

from floodmesh.core.io import report
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
    from floodmesh.core.steps.accuracy import residuals
    from floodmesh.core.steps.mesh import Mesh

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


def test_report_pngs_are_those_savefig_writes(tmp_path, classes_mix):
    """The pictures, drawn here and compressed on a second thread, are byte for byte those the
    figures give through matplotlib's savefig (at zlib's fastest level) one after another."""
    from affine import Affine

    from floodmesh.core.raster import Grid

    nodes, triangles = hole_mesh()
    xyz = check_points(classes_mix)
    rows, cols = np.mgrid[0:60, 0:100]
    dem = Grid(np.sin(cols / 7.0) + 0.02 * rows, Affine(1.0, 0, UTM_ORIGIN[0], 0, -1.0,
                                                        UTM_ORIGIN[1] + 60), None)
    lines = [xyz[:5, :2], xyz[5:12, :2]]
    report.write_report_pngs(tmp_path, nodes, triangles, xyz, classes_mix, dem=dem, lines=lines)
    for name, fig in ((report.HISTOGRAM_PNG, report.residual_histogram(classes_mix)),
                      (report.MAP_PNG, report.residual_map(nodes, triangles, xyz, classes_mix)),
                      (report.BREAKLINES_PNG, report.breaklines_map(dem, lines))):
        fig.savefig(tmp_path / "savefig.png", format="png", pil_kwargs={"compress_level": 1})
        assert (tmp_path / name).read_bytes() == (tmp_path / "savefig.png").read_bytes(), name


def test_map_draws_the_mesh_as_one_line():
    """The mesh's edges are one line broken between the edges and the points are markers: no
    collection of a path per edge or per point, which made the map slow."""
    nodes, triangles = hole_mesh()
    fig = report.residual_map(nodes, triangles, check_points([0.0, 0.2, 0.5]),
                              np.array([0.0, 0.2, 0.5]))
    ax = fig.axes[0]
    assert not ax.collections and not ax.patches
    edges = len(report.mesh_edges(triangles))
    assert sorted(len(line.get_xdata()) for line in ax.lines) == [1, 1, 1, 3 * edges]


def test_a_picture_failing_on_the_encoder_thread_fails_the_call(tmp_path, classes_mix):
    """An error writing a picture (its name taken by a folder) reaches the caller; the other
    pictures are written, no temporary file is left."""
    nodes, triangles = hole_mesh()
    (tmp_path / report.MAP_PNG).mkdir()
    with pytest.raises(OSError):
        report.write_report_pngs(tmp_path, nodes, triangles, check_points(classes_mix),
                                 classes_mix)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([report.MAP_PNG,
                                                                report.HISTOGRAM_PNG])


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


# --- the break lines over a hillshade, and report.html ---------------------------------------

def test_hillshade_lights_the_slopes_facing_the_sun():
    """Sun from the north-west (315°), 45° high: flat ground is lit sin 45°, a slope facing
    north-west brighter, one facing south-east darker, a steep one facing away black. Rows run
    from north to south, so z rising with the row index falls to the north."""
    from floodmesh.core.io.report import hillshade

    rows, cols = np.mgrid[0:20, 0:20].astype(float)
    flat = hillshade(np.zeros((20, 20)), 1.0)
    assert np.allclose(flat, np.sin(np.radians(45)))
    # z rising to the south-east (east and down the rows): the slope faces north-west
    facing_nw = hillshade(0.3 * (cols + rows), 1.0)
    facing_se = hillshade(-0.3 * (cols + rows), 1.0)
    assert facing_nw.min() > flat.max() + 0.1 and facing_se.max() < flat.min() - 0.1
    assert hillshade(-5.0 * (cols + rows), 1.0).max() == 0.0
    # the cell size scales the gradient: 2 m cells halve the slope
    assert np.allclose(hillshade(0.6 * (cols + rows), 2.0), facing_nw)
    # NaN stays NaN (and its neighbours, which have no gradient); tiny grids work
    holed = 0.3 * (cols + rows)
    holed[5, 5] = np.nan
    shade = hillshade(holed, 1.0)
    assert np.isnan(shade[4:7, 5]).all() and np.isnan(shade[5, 4:7]).all()
    assert np.isfinite(shade[0, 0]) and np.isfinite(shade[4, 4])
    assert hillshade(np.array([[1.0, 2.0]]), 1.0).shape == (1, 2)


def test_hillshade_is_sampled_for_a_large_dem():
    """A DEM of 4000 x 3000 cells is drawn from every 3rd cell (at most HILLSHADE_CELLS on the
    long side) over the same extent."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.raster import Grid
    from floodmesh.core.io.report import HILLSHADE_CELLS, sampled_hillshade

    values = np.zeros((3000, 4000), np.float32)
    dem = Grid(values, Affine(0.5, 0, 1000.0, 0, -0.5, 2000.0), CRS.from_epsg(25832))
    shade, extent = sampled_hillshade(dem)
    assert max(shade.shape) <= HILLSHADE_CELLS and shade.shape == (1000, 1334)
    assert extent[0] == 1000.0 and extent[3] == 2000.0
    assert extent[1] == pytest.approx(3001.0) and extent[2] == pytest.approx(500.0)


class _Page(HTMLParser):
    """What a test reads of report.html: the text of each element with an id, the cells of each
    table row with an id, the images' sources, every tag and every URL attribute."""

    def __init__(self, text):
        super().__init__(convert_charrefs=True)
        self.ids, self.cells, self.images, self.tags, self.urls = {}, {}, [], [], []
        self._open = []  # (tag, id) of the elements open
        self._row = None
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append(tag)
        for name in ("src", "href", "action", "background"):
            if name in attrs:
                self.urls.append(attrs[name])
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        if tag in ("img", "meta", "br", "hr", "link"):
            return
        if tag == "tr":
            self._row = attrs.get("id")
            if self._row:
                self.cells[self._row] = []
        if tag == "td" and self._row:
            self.cells[self._row].append("")
        if attrs.get("id"):
            self.ids[attrs["id"]] = ""
        self._open.append((tag, attrs.get("id")))

    def handle_endtag(self, tag):
        while self._open:
            if self._open.pop()[0] == tag:
                break
        if tag == "tr":
            self._row = None

    def handle_data(self, data):
        for _, element in self._open:
            if element:
                self.ids[element] += data
        if self._row and self._open and self._open[-1][0] == "td":
            self.cells[self._row][-1] += data


def _png_images(page):
    """The page's embedded images, decoded, checked as PNG: a list of (rows, cols, bands)
    arrays."""
    import base64
    import io as stdio

    images = []
    for src in page.images:
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix), src[:40]
        data = base64.b64decode(src[len(prefix):], validate=True)
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        images.append(imread(stdio.BytesIO(data), format="png"))
    return images


@pytest.fixture(scope="module")
def html_run(demo_points_file, tmp_path_factory):
    """One run on the small demo floodplain (2 points/m², 1 % held out)."""
    from floodmesh.core.chain.pipeline import RunOptions, run_pipeline

    out = tmp_path_factory.mktemp("html")
    report_dict = run_pipeline(demo_points_file, out, RunOptions(holdout=0.01))
    return out, report_dict


def test_run_writes_report_html_listed_in_report_json(html_run):
    out, report_dict = html_run
    written = json.loads((out / "report.json").read_text())
    for name in ("report.html", report.BREAKLINES_PNG):
        assert name in written["files"] and name in report_dict["files"]
        assert (out / name).stat().st_size > 0
    assert written["breakline_length_m"] > 100 * written["n_breaklines"] > 0


def test_report_html_figures_are_those_of_report_json(html_run):
    """The accuracy table holds report.json's numbers, formatted; the FEMA/NSSDA verdict and
    the bound it tested are there; mesh and break-line figures too."""
    out, _ = html_run
    written = json.loads((out / "report.json").read_text())
    page = _Page((out / "report.html").read_text(encoding="utf-8"))
    assert written["n_assessed"] > 100
    assert page.cells["rmse"] == [f"{100 * written['rmse_m']:.2f} cm"]
    assert page.cells["accuracy-95"] == [f"{100 * 1.96 * written['rmse_m']:.2f} cm"]
    assert page.cells["max-abs"] == [f"{100 * written['max_abs_residual_m']:.2f} cm"]
    assert page.cells["n-holdout"] == [f"{written['n_holdout']:,}"]
    assert page.cells["skew"] == [f"{written['skew']:.2f}"]
    assert page.cells["vertex-bound"][0].startswith(f"{written['vertex_error_bound_m']:.3f} m")
    shares = [page.cells[f"class-{k}"] for k in range(3)]
    assert sum(int(points.replace(",", "")) for points, _ in shares) == written["n_assessed"]
    assert shares[0][1] == f"{100 * written['classes']['<10 cm']:.1f} %"
    verdict = page.ids["nssda"]
    assert ("PASS" if written["nssda_pass"] else "FAIL") in verdict
    assert f"{100 * written['nssda_threshold_m']:.2f} cm" in verdict
    assert f"n = {written['n_assessed']:,}" in verdict and "2.326" in verdict
    assert page.cells["nodes"] == [f"{written['nodes']:,}"]
    assert page.cells["min-angle"][0].startswith(f"{written['min_angle_deg']:.1f}°")
    assert page.cells["cfl"][0].startswith(f"{written['hydraulics']['cfl_time_step_s']:.3g} s")
    assert page.cells["n-breaklines"] == [str(written["n_breaklines"])]
    assert page.cells["breakline-length"] == [f"{written['breakline_length_m']:,.1f} m"]
    assert page.ids["title"] == "FloodMesh run: floodplain.laz"


def test_report_html_embeds_the_three_pngs_and_nothing_external(html_run):
    out, _ = html_run
    text = (out / "report.html").read_text(encoding="utf-8")
    page = _Page(text)
    images = _png_images(page)
    assert len(images) == 3 and all(i.ndim == 3 and i.shape[0] > 200 for i in images)
    # the very files of the run folder
    import base64

    for name in (report.HISTOGRAM_PNG, report.MAP_PNG, report.BREAKLINES_PNG):
        uri = "data:image/png;base64," + base64.b64encode((out / name).read_bytes()).decode()
        assert uri in page.images, name
    assert not {"script", "link", "iframe", "object", "embed"} & set(page.tags)
    assert all(url.startswith("data:") for url in page.urls)
    assert "<script" not in text.lower() and "javascript:" not in text.lower()
    assert 'charset="utf-8"' in text


def test_breaklines_map_draws_magenta_lines_on_a_hillshade(html_run):
    out, _ = html_run
    image = imread(out / report.BREAKLINES_PNG)
    assert colour_pixels(image, report.BREAKLINE_COLOUR, tol=4 / 255) > 500
    assert colour_pixels(image, report.HALO_COLOUR) > 500
    grey = image[:, :, :3]
    grey = grey[(grey.max(axis=2) - grey.min(axis=2) < 0.01)]
    assert len(np.unique((grey * 255).round(), axis=0)) > 50  # the hillshade's shades


def test_report_html_escapes_text(html_run):
    """Notes, input names and options are text, never markup."""
    from floodmesh.core.io.report_html import report_html

    _, report_dict = html_run
    hostile = dict(report_dict, input="/data/<b>reach</b> & co.laz",
                   notes=['a note with <script>alert("x")</script> & <img src=x>'],
                   options=dict(report_dict["options"], crs="<i>EPSG</i>"))
    text = report_html(hostile, {})
    page = _Page(text)
    assert not {"script", "b", "i"} & set(page.tags) and page.images == []
    assert "&lt;script&gt;" in text and "&lt;b&gt;reach&lt;/b&gt; &amp; co.laz" in text
    assert '<script>alert("x")</script>' in page.ids["notes"]


def test_report_html_verdicts(html_run):
    """A failed test says FAIL, too few check points say the test was not made."""
    from floodmesh.core.io.report_html import report_html
    from floodmesh.core.steps.accuracy import nssda_threshold_m

    _, report_dict = html_run
    failed = _Page(report_html(dict(report_dict, nssda_pass=False), {}))
    assert "FAIL" in failed.ids["nssda"] and "PASS" not in failed.ids["nssda"]
    few = _Page(report_html(dict(report_dict, n_assessed=5, nssda_pass=None,
                                 nssda_threshold_m=None), {}))
    assert "not tested" in few.ids["nssda"]
    assert "it needs at least 7; FEMA asks for 20 or more" in few.ids["nssda"]
    # 12 points: the bound exists (from 7), but FEMA's test takes 20; that is why, not the 7
    twelve = _Page(report_html(dict(report_dict, n_assessed=12, nssda_pass=None,
                                    nssda_threshold_m=nssda_threshold_m(12)), {}))
    assert "not tested" in twelve.ids["nssda"] and "(12)" in twelve.ids["nssda"]
    assert "FEMA asks for 20 or more" in twelve.ids["nssda"]
    assert "at least 7" not in twelve.ids["nssda"]


def test_report_html_without_holdout(tmp_path):
    """Holdout 0: a sentence instead of the accuracy figures; the mesh, break lines and their
    map are still there, and the page is listed."""
    from pyproj import CRS

    from floodmesh.core import io
    from floodmesh.core.chain.pipeline import RunOptions, run_pipeline
    from floodmesh.core.points import PointCloud

    from ..conftest import plane_points

    xyz = plane_points(size=60.0, density=3.0, seed=4)
    xyz[:, 2] += np.where(xyz[:, 0] - xyz[:, 0].min() > 30, 2.0, 0.0)  # a 2 m bank
    source = tmp_path / "points.laz"
    io.write_points_las(source, PointCloud(xyz, CRS.from_epsg(25832)))
    out = tmp_path / "run"
    written = run_pipeline(source, out, RunOptions(holdout=0.0, cell_size=2.0, max_area=80.0))
    assert written["n_holdout"] == 0 and written["rmse_m"] is None
    assert "report.html" in json.loads((out / "report.json").read_text())["files"]
    page = _Page((out / "report.html").read_text(encoding="utf-8"))
    assert "not assessed" in page.ids["no-assessment"]
    assert "rmse" not in page.cells and "nssda" not in page.ids
    assert page.cells["nodes"] == [f"{written['nodes']:,}"]
    assert len(_png_images(page)) == 2  # the mesh map and the break lines; no histogram
    assert "breaklines_map" in page.ids and "residual_histogram" not in page.ids


@pytest.mark.parametrize("shape", ["square", "wide", "tall"])
def test_the_maps_legends_and_axis_titles_are_inside_the_picture(shape, classes_mix):
    """The legend beside each map and the northing axis title were cut off at the picture's
    edges (tight_layout ignored the legend outside the equal-aspect map): every label of both
    maps lies inside the figure, whatever the map's shape, with counts in the thousands."""
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.raster import Grid

    width, height = {"square": (1000, 1000), "wide": (1000, 300), "tall": (300, 1000)}[shape]
    nodes = np.array([[0, 0, 0], [width, 0, 0], [width, height, 0], [0, height, 0]], float)
    nodes[:, :2] += UTM_ORIGIN
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, width, 3000), rng.uniform(0, height, 3000),
                           np.zeros(3000)])
    xyz[:, :2] += UTM_ORIGIN
    res = np.resize(np.append(classes_mix, np.nan), 3000)
    dem = Grid(np.zeros((height // 2, width // 2)), Affine(2.0, 0, UTM_ORIGIN[0], 0, -2.0,
                                                          UTM_ORIGIN[1] + height),
               CRS.from_epsg(25832))
    line = np.array([[0.1, 0.5], [0.9, 0.5]]) * [width, height] + UTM_ORIGIN
    for fig in (report.residual_map(nodes, triangles, xyz, res),
                report.breaklines_map(dem, [line] * 1200)):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        inside = fig.bbox
        ax = fig.axes[0]
        for artist in (ax.get_legend(), ax.yaxis.label, ax.xaxis.label, ax.title,
                       *ax.get_yticklabels()):
            box = artist.get_window_extent(renderer)
            assert (box.x0 >= inside.x0 and box.x1 <= inside.x1 and box.y0 >= inside.y0
                    and box.y1 <= inside.y1), (artist, box, inside)


def _pictures_case(classes_mix):
    from affine import Affine
    from pyproj import CRS

    from floodmesh.core.raster import Grid

    nodes, triangles = hole_mesh()
    xyz = check_points(classes_mix)
    rows, cols = np.mgrid[0:60, 0:100]
    dem = Grid(np.sin(cols / 7.0) + 0.02 * rows, Affine(1.0, 0, UTM_ORIGIN[0], 0, -1.0,
                                                        UTM_ORIGIN[1] + 60), CRS.from_epsg(32633))
    return nodes, triangles, xyz, classes_mix, dem, [xyz[:5], xyz[5:12]]


def test_pictures_drawn_in_their_own_process_are_those_drawn_here(tmp_path, classes_mix):
    """The run's pictures, drawn by the picture process, are byte for byte those drawn in the
    chain's own process; the process is gone and its arrays' file removed afterwards."""
    from floodmesh.core.io.report_process import PicturesApart

    nodes, triangles, xyz, res, dem, lines = _pictures_case(classes_mix)
    (tmp_path / "apart").mkdir()
    (tmp_path / "here").mkdir()
    with PicturesApart() as pictures:
        pictures.start()
        assert pictures.child is not None
        pictures.draw(tmp_path / "apart", nodes, triangles, xyz, res, dem=dem, lines=lines)
        data = Path(pictures.data)
        assert data.exists()
        pictures.wait()
        assert pictures.child.returncode == 0  # drawn there, not here after a failure
    assert not data.exists()
    report.write_report_pngs(tmp_path / "here", nodes, triangles, xyz, res, dem=dem,
                             lines=lines)
    for name in (report.HISTOGRAM_PNG, report.MAP_PNG, report.BREAKLINES_PNG):
        assert (tmp_path / "apart" / name).read_bytes() == (tmp_path / "here" / name).read_bytes()


def test_pictures_are_drawn_here_when_their_process_fails(tmp_path, classes_mix, monkeypatch):
    """A picture process that cannot run (here a 'python' that fails at once) costs nothing
    but the overlap: the pictures are drawn in the chain's process."""
    import sys

    from floodmesh.core.io.report_process import PicturesApart

    broken = tmp_path / "python-broken"
    broken.write_text("#!/bin/sh\nexit 3\n")
    broken.chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(broken))
    nodes, triangles, xyz, res, dem, lines = _pictures_case(classes_mix)
    with PicturesApart() as pictures:
        pictures.start()
        pictures.draw(tmp_path, nodes, triangles, xyz, res, dem=dem, lines=lines)
        pictures.wait()
        assert pictures.child.returncode == 3
    assert all((tmp_path / name).exists()
               for name in (report.HISTOGRAM_PNG, report.MAP_PNG, report.BREAKLINES_PNG))


def test_a_run_that_ends_early_ends_its_picture_process(tmp_path):
    """An error or interrupt before the pictures are handed over ends the picture process: no
    process is left waiting."""
    import time

    from floodmesh.core.io.report_process import PicturesApart

    with pytest.raises(KeyboardInterrupt):
        with PicturesApart() as pictures:
            pictures.start()
            time.sleep(0.5)
            assert Path(f"/proc/{pictures.child.pid}").exists()  # it waits for its arrays
            raise KeyboardInterrupt
    assert pictures.child.poll() is not None
    assert not Path(f"/proc/{pictures.child.pid}").exists()  # ended and reaped
