"""Reading and writing at the pipeline's edges (floodmesh.core.io)."""
import os

import fiona
import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from floodmesh.core import io
from floodmesh.core.steps.breaklines import BreakLine
from floodmesh.core.errors import FloodMeshError
from floodmesh.core.options import is_point_source
from floodmesh.core.points import PointCloud
from floodmesh.core.raster import Grid

from ..conftest import plane_points

UTM32 = CRS.from_epsg(25832)


def _cloud(n=60, seed=3):
    xyz = plane_points(size=50.0, density=n / 2500.0, seed=seed, origin=(412_000.0, 5_652_000.0))
    return PointCloud(xyz, UTM32)


# ---------------------------------------------------------------------------------------------
# LAS / LAZ
@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_las_round_trip_reads_ground_class_by_default(tmp_path, ext):
    """Written points with classes 2 and 1 read back: class 2 only, to the 1 mm LAS scale, same CRS."""
    cloud = _cloud()
    classes = np.where(np.arange(len(cloud)) % 3 == 0, 1, 2).astype(np.uint8)
    path = tmp_path / f"points{ext}"
    io.write_points_las(path, cloud, classes=classes)

    ground = io.read_points(path)
    assert len(ground) == int((classes == 2).sum())
    np.testing.assert_allclose(ground.xyz, cloud.xyz[classes == 2], rtol=0, atol=1e-3)
    assert ground.crs == UTM32

    other = io.read_points(path, classes=(1,))
    assert len(other) == int((classes == 1).sum())
    np.testing.assert_allclose(other.xyz, cloud.xyz[classes == 1], rtol=0, atol=1e-3)
    assert other.crs == UTM32


def test_class_flags_of_older_point_formats_do_not_change_the_class(tmp_path):
    """Point formats 0 to 5 keep three flags (synthetic, key-point, withheld) in the top bits
    of the class byte: a flagged ground point is still ground, as laspy's own class says, but
    one flagged withheld is deleted by the LAS specification: left out, with a note."""
    import laspy

    cloud = _cloud(n=400)
    classes = np.where(np.arange(len(cloud)) % 3 == 0, 1, 2).astype(np.uint8)
    path = tmp_path / "flagged.laz"
    io.write_points_las(path, cloud, classes=classes)
    las = laspy.read(path)
    withheld = np.arange(len(cloud)) % 5 == 0
    las.synthetic = np.arange(len(cloud)) % 2 == 0
    las.withheld = withheld
    las.write(path)
    assert (np.asarray(laspy.read(path).points.array["raw_classification"]) > 31).any()
    notes = []
    ground = io.read_points(path, note=notes.append)
    np.testing.assert_allclose(ground.xyz, cloud.xyz[(classes == 2) & ~withheld], rtol=0,
                               atol=1e-3)
    assert any(f"{withheld.sum()} points flagged withheld" in n for n in notes)


def test_laz_of_las_1_4_layers_reads_its_ground_exactly(tmp_path):
    """A LAS 1.4 LAZ in point format 7 (its fields in layers compressed apart: FloodMesh
    decompresses only x, y, z, the class and its flags) with every other field filled: the
    ground points are those laspy reads with every layer, to the stored integer, but those
    flagged withheld, and a class above 31 (which only formats 6 to 10 hold) can be asked for."""
    import laspy

    cloud = _cloud(n=500)
    n = len(cloud)
    rng = np.random.default_rng(5)
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.scales, header.offsets = np.full(3, 0.001), np.array([412_000.0, 5_652_000.0, 0.0])
    header.add_crs(UTM32)
    las = laspy.LasData(header)
    las.x, las.y, las.z = cloud.xyz.T
    las.classification = rng.choice(np.array([1, 2, 64], np.uint8), n)
    las.intensity = rng.integers(0, 65535, n).astype(np.uint16)
    las.gps_time = rng.uniform(3e8, 3e8 + 60, n)
    las.return_number = rng.integers(1, 4, n).astype(np.uint8)
    las.number_of_returns = np.full(n, 3, np.uint8)
    las.scan_angle = rng.integers(-3000, 3000, n).astype(np.int16)
    las.red = las.green = las.blue = rng.integers(0, 65535, n).astype(np.uint16)
    las.withheld = rng.random(n) < 0.1
    path = tmp_path / "points_1_4.laz"
    las.write(path)

    whole = laspy.read(path)
    stored = np.column_stack([whole.x, whole.y, whole.z])
    kept = ~np.asarray(whole.withheld, bool)
    assert not kept.all()
    for classes, want in ((None, 2), ((64,), 64)):
        read = io.read_points(path, classes=classes)
        np.testing.assert_array_equal(
            read.xyz, stored[(np.asarray(whole.classification) == want) & kept])
        assert read.crs == UTM32


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_no_points_write_a_valid_empty_las(tmp_path, ext):
    """A library user writing a cloud of no points (a tile left empty by a filter) gets a valid
    LAS of none with its CRS, as write_points_gpkg writes an empty layer; reading it back as
    terrain is refused in one line."""
    import laspy

    path = tmp_path / f"empty{ext}"
    io.write_points_las(path, PointCloud(np.zeros((0, 3)), CRS.from_epsg(25832)))
    las = laspy.read(path)
    assert len(las.points) == 0 and las.header.parse_crs().to_epsg() == 25832
    with pytest.raises(FloodMeshError, match="holds no points"):
        io.read_points(path)


