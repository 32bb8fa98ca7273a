"""The small georeferenced grid type every raster step takes and returns."""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from affine import Affine

from .errors import FloodMeshError

if TYPE_CHECKING:  # pyproj is imported where a CRS is checked: it costs 0.1 s of start-up
    from pyproj import CRS

METRE_NAMES = {"metre", "meter", "metres", "meters"}
REPROJECT_POINTS = ("pdal translate IN OUT -f filters.reprojection "
                    "--filters.reprojection.out_srs=EPSG:{code}")
REPROJECT_RASTER = "gdalwarp -t_srs EPSG:{code} IN OUT"
REPROJECT_VECTOR = "ogr2ogr -t_srs EPSG:{code} OUT IN"
# Elevations (m) no ground has: the lowest dry land, the Dead Sea shore, lies at -430 m and
# Everest at 8849 m. They catch the no-data values that no nodata tag names, such as -9999,
# -32768 and ±3.4e38 (cells outside them are nodata, with a note: io.read_raster).
LOWEST_GROUND_M, HIGHEST_GROUND_M = -1000.0, 9000.0
SCALE_Z_POINTS = ('pdal translate IN OUT -f filters.assign '
                  '--filters.assign.value="Z = Z * {factor:.7g}"')
SCALE_Z_RASTER = 'gdal_calc.py -A IN --calc "A*{factor:.7g}" --outfile OUT'
# Units other than metres a raster's band may name for its values (GDAL's unit type, which a
# NetCDF's units attribute and a USGS DEM set): metres per unit
LENGTH_UNITS = {
    **dict.fromkeys(("ft", "foot", "feet", "international foot"), 0.3048),
    **dict.fromkeys(("us-ft", "ftus", "us survey foot", "us survey feet"), 1200 / 3937),
    **dict.fromkeys(("cm", "centimetre", "centimeter", "centimetres", "centimeters"), 0.01),
    **dict.fromkeys(("mm", "millimetre", "millimeter", "millimetres", "millimeters"), 0.001),
}


def _for_kind(kind: str | None, points: str, raster: str) -> str:
    """The command for points or rasters (``kind``), or both where the kind is not known."""
    if kind == "points":
        return f"`{points}`"
    if kind == "raster":
        return f"`{raster}`"
    return f"`{points}` for points, `{raster}` for rasters"


@dataclass(frozen=True)
class RefusedCRS:
    """What a file declares of its CRS that FloodMesh cannot work in, as ``reason`` (said after
    the file's name), where no CRS object says it (a LAS's GeoTIFF keys: a user-defined
    projection, elevations in feet); ``require_metric_crs`` refuses it, as it would the CRS."""

    reason: str


def _reproject_hint(kind: str | None, code: str = "XXXX") -> str:
    """How to reproject data of ``kind`` ("points", "raster", "vector": a line or polygon layer;
    None: not known) to EPSG:``code``."""
    if kind == "vector":
        return f"`{REPROJECT_VECTOR.format(code=code)}`"
    return _for_kind(kind, REPROJECT_POINTS.format(code=code), REPROJECT_RASTER.format(code=code))


def _scale_z_hint(kind: str | None, factor: float) -> str:
    """How to turn z in a unit of ``factor`` m into metres."""
    return _for_kind(kind, SCALE_Z_POINTS.format(factor=factor),
                     SCALE_Z_RASTER.format(factor=factor))


# How --crs may name a CRS: PROJ matches any other word to the nearest CRS name it knows
# ('foo' gives Amersfoort), which no user means
CRS_FORMS = re.compile(r"""\d+                       # a bare EPSG code
                           |[A-Za-z]+:\S+            # AUTHORITY:CODE, URN, URL
                           |[A-Za-z_]+\s*\[.*        # WKT
                           |\+.*|proj=.*             # a PROJ string
                           |\{.*                     # PROJJSON""", re.VERBOSE | re.DOTALL)


def parse_crs(crs, what: str) -> CRS:
    """``crs`` (a CRS object, an authority code such as EPSG:25832 or 25832, WKT, a PROJ string
    or PROJJSON) as a pyproj CRS; a name ("Amersfoort", "foo") is refused, as PROJ would
    take the nearest name it knows."""
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    if isinstance(crs, str) and not CRS_FORMS.fullmatch(crs.strip()):
        raise FloodMeshError(f"{what}: {crs!r} is not a CRS code: give it as EPSG:XXXX (or WKT, "
                             "a PROJ string), not as a name")
    try:
        return CRS.from_user_input(crs.strip() if isinstance(crs, str) else crs)
    except Exception as exc:  # pyproj raises CRSError with a technical message
        raise FloodMeshError(f"{what}: cannot understand the CRS {crs!r} ({exc}); "
                             "give it as EPSG:XXXX") from None


def horizontal_crs(crs: CRS) -> CRS:
    """The horizontal part of a compound CRS (e.g. RD New of RD New + NAP height), else
    ``crs``."""
    return crs.sub_crs_list[0] if crs.is_compound and crs.sub_crs_list else crs


