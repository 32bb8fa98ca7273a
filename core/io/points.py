"""Point files: LAS/LAZ, an Entwine Point Tile index (EPT) and XYZ/CSV text read as ground
points (``read_points``), a file's kind told by its content (``file_format``), and points written
as LAS/LAZ (``write_points_las``)."""
from __future__ import annotations

import json
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..engine.limits import check_memory
from ..errors import FloodMeshError
from ..options import EPT_NAME, POINT_EXTENSIONS
from ..points import PointCloud, clean_points
from ..raster import LENGTH_UNITS, RefusedCRS, chosen_crs, parse_crs, require_metre_elevations
from .outputs import atomic_output, require_file

GROUND_CLASS = 2
UNCLASSIFIED = (0, 1)  # LAS "created, never classified" and "unclassified"


def read_points(path, *, crs=None, classes=None, note=None, repeats: bool = True) -> PointCloud:
    """Read ground points from LAS/LAZ or an EPT index (class 2 when classified, or ``classes``)
    or XYZ/CSV text.

    ``crs`` overrides the file's own CRS (needed for text files, which carry none; ``note``
    hears where it replaces a different one). ``note`` receives what was assumed on the user's
    behalf (e.g. an unclassified file used whole), and what was found doubtful
    (``points.clean_points``; ``repeats=False`` leaves the check of repeated positions to the
    caller).
    """
    path = require_file(path, "point file")
    xyz, file_crs = read_point_file(path, classes, note)
    name = point_file_name(path)
    return clean_points(xyz, chosen_crs(crs, file_crs, name, note), name, kind="points",
                        note=note, repeats=repeats)


def point_file_name(path) -> str:
    """How notes and errors name a point file."""
    return f"point file {Path(path).name}"


def read_point_file(path: Path, classes=None, note=None):
    """(xyz as stored, the file's CRS or None) of a point file by its type, the points of
    ``classes`` as ``read_points`` keeps them, before its checks (``points.clean_points``)."""
    ext = path.suffix.lower()
    if path.name == EPT_NAME:
        return _read_ept(path, classes, note)
    if ext in (".las", ".laz"):
        return _read_las(path, classes, note)
    if ext in (".xyz", ".txt", ".csv", ".pts"):
        xyz, cls = read_xyz(path)
        if cls is not None:
            return classes_kept(xyz, cls, classes, path.name, note), None
        if classes is not None and note:
            note(f"{path.name} has no classification column: the classes given do not apply, "
                 "all its points are used")
        return xyz, None
    raise FloodMeshError(f"{path.name}: unknown point file type '{ext}'; use LAS/LAZ or "
                         "XYZ/CSV text (x y z per line), or a GeoTIFF DEM")


def _read_las(path: Path, classes, note=None):
    def check(header):
        count = int(header.point_count)
        if count == 0:
            raise FloodMeshError(f"{path.name} holds no points (its header counts 0): check "
                                 "that the export or tiling wrote this tile")
        check_memory(points=count, advice="split the point file into tiles (e.g. pdal "
                                          "tile or lastile) and mesh them one by one")

    las = read_las(path, f"{path.name} is not a readable LAS/LAZ file", check=check, note=note)
    file_crs = las_crs(las.header)
    cls = las_classes(las)
    keep = classes_table(np.bincount(cls, minlength=256), classes, path.name, note)
    return las_xyz(las, cls, keep), file_crs


GEOKEY_UNITS = {9001: "metres", 9002: "feet", 9003: "US survey feet"}  # EPSG unit codes
PROJECTED_CRS_KEY, PROJECTED_UNITS_KEY = 3072, 3076  # GeoTIFF keys (OGC 19-008r4)
VERTICAL_CRS_KEY, VERTICAL_UNITS_KEY = 4096, 4099
USER_DEFINED = 32767


