"""Reading and writing at the pipeline's edges: point files, rasters, GeoPackages, 2DM, JSON.

Every writer writes to a temporary name beside the target and renames it when complete, so an
error, Ctrl-C or a cancel leaves the previous file (or none), never a truncated one.
"""
from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..engine.limits import check_memory
from ..errors import FloodMeshError
from ..options import EPT_NAME, POINT_EXTENSIONS, is_point_source
from ..points import PointCloud, clean_points
from ..raster import Grid, METRE_NAMES, check_transform, require_metric_crs
from .outputs import remove_stale_temporaries, temp_name

RASTER_EXTENSIONS = (".tif", ".tiff", ".asc", ".img", ".vrt", ".nc")
GROUND_CLASS = 2
UNCLASSIFIED = (0, 1)  # LAS "created, never classified" and "unclassified"


# ---------------------------------------------------------------------------------------------
# atomic output
@contextlib.contextmanager
def atomic_output(path):
    """Yield a temporary path beside ``path`` (making its folder if missing); move it into
    place only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path.parent)  # of this target and others, from killed runs
    tmp = temp_name(path)
    try:
        yield tmp
        # the previous file goes first: ext4 writes out at once a file renamed over another
        # (auto_da_alloc), 0.05 s for a 144 MB raster; a new name leaves it to the kernel's
        # write-back, as for any new file
        with contextlib.suppress(FileNotFoundError):
            if not path.is_dir():
                path.unlink()
        os.replace(tmp, path)
    finally:
        for leftover in (tmp, Path(f"{tmp}-journal"), Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
            with contextlib.suppress(FileNotFoundError):
                leftover.unlink()


def require_file(path, what: str) -> Path:
    path = Path(path)
    if not path.exists():
        raise FloodMeshError(f"{what} {path} does not exist: check the path")
    if not path.is_file():
        raise FloodMeshError(f"{what} {path} is not a file")
    return path


# ---------------------------------------------------------------------------------------------
# points
def read_points(path, *, crs=None, classes=None, note=None) -> PointCloud:
    """Read ground points from LAS/LAZ or an EPT index (class 2 when classified, or ``classes``)
    or XYZ/CSV text.

    ``crs`` overrides the file's own CRS (needed for text files, which carry none). ``note``
    receives what was assumed on the user's behalf (e.g. an unclassified file used whole).
    """
    path = require_file(path, "point file")
    xyz, file_crs = read_point_file(path, classes, note)
    return clean_points(xyz, crs if crs is not None else file_crs, f"point file {path.name}",
                        kind="points", note=note)


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
    # lazy: laspy loads only when this runs
    import laspy

    try:
        with laspy.open(path) as reader:
            count = int(reader.header.point_count)
            if count == 0:
                raise FloodMeshError(f"{path.name} holds no points (its header counts 0): check "
                                     "that the export or tiling wrote this tile")
            check_memory(points=count, advice="split the point file into tiles (e.g. pdal "
                                              "tile or lastile) and mesh them one by one")
            las = reader.read()
    except FloodMeshError:
        raise
    except Exception as exc:
        raise FloodMeshError(f"{path.name} is not a readable LAS/LAZ file ({exc})") from None
    try:
        file_crs = las.header.parse_crs()
    except Exception:
        file_crs = None
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    return classes_kept(xyz, np.asarray(las.classification), classes, path.name, note), file_crs


def classes_kept(xyz, cls, classes, name: str, note=None):
    """The points of ``classes``, or of the ground class (2) when classified, or all of an
    unclassified cloud (with a note)."""
    def present() -> str:  # for the messages alone: np.unique sorts every point's class
        return ", ".join(str(c) for c in np.unique(cls)) or "none"

    if classes is None:
        if np.any(cls == GROUND_CLASS):
            keep = cls == GROUND_CLASS
        elif np.isin(cls, UNCLASSIFIED).all():
            keep = np.ones(len(cls), bool)
            if note:
                note(f"{name} is not classified (classes {present()} only): all {len(cls):,} "
                     "points are used as ground; classify the ground first (e.g. pdal "
                     "filters.smrf) if they include vegetation or buildings")
        else:
            raise FloodMeshError(
                f"{name} is classified but has no ground points (class 2; classes present: "
                f"{present()}): give the classes to grid (--classes, 'LAS classes' in QGIS), or "
                "classify the ground first (e.g. pdal translate with filters.smrf)")
    else:
        keep = np.isin(cls, list(classes))
        if not keep.any():
            raise FloodMeshError(f"{name} has no points of classes {sorted(classes)} "
                                 f"(classes present: {present()}); choose other classes")
    return xyz if keep.all() else xyz[keep]  # a ground-only file needs no copy


def _read_ept(path: Path, classes, note=None):
    """The points of an Entwine Point Tile index (``ept.json`` with LAZ nodes in ``ept-data``,
    as Entwine, untwine and QGIS 3.22 with PDAL write): every node, since each point lies in
    exactly one."""
    # lazy: laspy loads only when this runs
    import laspy

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
        try:
            las = laspy.read(node)
        except Exception as exc:
            raise FloodMeshError(f"{path}: node {node.name} is not readable LAZ ({exc})") from None
        parts.append(np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)]))
        cls.append(np.asarray(las.classification))
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


# ---------------------------------------------------------------------------------------------
# rasters
# values DEM exports use for "no data" without always saying so in the file's nodata tag
NODATA_SENTINELS = (-9999.0, -99999.0, -32768.0, -32767.0, 32767.0, 65535.0,
                    float(np.finfo(np.float32).min), float(np.finfo(np.float32).max))
SENTINEL_GAP_M = 100.0  # an untagged sentinel is nodata when this far beyond every other cell


def raster_crs(src, path: Path, crs=None):
    """The checked CRS of an open rasterio dataset (``crs`` overrides the file's): refuses
    control-point georeferencing, rotated or non-square grids, and CRSs not in metres."""
    transform, file_crs = src.transform, src.crs
    if src.gcps[0] and transform.is_identity:
        raise FloodMeshError(
            f"raster {path.name} is georeferenced by control points, not a geotransform: "
            "warp it to a north-up grid first (gdalwarp -tr D D IN OUT)")
    check_transform(transform, f"raster {path.name}")
    return require_metric_crs(crs if crs is not None else
                              (file_crs.to_wkt() if file_crs else None),
                              f"raster {path.name}", kind="raster")


def raster_crs_wkt(src, path: Path, crs=None) -> str:
    """``raster_crs`` as WKT, for a raster step that passes the CRS through: the file's own WKT
    where GDAL reads it as a projected (not compound) CRS in metres, without pyproj (0.1 s of
    start-up, a fifth of ``floodmesh slope``'s at 6000²); else ``raster_crs``, its checks and
    messages."""
    file_crs = src.crs
    if crs is None and file_crs and not src.gcps[0]:
        wkt = file_crs.to_wkt()
        unit, factor = file_crs.linear_units_factor if wkt.startswith("PROJCS[") else ("", 0)
        if factor == 1.0 and unit.lower() in METRE_NAMES:
            check_transform(src.transform, f"raster {path.name}")
            return wkt
    return raster_crs(src, path, crs).to_wkt()


def no_valid_cells(path) -> FloodMeshError:
    return FloodMeshError(f"raster {Path(path).name} has no valid cells (all nodata or NaN): "
                          "check its nodata value and that it is the right file")


def read_band(src, window=None, dtype=np.float64) -> np.ndarray:
    """Band 1 (or a window of it) as ``dtype`` with NaN for nodata and ±inf, in one buffer (no
    masked array) unless the file masks cells by a mask band rather than a nodata value."""
    # lazy: GDAL loads only when this runs
    from rasterio.enums import MaskFlags

    flags = src.mask_flag_enums[0]
    if MaskFlags.per_dataset in flags or MaskFlags.alpha in flags:
        values = src.read(1, window=window, masked=True).astype(dtype).filled(np.nan)
    else:
        values = src.read(1, window=window, out_dtype=dtype)
    bad = ~np.isfinite(values)  # ±inf cells are nodata too
    if src.nodata is not None and np.isfinite(src.nodata):
        # compare in the file's own type: a float32 nodata written as text may not round-trip
        native = np.dtype(src.dtypes[0])
        nodata = native.type(src.nodata) if native.kind == "f" else src.nodata
        bad |= values == values.dtype.type(nodata)
    values[bad] = np.nan
    return values


def nodata_tagged(path) -> bool:
    """Whether a raster file says which value is nodata (a tag or a mask band)."""
    # lazy: GDAL loads only when this runs
    import rasterio
    from rasterio.enums import MaskFlags

    try:
        with rasterio.open(require_file(path, "raster")) as src:
            return src.nodata is not None or MaskFlags.all_valid not in src.mask_flag_enums[0]
    except rasterio.errors.RasterioIOError as exc:
        raise FloodMeshError(f"{Path(path).name} is not a readable raster ({exc})") from None


def read_raster(path, *, crs=None, note=None) -> Grid:
    """Read band 1 of a raster as a float64 Grid with NaN for nodata.

    Without a nodata tag, cells holding a common sentinel (``NODATA_SENTINELS``) far beyond
    every other cell are nodata too. ``note`` (given for DEMs) receives what was assumed: such
    sentinels, further bands left unused, elevations stored as whole numbers.
    """
    # lazy: GDAL loads only when this runs
    import rasterio

    path = require_file(path, "raster")
    try:
        with rasterio.open(path) as src:
            transform, crs = src.transform, raster_crs(src, path, crs)
            check_memory(cells=src.width * src.height,
                         advice="resample it to larger cells or split it into tiles")
            values = read_band(src)
            tagged, count, dtype = src.nodata is not None, src.count, src.dtypes[0]
    except rasterio.errors.RasterioIOError as exc:
        raise FloodMeshError(f"{path.name} is not a readable raster ({exc})") from None
    if not tagged:
        _untagged_nodata(values, path.name, note)
    if note and count > 1:
        note(f"raster {path.name} has {count} bands: band 1 is used as the elevations; "
             f"extract another one first if it holds them (gdal_translate -b N IN OUT)")
    if note and np.issubdtype(np.dtype(dtype), np.integer):
        note(f"raster {path.name} stores elevations as whole numbers ({dtype}): its 1-unit "
             "steps are terraces whose edges the slope sees and break lines may follow; use a "
             "DEM with floating-point elevations (float32) where there is one")
    if not np.isfinite(values).any():
        raise no_valid_cells(path)
    return Grid(values, transform, crs)


def _untagged_nodata(values: np.ndarray, name: str, note=None) -> None:
    """Set to NaN the cells of an untagged raster holding a nodata sentinel that lies more
    than ``SENTINEL_GAP_M`` beyond every other cell, and say so."""
    for sentinel in NODATA_SENTINELS:
        hit = values == sentinel
        if not hit.any():
            continue
        rest = values[~hit & np.isfinite(values)]
        if rest.size and not (rest.min() - SENTINEL_GAP_M > sentinel
                              or rest.max() + SENTINEL_GAP_M < sentinel):
            continue
        values[hit] = np.nan
        if note:
            note(f"raster {name} has no nodata value, but {int(hit.sum()):,} cells hold "
                 f"{sentinel:g}, far from every other cell: they are taken as nodata; set it in "
                 f"the file (gdal_edit.py -a_nodata {sentinel:g} {name}) to say so")


TILE = 256  # GeoTIFF tile size (cells)
# Codecs chosen by measurement (benchmarks/run.py --only codec, and slope file to file on a
# 6000² DEM): float rasters (DEM, slope, LoG) are written uncompressed, as gdaldem writes them:
# on 16 M float32 cells ZSTD level 1 costs 0.19 s of CPU per 64 MB and saves only 17-20 % (the
# cells' low bits are noise), 30 % more CPU for the whole slope step; its floating-point
# predictor saves another 10 % at twice the CPU; LZW and DEFLATE are slower still. Integer
# rasters (breakpoints: mostly 0) take ZSTD level 1, which shrinks them 8x and more for almost
# nothing. GDAL's own worker threads (NUM_THREADS, GDAL_NUM_THREADS) are not used: GDAL 3.6's
# multi-threaded decoding hung in RasterIO (CPLJobQueue) in the tests.
CREATION_OPTIONS = dict(tiled=True, blockxsize=TILE, blockysize=TILE, bigtiff="if_safer")
INTEGER_COMPRESSION = dict(compress="zstd", zstd_level=1)


def raster_profile(shape, transform, crs, dtype, nodata) -> dict:
    """A tiled GeoTIFF profile, compressed for integer rasters (``CREATION_OPTIONS``; rasters
    under a tile stay striped); ``crs`` a pyproj CRS or WKT."""
    wkt = crs if isinstance(crs, str) else crs.to_wkt()
    profile = dict(driver="GTiff", height=shape[0], width=shape[1], count=1, dtype=dtype,
                   crs=wkt, transform=transform, nodata=nodata, **CREATION_OPTIONS)
    if np.dtype(dtype).kind != "f":
        profile.update(INTEGER_COMPRESSION)
    if shape[0] < TILE or shape[1] < TILE:
        for key in ("tiled", "blockxsize", "blockysize"):
            profile.pop(key)
    return profile


def write_raster(path, grid: Grid, *, valid: np.ndarray | None = None) -> None:
    """Write a Grid as a tiled, compressed GeoTIFF (``raster_profile``); float NaN (or
    cells outside ``valid``) become nodata."""
    # lazy: GDAL loads only when this runs
    import rasterio

    values = grid.values
    if values.dtype == bool:
        values = values.astype(np.uint8)
    if np.issubdtype(values.dtype, np.floating):
        values = values.astype(np.float32)
        nodata = -9999.0
        values = np.where(np.isfinite(values), values, nodata)
    else:
        nodata = 255
        values = values.astype(np.uint8)
    if valid is not None:
        values = np.where(valid, values, nodata)
    profile = raster_profile(values.shape, grid.transform, grid.crs, values.dtype, nodata)
    with atomic_output(path) as tmp:
        with rasterio.open(tmp, "w", **profile) as dst:
            dst.write(values, 1)


def read_input(path, *, crs=None, classes=None, note=None):
    """A point file (→ PointCloud) or a raster DEM (→ Grid), by extension."""
    ext = Path(path).suffix.lower()
    if ext in RASTER_EXTENSIONS:
        return read_raster(path, crs=crs, note=note)
    if is_point_source(path):
        return read_points(path, crs=crs, classes=classes, note=note)
    require_file(path, "input")
    raise FloodMeshError(f"{Path(path).name}: unknown input type '{ext}'; give a LAS/LAZ or XYZ/CSV "
                         "point file, or a GeoTIFF/ASCII-grid DEM")


# ---------------------------------------------------------------------------------------------
# vectors (GeoPackage through fiona/GDAL)
# GeoPackages record when their content last changed; a fixed time makes the same inputs give
# byte-identical files (GDAL's OGR_CURRENT_DATE), as reproducible builds do.
GPKG_TIMESTAMP = "2000-01-01T00:00:00.000Z"


def write_gpkg(path, layer: str, geometry_type: str, properties: dict, records, crs, *,
                atomic: bool = True) -> None:
    """Write one layer; ``atomic=False`` adds it to ``path`` as it is (a GeoPackage being
    assembled under a temporary name, see ``atomic_output``)."""
    # lazy: OGR loads only when this runs
    import fiona

    schema = {"geometry": geometry_type, "properties": properties}
    with atomic_output(path) if atomic else contextlib.nullcontext(path) as target:
        with fiona.Env(OGR_CURRENT_DATE=GPKG_TIMESTAMP):
            with fiona.open(target, "w", driver="GPKG", layer=layer, schema=schema,
                            crs_wkt=crs.to_wkt()) as dst:
                dst.writerecords(records)


def _field_type(values) -> str:
    kind = np.asarray(values).dtype.kind
    return {"i": "int", "u": "int", "b": "int", "f": "float"}.get(kind, "str")


RECORD_CHUNK = 20_000  # features turned into Python objects at a time, for fiona to write


def _records(geometries, attributes: dict):
    """fiona records of ``geometries`` (an iterable) with one value per feature from each
    attribute column, converted a chunk at a time: as Python objects a feature takes some
    1 kB, so a mesh of millions of triangles converted at once took gigabytes."""
    arrays = {name: np.asarray(v) for name, v in attributes.items()}
    geometries = iter(geometries)
    if not arrays:
        yield from ({"geometry": g, "properties": {}} for g in geometries)
        return
    n = len(next(iter(arrays.values())))
    for start in range(0, n, RECORD_CHUNK):
        columns = {name: a[start:start + RECORD_CHUNK].tolist() for name, a in arrays.items()}
        for i in range(min(RECORD_CHUNK, n - start)):
            yield {"geometry": next(geometries),
                   "properties": {name: values[i] for name, values in columns.items()}}


def write_lines_gpkg(path, lines, crs, *, layer="breaklines", attributes=None,
                     atomic: bool = True) -> None:
    """Write (k, 3) coordinate arrays as LineStringZ features with per-line attributes
    (name → sequence, one value per line)."""
    attributes = attributes or {}
    geometries = ({"type": "LineString", "coordinates": [tuple(p) for p in line.tolist()]}
                  for line in lines)
    props = {name: _field_type(v) for name, v in attributes.items()}
    write_gpkg(path, layer, "3D LineString", props, _records(geometries, attributes), crs,
                atomic=atomic)


def write_breaklines(path, lines, crs, *, fit_rms=None) -> None:
    """Write BreakLines with their id, point count, length and slope figures, and with
    ``fit_rms`` (one per line, m) the localisation's confidence, ``fit_rms_m``."""
    def per_line(f):
        return np.array([f(line) for line in lines], dtype=float)

    with np.errstate(all="ignore"):
        attributes = {
            "line_id": np.arange(1, len(lines) + 1),
            "component_id": np.array([line.component for line in lines], dtype=np.int64),
            "n_points": np.array([len(line.coords) for line in lines], dtype=np.int64),
            "length_m": per_line(lambda line: line.length),
            "mean_slope_deg": per_line(lambda line: np.nanmean(line.slopes) if np.isfinite(line.slopes).any() else np.nan),
            "max_slope_deg": per_line(lambda line: np.nanmax(line.slopes) if np.isfinite(line.slopes).any() else np.nan),
        }
        if fit_rms is not None:
            attributes["fit_rms_m"] = np.asarray(fit_rms, dtype=float)
    write_lines_gpkg(path, [line.coords for line in lines], crs, attributes=attributes)


def write_points_gpkg(path, xyz: np.ndarray, crs, *, layer="points", attributes=None,
                      atomic: bool = True) -> None:
    """Write points as PointZ features with per-point attributes (name → sequence)."""
    attributes = attributes or {}
    geometries = ({"type": "Point", "coordinates": tuple(p)} for p in xyz.tolist())
    props = {name: _field_type(v) for name, v in attributes.items()}
    write_gpkg(path, layer, "3D Point", props, _records(geometries, attributes), crs,
                atomic=atomic)


def write_residuals(path, xyz: np.ndarray, res: np.ndarray, crs) -> None:
    """Check points with their residual (m), the TIN's z there and the residual class
    (0: <10 cm, 1: 10–25 cm, 2: >25 cm, −1: outside the mesh)."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.accuracy import residual_class

    write_points_gpkg(path, xyz, crs, layer="residuals",
                      attributes={"residual_m": res, "tin_z": xyz[:, 2] - res,
                                  "class": residual_class(res)})


def read_breaklines(path) -> list:
    """Read a line layer as BreakLines (slopes unknown: NaN; component from ``component_id``
    where the layer has it, else 0)."""
    # lazy: numba loads only when this runs
    from ..steps.breaklines import BreakLine

    return [BreakLine(coords, np.full(len(coords), np.nan),
                      int(properties.get("component_id") or 0))
            for coords, properties in _line_parts(path)]


def read_lines_gpkg(path, note=None) -> list[np.ndarray]:
    """Read the line features of a vector file as (k, 3) arrays (z = NaN where 2-D); parts that
    are no line (non-finite, or fewer than two distinct vertices) are left out, said to
    ``note``."""
    return [coords for coords, _ in _line_parts(path, note)]


def _line_part(part, z_missing=np.nan) -> np.ndarray | None:
    """A line part as (k, 3) coordinates without repeated vertices, or None where it is no line:
    a coordinate not finite, or fewer than two distinct vertices (zero length)."""
    arr = np.array([tuple(p[:3]) + (z_missing,) * (3 - len(p[:3])) for p in part], float)
    if len(arr) == 0 or not np.isfinite(arr[:, :2]).all():
        return None
    keep = np.ones(len(arr), bool)
    keep[1:] = np.any(arr[1:, :2] != arr[:-1, :2], axis=1)
    arr = arr[keep]
    return arr if len(arr) >= 2 else None


def _line_parts(path, note=None) -> list[tuple[np.ndarray, dict]]:
    """Each part of each line feature as ((k, 3) coordinates, the feature's attributes)."""
    # lazy: OGR loads only when this runs
    import fiona

    path = require_file(path, "line file")
    parts_out, dropped = [], []
    try:
        with fiona.open(path) as src:
            for number, feat in enumerate(src, 1):
                geom = feat["geometry"]
                if geom is None:
                    continue
                parts = ([geom["coordinates"]] if geom["type"] == "LineString"
                         else geom["coordinates"] if geom["type"] == "MultiLineString" else None)
                if parts is None:
                    raise FloodMeshError(f"{path.name} holds {geom['type']} features; "
                                         "break lines must be lines")
                properties = dict(feat["properties"])
                for part in parts:
                    arr = _line_part(part)
                    if arr is None:
                        dropped.append(number)
                    else:
                        parts_out.append((arr, properties))
    except fiona.errors.FionaError as exc:
        raise FloodMeshError(f"{path.name} is not a readable vector file ({exc})") from None
    if dropped and note:
        note(f"{path.name}: {len(dropped)} line part(s) of feature(s) "
             f"{', '.join(map(str, sorted(set(dropped))[:10]))} left out: zero length (fewer "
             "than two distinct vertices) or coordinates that are not numbers")
    return parts_out


def read_regions(path, *, field: str | None = None, what: str = "regions") -> list:
    """Polygon features as (shapely geometry, material id): the integer attribute ``field``, or
    2, 3, … in feature order (1 being the rest of the domain)."""
    # lazy: OGR and GEOS load only when this runs
    import fiona
    import shapely.geometry

    path = require_file(path, "region layer")
    regions = []
    try:
        with fiona.open(path) as src:
            fields = list(src.schema["properties"])
            if field and field not in fields:
                raise FloodMeshError(f"{path.name} has no field {field!r} (its fields: "
                                     f"{', '.join(fields) or 'none'}); name the material id field")
            for feat in src:
                geom = feat["geometry"]
                if geom is None:
                    continue
                if geom["type"] not in ("Polygon", "MultiPolygon"):
                    raise FloodMeshError(f"{path.name} holds {geom['type']} features; {what} "
                                         "must be polygons: give a polygon layer (QGIS: "
                                         "Lines to polygons)")
                value = len(regions) + 2 if not field else feat["properties"][field]
                try:
                    material = float(value)
                except (TypeError, ValueError):
                    material = np.nan
                if not (np.isfinite(material) and material == int(material)):
                    raise FloodMeshError(f"a region of {path.name} has {field} = {value!r}; "
                                         "material ids must be whole numbers")
                regions.append((shapely.geometry.shape(geom), int(material)))
    except fiona.errors.FionaError as exc:
        raise FloodMeshError(f"{path.name} is not a readable vector file ({exc})") from None
    if not regions:
        raise FloodMeshError(f"{path.name} holds no polygons")
    return regions


def read_points_vector(path) -> np.ndarray:
    """Read the PointZ features of a vector file (e.g. holdout points) as an (N, 3) array."""
    # lazy: OGR loads only when this runs
    import fiona

    path = require_file(path, "point layer")
    with fiona.open(path) as src:
        xyz = [feat["geometry"]["coordinates"] for feat in src if feat["geometry"]]
    if not xyz or len(xyz[0]) < 3:
        raise FloodMeshError(f"{path.name} has no 3-D points")
    return np.asarray(xyz, dtype=float)[:, :3]


def read_boundary(path) -> list:
    """The polygons (shapely) of a polygon layer, e.g. a model domain, as drawn (unchecked)."""
    return [geometry for geometry, _ in read_regions(path, what="a model domain (boundary)")]


def vector_crs(path):
    """The CRS (WKT) of a vector file, or None where it has none."""
    # lazy: OGR loads only when this runs
    import fiona

    path = require_file(path, "vector layer")
    try:
        with fiona.open(path) as src:
            return src.crs_wkt or None
    except fiona.errors.FionaError as exc:
        raise FloodMeshError(f"{path.name} is not a readable vector file ({exc})") from None


# ---------------------------------------------------------------------------------------------
# meshes
def write_mesh_2dm(path, nodes: np.ndarray, triangles: np.ndarray, *, material: int = 1,
                   materials=None, element_z=None, node_strings=(), crs=None) -> None:
    """Write a triangular mesh as SMS 2DM: 1-based ids, ``E3T id n1 n2 n3 matid`` lines, then
    ``ND id x y z`` (m), then node strings.

    ``materials`` (one integer per triangle) replaces the single ``material``; ``element_z``
    (m, one per triangle) adds BASEMENT 3's element elevation as the second material column;
    either writes the ``NUM_MATERIALS_PER_ELEM`` card. ``node_strings`` are sequences of node
    indices, each written as ``NS`` lines of up to 10 ids, the last negative, then its number.
    ``crs`` (a 2DM has no place for it) goes into the sidecar ``<stem>.prj`` (``write_prj``).
    """
    n_tri = len(triangles)
    ids = np.arange(1, n_tri + 1)
    mats = np.full(n_tri, material) if materials is None else np.asarray(materials)
    columns = [ids, triangles + 1, mats]
    fmt = "E3T %d %d %d %d %d"
    if element_z is not None:
        columns.append(np.asarray(element_z, float))
        fmt += " %.4f"
    elements = np.column_stack(columns)
    node_rows = np.column_stack([np.arange(1, len(nodes) + 1), nodes])
    with atomic_output(path) as tmp:
        with open(tmp, "w") as fh:
            fh.write("MESH2D\n")
            if materials is not None or element_z is not None:
                fh.write(f"NUM_MATERIALS_PER_ELEM {1 if element_z is None else 2}\n")
            np.savetxt(fh, elements, fmt=fmt)
            np.savetxt(fh, node_rows, fmt="ND %d %.4f %.4f %.4f")
            for number, string in enumerate(node_strings, start=1):
                ids_ = np.asarray(string, np.int64) + 1
                for start in range(0, len(ids_), 10):
                    chunk = ids_[start:start + 10].tolist()
                    last = start + 10 >= len(ids_)
                    if last:
                        chunk[-1] = -chunk[-1]
                    fh.write("NS " + " ".join(map(str, chunk)) + (f" {number}\n" if last else "\n"))
    if crs is not None:
        write_prj(path, crs)


def write_prj(path, crs) -> None:
    """The CRS of a file that cannot hold one (SMS 2DM) as WKT in ``<stem>.prj`` beside it, as
    shapefiles and ASCII grids carry theirs; ``read_prj`` and the QGIS plugin read it back."""
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    with atomic_output(Path(path).with_suffix(".prj")) as tmp:
        Path(tmp).write_text(CRS.from_user_input(crs).to_wkt() + "\n")


def read_prj(path) -> str | None:
    """The WKT of ``<stem>.prj`` beside ``path``, or None when there is none."""
    prj = Path(path).with_suffix(".prj")
    return prj.read_text().strip() or None if prj.is_file() else None


@dataclass(frozen=True)
class Mesh2DM:
    """What an SMS 2DM file holds: ``nodes`` (n, 3), ``triangles`` (m, 3) zero-based,
    ``materials`` (m,) integers (1 where the file gives none), ``element_z`` (m,) or None,
    ``node_strings`` zero-based node index arrays."""

    nodes: np.ndarray
    triangles: np.ndarray
    materials: np.ndarray
    element_z: np.ndarray | None
    node_strings: list
    crs: str | None = None  # WKT of the sidecar .prj (write_prj), if there is one


def read_2dm(path) -> Mesh2DM:
    """Read an SMS 2DM mesh of triangles (E3T) with its materials and node strings."""
    path = require_file(path, "mesh file")
    nodes, tris, extra, strings, current = {}, [], [], [], []
    n_materials = None
    try:
        with open(path, errors="replace") as fh:
            first = fh.readline().split()
            if not first or first[0] != "MESH2D":
                raise FloodMeshError(f"{path.name} is not an SMS 2DM mesh (no MESH2D line)")
            for line in fh:
                parts = line.split("#", 1)[0].split()
                if not parts:
                    continue
                card = parts[0]
                if card == "ND":
                    nodes[int(parts[1])] = (float(parts[2]), float(parts[3]), float(parts[4]))
                elif card == "E3T":
                    tris.append((int(parts[2]), int(parts[3]), int(parts[4])))
                    extra.append([float(v) for v in parts[5:]])
                elif card in ("E4Q", "E6T", "E8Q", "E9Q"):
                    raise FloodMeshError(f"{path.name} has {card} elements; only triangles (E3T) "
                                         "are supported")
                elif card == "NUM_MATERIALS_PER_ELEM":
                    n_materials = int(parts[1])
                elif card == "NS":
                    for token in parts[1:]:
                        value = int(token)
                        current.append(abs(value))
                        if value < 0:
                            strings.append(current)
                            current = []
                            break
    except FloodMeshError:
        raise
    except (ValueError, IndexError, UnicodeDecodeError) as exc:
        raise FloodMeshError(f"{path.name} is not a readable SMS 2DM mesh ({exc})") from None
    if not tris:
        raise FloodMeshError(f"{path.name} holds no triangles (E3T lines): nothing to export")
    ids = np.array(sorted(nodes))
    index = {nid: i for i, nid in enumerate(ids)}
    try:
        tri_arr = np.array([[index[a], index[b], index[c]] for a, b, c in tris], dtype=np.int64)
        string_arr = [np.array([index[i] for i in s], dtype=np.int64) for s in strings]
    except KeyError as exc:
        raise FloodMeshError(f"{path.name} refers to node {exc} that it does not define") from None
    node_arr = np.array([nodes[i] for i in ids], dtype=float).reshape(-1, 3)
    width = min((len(e) for e in extra), default=0)
    values = np.array([e[:width] for e in extra], float).reshape(len(extra), width)
    materials = (values[:, 0].astype(np.int64) if width >= 1
                 else np.ones(len(tris), np.int64))
    # BASEMENT 3 (and MDAL): the column after the material id is the element's elevation
    has_z = width >= 2 and (n_materials is None or n_materials >= 2)
    element_z = values[:, 1].copy() if has_z else None
    return Mesh2DM(node_arr, tri_arr.reshape(-1, 3), materials, element_z, string_arr,
                   read_prj(path))


def read_mesh_2dm(path) -> tuple[np.ndarray, np.ndarray]:
    """Read nodes (n, 3) and triangles (m, 3, zero-based) of an SMS 2DM file."""
    mesh = read_2dm(path)
    return mesh.nodes, mesh.triangles


def write_mesh_gpkg(path, nodes: np.ndarray, triangles: np.ndarray, crs, *, layer="triangles",
                    attributes=None, atomic: bool = True):
    """Write the mesh's triangles as PolygonZ features (id, area_m2, min_angle_deg, and any
    per-triangle ``attributes``)."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import triangle_angles, triangle_areas

    areas = triangle_areas(nodes, triangles)
    min_angles = triangle_angles(nodes, triangles).min(axis=1)
    columns = {"id": np.arange(1, len(triangles) + 1), "area_m2": areas,
               "min_angle_deg": min_angles, **(attributes or {})}
    geometries = ({"type": "Polygon", "coordinates": [[*map(tuple, c), tuple(c[0])]]}
                  for start in range(0, len(triangles), RECORD_CHUNK)
                  for c in nodes[triangles[start:start + RECORD_CHUNK]].tolist())
    props = {name: _field_type(v) for name, v in columns.items()}
    write_gpkg(path, layer, "3D Polygon", props, _records(geometries, columns), crs,
                atomic=atomic)


def jsonable(value):
    """``value`` with numpy numbers as Python ones and non-finite floats as None (null)."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    return value


def write_json(path, data: dict) -> None:
    """Write ``data`` as indented JSON (see ``jsonable``), atomically."""
    with atomic_output(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(jsonable(data), fh, indent=2, sort_keys=False)
            fh.write("\n")
