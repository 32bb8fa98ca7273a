"""The keys a flood scenario (JSON) may hold at each of its levels, and the check that refuses
any other: a misspelt optional key (``initial_stage`` for ``initial_stage_m``) would otherwise
leave its default in force without a word, and the flood run would be another one. Standard
library only."""
from __future__ import annotations

import difflib

from ..errors import FloodMeshError

SCENARIO = ("duration_s", "output_interval_s", "manning", "inflows", "boundaries", "roughness",
            "buildings", "initial_stage_m", "wet_depth_m", "unstable_speed_m_s",
            "observation_points", "cell_size_m")
INFLOW = ("region", "line", "circle", "discharge_m3s", "hydrograph")
BOUNDARY = ("kind", "sides", "line", "level_m", "levels", "snap_m")
ROUGHNESS = ("polygons", "file", "manning")
BUILDINGS = ("polygons", "mode", "height_m")
POINT = ("name", "x", "y")
CIRCLE = ("centre", "radius")
SHAPES = ("file", "circle")  # polygons given as an object instead of coordinates
# names modellers give a key that difflib does not find: Manning's n, a discharge Q
SYNONYMS = {"n": "manning", "mannings_n": "manning", "q": "discharge_m3s",
            "q_m3s": "discharge_m3s", "flow_m3s": "discharge_m3s", "center": "centre"}
RAIN = ("rain is not supported: give it as an inflow into the catchment's region, a "
        "discharge_m3s of intensity (mm/h) × area (m²) / 3,600,000, or a hydrograph of it")
DOCS = "see docs/user-guide.md, The scenario"
COMMENT = "_"  # JSON has no comments: a key beginning with it ("_comment", "_source") is one


def check_keys(data) -> None:
    """Refuse a scenario (its parsed JSON) holding a key FloodMesh does not read, at any level:
    one error naming each such key, where it is, the closest known key and the keys known
    there. Also refuses levels of the wrong kind (a list where an object belongs)."""
    found = []
    _unknown(_object(data, "the scenario"), SCENARIO, "at its top level", found)
    for k, item in enumerate(entries(data, "inflows", "inflow")):
        where = f"inflow {k + 1}"
        _unknown(item, INFLOW, f"in {where}", found)
        for key in ("region", "line"):
            _shape(item.get(key), f"in {where}'s {key}", found)
        if "circle" in item:
            _unknown(_object(item["circle"], f"{where}'s circle"), CIRCLE,
                     f"in {where}'s circle", found)
    for k, item in enumerate(entries(data, "boundaries", "boundary")):
        _unknown(item, BOUNDARY, f"in boundary {k + 1}", found)
    for k, item in enumerate(entries(data, "roughness", "roughness zone")):
        where = f"roughness zone {k + 1}"
        _unknown(item, ROUGHNESS, f"in {where}", found)
        _shape(item.get("polygons"), f"in {where}'s polygons", found)
    if data.get("buildings") is not None:
        buildings = _object(data["buildings"], "the scenario's buildings")
        _unknown(buildings, BUILDINGS, "in the buildings", found)
        _shape(buildings.get("polygons"), "in the buildings' polygons", found)
    for k, item in enumerate(entries(data, "observation_points", "observation point")):
        _unknown(item, POINT, f"in observation point {k + 1}", found)
    if found:
        raise FloodMeshError(f"the scenario holds {'a key' if len(found) == 1 else 'keys'} "
                             f"FloodMesh does not read: {'; '.join(found)} ({DOCS})")


def entries(data: dict, key: str, what: str) -> list:
    """``data[key]``, a list of objects (none: []), or an error saying what it must be."""
    value = data.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise FloodMeshError(f"the scenario's {key} must be a list of objects "
                             f"([{{...}}, ...], one {what} each), got {_kind(value)}")
    for k, item in enumerate(value):
        _object(item, f"{what} {k + 1}")
    return value


def _object(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise FloodMeshError(f"{where} must be an object ({{\"key\": value, ...}}), got "
                             f"{_kind(value)} ({DOCS})")
    return value


def _kind(value) -> str:
    return {list: "a list", dict: "an object", str: f"the text {value!r}"}.get(
        type(value), f"{value!r}")


def _shape(spec, where: str, found: list) -> None:
    """Polygons given as an object: {"file": ...} or {"circle": {"centre", "radius"}}."""
    if isinstance(spec, dict):
        _unknown(spec, SHAPES, where, found)
        if isinstance(spec.get("circle"), dict):
            _unknown(spec["circle"], CIRCLE, f"{where}'s circle", found)


def _unknown(entry: dict, known: tuple, where: str, found: list) -> None:
    for key in entry:
        if key in known or str(key).startswith(COMMENT):
            continue
        if "rain" in str(key).lower() or "precip" in str(key).lower():
            found.append(f"{key!r} {where}: {RAIN}")
            continue
        close = ([SYNONYMS[str(key).lower()]] if SYNONYMS.get(str(key).lower()) in known
                 else difflib.get_close_matches(str(key), known, n=1, cutoff=0.6))
        hint = f"did you mean {close[0]!r}? " if close else ""
        found.append(f"{key!r} {where} ({hint}it takes {', '.join(known)})")