def test_crs_given_for_a_las_in_another_is_said(tmp_path):
    """--crs over a LAS's own, different CRS is used, and said; the same CRS is said nothing."""
    path = tmp_path / "points.laz"
    io.write_points_las(path, _cloud())
    notes = []
    assert io.read_points(path, crs="EPSG:25833", note=notes.append).crs.to_epsg() == 25833
    assert any("is in ETRS89 / UTM zone 32N, but the CRS given is used" in n for n in notes)
    notes.clear()
    io.read_points(path, crs="EPSG:25832", note=notes.append)
    assert not any("the CRS given" in n for n in notes)


def test_las_absent_classes_are_refused_with_the_present_ones(tmp_path):
    """Asking for classes the file lacks raises FloodMeshError listing the classes present (1, 2)."""
    cloud = _cloud()
    classes = np.where(np.arange(len(cloud)) % 2 == 0, 1, 2).astype(np.uint8)
    path = tmp_path / "points.laz"
    io.write_points_las(path, cloud, classes=classes)
    with pytest.raises(FloodMeshError, match=r"classes present: 1, 2"):
        io.read_points(path, classes=(6, 9))


# ---------------------------------------------------------------------------------------------
# XYZ text
XYZ = np.array([[412_000.5, 5_652_000.25, 10.0], [412_010.0, 5_652_001.0, 11.5],
                [412_003.0, 5_652_012.5, 12.25], [412_020.0, 5_652_020.0, 9.75]])


@pytest.mark.parametrize("name, text", [
    ("spaces.xyz", "\n".join(f"{x} \t{y}   {z}" for x, y, z in XYZ) + "\n"),
    ("header.csv", "x,y,z\n" + "\n".join(f"{x},{y},{z}" for x, y, z in XYZ) + "\n"),
    ("semicolon.txt", "\n".join(f"{x};{y};{z}" for x, y, z in XYZ) + "\n"),
])
def test_xyz_text_variants(tmp_path, name, text):
    """Whitespace, comma-with-header and semicolon text files give the written coordinates exactly."""
    path = tmp_path / name
    path.write_text(text)
    points = io.read_points(path, crs="EPSG:25832")
    np.testing.assert_array_equal(points.xyz, XYZ)
    assert points.crs == UTM32


def _rows(columns, sep=","):
    return "".join(sep.join(f"{v}" for v in row) + "\n" for row in columns)


@pytest.mark.parametrize("header, columns", [
    ("Northing,Easting,Height", (1, 0, 2)),  # y first, as many surveyors write it
    ("N,E,Z", (1, 0, 2)),
    ("Elev,East,North", (1, 2, 0)),
    ("X [m],Y [m],Z [m],Intensity,Classification", (0, 1, 2)),  # units, names with spaces
    ("x (m),y (m),z (m)", (0, 1, 2)),
    ("PointID,E,N,Z", (1, 2, 3)),
    ("\ufeffz,x,y", (1, 2, 0)),  # Excel's "CSV UTF-8" begins with a byte-order mark
])
def test_xyz_header_names_its_columns_in_any_order(tmp_path, header, columns):
    """The columns are those the header names, whatever their order, case, units or a
    byte-order mark (the other columns, a class among them, hold 2)."""
    rows = np.full((len(XYZ), header.count(",") + 1), 2.0)
    rows[:, list(columns)] = XYZ
    path = tmp_path / "points.csv"
    path.write_text(header + "\n" + _rows(rows), encoding="utf-8")
    np.testing.assert_array_equal(io.read_points(path, crs="EPSG:25832").xyz, XYZ)


def test_xyz_byte_order_mark_without_header_keeps_every_point(tmp_path):
    """A UTF-8 byte-order mark before the first number is no header: no point is lost."""
    path = tmp_path / "points.xyz"
    path.write_text("\ufeff" + _rows(XYZ, " "), encoding="utf-8")
    np.testing.assert_array_equal(io.read_points(path, crs="EPSG:25832").xyz, XYZ)


def test_xyz_class_column_keeps_the_ground(tmp_path):
    """A classification column is read as LAS classes: the ground (2) when there is one, or the
    classes asked for; without one, --classes is said not to apply."""
    noise = XYZ - [0.0, 0.0, 20.0]
    rows = np.vstack([np.column_stack([XYZ, np.full(4, 2)]), np.column_stack([noise,
                                                                              np.full(4, 7)])])
    path = tmp_path / "classified.csv"
    path.write_text("x,y,z,classification\n" + _rows(rows))
    np.testing.assert_array_equal(io.read_points(path, crs="EPSG:25832").xyz, XYZ)
    np.testing.assert_array_equal(io.read_points(path, crs="EPSG:25832", classes=[7]).xyz, noise)
    plain, notes = tmp_path / "plain.csv", []
    plain.write_text("x,y,z\n" + _rows(XYZ))
    io.read_points(plain, crs="EPSG:25832", classes=[2], note=notes.append)
    assert any("no classification column" in n for n in notes)


def test_xyz_empty_fields_are_left_out_with_a_note(tmp_path):
    """A row with an empty field is left out, said in a note, as the user guide promises."""
    path, notes = tmp_path / "gaps.csv", []
    path.write_text(_rows(XYZ) + "412030.0,5652030.0,\n")
    points = io.read_points(path, crs="EPSG:25832", note=notes.append)
    np.testing.assert_array_equal(points.xyz, XYZ)
    assert any("1 points without a finite x, y and z" in n for n in notes)