def _vertical_crs(crs: CRS) -> CRS | None:
    """The vertical part of a compound CRS, else None."""
    return crs.sub_crs_list[-1] if crs.is_compound and len(crs.sub_crs_list) > 1 else None


def same_place(a: CRS, b: CRS, *, heights: bool = False) -> bool:
    """Whether data in ``a`` and ``b`` lie alike: the same horizontal CRS (a DEM in RD New + NAP
    height and a boundary in RD New do); with ``heights``, also the same vertical CRS where
    both name one."""
    if not horizontal_crs(a).equals(horizontal_crs(b), ignore_axis_order=True):
        return False
    va, vb = _vertical_crs(a), _vertical_crs(b)
    return not heights or va is None or vb is None or va.equals(vb)


def require_same_place(own: CRS, crs: CRS, what: str, of: str, *, heights: bool = False):
    """Refuse ``what`` (a file, by name) in ``own`` where it does not lie alike in ``crs``,
    the ``of``'s (``same_place``)."""
    if not same_place(own, crs, heights=heights):
        raise FloodMeshError(f"the {what} is in {own.name}, the {of} in {crs.name}; reproject "
                             f"it to the {of}'s CRS")


def chosen_crs(given, own, what: str, note=None):
    """The CRS to take: ``given`` (--crs, QGIS's CRS parameter) over the file's ``own``, where
    ``note`` hears that it replaces a different one; ``own`` when none is given."""
    if given is None or own is None or note is None:
        return own if given is None else given
    given_crs = parse_crs(given, what)
    try:
        own_crs = parse_crs(own, what)
    except FloodMeshError:  # a CRS the file holds but PROJ cannot read: the reason to give one
        own_crs = None
    if own_crs is None or not given_crs.equals(own_crs, ignore_axis_order=True):
        said = f"is in {own_crs.name}" if own_crs is not None else "has a CRS PROJ cannot read"
        note(f"{what} {said}, but the CRS given is used: {given_crs.name} (--crs, or the CRS "
             "parameter in QGIS); leave that out to keep the file's")
    return given


def require_metric_crs(crs, what: str, kind: str | None = None, *,
                       given: str | None = None) -> CRS:
    """Return ``crs`` as a pyproj CRS, refusing none (and a ``RefusedCRS``), geographic,
    geocentric and vertical ones (only a projected CRS, or a local engineering one, places x, y
    on a plane), and horizontal or vertical units other than metres. ``kind`` ("points" or
    "raster") picks the commands the message suggests; ``given`` says how a library user gives
    the CRS of what they built in memory (e.g. ``GRID_CRS``; None: a file's, on the command line
    or in QGIS)."""
    if isinstance(crs, RefusedCRS):
        raise FloodMeshError(f"{what} {crs.reason}")
    if crs is None:
        raise FloodMeshError(
            f"{what} has no coordinate reference system: give one "
            f"({given or '--crs EPSG:XXXX, or the CRS parameter in QGIS'}), a projected CRS in "
            "metres such as the survey's UTM zone")
    crs = parse_crs(crs, what)
    horizontal = horizontal_crs(crs)
    if crs.is_geographic or horizontal.is_geographic:
        raise FloodMeshError(
            f"{what} is in a geographic CRS ({crs.name}, degrees): slopes and areas need metres. "
            f"Reproject it to a projected CRS in metres (e.g. the UTM zone) first: "
            f"{_reproject_hint(kind)}")
    if not (horizontal.is_projected or horizontal.is_engineering):
        raise FloodMeshError(
            f"{what} is in {crs.name}, a {horizontal.type_name.replace(' CRS', '').lower()} "
            "CRS, not a projected one: FloodMesh needs x, y on a map in metres, such as the "
            "survey's UTM zone (EPSG:XXXX; with its heights EPSG:XXXX+VVVV)")
    for axis in crs.axis_info:
        if axis.unit_conversion_factor == 1.0 and axis.unit_name.lower() in METRE_NAMES:
            continue
        unit = axis.unit_name or "unknown"
        if axis.direction.lower() in ("up", "down"):
            raise FloodMeshError(
                f"{what} has elevations in '{unit}' ({crs.name}); FloodMesh works in metres: "
                f"convert z to metres first, e.g. {_reproject_hint(kind, 'HHHH+VVVV')} with "
                "VVVV a vertical CRS in metres")
        raise FloodMeshError(
            f"{what} has horizontal units of '{unit}' ({crs.name}); FloodMesh works in metres "
            "and does not convert: reproject x, y to metres, e.g. "
            f"{_reproject_hint(kind)} (the UTM zone), and if z is in '{unit}' too scale it, "
            f"e.g. {_scale_z_hint(kind, axis.unit_conversion_factor)}")
    return crs


