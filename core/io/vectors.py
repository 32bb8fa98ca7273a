"""Vector layers through fiona (OGR): GeoPackage layers of lines, points and polygons written
(``write_gpkg`` and the writers on it), and lines, regions, a domain boundary and points read
from any vector file OGR reads."""
from __future__ import annotations

import contextlib

import numpy as np

from ..errors import FloodMeshError
from .outputs import atomic_output, require_file

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


def gpkg_field_type(values) -> str:
    """The GeoPackage field type (fiona's "int", "float" or "str") of a column of values."""
    kind = np.asarray(values).dtype.kind
    return {"i": "int", "u": "int", "b": "int", "f": "float"}.get(kind, "str")


RECORD_CHUNK = 20_000  # features turned into Python objects at a time, for fiona to write


def gpkg_records(geometries, attributes: dict):
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
    props = {name: gpkg_field_type(v) for name, v in attributes.items()}
    write_gpkg(path, layer, "3D LineString", props, gpkg_records(geometries, attributes), crs,
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
    props = {name: gpkg_field_type(v) for name, v in attributes.items()}
    write_gpkg(path, layer, "3D Point", props, gpkg_records(geometries, attributes), crs,
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
