"""Rasters through rasterio (GDAL): a DEM read as a ``Grid`` with NaN for nodata (``read_raster``;
``read_band`` for band 1 or a window of it), its CRS checked (``raster_crs``), and ``Grid``s
written as tiled GeoTIFFs (``raster_profile``, ``write_raster``); ``read_input`` takes a point
file or a DEM."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..engine.limits import check_memory
from ..errors import FloodMeshError
from ..options import is_point_source
from ..raster import (ELEVATION, METRE_NAMES, QUANTITIES, SCALE_TOLERANCE, Grid, check_transform,
                      chosen_crs, drop_implausible, holds_instead, implausible_note, metric_crs_at,
                      require_metre_elevations)
from .outputs import atomic_output, require_file
from .points import read_points

RASTER_EXTENSIONS = (".tif", ".tiff", ".asc", ".img", ".vrt", ".nc")


def raster_crs(src, path: Path, crs=None, note=None, default_crs=None):
    """The checked CRS of an open rasterio dataset (``crs`` overrides the file's, which
    ``note`` hears of; ``default_crs`` is taken where it has none): refuses control-point
    georeferencing, rotated or non-square grids, CRSs not in metres and those whose scale at
    the raster is far from true."""
    transform, file_crs = src.transform, src.crs
    if src.gcps[0] and transform.is_identity:
        raise FloodMeshError(
            f"raster {path.name} is georeferenced by control points, not a geotransform: "
            "warp it to a north-up grid first (gdalwarp -tr D D IN OUT)")
    check_transform(transform, f"raster {path.name}")
    what = f"raster {path.name}"
    own = file_crs.to_wkt() if file_crs else None
    return metric_crs_at(chosen_crs(crs, own, what, note) or default_crs, src.bounds, what,
                         "raster")


# A Transverse Mercator's scale at d m from its central meridian is k0 (1 + d² / 2R²) to 0.01 %
# out to 1000 km (0.9996 to 1.001 across a UTM zone): the fast path below takes only what lies
# within half SCALE_TOLERANCE of true by it, and leaves the rest to PROJ (``check_scale``)
EARTH_RADIUS_M = 6_371_000.0


def _transverse_mercator_scale(wkt: str, bounds) -> float | None:
    """The largest departure from true scale of a WKT1 Transverse Mercator (UTM, national
    grids) across ``bounds``, from its parameters alone (no PROJ); None for other
    projections."""
    if 'PROJECTION["Transverse_Mercator"]' not in wkt:
        return None
    parameters = dict(re.findall(r'PARAMETER\["(\w+)",([-+\d.eE]+)\]', wkt))
    k0 = float(parameters.get("scale_factor", 1.0))
    d = max(abs(x - float(parameters.get("false_easting", 0.0))) for x in bounds[::2])
    return abs(k0 * (1.0 + 0.5 * (d / EARTH_RADIUS_M) ** 2) - 1.0)


def raster_crs_wkt(src, path: Path, crs=None) -> str:
    """``raster_crs`` as WKT, for a raster step that passes the CRS through: the file's own WKT
    where GDAL reads it as a Transverse Mercator (not compound) CRS in metres true to scale
    across the raster, without pyproj (0.1 s of start-up, a fifth of ``floodmesh slope``'s at
    6000²); else ``raster_crs``, its checks and messages."""
    file_crs = src.crs
    if crs is None and file_crs and not src.gcps[0]:
        wkt = file_crs.to_wkt()
        unit, factor = file_crs.linear_units_factor if wkt.startswith("PROJCS[") else ("", 0)
        scale = _transverse_mercator_scale(wkt, src.bounds)
        if (factor == 1.0 and unit.lower() in METRE_NAMES and scale is not None
                and scale <= SCALE_TOLERANCE / 2):
            check_transform(src.transform, f"raster {path.name}")
            return wkt
    return raster_crs(src, path, crs).to_wkt()


def no_valid_cells(path) -> FloodMeshError:
    return FloodMeshError(f"raster {Path(path).name} has no valid cells (all nodata or NaN): "
                          "check its nodata value and that it is the right file")


FLOAT32_MAX = float(np.finfo(np.float32).max)
FLOAT32_EPS = float(np.finfo(np.float32).eps)
# half the spacing of float32 numbers at FLT_MAX: a float32 sum overflows to inf where its
# exact value reaches FLT_MAX plus this (it rounds up from there)
FLOAT32_TOP_HALF_STEP = 2.0 ** 103


def nodata_range(src) -> tuple[float, float]:
    """(low, high): the values of band 1 of the open ``src`` that its nodata tag names, as
    GDAL's mask (``gdalinfo -stats``, QGIS, rasterio's masked reads) takes them; (NaN, NaN)
    without a finite tag. Integer bands: the tag. Float bands: within 4 float32 epsilons
    (5·10⁻⁷ of it) of the tag in the band's own type, GDAL's ARE_REAL_EQUAL (to a float32 ulp
    at the ends); in float32 GDAL's test also holds where cell plus tag overflows, which near
    ±FLT_MAX reaches the tag: a tag written with six digits, -3.40282e+38 (gdal_edit.py
    -a_nodata), names the -3.4028235e+38 that the cells hold; a tag of ±FLT_MAX itself
    (gdal_calc.py's, QGIS's raster calculator's) names the cells beyond ±1.01·10³¹ of its
    sign, not the elevations."""
    nodata = src.nodata
    if nodata is None or not np.isfinite(nodata):  # NaN and ±inf cells are nodata anyway
        return np.nan, np.nan
    native = np.dtype(src.dtypes[0])
    if native.kind != "f":
        return float(nodata), float(nodata)
    tag = float(native.type(nodata))
    reach = 4 * FLOAT32_EPS * abs(tag)
    low, high = tag - reach, tag + reach
    # cells of the tag's sign from here on overflow the float32 sum
    edge = FLOAT32_MAX - abs(tag) + FLOAT32_TOP_HALF_STEP
    if native == np.float32 and edge <= abs(tag) + reach:  # and that reaches the tag
        low, high = (min(low, edge), FLOAT32_MAX) if tag > 0 else (-FLOAT32_MAX, max(high, -edge))
    return low, high


def band_scaling(src) -> tuple[float, float]:
    """(scale, offset) of band 1 of the open ``src``: its values are stored · scale + offset (a
    DEM packed as whole centimetres has scale 0.01), as GDAL defines them and QGIS shows them;
    (1, 0) where the file gives none, or a scale of 0, which GDAL and QGIS ignore."""
    scale, offset = float(src.scales[0]), float(src.offsets[0])
    return (1.0, 0.0) if scale == 0 else (scale, offset)


def read_band(src, window=None, dtype=np.float64) -> np.ndarray:
    """Band 1 (or a window of it) as ``dtype`` with NaN for nodata (``nodata_range``) and ±inf,
    in one buffer (no masked array) unless the file masks cells by a mask band rather than a
    nodata value; a float ``dtype`` holds the values unpacked (``band_scaling``)."""
    # lazy: GDAL loads only when this runs
    from rasterio.enums import MaskFlags

    flags = src.mask_flag_enums[0]
    if MaskFlags.per_dataset in flags or MaskFlags.alpha in flags:
        values = src.read(1, window=window, masked=True).astype(dtype).filled(np.nan)
    else:
        values = src.read(1, window=window, out_dtype=dtype)
    bad = ~np.isfinite(values)  # ±inf cells are nodata too
    low, high = nodata_range(src)
    if low == low:
        bad |= (values >= low) & (values <= high)
    values[bad] = np.nan
    scale, offset = band_scaling(src)
    if (scale, offset) != (1.0, 0.0) and values.dtype.kind == "f":
        values *= values.dtype.type(scale)
        values += values.dtype.type(offset)
    return values


def read_raster(path, *, crs=None, elevations: bool = True, note=None, default_crs=None,
                dem: bool = False, holds: tuple[str, str] | None = None) -> Grid:
    """Read band 1 of a raster as a float64 Grid with NaN for nodata, in ``crs``, else its own
    CRS, else ``default_crs`` (``raster_crs``).

    With ``elevations`` (a DEM), cells no ground has are nodata too (``drop_implausible``).
    ``note`` (given for DEMs) receives what was assumed: such cells, further bands left unused,
    elevations stored as whole numbers. ``dem`` (a step's DEM): a slope, LoG response or
    breakpoints that FloodMesh's steps wrote are refused (``refuse_non_elevations``).
    ``holds`` (the quantity wanted, a key of ``QUANTITIES``, and the fix): a raster FloodMesh
    tagged as holding another is refused first, as ``check_quantity`` refuses it.
    """
    # lazy: GDAL loads only when this runs
    import rasterio

    path = require_file(path, "raster")
    try:
        with rasterio.open(path) as src:
            if dem:
                refuse_non_elevations(src, f"raster {path.name}")
            if holds:
                refuse_other_quantity(held_quantity(src), f"raster {path.name}", *holds)
            if elevations:
                require_metre_elevations(src.units[0], f"raster {path.name}")
            transform, crs = src.transform, raster_crs(src, path, crs, note, default_crs)
            check_memory(cells=src.width * src.height,
                         advice="resample it to larger cells or split it into tiles")
            values = read_band(src)
            nodata, count, dtype = src.nodata, src.count, src.dtypes[0]
            held, step = held_quantity(src), abs(band_scaling(src)[0])
    except rasterio.errors.RasterioIOError as exc:
        raise FloodMeshError(f"{path.name} is not a readable raster ({exc})") from None
    if elevations:
        drop_implausible(values, dem_file(path.name, nodata), path.name, note)
    if note and count > 1:
        note(f"raster {path.name} has {count} bands: band 1 is used as the elevations; "
             f"extract another one first if it holds them (gdal_translate -b N IN OUT)")
    if note and np.issubdtype(np.dtype(dtype), np.integer):
        steps = "1-unit" if step == 1 else f"{step:g} m"
        note(f"raster {path.name} stores elevations as whole numbers ({dtype}): its {steps} "
             "steps are terraces whose edges the slope sees and break lines may follow; use a "
             "DEM with floating-point elevations (float32) where there is one")
    if not np.isfinite(values).any():
        raise no_valid_cells(path)
    return Grid(values, transform, crs, None if held == ELEVATION else held)


def read_dem(path, *, crs=None, note=None) -> Grid:
    """The DEM a step takes (``read_raster``), refusing a slope, LoG response or breakpoints
    that FloodMesh's steps wrote (``refuse_non_elevations``)."""
    return read_raster(path, crs=crs, note=note, dem=True)


def dem_file(name: str, nodata) -> str:
    """``implausible_note``'s words for DEM file ``name`` with the nodata tag ``nodata``."""
    return f"raster {name} ({'no nodata tag' if nodata is None else f'nodata tag {nodata:g}'})"


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


# What a raster FloodMesh writes holds (``raster.QUANTITIES``), as a GeoTIFF metadata item that
# the steps taking it read back (``check_quantity``, ``refuse_non_elevations``), with the band's
# description and unit, which QGIS and gdalinfo show. A raster without it, another program's
# (gdaldem slope), is taken as the step is told
QUANTITY_TAG = "FLOODMESH_QUANTITY"
# the names FloodMesh gives its rasters other than a DEM, for those it wrote before it tagged them
NAMED = {"slope.tif": "slope", "breakpoints.tif": "breakpoints", "max_depth.tif": "max_depth",
         "max_water_level.tif": "max_stage", "max_speed.tif": "max_speed",
         "arrival_time.tif": "arrival_s", "size_field.tif": "size_field",
         "depth_difference.tif": "depth_difference",
         "extent_difference.tif": "extent_difference"}


def describe_band(dst, quantity: str | None) -> None:
    """Tag the open rasterio dataset ``dst`` as holding ``quantity`` (a key of ``QUANTITIES``;
    None: nothing is said)."""
    if quantity is None:
        return
    description, unit, _, _ = QUANTITIES[quantity]
    dst.update_tags(**{QUANTITY_TAG: quantity})
    dst.set_band_description(1, description)
    if unit:
        dst.set_band_unit(1, unit)


def held_quantity(src) -> str | None:
    """What the open raster ``src`` holds by FloodMesh's tag (``describe_band``), or None."""
    held = src.tags().get(QUANTITY_TAG)
    return held if held in QUANTITIES else None


def named_instead(name: str, path) -> str | None:
    """That ``name`` (file ``path``) is named as FloodMesh names a raster of another quantity
    than elevations (``NAMED``), or None."""
    quantity = NAMED.get(Path(path).name.lower())
    return None if quantity is None else (f"{name} is named as FloodMesh names "
                                          f"{QUANTITIES[quantity][2]}, an earlier run's output")


def refuse_non_elevations(src, name: str, fix: str = "give the DEM (a run's dem.tif)") -> None:
    """Refuse the open raster ``src`` (``name``) where elevations are wanted if FloodMesh tagged
    it (``describe_band``) as holding anything else, a slope, breakpoints or a flood's depths,
    or, untagged, is named as FloodMesh names those (``named_instead``: an earlier run's,
    written before it tagged them): a slope gridded, sloped or meshed as ground gives a mesh of
    degrees without a word."""
    held = held_quantity(src)
    if held not in (None, ELEVATION):
        raise FloodMeshError(f"{holds_instead(name, held, 'elevations')}: {fix}")
    named = named_instead(name, src.name) if held is None else None
    if named:
        raise FloodMeshError(f"{named}: {fix}, or rename it if it holds elevations")


def check_quantity(path, wanted: str, fix: str) -> None:
    """Refuse a raster that FloodMesh tagged (``describe_band``) as holding another quantity
    than ``wanted`` (a key of ``QUANTITIES``), naming what it holds and ``fix``; a raster
    without the tag, or one GDAL cannot open (the step reading it says so), is not judged."""
    # lazy: GDAL loads only when this runs
    import rasterio

    try:
        with rasterio.open(require_file(path, "raster")) as src:
            held = held_quantity(src)
    except rasterio.errors.RasterioIOError:
        return
    refuse_other_quantity(held, f"raster {Path(path).name}", wanted, fix)


def refuse_other_quantity(held: str | None, name: str, wanted: str, fix: str) -> None:
    """Refuse raster ``name`` whose tag (``held_quantity``) says it holds another quantity than
    ``wanted`` (keys of ``QUANTITIES``), naming what it holds and ``fix`` (a DEM where its slope
    belongs: how to make the slope); untagged (None), it is not judged."""
    if held == ELEVATION and wanted in ("slope", "log"):  # a DEM where its slope belongs
        fix = (f"give the DEM's {QUANTITIES[wanted][0]} (floodmesh slope DEM"
               f"{' --method log' if wanted == 'log' else ''}; Slope for break lines in QGIS)")
    if held is not None and held != wanted:
        raise FloodMeshError(f"{holds_instead(name, held, QUANTITIES[wanted][2])}: {fix}")


def write_raster(path, grid: Grid, *, valid: np.ndarray | None = None,
                 quantity: str | None = None) -> None:
    """Write a Grid as a tiled, compressed GeoTIFF (``raster_profile``); float NaN (or
    cells outside ``valid``) become nodata; ``quantity`` (default the grid's) says what it
    holds (``describe_band``)."""
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
            describe_band(dst, quantity or grid.quantity)


def read_input(path, *, crs=None, classes=None, note=None):
    """A point file (→ PointCloud) or a raster DEM (→ Grid), by extension."""
    ext = Path(path).suffix.lower()
    if ext in RASTER_EXTENSIONS:
        return read_dem(path, crs=crs, note=note)
    if is_point_source(path):
        return read_points(path, crs=crs, classes=classes, note=note)
    require_file(path, "input")
    raise FloodMeshError(f"{Path(path).name}: unknown input type '{ext}'; give a LAS/LAZ or XYZ/CSV "
                         "point file, or a GeoTIFF/ASCII-grid DEM")