def require_metre_elevations(unit: str | None, what: str, *, kind: str = "raster",
                             said: str = "its band's unit", of: str = "elevations") -> None:
    """Refuse ``what`` (a DEM, or point text: ``kind``) whose ``of`` (elevations, or x, y) are
    said (``said``: by its band's unit, GDAL's unit type, or its header) to be in a unit other
    than metres (``unit``: feet, centimetres, ``LENGTH_UNITS``, alone or before a datum's name:
    "ft NAVD88"), naming the conversion; no unit, or another word, is taken as metres."""
    key = (unit or "").strip().lower()
    factor = LENGTH_UNITS.get(key, LENGTH_UNITS.get(key.split(" ")[0]))
    if factor is not None:
        fix = _scale_z_hint(kind, factor) if of == "elevations" else _reproject_hint(kind)
        raise FloodMeshError(
            f"{what} has {of} in '{unit.strip()}' ({said}); FloodMesh works in metres: convert "
            f"them first, e.g. {fix}")


# A projected CRS's scale at the data may differ from true by this fraction: UTM zones and
# national grids stay within 0.1 %; Web Mercator's is 1.56 at 50° N, where its metre is 0.64 m
SCALE_TOLERANCE = 0.02


def check_scale(crs: CRS, x, y, what: str, kind: str | None = None) -> None:
    """Refuse data at map points ``x``, ``y`` (m; e.g. the data's corners and centre) far
    outside the area ``crs`` is used in (``check_area_of_use``), and a projected CRS whose
    scale there differs from true by more than ``SCALE_TOLERANCE``: slopes, areas and cell
    sizes would be off by as much. Points off the projection's domain are not judged."""
    # lazy: PROJ loads only when this runs
    from pyproj import Proj
    from pyproj.exceptions import CRSError, ProjError

    horizontal = horizontal_crs(crs)
    if not horizontal.is_projected:  # a local engineering CRS has no place on the earth
        return
    check_area_of_use(crs, x, y, what)
    try:
        projection = Proj(horizontal)
    except (CRSError, ProjError):  # a projection PROJ cannot run backwards: not judged
        return
    lon, lat = projection(np.asarray(x, float), np.asarray(y, float), inverse=True)
    factors = projection.get_factors(lon, lat, errcheck=False)
    scales = np.concatenate([np.atleast_1d(factors.meridional_scale),
                             np.atleast_1d(factors.parallel_scale)])
    scales = scales[np.isfinite(scales) & (scales > 0)]
    if not scales.size:
        return
    worst = float(scales[np.argmax(np.abs(np.log(scales)))])
    if abs(worst - 1.0) <= SCALE_TOLERANCE:
        return
    lon0, lat0 = float(np.nanmean(lon)), float(np.nanmean(lat))
    zone = int((lon0 + 180.0) // 6.0) % 60 + 1
    code = f"{326 if lat0 >= 0 else 327}{zone:02d}"
    raise FloodMeshError(
        f"{what} is in {crs.name}, whose metre is {1.0 / worst:.2f} m on the ground at the "
        f"data (scale {worst:.3f}): slopes, areas and cell sizes would be off by as much. "
        f"Reproject it to the UTM zone first, e.g. EPSG:{code} (WGS 84 / UTM zone {zone}"
        f"{'N' if lat0 >= 0 else 'S'}): {_reproject_hint(kind, code)}")


# How far data may lie beyond its CRS's area of use before it is refused: twice the area's
# larger side each way, at least 1,000 km; so a UTM zone's reaches past the equator and 10,000 km
# east and west, and eastings with the zone number before them (from zone 11 on: 11,000 km
# east) lie beyond it
AREA_MARGIN_SIDES, AREA_MARGIN_M = 2.0, 1_000_000.0
UTM_ZONE_PREFIX_M = 1_000_000.0  # a zone number written before the easting: zone 32 adds 32e6 m


def check_area_of_use(crs: CRS, x, y, what: str) -> None:
    """Refuse data at map points ``x``, ``y`` (m) far outside the area where the projected
    ``crs`` is used (its area of use, as EPSG gives it, widened by ``AREA_MARGIN_SIDES`` its
    larger side, at least ``AREA_MARGIN_M``, each way): coordinates in another CRS, or eastings
    with the UTM zone number before them. A CRS without an area of use (a custom or local one)
    is not judged."""
    horizontal = horizontal_crs(crs)
    area = _area_of_use(horizontal) if horizontal.is_projected else None
    if area is None:
        return
    name, (xmin, ymin, xmax, ymax) = area
    x, y = np.asarray(x, float), np.asarray(y, float)
    margin = max(AREA_MARGIN_M, AREA_MARGIN_SIDES * max(xmax - xmin, ymax - ymin))
    widened = (xmin - margin, ymin - margin, xmax + margin, ymax + margin)
    if _within(x, y, widened):
        return
    raise FloodMeshError(
        f"{what} lies at {extent_words(x.min(), y.min(), x.max(), y.max())}, far outside the "
        f"area where {crs.name} is used ({name}: {extent_words(xmin, ymin, xmax, ymax)}): "
        f"{_place_fix(horizontal, x, y, widened)}")


def extent_words(xmin: float, ymin: float, xmax: float, ymax: float) -> str:
    """A box (m) in words: 'x 500,000 to 500,080, y 5,700,000 to 5,700,060 m'."""
    return f"x {xmin:,.0f} to {xmax:,.0f}, y {ymin:,.0f} to {ymax:,.0f} m"


def _within(x: np.ndarray, y: np.ndarray, box) -> bool:
    """Whether all the points ``x``, ``y`` lie in ``box`` (xmin, ymin, xmax, ymax)."""
    return bool(box[0] <= x.min() and x.max() <= box[2] and box[1] <= y.min()
                and y.max() <= box[3])


# _area_of_use by the horizontal CRS's WKT: a PROJ transform each, and the same CRS is checked
# tile by tile
_AREAS: dict = {}
_AREAS_KEPT = 64


def _area_of_use(horizontal: CRS) -> tuple[str, tuple[float, ...]] | None:
    """(the name, the (xmin, ymin, xmax, ymax) m) of a projected CRS's area of use, from EPSG
    where its WKT names none (a GeoTIFF's WKT1); None where neither gives one. Found once per
    CRS (``_AREAS``)."""
    key = horizontal.to_wkt()
    if key is None:  # a CRS PROJ cannot write as WKT
        return _find_area_of_use(horizontal)
    area = _AREAS.get(key, _AREAS)  # (the dict itself: not found; None is an answer)
    if area is not _AREAS:
        return area
    area = _find_area_of_use(horizontal)
    if len(_AREAS) >= _AREAS_KEPT:
        _AREAS.clear()
    _AREAS[key] = area
    return area


def _find_area_of_use(horizontal: CRS) -> tuple[str, tuple[float, ...]] | None:
    """``_area_of_use`` found anew."""
    # lazy: PROJ loads only when this runs
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError, ProjError

    area = horizontal.area_of_use
    try:
        if area is None:
            authority = horizontal.to_authority(min_confidence=90)
            area = CRS.from_authority(*authority).area_of_use if authority else None
        if area is None:
            return None
        to_map = Transformer.from_crs(horizontal.geodetic_crs, horizontal, always_xy=True)
        box = to_map.transform_bounds(*area.bounds, densify_pts=21)
    except (CRSError, ProjError):
        return None
    if not np.all(np.isfinite(box)) or box[0] >= box[2] or box[1] >= box[3]:
        return None
    return area.name.split(":")[0].rstrip(". "), tuple(float(v) for v in box)


def _place_fix(horizontal: CRS, x: np.ndarray, y: np.ndarray, box) -> str:
    """The fix for data at ``x``, ``y`` outside a UTM zone's ``box`` (m): where the data fall
    in it once a zone number before the eastings (32 in 32,412,000) is taken off, the zone-
    prefixed CRS where EPSG has one; else the CRS the data are in."""
    # lazy: PROJ loads only when this runs
    from pyproj.database import query_crs_info
    from pyproj.enums import PJType

    zone = int(np.floor(np.median(x) / UTM_ZONE_PREFIX_M))
    if ("UTM zone" not in horizontal.name or not 1 <= zone <= 60
            or not _within(x - zone * UTM_ZONE_PREFIX_M, y, box)):
        return ("check its CRS and give the one its x, y are in (--crs EPSG:XXXX, or the CRS "
                "parameter in QGIS)")
    prefixed = re.sub(r"UTM zone \d+", f"UTM zone {zone}", horizontal.name) + " (zE-N)"
    codes = [f"EPSG:{c.code}" for c in query_crs_info(auth_name="EPSG",
                                                       pj_types=PJType.PROJECTED_CRS)
             if c.name == prefixed and not c.deprecated]
    give = (f"give the zone-prefixed CRS, --crs {codes[0]} ({prefixed}; or the CRS parameter in "
            "QGIS), or " if codes else "")
    return (f"its eastings look like they carry the UTM zone number before them ({zone} "
            f"before {np.median(x) - zone * UTM_ZONE_PREFIX_M:,.0f} m): {give}take "
            f"{zone * UTM_ZONE_PREFIX_M:,.0f} m off x first")


# how a library user gives the CRS of a Grid, a PointCloud or a Mesh (``require_metric_crs``)
GRID_CRS = 'Grid(values, transform, crs="EPSG:XXXX")'
CLOUD_CRS = 'PointCloud(xyz, crs="EPSG:XXXX")'
MESH_CRS = 'Mesh(nodes, triangles, crs="EPSG:XXXX")'


def metric_crs_at(crs, bounds, what: str, kind: str | None = None, *,
                  given: str | None = None) -> CRS:
    """``crs`` as a pyproj CRS where data of ``bounds`` (xmin, ymin, xmax, ymax; m) may be
    taken in it: in metres (``require_metric_crs``, ``given`` as there), true to scale there
    and not far outside its area of use (``check_scale``, at the box's corners and centre)."""
    crs = require_metric_crs(crs, what, kind, given=given)
    check_scale(crs, *corners_and_centre(*bounds), what, kind)
    return crs


def corners_and_centre(xmin: float, ymin: float, xmax: float, ymax: float):
    """(x, y) of a box's corners and centre, where ``check_scale`` looks."""
    x = np.array([xmin, xmax, xmin, xmax, (xmin + xmax) / 2])
    y = np.array([ymin, ymin, ymax, ymax, (ymin + ymax) / 2])
    return x, y


def check_transform(t: Affine, what: str = "the raster") -> None:
    """Refuse geotransforms that are not north-up with square cells, naming the GDAL fix."""
    if t.b != 0 or t.d != 0:
        raise FloodMeshError(
            f"{what} is rotated (its geotransform has rotation terms {t.b:g}, {t.d:g}): warp it "
            "to a north-up grid with square cells first (gdalwarp -tr D D IN OUT)")
    if t.e >= 0 or t.a <= 0:
        raise FloodMeshError(
            f"{what} is not north-up (pixel size {t.a:g} x {t.e:g}): warp it to a north-up grid "
            "first (gdalwarp -tr D D IN OUT)")
    if not np.isclose(t.a, -t.e, rtol=1e-6):
        raise FloodMeshError(
            f"{what} has cells that are not square ({t.a:g} x {-t.e:g} m): resample it to square "
            f"cells first (gdalwarp -tr D D IN OUT, e.g. D = {min(t.a, -t.e):g})")


# m: LiDAR DEMs have cells of centimetres to metres; cells under a millimetre are coordinates
# in degrees (or another unit) under a CRS that says metres
SMALLEST_DEM_CELL_M = 0.001
# cells each way a DEM's data must span to be meshed: the domain lies half a cell inside the
# outer cell centres and must exceed 4 cells (steps.mesh.domain_from_dem), which 3 x 3 does not
MIN_DEM_CELLS_ACROSS = 4


def check_dem_size(values: np.ndarray, cell_size: float, what: str) -> None:
    """Refuse a DEM (``values`` with NaN for nodata, cells of ``cell_size`` m) whose cells are
    far smaller than a LiDAR DEM's, a CRS or unit mistake, or whose data spans too few cells to
    mesh, saying how much ground its data covers."""
    valid = np.isfinite(values)
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    across = (cols[-1] - cols[0] + 1, rows[-1] - rows[0] + 1) if rows.size else (0, 0)
    width, height = across[0] * cell_size, across[1] * cell_size
    if cell_size < SMALLEST_DEM_CELL_M:
        raise FloodMeshError(
            f"{what} has cells of {cell_size:g} m, far smaller than a LiDAR DEM's (centimetres "
            f"to metres), so its data covers only {width:.3g} x {height:.3g} m: check its CRS "
            "and units (coordinates in degrees under a CRS in metres give such cells)")
    check_cells_across(across, (width, height), cell_size, f"the data of {what}",
                       "check that it is the right file")


def check_cells_across(cells: tuple[int, int], extent: tuple[float, float], cell_size: float,
                       what: str, fix: str) -> None:
    """Refuse ``what`` (a DEM's data, points to grid) spanning ``cells`` (columns, rows) of
    ``cell_size`` m over ``extent`` (width, height; m), fewer than ``MIN_DEM_CELLS_ACROSS``
    either way: too little to mesh; ``fix`` says what to do."""
    if min(cells) < MIN_DEM_CELLS_ACROSS:
        width, height = (round(float(e), 2) for e in extent)
        raise FloodMeshError(
            f"{what} covers only {width:g} x {height:g} m, fewer than {MIN_DEM_CELLS_ACROSS} "
            f"cells of {cell_size:g} m each way ({cells[0]} x {cells[1]}): too little to mesh; "
            f"{fix}")


def require_numbers(values, what: str, holding: str) -> None:
    """Refuse ``values`` (a ``Grid``'s, a ``PointCloud``'s) that are not a numpy array of numbers
    (a list, an object or text array), naming ``what`` and the fix."""
    dtype = getattr(values, "dtype", None)
    if not isinstance(values, np.ndarray) or dtype.kind not in "biuf":
        of = f" of {dtype}" if dtype is not None else ""
        raise FloodMeshError(f"{what} must be a numpy array of numbers ({holding}), got "
                             f"{type(values).__name__}{of}: give np.asarray(values, float)")


# What a grid or raster FloodMesh makes holds (``Grid.quantity``; in a file, the
# FLOODMESH_QUANTITY tag that ``io.write_raster`` writes): (description, unit, what it is in
# words, what made it). A grid without it holds elevations, or what the step given it is told
ELEVATION = "elevation"
QUANTITIES = {
    ELEVATION: ("elevation", "m", "elevations in metres", "FloodMesh's gridding"),
    "slope": ("slope", "degree", "a slope in degrees", "FloodMesh's slope step"),
    "log": ("Laplacian-of-Gaussian response", "m", "a Laplacian-of-Gaussian response in metres",
            "FloodMesh's slope step"),
    "breakpoints": ("breakpoints", "", "breakpoints (1) and other cells (0)",
                    "FloodMesh's breakpoint step"),
    "max_depth": ("maximum depth", "m", "a flood's maximum depth in metres", "FloodMesh's flood"),
    "max_stage": ("maximum water level", "m", "a flood's maximum water level in metres",
                  "FloodMesh's flood"),
    "max_speed": ("maximum speed", "m/s", "a flood's maximum speed in m/s", "FloodMesh's flood"),
    "arrival_s": ("arrival time", "s", "a flood's arrival times in seconds", "FloodMesh's flood"),
    "size_field": ("maximum triangle area", "m2", "a size field of triangle areas in m²",
                   "FloodMesh's flood"),
    "depth_difference": ("maximum depth difference", "m",
                         "two floods' maximum depth difference in metres",
                         "FloodMesh's flood comparison"),
    "extent_difference": ("extent difference", "", "two floods' extent difference codes",
                          "FloodMesh's flood comparison")}


def holds_instead(name: str, held: str, wanted: str) -> str:
    """``name`` holds what FloodMesh marked as ``held`` (a key of ``QUANTITIES``), not
    ``wanted`` (in words)."""
    return (f"{name} holds {QUANTITIES[held][2]}, as {QUANTITIES[held][3]} wrote it, not "
            f"{wanted}")


@dataclass(frozen=True)
class Grid:
    """A north-up raster with square cells: ``values`` (rows, cols), NaN where there is no data.

    ``transform`` maps (col, row) to map coordinates of the cell's upper-left corner, as in
    GDAL/rasterio; ``crs`` is a projected CRS in metres. Integer grids (breakpoints) have no NaN;
    their nodata cells are those given by ``valid`` when written.
    """

    values: np.ndarray
    transform: Affine
    crs: CRS
    quantity: str | None = None  # a key of QUANTITIES (the slope step's); None: elevations

    def __post_init__(self):
        require_numbers(self.values, "a Grid's values", "NaN for nodata")
        if self.values.ndim != 2:
            raise FloodMeshError(f"a grid must be 2-D, got {self.values.ndim}-D")
        if not isinstance(self.transform, Affine):
            raise FloodMeshError(
                f"a Grid's transform must be an affine.Affine, got {self.transform!r}: give "
                "Affine(d, 0, x_left, 0, -d, y_top), or Affine.from_gdal(*geotransform)")
        check_transform(self.transform)
        if self.quantity is not None and self.quantity not in QUANTITIES:
            raise FloodMeshError(f"a Grid's quantity is one of {', '.join(QUANTITIES)} or None "
                                 f"(elevations), got {self.quantity!r}")

    @property
    def cell_size(self) -> float:
        """Cell size d in metres."""
        return float(self.transform.a)

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape

    def with_values(self, values: np.ndarray, quantity: str | None = None) -> "Grid":
        """The same georeference with other values of the same shape, holding ``quantity``."""
        if values.shape != self.values.shape:
            raise ValueError(f"shape {values.shape} differs from the grid's {self.values.shape}")
        return Grid(values, self.transform, self.crs, quantity)

    def cell_centres(self, rows, cols) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates (x, y) of the centres of cells (rows, cols)."""
        t = self.transform
        x = t.c + (np.asarray(cols) + 0.5) * t.a
        y = t.f + (np.asarray(rows) + 0.5) * t.e
        return x, y

    def fractional_index(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) as floats of map points, with cell centres at whole numbers."""
        t = self.transform
        col = (np.asarray(x) - t.c) / t.a - 0.5
        row = (np.asarray(y) - t.f) / t.e - 0.5
        return row, col

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the cell edges."""
        t = self.transform
        rows, cols = self.shape
        return t.c, t.f + rows * t.e, t.c + cols * t.a, t.f


def nearest_value(grid: Grid, x, y) -> np.ndarray:
    """The grid's value in the cell holding each map point (NaN outside the grid)."""
    r, c = grid.fractional_index(x, y)
    r, c = np.rint(r).astype(np.int64), np.rint(c).astype(np.int64)
    inside = (r >= 0) & (r < grid.shape[0]) & (c >= 0) & (c < grid.shape[1])
    out = np.full(np.shape(r), np.nan)
    out[inside] = grid.values[r[inside], c[inside]]  # the cells', not the grid's, as floats
    return out


def bilinear(grid: Grid, x, y) -> np.ndarray:
    """Elevation at map points by bilinear interpolation between cell centres.

    Points beyond the outer cell centres take the nearest edge values; NaN neighbours are left
    out and the remaining weights renormalised, so only points with no valid neighbour get NaN.
    """
    z = grid.values
    rows, cols = z.shape
    r, c = grid.fractional_index(x, y)
    r = np.clip(r, 0, rows - 1)
    c = np.clip(c, 0, cols - 1)
    r0 = np.minimum(np.floor(r).astype(np.int64), max(rows - 2, 0))
    c0 = np.minimum(np.floor(c).astype(np.int64), max(cols - 2, 0))
    r1 = np.minimum(r0 + 1, rows - 1)
    c1 = np.minimum(c0 + 1, cols - 1)
    fr = r - r0
    fc = c - c0
    total = np.zeros(np.shape(r))
    weight = np.zeros(np.shape(r))
    for rr, cc, w in ((r0, c0, (1 - fr) * (1 - fc)), (r0, c1, (1 - fr) * fc),
                      (r1, c0, fr * (1 - fc)), (r1, c1, fr * fc)):
        v = z[rr, cc]
        ok = np.isfinite(v)
        total += np.where(ok, v, 0.0) * w
        weight += np.where(ok, w, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / weight
    # A point exactly on a NaN-free side can get zero total weight only if every neighbour is NaN.
    return np.where(weight > 1e-12, out, np.nan)


_AROUND = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)


def inner_cells(values: np.ndarray) -> np.ndarray:
    """Flat indices of the valid cells whose eight neighbours are valid too: cells that can be
    taken out of the data and filled from around without moving its edge."""
    valid = np.isfinite(values)
    rows, cols = valid.shape
    inner = np.zeros_like(valid)
    if rows > 2 and cols > 2:
        middle = valid[1:-1, 1:-1].copy()
        for dr, dc in _AROUND:
            middle &= valid[1 + dr:rows - 1 + dr, 1 + dc:cols - 1 + dc]
        inner[1:-1, 1:-1] = middle
    return np.flatnonzero(inner)


def fill_from_around(values: np.ndarray, cells: np.ndarray) -> None:
    """Replace the flat ``cells`` of ``values`` (``inner_cells``) in place by linear
    interpolation from the neighbours not among them, as a TIN of the other data would: the
    midpoint of the opposite pair (across, up and down, or a diagonal) that differ least, the
    one along a wall or bank rather than across it (a mean of all would put a ramp's height at
    a wall's foot), else the mean of the neighbours known; cells beside others are filled
    pass by pass, those with the most pairs known first."""
    values.flat[cells] = np.nan
    pending = np.asarray(cells)
    while pending.size:
        r, c = np.divmod(pending, values.shape[1])
        pairs = np.stack([(values[r + dr, c + dc], values[r - dr, c - dc])
                          for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1))])  # (4, 2, n)
        step = np.abs(pairs[:, 0] - pairs[:, 1])
        steady = np.argmin(np.where(np.isfinite(step), step, np.inf), axis=0)
        estimate = pairs[steady, :, np.arange(len(r))].mean(axis=1)
        around = np.stack([values[r + dr, c + dc] for dr, dc in _AROUND])
        known = np.isfinite(around)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(known, around, 0.0).sum(axis=0) / known.sum(axis=0)
        estimate = np.where(np.isfinite(estimate), estimate, mean)
        known_pairs = np.isfinite(step).sum(axis=0)
        filled = np.isfinite(estimate) & (known_pairs == known_pairs.max())
        if not filled.any():  # every pending cell walled in by pending ones: no inner cells
            raise FloodMeshError("cells to fill have no data around them")
        values[r[filled], c[filled]] = estimate[filled]
        pending = pending[~filled]