def las_crs(header):
    """The CRS a LAS header declares: its WKT, else its GeoTIFF keys' EPSG CRS as laspy reads
    them; a ``RefusedCRS`` where the keys say what laspy leaves out (a user-defined projection,
    elevations in feet); None where it declares none."""
    try:
        crs = header.parse_crs()
    except Exception:
        crs = None
    names = {type(vlr).__name__: vlr for vlr in header.vlrs}
    if "GeoKeyDirectoryVlr" not in names or (crs is not None
                                             and "WktCoordinateSystemVlr" in names):
        return crs
    keys = {key.id: key.value_offset for key in names["GeoKeyDirectoryVlr"].geo_keys
            if key.tiff_tag_location == 0}  # values held in the directory itself
    unit = _vertical_unit(keys)
    if unit not in (None, "metres"):
        return RefusedCRS(
            f"has elevations in {unit} (its GeoTIFF keys' vertical CRS); FloodMesh works in "
            "metres: convert z to metres first (pdal translate IN OUT -f filters.assign "
            "--filters.assign.value=\"Z = Z * 0.3048\" for feet, 0.3048006 for US survey "
            "feet)")
    if keys.get(PROJECTED_CRS_KEY) == USER_DEFINED:
        unit = GEOKEY_UNITS.get(keys.get(PROJECTED_UNITS_KEY))
        fix = ("give its CRS (--crs EPSG:XXXX)" if unit in (None, "metres") else
               "reproject x, y and z to a CRS in metres first (pdal translate IN OUT -f "
               "filters.reprojection --filters.reprojection.out_srs=EPSG:XXXX, with z scaled)")
        return RefusedCRS(f"has a user-defined projection in its GeoTIFF keys"
                          f"{f' (in {unit})' if unit else ''} that FloodMesh cannot read: {fix}")
    return crs


def _vertical_unit(keys: dict) -> str | None:
    """The unit of the elevations GeoTIFF ``keys`` (id: value) declare: their vertical units, or
    their EPSG vertical CRS's; None where they declare neither."""
    if VERTICAL_UNITS_KEY in keys:
        code = keys[VERTICAL_UNITS_KEY]
        return GEOKEY_UNITS.get(code, f"unit {code}")
    if not 1024 <= keys.get(VERTICAL_CRS_KEY, 0) < USER_DEFINED:
        return None
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    try:
        axis = CRS.from_epsg(keys[VERTICAL_CRS_KEY]).axis_info[0]
    except Exception:  # a code PROJ does not know
        return None
    return "metres" if axis.unit_conversion_factor == 1.0 else axis.unit_name


def read_las(path: Path, unreadable: str, *, check=None, note=None):
    """A LAS/LAZ file's points (laspy's ``LasData``) but those flagged withheld, which the LAS
    specification counts as deleted (``note`` told how many), only x, y, z, the class and its
    flags decompressed (``las_fields_read``), after ``check(header)`` where given. Where laspy
    cannot read it, or a LAS holds fewer points than its header counts (a copy cut short),
    ``FloodMeshError``: ``unreadable`` and the reason."""
    # lazy: laspy loads only when this runs
    import laspy

    try:
        with laspy.open(path, **las_fields_read(laspy)) as reader:
            header = reader.header
            if check is not None:
                check(header)
            if not header.are_points_compressed:
                held = (path.stat().st_size - header.offset_to_point_data) \
                    // header.point_format.size
                if held < header.point_count:
                    raise FloodMeshError(
                        f"{unreadable}: its header counts {header.point_count:,} points, the "
                        f"file holds {max(held, 0):,}: it was cut short; copy or export it again")
            las = reader.read()
    except FloodMeshError:
        raise
    except Exception as exc:
        raise FloodMeshError(f"{unreadable} ({exc})") from None
    withheld = np.asarray(las.withheld, bool)
    if withheld.any():
        las.points = las.points[~withheld]
        if note:
            note(f"{path.name}: {int(withheld.sum()):,} points flagged withheld (deleted, by the "
                 "LAS specification) were left out")
    return las


def las_classes(las) -> np.ndarray:
    """The LAS class of each point of ``las`` (a ``LasData``), contiguous (one compiled
    variant of ``las_xyz``'s kernel for every point format)."""
    return np.ascontiguousarray(las.classification)