def test_points_at_a_no_data_z_are_left_out_with_a_note(tmp_path):
    """Points exported with z -9999 (a survey's no-data value) are no ground: left out, said."""
    path, notes = tmp_path / "gaps.xyz", []
    path.write_text(_rows(XYZ, " ") + "412030.0 5652030.0 -9999\n412031.0 5652030.0 -9999\n")
    points = io.read_points(path, crs="EPSG:25832", note=notes.append)
    np.testing.assert_array_equal(points.xyz, XYZ)
    assert any("2 points with a z no ground has (-9999 m" in n for n in notes), notes


def test_xyz_bad_row_is_named_by_its_line(tmp_path):
    """A field that is no number is named by the file's own line number, header and comments
    counted."""
    path = tmp_path / "points.csv"
    path.write_text("# survey\nx,y,z\n" + _rows(XYZ[:2]) + "412020.0,oops,9.75\n")
    with pytest.raises(FloodMeshError, match="'oops' to float64 on line 5"):
        io.read_points(path, crs="EPSG:25832")


def test_xyz_without_crs_asks_for_crs(tmp_path):
    """A text file carries no CRS: without one the error points to --crs."""
    path = tmp_path / "points.xyz"
    path.write_text("\n".join(f"{x} {y} {z}" for x, y, z in XYZ))
    with pytest.raises(FloodMeshError, match="--crs"):
        io.read_points(path)


# ---------------------------------------------------------------------------------------------
# errors
def test_missing_file(tmp_path):
    """A path that does not exist is named as missing."""
    with pytest.raises(FloodMeshError, match="does not exist"):
        io.read_points(tmp_path / "nowhere.laz")
    with pytest.raises(FloodMeshError, match="does not exist"):
        io.read_raster(tmp_path / "nowhere.tif")


def test_garbage_laz(tmp_path):
    """A .laz file holding text is reported as not a readable LAS/LAZ file."""
    path = tmp_path / "garbage.laz"
    path.write_text("this is not a point cloud\n" * 20)
    with pytest.raises(FloodMeshError, match="not a readable LAS/LAZ"):
        io.read_points(path)


def test_unknown_extension(tmp_path):
    """An existing file with an unknown extension is refused by type, naming the extension."""
    path = tmp_path / "points.foo"
    path.write_text("\n".join(f"{x} {y} {z}" for x, y, z in XYZ))
    with pytest.raises(FloodMeshError, match=r"unknown point file type '\.foo'"):
        io.read_points(path, crs="EPSG:25832")
    with pytest.raises(FloodMeshError, match=r"unknown input type '\.foo'"):
        io.read_input(path, crs="EPSG:25832")


def test_geographic_crs_is_refused(tmp_path):
    """EPSG:4326 (degrees) is refused with advice to reproject."""
    path = tmp_path / "points.xyz"
    path.write_text("\n".join(f"{x} {y} {z}" for x, y, z in XYZ))
    with pytest.raises(FloodMeshError, match="(?i)reproject"):
        io.read_points(path, crs="EPSG:4326")


def test_crs_in_feet_is_refused(tmp_path):
    """EPSG:2994 (Oregon Lambert, feet) is refused because FloodMesh works in metres."""
    path = tmp_path / "points.xyz"
    path.write_text("\n".join(f"{x} {y} {z}" for x, y, z in XYZ))
    with pytest.raises(FloodMeshError, match="metres") as err:
        io.read_points(path, crs="EPSG:2994")
    assert "foot" in str(err.value)


def test_fewer_than_three_points(tmp_path):
    """Two usable points (a third with NaN z is dropped) are too few for a terrain model."""
    path = tmp_path / "points.xyz"
    path.write_text("412000 5652000 10\n412010 5652010 11\n412020 5652000 nan\n")
    with pytest.raises(FloodMeshError, match="2 usable points"):
        io.read_points(path, crs="EPSG:25832")


# ---------------------------------------------------------------------------------------------
# real data
def test_real_topography_laz_ground_points(real_data):
    """Topography.laz: 8159 ground (class 2) points in EPSG:2949, as its README says."""
    points = io.read_points(real_data / "Topography.laz")
    assert len(points) == 8159
    assert points.crs.to_epsg() == 2949
    assert points.crs == CRS.from_epsg(2949)


def test_real_autzen_is_refused_for_feet(real_data):
    """autzen_trim.laz is in international feet and is refused, the message saying so."""
    with pytest.raises(FloodMeshError, match="foot") as err:
        io.read_points(real_data / "autzen_trim.laz")
    assert "metres" in str(err.value)


# ---------------------------------------------------------------------------------------------
# rasters
def _grid(values, d=2.0, origin=(412_000.0, 5_652_000.0), crs=UTM32):
    rows = values.shape[0]
    return Grid(values, Affine(d, 0.0, origin[0], 0.0, -d, origin[1] + rows * d), crs)