def step_grid(grid, what: str, holds: str | None = None,
              fix: str | None = None) -> None:
    """Refuse ``grid`` where a step takes it as ``what``, holding ``holds`` (a key of
    ``QUANTITIES``, else in words; None: elevations), as the readers refuse a file: not a
    ``Grid``, without cells, in a CRS not in metres or far from true scale or its area of use
    there (``require_metric_crs``, ``check_scale``), or holding another quantity (``fix``
    said; default: give the DEM, not its slope or what else it holds)."""
    if not isinstance(grid, Grid):
        raise FloodMeshError(f"{what} must be a Grid, got {type(grid).__name__}: give "
                             "Grid(values, transform, crs), as grid_points returns")
    if not grid.values.size:
        raise FloodMeshError(f"{what} has no cells (shape {grid.shape}): give a grid with data")
    held = None if grid.quantity == ELEVATION else grid.quantity
    if held != holds and held is not None:
        wanted = QUANTITIES[holds][2] if holds in QUANTITIES else holds or "elevations"
        fix = fix or f"give the DEM (what grid_points returns), not its {QUANTITIES[held][0]}"
        raise FloodMeshError(f"{holds_instead(what, held, wanted)}: {fix}")
    metric_crs_at(grid.crs, grid.bounds, what, "raster", given=GRID_CRS)