def las_xyz(las, cls: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) x, y, z in metres of the points of ``las`` (a ``LasData``; ``cls``: its
    ``las_classes``) whose class ``keep`` marks (a bool per LAS class, 256; None: all), scaled
    from the stored integers in one pass as laspy scales them (``scaled_points``)."""
    # lazy: numba loads only when points are read
    import numba

    from .._kernels.points import scaled_points

    keep = np.ones(256, bool) if keep is None else keep
    stored, header = las.points.array, las.header
    return scaled_points(stored["X"], stored["Y"], stored["Z"], cls, keep, header.scales,
                         header.offsets, numba.get_num_threads())


def las_fields_read(laspy) -> dict:
    """laspy.open's arguments that decompress only what FloodMesh reads (x, y, z, the class
    and its flags, withheld among them) of a LAZ in a layered point format (6 to 10, LAS
    1.4's): on 9 M points in format 7
    (with intensity, GPS time, scan angle and colour) 1.5–1.9 s where the whole point took
    2.3 s. Other formats are decompressed whole whatever is asked; laspy before 2.2 cannot
    choose."""
    choose = getattr(laspy, "DecompressionSelection", None)
    if choose is None:
        return {}
    return {"decompression_selection": choose.XY_RETURNS_CHANNEL | choose.Z
            | choose.CLASSIFICATION | choose.FLAGS}


def classes_kept(xyz, cls, classes, name: str, note=None):
    """The points of ``classes``, or of the ground class (2) when classified, or all of an
    unclassified cloud (with a note)."""
    keep = classes_table(np.bincount(cls, minlength=256), classes, name, note)[cls]
    return xyz if keep.all() else xyz[keep]  # a ground-only file needs no copy


def classes_table(counts: np.ndarray, classes, name: str, note=None) -> np.ndarray:
    """Which of the 256 LAS classes to keep (a bool per class), from the points' ``counts`` per
    class: ``classes``, or the ground class (2) when classified, or all of an unclassified
    cloud (with a note); refused when that keeps no point."""
    present = ", ".join(str(c) for c in np.flatnonzero(counts)) or "none"
    keep = np.zeros(256, bool)
    if classes is None:
        if counts[GROUND_CLASS]:
            keep[GROUND_CLASS] = True
        elif counts.sum() == counts[list(UNCLASSIFIED)].sum():
            keep[:] = True
            if note:
                note(f"{name} is not classified (classes {present} only): all "
                     f"{int(counts.sum()):,} points are used as ground; classify the ground "
                     "first (e.g. pdal filters.smrf) if they include vegetation or buildings")
        else:
            raise FloodMeshError(
                f"{name} is classified but has no ground points (class 2; classes present: "
                f"{present}): give the classes to grid (--classes, 'LAS classes' in QGIS), or "
                "classify the ground first (e.g. pdal translate with filters.smrf)")
    else:
        keep[[c for c in classes if 0 <= c < 256]] = True
        if not counts[keep].any():
            raise FloodMeshError(f"{name} has no points of classes {sorted(classes)} "
                                 f"(classes present: {present}); choose other classes")
    return keep


def _read_ept(path: Path, classes, note=None):
    """The points of an Entwine Point Tile index (``ept.json`` with LAZ nodes in ``ept-data``,
    as Entwine, untwine and QGIS 3.22 with PDAL write): every node, since each point lies in
    exactly one."""
    try:
        meta = json.loads(path.read_text())
        kind, count = meta.get("dataType"), int(meta.get("points", 0))
    except (OSError, ValueError, AttributeError) as exc:
        raise FloodMeshError(f"{path} is not a readable EPT index ({exc})") from None
    if kind != "laszip":
        raise FloodMeshError(f"{path}: EPT nodes of type {kind!r} cannot be read, only laszip "
                             "(LAZ): give the LAS/LAZ files the index was built from")
    nodes = sorted((path.parent / "ept-data").glob("*.laz"))
    if not nodes:
        raise FloodMeshError(f"{path}: its ept-data folder holds no LAZ nodes")
    check_memory(points=count, advice="give the LAS/LAZ tiles the index was built from as "
                                      "tiles")
    parts, cls = [], []
    for node in nodes:
        las = read_las(node, f"{path}: node {node.name} is not readable LAZ")
        cls.append(las_classes(las))
        parts.append(las_xyz(las, cls[-1]))
    srs = meta.get("srs") or {}
    file_crs = srs.get("wkt") or (f"{srs['authority']}:{srs['horizontal']}"
                                  if srs.get("authority") and srs.get("horizontal") else None)
    name = f"{path.parent.name}/{EPT_NAME}"
    return classes_kept(np.vstack(parts), np.concatenate(cls), classes, name, note), file_crs


XYZ_HEAD_LINES = 5  # lines of XYZ text looked at for its layout
HEAD_BYTES = 4096  # bytes of a file read to tell what it holds
COLUMN_NAMES = {  # what a header line of XYZ text may call each column, once unit and case are cut
    "x": ("x", "easting", "east", "e", "lon", "long", "longitude"),
    "y": ("y", "northing", "north", "n", "lat", "latitude"),
    "z": ("z", "elevation", "elev", "height", "h", "altitude", "alt"),
    "class": ("classification", "class", "cls"),
}
_DECIMAL_COMMA = re.compile(r"-?\d+(,\d+)?([eE][-+]?\d+)?")


@dataclass(frozen=True)
class XyzLayout:
    """How XYZ text lays out its points: the field ``delimiter`` (None: white space), the lines
    to ``skip`` (up to a header), the x, y, z ``columns`` and the LAS class column or None."""

    delimiter: str | None
    skip: int
    columns: tuple[int, int, int]
    classes: int | None = None


def read_xyz(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(x, y, z of every row, their LAS classes or None) of XYZ/CSV text laid out as
    ``xyz_layout`` finds; a UTF-8 byte-order mark is skipped and empty fields are read as NaN
    (``points.clean_points`` leaves those rows out, with a note)."""
    size = path.stat().st_size
    if size == 0:
        raise FloodMeshError(f"{path.name} is empty: it holds no points")
    # a line "x y z" takes at least about 20 characters at millimetre precision
    check_memory(points=size // 20, advice="split the point file into tiles and mesh them one "
                                           "by one")
    with open(path, "rb") as fh:
        head = fh.read(HEAD_BYTES)
        if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
            raise FloodMeshError(f"{path.name} is UTF-16 text: save it as UTF-8 (or ASCII) text")
        if b"\x00" in head:
            raise FloodMeshError(f"{path.name} is not an XYZ text file: it holds binary data; "
                                 "give it its real extension")
        whole = len(head) < HEAD_BYTES
        while not whole and len(_head_lines(head, whole)) < XYZ_HEAD_LINES:  # long lines
            more = fh.read(HEAD_BYTES)
            head, whole = head + more, len(more) < HEAD_BYTES
    layout = xyz_layout(_head_lines(head, whole), path.name)
    columns = layout.columns + (() if layout.classes is None else (layout.classes,))
    where = "the columns its header names" if layout.skip else "the first three columns"
    try:
        try:
            data = _load_text(path, layout, columns)
        except ValueError as exc:
            if "could not convert string ''" not in str(exc):
                raise
            data = _load_text(path, layout, columns, empty=np.nan)
    except (ValueError, IndexError) as exc:  # a field that is no number, a row too short
        raise FloodMeshError(f"{path.name} is not an XYZ text file with x, y, z in {where} "
                             f"({_at_line(exc, path, layout)})") from None
    if not len(data):
        raise FloodMeshError(f"{path.name} holds no points, only its header line")
    if layout.classes is None:
        return data, None
    return data[:, :3], _class_codes(data[:, 3], path.name)


def _load_text(path: Path, layout: XyzLayout, columns, empty=None) -> np.ndarray:
    """The ``columns`` of XYZ text as float64 (numpy's compiled reader); ``empty``: what an
    empty field reads as (None: refused), through a converter, some ten times slower."""
    convert = None if empty is None else (lambda field: float(field) if field.strip() else empty)
    with open(path, encoding="utf-8-sig", errors="replace") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data": said below
        return np.loadtxt(fh, delimiter=layout.delimiter, skiprows=layout.skip, usecols=columns,
                          ndmin=2, converters=convert)


def _at_line(exc: Exception, path: Path, layout: XyzLayout) -> str:
    """numpy's reason, its row (of the lines after the skipped ones that are neither blank nor
    # comments; from 1 where a row is too short, else from 0) told as the file's line."""
    def line(match) -> str:
        row = int(match.group(1)) - ("invalid column index" in str(exc))
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            for number, text in enumerate(fh, 1):
                if number > layout.skip and _holds_data(text):
                    if row == 0:
                        return f"on line {number}"
                    row -= 1
        return match.group(0)

    return re.sub(r"at row (\d+)", line, str(exc)).rstrip(".")


def _class_codes(values: np.ndarray, name: str) -> np.ndarray:
    """A class column's values as LAS classes (0-255); refused where they are not."""
    bad = ~np.isfinite(values) | (values < 0) | (values > 255) | (values != np.round(values))
    if bad.any():
        raise FloodMeshError(f"{name}: its classification column holds {values[bad][0]:g}, not "
                             "a LAS class (0-255): correct the column or remove its name from "
                             "the header line")
    return values.astype(np.uint8)


def _head_lines(head: bytes, whole: bool) -> list[str]:
    """The first ``XYZ_HEAD_LINES`` lines of text that begins with the bytes ``head`` (UTF-8, a
    byte-order mark skipped; ``whole``: all of it), split as numpy's reader splits them (at
    \\n, \\r\\n or \\r); a line the head cuts off left out, empty ones after the text's end."""
    lines = re.split(r"\r\n|\r|\n", head.decode("utf-8-sig", "replace"))
    if not (whole and lines[-1]):  # cut off, or after the last line's end
        lines.pop()
    return (lines + [""] * XYZ_HEAD_LINES if whole else lines)[:XYZ_HEAD_LINES]


def _holds_data(line: str) -> bool:
    """Whether a line of XYZ text is neither blank nor a # comment (which numpy skips)."""
    return bool(line.strip()) and not line.lstrip().startswith("#")


def _fields(line: str, delimiter: str | None) -> list[str]:
    return line.split(delimiter) if delimiter else line.split()


# a unit a header field gives its column after its name: "[ft]", "(m)", "_m", " ft"
_FIELD_UNIT = re.compile(r"[\[(]\s*([^\])]*?)\s*[\])].*|[ _](m|" + "|".join(
    re.escape(u) for u in LENGTH_UNITS if " " not in u) + r")$", re.IGNORECASE)


def _column_name(field: str) -> tuple[str, str | None]:
    """(the name, as ``COLUMN_NAMES`` spells it, and the unit) of a header field: quotes, the
    unit ("[m]", "(ft)", "_m", " ft") and case cut."""
    field = field.strip().strip("\"'").strip()
    unit = _FIELD_UNIT.search(field)
    name = field[:unit.start()] if unit else field
    return name.strip().lower(), (unit.group(1) or unit.group(2)) if unit else None


def xyz_layout(head: list[str], name: str) -> XyzLayout:
    """The layout of XYZ text from its first lines: fields split at commas, else semicolons, else
    white space; a first line (after blank and # lines) that is not numbers is a header, whose
    names (``COLUMN_NAMES``, in any order) give the columns; without one, the first three are
    x, y, z. Refused, naming the fix: a header that does not name x, y and z, and numbers with a
    decimal comma."""
    lines = [(k, line) for k, line in enumerate(head) if _holds_data(line)]
    if not lines:
        raise FloodMeshError(f"{name} holds no points in its first {len(head)} lines")
    for _, line in lines:
        fields = re.split(r"[;\t ]+", line.strip())
        if len(fields) >= 3 and any("," in f for f in fields) and all(
                _DECIMAL_COMMA.fullmatch(f) for f in fields):
            raise FloodMeshError(f"{name} writes numbers with a decimal comma ({line.strip()!r}): "
                                 "export it with a decimal point (e.g. in the spreadsheet's "
                                 "language settings, or with sed 's/,/./g' IN > OUT)")
    text = "".join(line for _, line in lines)
    delimiter = "," if "," in text else (";" if ";" in text else None)
    first, fields = lines[0][0], _fields(lines[0][1], delimiter)
    try:
        [float(v) for v in fields[:3]]
        return XyzLayout(delimiter, first, (0, 1, 2))
    except ValueError:  # a header line: the columns are those it names
        pass
    names, units = zip(*(_column_name(f) for f in fields))
    found = {role: [k for k, n in enumerate(names) if n in aliases]
             for role, aliases in COLUMN_NAMES.items()}
    if any(len(found[role]) != 1 for role in "xyz") or len(found["class"]) > 1:
        raise FloodMeshError(
            f"{name}: its header line names the columns {', '.join(f.strip() for f in fields)}, "
            "not one x, one y and one z column: name them x, y, z (or easting, northing, "
            "elevation), or delete the header line to read the first three columns as x, y, z")
    for role, of in (("x", "x, y"), ("y", "x, y"), ("z", "elevations")):
        k = found[role][0]
        require_metre_elevations(units[k], name, kind="points", of=of,
                                 said=f"its header's {fields[k].strip()}")
    return XyzLayout(delimiter, first + 1, tuple(found[role][0] for role in "xyz"),
                     found["class"][0] if found["class"] else None)


TIFF_SIGNATURES = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # TIFF and BigTIFF
RASTER_SIGNATURES = {".vrt": (b"<vrtdataset",), ".img": (b"ehfa_header_tag",),
                     ".asc": (b"ncols", b"nrows", b"xll", b"yll", b"cellsize")}


def file_format(path) -> str | None:
    """What a file holds, by its content: "las" (LAS/LAZ, 'LASF'), "tiff" (a TIFF header),
    "raster" (a VRT, Erdas Imagine or ESRI ASCII grid by its first bytes and extension), "xyz"
    (an .xyz/.txt/.csv/.pts file whose first lines are numbers, x, y, z, after at most a header
    naming them); None for anything else or an unreadable file."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(HEAD_BYTES)
    except OSError:
        return None
    if head[:4] == b"LASF":
        return "las"
    if head[:4] in TIFF_SIGNATURES:
        return "tiff"
    ext = path.suffix.lower()
    if head.lstrip()[:16].lower().startswith(RASTER_SIGNATURES.get(ext, ())):
        return "raster"
    if ext not in POINT_EXTENSIONS or b"\x00" in head:
        return None
    lines = _head_lines(head, len(head) < HEAD_BYTES)
    try:
        layout = xyz_layout(lines, path.name)
    except FloodMeshError:
        return None
    rows = [_fields(line, layout.delimiter) for line in lines[layout.skip:] if _holds_data(line)]
    try:
        ok = bool(rows) and all([float(row[c]) for c in layout.columns] for row in rows)
    except (ValueError, IndexError):
        return None
    return "xyz" if ok else None


def write_points_las(path, points: PointCloud, *, classes=GROUND_CLASS) -> None:
    """Write points as LAS/LAZ (by extension) with the CRS; ``classes`` one code or one per point.
    No points write a valid LAS of none (a header alone), as ``write_points_gpkg`` writes an
    empty layer; FloodMesh's readers refuse it as having no usable points."""
    # lazy: laspy loads only when this runs
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.4")
    header.offsets = np.floor(points.xyz.min(axis=0)) if len(points) else np.zeros(3)
    header.scales = np.array([0.001, 0.001, 0.001])
    if points.crs is not None:
        header.add_crs(parse_crs(points.crs, f"the CRS of {Path(path).name}"))
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.xyz[:, 0], points.xyz[:, 1], points.xyz[:, 2]
    las.classification = np.broadcast_to(np.asarray(classes, np.uint8), (len(points),)).copy()
    with atomic_output(path) as tmp:
        las.write(str(tmp), do_compress=Path(path).suffix.lower() == ".laz")