def test_geotiff_round_trip(tmp_path):
    """Values (to float32), NaN nodata, transform and CRS come back as written."""
    rng = np.random.default_rng(5)
    values = rng.uniform(10.0, 50.0, (23, 31))
    values[3:6, 4:9] = np.nan
    values[-1, -1] = np.nan
    grid = _grid(values)
    path = tmp_path / "dem.tif"
    io.write_raster(path, grid)
    back = io.read_raster(path)
    assert back.shape == grid.shape
    assert np.array_equal(np.isnan(back.values), np.isnan(values))
    ok = np.isfinite(values)
    np.testing.assert_array_equal(back.values[ok], values[ok].astype(np.float32).astype(np.float64))
    assert back.transform.almost_equals(grid.transform, precision=1e-9)
    assert back.crs == UTM32


def test_geotiff_uint8_with_valid_mask(tmp_path):
    """A uint8 grid written with a valid mask reads back NaN outside the mask, its values inside."""
    rng = np.random.default_rng(6)
    values = rng.integers(0, 2, (20, 25)).astype(np.uint8)
    valid = np.ones(values.shape, bool)
    valid[:, :5] = False
    valid[12:, 10:14] = False
    path = tmp_path / "breakpoints.tif"
    io.write_raster(path, _grid(values), valid=valid)
    back = io.read_raster(path)
    assert np.isnan(back.values[~valid]).all()
    np.testing.assert_array_equal(back.values[valid], values[valid].astype(float))


def test_all_nodata_raster_is_refused(tmp_path):
    """A raster whose every cell is nodata raises FloodMeshError saying it has no valid cells."""
    path = tmp_path / "empty.tif"
    io.write_raster(path, _grid(np.full((10, 12), np.nan)))
    with pytest.raises(FloodMeshError, match="no valid cells"):
        io.read_raster(path)


@pytest.mark.parametrize("crs", [None, "EPSG:32756"])
def test_real_merewether_ascii_grid(real_data, crs):
    """merewether_topography1.asc reads with the CRS of its .prj (UTM 56S) or an explicit one."""
    grid = io.read_raster(real_data / "merewether_topography1.asc", crs=crs)
    assert grid.shape == (416, 321)
    assert grid.crs == CRS.from_epsg(32756)
    assert grid.cell_size == pytest.approx(0.99993681000029, abs=1e-12)
    assert grid.transform.c == pytest.approx(382249.79174463, abs=1e-6)
    assert np.nanmin(grid.values) == pytest.approx(16.47, abs=0.01)
    assert np.nanmax(grid.values) == pytest.approx(51.97, abs=0.01)
    # the first column holds NODATA (-9999) cells: they must come back as NaN, not -9999
    assert np.isnan(grid.values).any()
    assert np.nanmin(grid.values) > 0


# ---------------------------------------------------------------------------------------------
# atomic output
def test_atomic_output_failure_leaves_nothing(tmp_path):
    """An exception inside atomic_output leaves no target and no temporary file behind."""
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError):
        with io.atomic_output(target) as tmp:
            with open(tmp, "w") as fh:
                fh.write("half")
            raise RuntimeError("boom")
    assert not target.exists()
    assert os.listdir(tmp_path) == []


def test_atomic_output_failure_keeps_old_content(tmp_path):
    """A failing write over an existing file leaves the old content and no other file."""
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with io.atomic_output(target) as tmp:
            with open(tmp, "w") as fh:
                fh.write("new, incomplete")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert os.listdir(tmp_path) == ["out.txt"]


def test_atomic_output_replaces_an_existing_file(tmp_path):
    """A completed write replaces the previous file (deleted first, as gdaldem does, then the new
    one moved in): a reader that has it open keeps reading the old content, the name gives the
    new one, and no temporary is left; a folder in the way is refused and kept."""
    target = tmp_path / "out.txt"
    target.write_text("old")
    with open(target) as reader:
        with io.atomic_output(target) as tmp:
            tmp.write_text("new")
        assert reader.read() == "old"
    assert target.read_text() == "new"
    assert os.listdir(tmp_path) == ["out.txt"]
    folder = tmp_path / "folder.txt"
    folder.mkdir()
    with pytest.raises(OSError):
        with io.atomic_output(folder) as tmp:
            tmp.write_text("new")
    assert folder.is_dir() and sorted(os.listdir(tmp_path)) == ["folder.txt", "out.txt"]


def test_failing_writer_keeps_old_mesh(tmp_path):
    """write_mesh_2dm failing half-way (bad triangle data) keeps the previous mesh file intact."""
    target = tmp_path / "mesh.2dm"
    nodes = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 2.0], [0.0, 1.0, 3.0]])
    io.write_mesh_2dm(target, nodes, np.array([[0, 1, 2]]))
    old = target.read_bytes()
    with pytest.raises(Exception):
        io.write_mesh_2dm(target, nodes, np.array([["a", "b", "c"]]))
    assert target.read_bytes() == old
    assert os.listdir(tmp_path) == ["mesh.2dm"]


def test_atomic_output_missing_folder(tmp_path):
    """Writing into a folder that does not exist makes it (whether it can be made is checked
    before the work, core.outputs.check_outputs)."""
    target = tmp_path / "missing" / "out.txt"
    with io.atomic_output(target) as tmp:
        tmp.write_text("x")
    assert target.read_text() == "x"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