def lines_near(lines, bounds, what: str, where: str) -> None:
    """Refuse any of ``lines`` ((k, 2|3) arrays, named ``what``) lying wholly beyond ``bounds``
    (xmin, ymin, xmax, ymax; m; of ``where``, e.g. "the DEM") widened by their larger side
    each way: a line of another place or CRS, not one drawn a little past the data (which the
    step leaves out with a note); and lines of other than numbers. Lines without finite x, y
    are left to the step."""
    xmin, ymin, xmax, ymax = bounds
    margin = max(xmax - xmin, ymax - ymin)
    for k, line in enumerate(lines):
        try:
            xy = np.asarray(line, float)
        except (TypeError, ValueError):
            raise FloodMeshError(f"{what} {k + 1} must be an array of numbers, x, y (and z) a "
                                 f"row, got {type(line).__name__} {str(line)[:40]}") from None
        xy = xy[:, :2] if xy.ndim == 2 and xy.shape[1] >= 2 else np.empty((0, 2))
        xy = xy[np.isfinite(xy).all(axis=1)]  # own lines' z is NaN where they are 2-D
        if len(xy) and (xy[:, 0].max() < xmin - margin or xy[:, 0].min() > xmax + margin
                        or xy[:, 1].max() < ymin - margin or xy[:, 1].min() > ymax + margin):
            low, high = xy.min(axis=0), xy.max(axis=0)
            raise FloodMeshError(
                f"{what} {k + 1} lies at {extent_words(*low, *high)}, far from {where} at "
                f"{extent_words(*bounds)}: give lines in {where}'s CRS, of its place")


