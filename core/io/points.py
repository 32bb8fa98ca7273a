"""Point files: LAS/LAZ, an Entwine Point Tile index (EPT) and XYZ/CSV text read as ground
points (``read_points``), a file's kind told by its content (``file_format``), and points written
as LAS/LAZ (``write_points_las``)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..engine.limits import check_memory
from ..errors import FloodMeshError
from ..options import EPT_NAME, POINT_EXTENSIONS
from ..points import PointCloud, clean_points
from .outputs import atomic_output, require_file

GROUND_CLASS = 2
UNCLASSIFIED = (0, 1)  # LAS "created, never classified" and "unclassified"


def read_points(path, *, crs=None, classes=None, note=None, repeats: bool = True) -> PointCloud:
    """Read ground points from LAS/LAZ or an EPT index (class 2 when classified, or ``classes``)
    or XYZ/CSV text.

    ``crs`` overrides the file's own CRS (needed for text files, which carry none). ``note``
    receives what was assumed on the user's behalf (e.g. an unclassified file used whole), and
    what was found doubtful (``points.clean_points``; ``repeats=False`` leaves the check of
    repeated positions to the caller).
    """
    path = require_file(path, "point file")
    xyz, file_crs = read_point_file(path, classes, note)
    return clean_points(xyz, crs if crs is not None else file_crs, point_file_name(path),
                        kind="points", note=note, repeats=repeats)


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
        return read_xyz(path), None
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

    las = read_las(path, f"{path.name} is not a readable LAS/LAZ file", check=check)
    try:
        file_crs = las.header.parse_crs()
    except Exception:
        file_crs = None
    cls = las_classes(las)
    keep = classes_table(np.bincount(cls, minlength=256), classes, path.name, note)
    return las_xyz(las, cls, keep), file_crs


def read_las(path: Path, unreadable: str, *, check=None):
    """A LAS/LAZ file's points (laspy's ``LasData``), only x, y, z and the class decompressed
    (``las_fields_read``), after ``check(header)`` where given; where laspy cannot read it,
    ``FloodMeshError``: ``unreadable`` and laspy's reason."""
    # lazy: laspy loads only when this runs
    import laspy

    try:
        with laspy.open(path, **las_fields_read(laspy)) as reader:
            if check is not None:
                check(reader.header)
            return reader.read()
    except FloodMeshError:
        raise
    except Exception as exc:
        raise FloodMeshError(f"{unreadable} ({exc})") from None


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
    """laspy.open's arguments that decompress only what FloodMesh reads (x, y, z and the
    class) of a LAZ in a layered point format (6 to 10, LAS 1.4's): on 9 M points in format 7
    (with intensity, GPS time, scan angle and colour) 1.5–1.9 s where the whole point took
    2.3 s. Other formats are decompressed whole whatever is asked; laspy before 2.2 cannot
    choose."""
    choose = getattr(laspy, "DecompressionSelection", None)
    if choose is None:
        return {}
    return {"decompression_selection": choose.XY_RETURNS_CHANNEL | choose.Z
            | choose.CLASSIFICATION}


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


def read_xyz(path: Path) -> np.ndarray:
    size = path.stat().st_size
    if size == 0:
        raise FloodMeshError(f"{path.name} is empty: it holds no points")
    # a line "x y z" takes at least about 20 characters at millimetre precision
    check_memory(points=size // 20, advice="split the point file into tiles and mesh them one "
                                           "by one")
    with open(path, "r", errors="replace") as fh:
        head = [fh.readline() for _ in range(5)]
    delimiter, skip, columns = _xyz_layout(head)
    try:
        data = np.loadtxt(path, delimiter=delimiter, skiprows=skip, usecols=columns or (0, 1, 2),
                          ndmin=2)
    except (ValueError, IndexError) as exc:
        raise FloodMeshError(f"{path.name} is not an XYZ text file with x, y, z in the first "
                             f"three columns ({exc})") from None
    return data


XYZ_HEADERS = (("x", "y", "z"), ("easting", "northing", "elevation"), ("east", "north", "height"),
               ("lon", "lat", "z"))  # column names a header line of XYZ text may give


def _fields(line: str) -> list[str]:
    return line.replace(",", " ").replace(";", " ").split()


def _xyz_layout(head: list[str]):
    """(delimiter, header lines to skip, x, y, z columns) of XYZ text from its first lines; a
    first line that is not numbers is a header, and the columns are those it names (None when it
    names none of ``XYZ_HEADERS``)."""
    delimiter = "," if any("," in line for line in head) else (";" if any(";" in line for line in head) else None)
    first = _fields(head[0])
    try:
        [float(v) for v in first[:3]]
        return delimiter, 0, (0, 1, 2)
    except ValueError:  # a header line such as "x,y,z": take the columns it names
        names = [name.strip("\"'").lower() for name in first]
        for aliases in XYZ_HEADERS:
            if all(a in names for a in aliases):
                return delimiter, 1, tuple(names.index(a) for a in aliases)
        return delimiter, 1, None


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
            head = fh.read(4096)
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
    lines = head.decode("utf-8", "replace").splitlines()
    lines = [line for line in lines[:-1 if len(head) == 4096 else None] if line.strip()][:5]
    if not lines:
        return None
    _, skip, columns = _xyz_layout(lines)
    rows = [_fields(line) for line in lines[skip:]]
    try:
        ok = bool(rows) and columns is not None and all(
            [float(row[c]) for c in columns] for row in rows)
    except (ValueError, IndexError):
        return None
    return "xyz" if ok else None


def write_points_las(path, points: PointCloud, *, classes=GROUND_CLASS) -> None:
    """Write points as LAS/LAZ (by extension) with the CRS; ``classes`` one code or one per point."""
    # lazy: laspy loads only when this runs
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.4")
    header.offsets = np.floor(points.xyz.min(axis=0))
    header.scales = np.array([0.001, 0.001, 0.001])
    header.add_crs(points.crs)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.xyz[:, 0], points.xyz[:, 1], points.xyz[:, 2]
    las.classification = np.broadcast_to(np.asarray(classes, np.uint8), (len(points),)).copy()
    with atomic_output(path) as tmp:
        las.write(str(tmp), do_compress=Path(path).suffix.lower() == ".laz")