# ---------------------------------------------------------------------------------------------
# 2DM
def test_2dm_round_trip(tmp_path):
    """Nodes come back to the 1e-4 m written precision and triangles exactly."""
    rng = np.random.default_rng(7)
    nodes = np.column_stack([412_000 + rng.uniform(0, 100, 9), 5_652_000 + rng.uniform(0, 100, 9),
                             rng.uniform(5, 30, 9)])
    triangles = np.array([[0, 1, 2], [2, 1, 3], [3, 4, 2], [5, 6, 7], [8, 7, 6]])
    path = tmp_path / "mesh.2dm"
    io.write_mesh_2dm(path, nodes, triangles)
    back_nodes, back_tris = io.read_mesh_2dm(path)
    assert back_nodes.shape == nodes.shape
    np.testing.assert_allclose(back_nodes, nodes, rtol=0, atol=0.5e-4 + 1e-9)
    np.testing.assert_array_equal(back_tris, triangles)


def test_2dm_rows_are_those_of_savetxt():
    """write_rows, a chunk of rows formatted at a time, writes what np.savetxt wrote: ids of
    integer and of float arrays, coordinates to 0.1 mm."""
    import io as text_io

    rng = np.random.default_rng(2)
    elements = np.column_stack([np.arange(1, 24), rng.integers(1, 99, (23, 4))])
    nodes = np.column_stack([np.arange(1, 24), rng.uniform(-1e6, 1e6, (23, 3))])
    for fmt, rows in (("E3T %d %d %d %d %d", elements), ("ND %d %.4f %.4f %.4f", nodes),
                      ("E3T %d %d %d %d %d %.4f", np.column_stack([elements, nodes[:, 1]]))):
        ours, numpys = text_io.StringIO(), text_io.StringIO()
        io.meshes.write_rows(ours, fmt, rows, chunk=5)
        np.savetxt(numpys, rows, fmt=fmt)
        assert ours.getvalue() == numpys.getvalue()


def test_2dm_without_header(tmp_path):
    """A file not starting with MESH2D is refused."""
    path = tmp_path / "mesh.2dm"
    path.write_text("E3T 1 1 2 3 1\nND 1 0 0 0\nND 2 1 0 0\nND 3 0 1 0\n")
    with pytest.raises(FloodMeshError, match="MESH2D"):
        io.read_mesh_2dm(path)


# ---------------------------------------------------------------------------------------------
# GeoPackage
def test_breaklines_gpkg_round_trip(tmp_path):
    """write_breaklines → read_lines_gpkg gives the coordinates back; fiona sees 3D LineStrings with
    line_id, n_points and length_m equal to the lines' own figures."""
    rng = np.random.default_rng(8)
    lines = []
    for k in (2, 5, 11):
        xy = np.cumsum(rng.uniform(-2, 2, (k, 2)), axis=0) + [412_050.0, 5_652_050.0]
        coords = np.column_stack([xy, rng.uniform(10, 12, k)])
        lines.append(BreakLine(coords, rng.uniform(10, 40, k)))
    path = tmp_path / "breaklines.gpkg"
    io.write_breaklines(path, lines, UTM32)

    back = io.read_lines_gpkg(path)
    assert len(back) == len(lines)
    for got, line in zip(back, lines):
        np.testing.assert_allclose(got, line.coords, rtol=0, atol=1e-9)

    with fiona.open(path) as src:
        assert src.schema["geometry"] == "3D LineString"
        assert {"line_id", "n_points", "length_m"} <= set(src.schema["properties"])
        feats = list(src)
    assert [f["properties"]["line_id"] for f in feats] == [1, 2, 3]
    assert [f["properties"]["n_points"] for f in feats] == [2, 5, 11]
    for f, line in zip(feats, lines):
        expected = np.hypot(*np.diff(line.coords[:, :2], axis=0).T).sum()
        assert f["properties"]["length_m"] == pytest.approx(expected, rel=1e-12)
        assert f["properties"]["mean_slope_deg"] == pytest.approx(line.slopes.mean(), rel=1e-12)
        assert f["properties"]["max_slope_deg"] == pytest.approx(line.slopes.max(), rel=1e-12)


def test_points_gpkg_attributes_round_trip(tmp_path):
    """write_points_gpkg with int, float and str attributes reads back equal through fiona."""
    xyz = plane_points(size=10.0, density=0.1, seed=4)
    n = len(xyz)
    ints = np.arange(n, dtype=np.int64) * 3 - 7
    floats = np.linspace(-1.5, 2.25, n)
    strs = np.array([f"p{i}" for i in range(n)])
    path = tmp_path / "points.gpkg"
    io.write_points_gpkg(path, xyz, UTM32, layer="pts",
                         attributes={"count": ints, "value": floats, "label": strs})
    with fiona.open(path, layer="pts") as src:
        assert src.schema["geometry"] == "3D Point"
        assert CRS.from_wkt(src.crs_wkt) == UTM32
        feats = list(src)
    assert len(feats) == n
    got_xyz = np.array([f["geometry"]["coordinates"] for f in feats])
    np.testing.assert_allclose(got_xyz, xyz, rtol=0, atol=1e-9)
    assert [f["properties"]["count"] for f in feats] == ints.tolist()
    assert all(isinstance(f["properties"]["count"], int) for f in feats)
    np.testing.assert_allclose([f["properties"]["value"] for f in feats], floats, rtol=0, atol=0)
    assert [f["properties"]["label"] for f in feats] == strs.tolist()
    np.testing.assert_allclose(io.read_points_vector(path), xyz, rtol=0, atol=1e-9)