def one_place(grid: Grid, other: Grid, what: str, other_what: str, fix: str) -> None:
    """Refuse grids ``grid`` and ``other`` (named ``what``, ``other_what``) that a step combines
    cell by cell but that do not lie on the same cells in one CRS: a shape alike is not a place
    alike."""
    crs, other_crs = parse_crs(grid.crs, what), parse_crs(other.crs, other_what)
    alike = same_place(crs, other_crs)
    if alike and grid.shape == other.shape and grid.transform.almost_equals(other.transform):
        return
    raise FloodMeshError(
        f"{what} lies at {extent_words(*grid.bounds)}{'' if alike else f' in {crs.name}'}, "
        f"{other_what} at {extent_words(*other.bounds)}"
        f"{'' if alike else f' in {other_crs.name}'}, not on the same cells: {fix}")


def usable_dem(dem: Grid, what: str = "the DEM", note=None) -> Grid:
    """``dem`` itself where every cell is NaN (nodata) or an elevation some ground has; else a
    float copy (an integer band's too) whose other cells (-9999, inf and the like) are NaN, as
    a DEM file's are when read (``drop_implausible``, ``note`` told): the rule where a ``Grid``
    enters a step, after ``step_grid``'s checks."""
    step_grid(dem, what)
    values = np.asarray(dem.values)
    if values.dtype.kind not in "fiu" or not values.size:
        return dem
    # the least and greatest cell past NaN, in two passes without a full-size temporary: a
    # cleaned DEM (the pipeline's, each refine round's) costs one read of its cells
    least, greatest = np.fmin.reduce(values, axis=None), np.fmax.reduce(values, axis=None)
    if not (least < LOWEST_GROUND_M or greatest > HIGHEST_GROUND_M):
        return dem
    values = values.astype(np.result_type(values.dtype, np.float32))  # a copy that holds NaN
    drop_implausible(values, what, None, note)
    if not np.isfinite(values).any():
        raise FloodMeshError(f"{what} has no cell with an elevation some ground has (between "
                             f"{LOWEST_GROUND_M:g} and {HIGHEST_GROUND_M:g} m): check its values")
    return dem.with_values(values)


def _implausible(values: np.ndarray) -> np.ndarray:
    """Which cells hold an elevation no ground has (inf included); NaN cells do not."""
    return (values < LOWEST_GROUND_M) | (values > HIGHEST_GROUND_M)


def drop_implausible(values: np.ndarray, what: str, file: str | None, note=None) -> None:
    """Set to NaN, in place, the cells of a DEM's ``values`` (m) below ``LOWEST_GROUND_M`` or
    above ``HIGHEST_GROUND_M``: no ground lies there, they hold a no-data value that no tag
    names. ``note`` is told (``implausible_note``: ``what``, ``file``)."""
    outside = _implausible(values)
    count = int(np.count_nonzero(outside))
    if count:
        held = values[outside]
        if note:
            note(implausible_note(what, file, count, float(held.min()), float(held.max())))
        values[outside] = np.nan


def implausible_note(what: str, file: str | None, count: int, least: float,
                     greatest: float) -> str:
    """The note on ``count`` cells of ``what`` (``dem_file``, or the DEM tiles) holding
    ``least`` to ``greatest``, beyond any ground, taken as nodata; ``file`` the name to tag
    (None: an in-memory ``Grid``)."""
    value = f"{least:g}" if least == greatest else "VALUE"
    held = f"{value}, an elevation" if least == greatest else \
        f"{least:g} to {greatest:g}, elevations"
    fix = ("set them to NaN in the Grid's values to say so" if file is None else
           f"tag that value in the file to say so (gdal_edit.py -a_nodata {value} {file})")
    return (f"{what}: {count:,} cells hold {held} no ground has (below {LOWEST_GROUND_M:g} m "
            f"or above {HIGHEST_GROUND_M:g} m): they are taken as nodata; {fix}")