# the GeoPackage writer adds features in bulk by SQLite: what it writes is read back by OGR
# (fiona, ogrinfo, the spatial filter on the R-tree) and checked by SQLite itself
def _grid_mesh(n, origin=(412_000.0, 5_652_000.0)):
    """A square grid of n × n cells of 2 m, each two triangles: (nodes (m, 3), triangles)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    nodes = np.column_stack([origin[0] + 2.0 * i.ravel(), origin[1] + 2.0 * j.ravel(),
                             10.0 + 0.1 * i.ravel() - 0.05 * j.ravel()])
    corner = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    triangles = np.concatenate([np.column_stack([corner, corner + n + 1, corner + 1]),
                                np.column_stack([corner + 1, corner + n + 1, corner + n + 2])])
    return nodes, triangles


def _ogr_reference(path, layer, geometry_type, properties, geometries, columns):
    """The layer as OGR writes it one feature at a time (fiona's writerecords)."""
    import shapely.geometry

    from floodmesh.core.io.vectors import GPKG_TIMESTAMP

    records = [{"geometry": None if g is None else shapely.geometry.mapping(g),
                "properties": {name: values[k] for name, values in columns.items()}}
               for k, g in enumerate(geometries)]
    with fiona.Env(OGR_CURRENT_DATE=GPKG_TIMESTAMP):
        with fiona.open(path, "w", driver="GPKG", layer=layer, crs_wkt=UTM32.to_wkt(),
                        schema={"geometry": geometry_type, "properties": properties}) as dst:
            dst.writerecords(records)


def _tables(path, layer):
    """What a GeoPackage holds apart from its R-tree's nodes: the layer's rows, the GeoPackage
    tables on it, the schema."""
    import sqlite3

    con = sqlite3.connect(path)
    try:
        return {query: con.execute(query).fetchall() for query in (
            f'SELECT * FROM "{layer}" ORDER BY fid', "SELECT * FROM gpkg_contents",
            "SELECT * FROM gpkg_ogr_contents", "SELECT * FROM gpkg_geometry_columns",
            "SELECT * FROM gpkg_extensions", "SELECT * FROM gpkg_spatial_ref_sys",
            "SELECT * FROM sqlite_sequence",
            "SELECT type, name, tbl_name, sql FROM sqlite_master ORDER BY name")}
    finally:
        con.close()


def _rtree(path, layer):
    """The R-tree's boxes (id, minx, maxx, miny, maxy) and SQLite's checks of the file."""
    import sqlite3

    con = sqlite3.connect(path)
    try:
        boxes = np.array(con.execute(f'SELECT * FROM "rtree_{layer}_geom" ORDER BY id')
                         .fetchall()).reshape(-1, 5)
        checks = (con.execute("PRAGMA integrity_check").fetchone()[0],
                  con.execute(f"SELECT rtreecheck('rtree_{layer}_geom')").fetchone()[0])
        return boxes, checks
    finally:
        con.close()


def test_gpkg_layers_hold_what_ogr_writes_itself(tmp_path):
    """Points, lines (one 2-D in the 3-D layer) and triangles with int, bool, float (NaN
    among them) and text fields, and a null geometry through write_gpkg's records: the rows
    (geometry blobs byte for byte), the GeoPackage tables (extent, feature count) and the
    schema with its triggers are those OGR writes feature by feature; the R-tree holds each
    feature's box, rounded outwards to 32-bit floats."""
    import shapely

    rng = np.random.default_rng(5)
    nodes, triangles = _grid_mesh(8)
    lines = [np.column_stack([412_000 + np.cumsum(rng.uniform(0, 3, k)),
                              5_652_000 + np.cumsum(rng.uniform(-2, 2, k)),
                              rng.uniform(10, 12, k)]) for k in (2, 7, 30)]
    lines.append(lines[0][:, :2] + 5.0)
    n_pts = 70
    cases = {
        "pts": ("3D Point", shapely.points(nodes[:n_pts]),
                {"count": np.arange(n_pts) - 7, "flag": np.arange(n_pts) % 3 == 0,
                 "value": np.where(np.arange(n_pts) % 5 == 0, np.nan, np.linspace(-2, 3, n_pts)),
                 "label": np.array([f"p{i}" for i in range(n_pts)])}),
        "lines": ("3D LineString", [shapely.linestrings(line) for line in lines],
                  {"kind": np.array(["open", "land", "open", "land"]),
                   "n": np.array([len(line) for line in lines])}),
        "tris": ("3D Polygon", shapely.polygons(nodes[triangles]),
                 {"id": np.arange(1, len(triangles) + 1), "z": nodes[triangles, 2].mean(axis=1)}),
    }
    for layer, (geometry_type, geometries, columns) in cases.items():
        properties = {name: io.vectors.gpkg_field_type(v) for name, v in columns.items()}
        ours, theirs = tmp_path / f"{layer}.gpkg", tmp_path / f"{layer}_ogr.gpkg"
        io.vectors.write_gpkg_layer(ours, layer, geometry_type, len(geometries),
                                    io.vectors.shapely_features(
                                        lambda start, stop: geometries[start:stop]),
                                    columns, UTM32)
        _ogr_reference(theirs, layer, geometry_type, properties, geometries,
                       {name: v.tolist() for name, v in columns.items()})
        assert _tables(ours, layer) == _tables(theirs, layer), layer
        (boxes, checks), (ogr_boxes, _) = _rtree(ours, layer), _rtree(theirs, layer)
        assert checks == ("ok", "ok")
        bounds = shapely.bounds(np.asarray(geometries))[:, [0, 2, 1, 3]]
        assert boxes[:, 0].tolist() == list(range(1, len(bounds) + 1))
        assert (boxes[:, [1, 3]] <= bounds[:, [0, 2]]).all()
        assert (boxes[:, [2, 4]] >= bounds[:, [1, 3]]).all()
        assert (boxes[:, 1:] == boxes[:, 1:].astype(np.float32)).all()
        # as tight as OGR's, which rounds a float32-exact bound one step further
        assert (boxes[:, [1, 3]] >= ogr_boxes[:, [1, 3]]).all()
        assert (boxes[:, [2, 4]] <= ogr_boxes[:, [2, 4]]).all()

    # the mesh's triangles, their blobs built by NumPy, are those too, and so is the extent
    io.write_mesh_gpkg(tmp_path / "mesh.gpkg", nodes, triangles, UTM32)
    ours, theirs = _tables(tmp_path / "mesh.gpkg", "triangles"), _tables(
        tmp_path / "tris_ogr.gpkg", "tris")
    assert [row[:2] for row in ours['SELECT * FROM "triangles" ORDER BY fid']] \
        == [row[:2] for row in theirs['SELECT * FROM "tris" ORDER BY fid']]
    assert ours["SELECT * FROM gpkg_contents"][0][5:] \
        == theirs["SELECT * FROM gpkg_contents"][0][5:]

    zone = [{"geometry": None, "properties": {"id": 1}},
            {"geometry": shapely.geometry.mapping(shapely.box(412_000, 5_652_000, 412_010,
                                                              5_652_005)),
             "properties": {"id": 2}}]
    io.write_gpkg(tmp_path / "zone.gpkg", "zone", "Polygon", {"id": "int"}, zone, UTM32)
    _ogr_reference(tmp_path / "zone_ogr.gpkg", "zone", "Polygon", {"id": "int"},
                   [None, shapely.geometry.shape(zone[1]["geometry"])], {"id": [1, 2]})
    assert _tables(tmp_path / "zone.gpkg", "zone") == _tables(tmp_path / "zone_ogr.gpkg", "zone")
    assert _rtree(tmp_path / "zone.gpkg", "zone")[0][:, 0].tolist() == [2]


def test_gpkg_mesh_read_back_by_ogr_its_rtree_filter_and_an_append(tmp_path, monkeypatch):
    """A mesh of 20 000 triangles (an R-tree three levels deep) written twice, at once and in
    chunks of 7 000, gives the same bytes; fiona reads every feature and attribute back, ogrinfo gives its feature count and
    extent, GDAL's spatial filter (answered by the R-tree: with the tree emptied it finds
    nothing) returns the triangles in its box, SQLite finds the file and tree sound, and a
    triangle appended through OGR updates the tree and the count (its triggers are intact)."""
    import shutil
    import sqlite3
    import subprocess

    import shapely

    nodes, triangles = _grid_mesh(100)
    path = tmp_path / "mesh.gpkg"
    io.write_mesh_gpkg(path, nodes, triangles, UTM32, attributes={"material": np.arange(
        len(triangles)) % 4 + 1})
    monkeypatch.setattr(io.vectors, "GPKG_CHUNK", 7_000)
    io.write_mesh_gpkg(tmp_path / "again.gpkg", nodes, triangles, UTM32,
                       attributes={"material": np.arange(len(triangles)) % 4 + 1})
    assert path.read_bytes() == (tmp_path / "again.gpkg").read_bytes()

    with fiona.open(path) as src:
        assert src.schema == {"geometry": "3D Polygon", "properties": {
            "id": "int", "area_m2": "float", "min_angle_deg": "float", "material": "int"}}
        feats = list(src)
    assert [int(f.id) for f in feats] == list(range(1, len(triangles) + 1))
    got = np.array([f["geometry"]["coordinates"][0] for f in feats])
    np.testing.assert_array_equal(got[:, :3], nodes[triangles])
    np.testing.assert_array_equal(got[:, 3], got[:, 0])
    assert [f["properties"]["id"] for f in feats] == list(range(1, len(triangles) + 1))
    assert {f["properties"]["area_m2"] for f in feats} == {2.0}
    assert [f["properties"]["material"] for f in feats] == (np.arange(len(triangles)) % 4
                                                            + 1).tolist()
    assert {round(f["properties"]["min_angle_deg"], 9) for f in feats} == {45.0}

    if shutil.which("ogrinfo"):
        info = subprocess.run(["ogrinfo", "-al", "-so", str(path)], capture_output=True,
                              text=True, check=True).stdout
        assert f"Feature Count: {len(triangles)}" in info
        assert "Extent: (412000.000000, 5652000.000000) - (412200.000000, 5652200.000000)" in info

    box = (412_031.0, 5_652_047.0, 412_058.0, 5_652_063.0)
    polygons = shapely.polygons(nodes[triangles])
    bounds = shapely.bounds(polygons)
    near = set(np.flatnonzero((bounds[:, 0] <= box[2]) & (bounds[:, 2] >= box[0])
                              & (bounds[:, 1] <= box[3]) & (bounds[:, 3] >= box[1])) + 1)
    touching = set(np.flatnonzero(shapely.intersects(polygons, shapely.box(*box))) + 1)
    with fiona.open(path) as src:
        found = {int(f.id) for f in src.filter(bbox=box)}
    assert touching <= found <= near and len(touching) > 100

    con = sqlite3.connect(path)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("SELECT rtreecheck('rtree_triangles_geom')").fetchone()[0] == "ok"
    root = con.execute("SELECT data FROM rtree_triangles_geom_node WHERE nodeno = 1").fetchone()
    assert int.from_bytes(root[0][:2], "big") == 2  # depth: root, one level, leaves
    con.close()

    far = [[412_500.0, 5_652_500.0, 1.0], [412_504.0, 5_652_500.0, 1.0],
           [412_500.0, 5_652_503.0, 1.0], [412_500.0, 5_652_500.0, 1.0]]
    with fiona.open(path, "a") as dst:
        dst.write({"geometry": {"type": "Polygon", "coordinates": [far]},
                   "properties": {"id": 0, "area_m2": 6.0, "min_angle_deg": 36.9,
                                  "material": 9}})
    with fiona.open(path) as src:
        assert len(src) == len(triangles) + 1
        assert [f["properties"]["material"] for f in src.filter(
            bbox=(412_499.0, 5_652_499.0, 412_501.0, 5_652_501.0))] == [9]
    con = sqlite3.connect(path)
    assert con.execute("SELECT id FROM rtree_triangles_geom WHERE minx > 412400").fetchall() \
        == [(len(triangles) + 1,)]
    assert con.execute("SELECT feature_count FROM gpkg_ogr_contents").fetchone()[0] \
        == len(triangles) + 1
    assert con.execute("SELECT rtreecheck('rtree_triangles_geom')").fetchone()[0] == "ok"
    con.execute("DELETE FROM rtree_triangles_geom")
    con.commit()
    con.close()
    with fiona.open(path) as src:
        assert list(src.filter(bbox=box)) == []


def test_gpkg_layers_added_to_one_file(tmp_path):
    """Layers written with atomic=False into one GeoPackage (as the solver export does) each
    get their rows, R-tree and count; the file stays sound."""
    import sqlite3

    nodes, triangles = _grid_mesh(30)
    path = tmp_path / "all.gpkg"
    io.write_mesh_gpkg(path, nodes, triangles, UTM32, atomic=False)
    io.write_points_gpkg(path, nodes, UTM32, layer="nodes", atomic=False,
                         attributes={"z": nodes[:, 2]})
    io.write_lines_gpkg(path, [nodes[:31], nodes[31:62]], UTM32, layer="edges", atomic=False)
    assert fiona.listlayers(path) == ["triangles", "nodes", "edges"]
    con = sqlite3.connect(path)
    counts = dict(con.execute("SELECT table_name, feature_count FROM gpkg_ogr_contents"))
    assert counts == {"triangles": len(triangles), "nodes": len(nodes), "edges": 2}
    for layer, n in counts.items():
        assert con.execute(f"SELECT count(*) FROM rtree_{layer}_geom").fetchone()[0] == n
        assert con.execute(f"SELECT rtreecheck('rtree_{layer}_geom')").fetchone()[0] == "ok"
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    con.close()
    with fiona.open(path, layer="nodes") as src:
        np.testing.assert_array_equal([f["geometry"]["coordinates"] for f in src], nodes)


def test_an_ept_index_reads_as_the_laz_it_was_built_from(real_data, tmp_path):
    """Every node of an Entwine Point Tile index, each point in exactly one: the same ground
    points (class 2) and CRS as the LAZ."""
    import json

    from ..ept import write_ept

    ept = write_ept(real_data / "Topography.laz", tmp_path / "ept", nodes=3)
    from_ept = io.read_points(ept)
    from_laz = io.read_points(real_data / "Topography.laz")
    order = lambda xyz: xyz[np.lexsort(xyz.T)]  # noqa: E731
    np.testing.assert_array_equal(order(from_ept.xyz), order(from_laz.xyz))
    assert from_ept.crs == from_laz.crs
    assert is_point_source(ept) and not is_point_source(tmp_path / "other.json")
    meta = json.loads(ept.read_text())
    ept.write_text(json.dumps({**meta, "dataType": "binary"}))
    with pytest.raises(FloodMeshError, match="EPT nodes of type 'binary' cannot be read"):
        io.read_points(ept)


@pytest.mark.parametrize("crs", ["EPSG:25832", CRS.from_epsg(25832).to_wkt(), None])
def test_write_points_gpkg_takes_a_crs_as_write_points_las_does(tmp_path, crs):
    """write_points_gpkg with the CRS as text ('EPSG:25832', WKT), as write_points_las takes
    it, stopped with AttributeError: 'str' object has no attribute 'to_wkt'; None writes a
    layer without a CRS."""
    path = tmp_path / "points.gpkg"
    io.write_points_gpkg(path, np.array([[412_000.0, 5_652_000.0, 10.0]]), crs)
    with fiona.open(path) as layer:
        assert len(layer) == 1
        own = CRS.from_wkt(layer.crs_wkt) if layer.crs_wkt else None
    assert (own.to_epsg() if own else None) == (25832 if crs else None)
