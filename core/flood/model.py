"""A flood on the mesh: ANUGA (Geoscience Australia's finite-volume shallow-water solver on
triangles, flow algorithm DE0) run on a FloodMesh mesh with a scenario, and its results as
layers a modeller reads.

ANUGA 4 needs numpy >= 2, which Debian 12's QGIS stack (numpy 1.24) cannot share a process
with, so ANUGA runs as a child process in its own environment (``.venv-flood``, made by
``scripts/setup.sh``; or ``FLOODMESH_FLOOD_PYTHON``): ``anuga_worker.py`` reads the prepared
mesh and scenario, runs, and writes per-triangle maxima and time series; this module does all
geometry before (boundary tags, roughness, buildings, inflow regions) and all output after
(GeoTIFFs in the mesh's CRS, the outflow hydrograph, the mass balance).
"""
from __future__ import annotations

import csv
import glob
import json
import os
import queue
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from .. import io
from ..engine.arrays import boundary_edges, edge_nodes, spatial_order
from ..engine.progress import poll
from ..errors import FloodMeshError
from ..io.outputs import check_output_folder, staged_folder
from ..options import DRY_BELOW_M, RESULT_RASTERS
from ..raster import Grid, require_metric_crs
from ..steps.hydraulics import collinear_wall_stencils, hydraulic_checks, inradii, neighbours
from .scenario_keys import check_keys, entries

BOUNDARY_KINDS = ("wall", "outflow", "level")
SIDES = ("north", "south", "east", "west")
BUILDING_MODES = ("raised", "holes")
WORKER = Path(__file__).with_name("anuga_worker.py")
FLOOD_FILES = tuple(RESULT_RASTERS.values()) + ("hydrograph.csv", "observations.csv",
                                                "time_step.gpkg", "triangles.npz", "report.json")
# what floodmesh flood --size-field-area writes beside them, for a second mesh: gone from the
# folder with the flood it came from
FLOW_FIELD_FILES = ("size_field.tif", "wet_zone.gpkg")
SETTER_FIELDS = ("inradius_m", "share_of_steps", "checks", "max_depth_m", "max_speed_ms")
# a mass balance's error is given as a share only of volumes above this depth over the mesh
# (m): a thinner film is below any depth a flood reports (wet_depth_m, the worker's 1 cm
# for speeds), so the share of its volume measures round-off, not the flood
FILM_M = 0.001


# ---------------------------------------------------------------------------------------------
# the scenario: plain data, checked when made
@dataclass(frozen=True)
class Inflow:
    """A discharge into a region (polygon, ≥ 3 points) or across a line (2 points), in m³/s:
    constant, or a hydrograph of (time s, discharge m³/s) rows, linear between them."""

    region: tuple
    discharge_m3s: float | None = None
    hydrograph: tuple = ()


@dataclass(frozen=True)
class Boundary:
    """A kind (wall, outflow, level) for the boundary edges on given ``sides`` (by outward
    normal: north, south, east, west; "all" for every edge) or within ``snap`` m of a
    ``line``. Later boundaries override earlier ones; what none names is a wall."""

    kind: str
    sides: tuple = ()
    line: tuple = ()
    level_m: float | None = None
    snap_m: float = 1.0
    levels: tuple = ()   # a level hydrograph ((time s, level m), ...) instead of level_m


@dataclass(frozen=True)
class Buildings:
    """Building footprints: raised ``height_m`` above the ground (their nodes lifted) or left
    out of the mesh as holes with walls."""

    polygons: tuple = ()
    mode: str = "raised"
    height_m: float = 3.0


@dataclass(frozen=True)
class Scenario:
    """What to simulate on a mesh. Coordinates in the mesh's CRS (m), times in s."""

    duration_s: float
    inflows: tuple = ()
    boundaries: tuple = ()
    manning: float = 0.04
    roughness: tuple = ()             # ((polygon coords, n), ...), later ones win
    buildings: Buildings = field(default_factory=Buildings)
    initial_stage_m: float | None = None  # a level of still water (None: dry)
    output_interval_s: float = 10.0
    wet_depth_m: float = 0.05         # flooded above this depth (extent, arrival time)
    unstable_speed_m_s: float = 20.0  # water this fast (deeper than wet) stops the run
    observation_points: tuple = ()    # ((name, x, y), ...)
    cell_size_m: float | None = None  # of the result rasters (None: from the mesh)
    input_files: tuple = ()           # the files it was read from (never written over)

    def __post_init__(self):
        positive = {"duration": self.duration_s, "output interval": self.output_interval_s,
                    "wet depth": self.wet_depth_m, "Manning's n": self.manning,
                    "unstable speed": self.unstable_speed_m_s,
                    "buildings' height": self.buildings.height_m}
        for what, value in positive.items():
            if not (value is not None and np.isfinite(value) and value > 0):
                raise FloodMeshError(f"the scenario's {what} must be above 0, got {value}")
        if self.output_interval_s > self.duration_s:
            raise FloodMeshError(f"the scenario's output interval ({self.output_interval_s} s) "
                                 f"is longer than its duration ({self.duration_s} s)")
        names = [name for name, _, _ in self.observation_points]
        for k, name in enumerate(names):
            if name in names[:k]:
                raise FloodMeshError(f"observation points {names.index(name) + 1} and {k + 1} "
                                     f"are both named {name!r}: give each its own name")
        for k, inflow in enumerate(self.inflows, 1):
            if len(inflow.region) < 2:
                raise FloodMeshError(f"inflow {k} needs a line (2 points) or a region (3 or "
                                     "more points, or a circle)")
            if inflow.discharge_m3s is None and not inflow.hydrograph:
                raise FloodMeshError(f"inflow {k} has no discharge: give it a discharge_m3s "
                                     "(m³/s) or a hydrograph (a CSV of time s, m³/s, or "
                                     "[[t, q], ...])")
            if inflow.discharge_m3s is not None and inflow.hydrograph:
                raise FloodMeshError(f"inflow {k} has both a discharge_m3s and a hydrograph: "
                                     "give one")
        for b in self.boundaries:
            if b.kind not in BOUNDARY_KINDS:
                raise FloodMeshError(f"boundary kind {b.kind!r} is not one of "
                                     f"{', '.join(BOUNDARY_KINDS)}")
            if b.kind == "level" and b.level_m is None and not b.levels:
                raise FloodMeshError("a level boundary needs its water level (level_m, or levels: "
                                     "[[time s, level m], ...])")
            bad = [s for s in b.sides if s not in SIDES + ("all",)]
            if bad or (not b.sides and len(b.line) < 2):
                raise FloodMeshError(f"a boundary needs sides ({', '.join(SIDES)} or all) or a "
                                     f"line of 2 or more points; got sides {list(b.sides)}")
        if self.buildings.mode not in BUILDING_MODES:
            raise FloodMeshError(f"buildings mode {self.buildings.mode!r} is not raised or "
                                 "holes")
        for _, n in self.roughness:
            if not n > 0:
                raise FloodMeshError(f"a roughness polygon has Manning's n {n}; it must be > 0")


def scenario_notes(scenario: Scenario) -> list[str]:
    """What a scenario asks that is legal but may not be meant: an inflow below 0 (m³/s)."""
    notes = []
    for k, inflow in enumerate(scenario.inflows, 1):
        rates = ([inflow.discharge_m3s] if inflow.discharge_m3s is not None
                 else [q for _, q in inflow.hydrograph])
        if min(rates) < 0:
            notes.append(f"inflow {k} has a discharge below 0 ({min(rates):g} m³/s): it takes "
                         "water out, and only where there is some (none from dry ground); the "
                         "mass balance's inflow_volume_m3 says how much it took")
    return notes


def _polygon_list(spec, base: Path, where: str = "the scenario") -> list:
    """Polygons from a scenario entry: a list of coordinate lists, or {"file": …} naming a
    vector file or a glob of x,y CSV files (one polygon each, a header row allowed)."""
    if isinstance(spec, dict) and "file" in spec:
        pattern = str(base / spec["file"])
        paths = sorted(glob.glob(pattern))
        if not paths:
            raise FloodMeshError(f"{where} names {spec['file']}, which matches no file "
                                 f"beside the scenario ({base.resolve()}): check the path")
        polygons = []
        for path in paths:
            if path.lower().endswith((".csv", ".txt")):
                polygons.append(_read_xy_csv(path, f"{where}'s file"))
            else:
                # lazy: GEOS loads only when this runs
                import shapely
                for geometry, _ in io.read_regions(path):
                    for part in getattr(geometry, "geoms", [geometry]):
                        polygons.append(shapely.get_coordinates(part.exterior))
        return polygons
    if isinstance(spec, dict) and "circle" in spec:
        return [_circle(spec["circle"], f"{where}'s circle")]
    if not isinstance(spec, list):
        raise FloodMeshError(f"{where} must be a list of polygons ([[[x, y], ...], ...]), "
                             f"{{\"file\": ...}} or {{\"circle\": ...}}, got {spec!r:.60}")
    return [_points(p, f"polygon {k + 1} of {where}", 3) for k, p in enumerate(spec)]


def _points(value, where: str, least: int) -> np.ndarray:
    """(k, 2+) finite coordinates from a list of [x, y] points, at least ``least`` of them."""
    try:
        xy = np.asarray(value, float)
    except (TypeError, ValueError):
        xy = np.empty(0)
    if xy.ndim != 2 or xy.shape[1] < 2 or len(xy) < least or not np.isfinite(xy).all():
        raise FloodMeshError(f"{where} must be a list of {least} or more [x, y] points, got "
                             f"{value!r:.60}")
    return xy


def _read_xy_csv(path, what: str = "the polygon file", columns: str = "x, y",
                 exact: bool = False) -> np.ndarray:
    """The rows of a CSV of two numbers a line (``columns``; more with ``exact`` False): a
    header line first allowed, blank lines skipped; ``what`` names it in errors (the
    scenario's key that names the file)."""
    path = Path(path)
    if path.is_dir():
        raise FloodMeshError(f"{what} names {path.name}, a folder: name a CSV file of {columns}")
    if not path.is_file():
        raise FloodMeshError(f"{what} names {path.name}, which does not exist in "
                             f"{path.parent.resolve()}: check the path (a scenario's file "
                             "names are relative to its folder)")
    rows = []
    try:
        with open(path, newline="") as fh:
            for line, row in enumerate(csv.reader(fh), 1):
                if not "".join(row).strip():
                    continue
                try:
                    values = [float(v) for v in row]
                except ValueError:
                    if not rows and line == 1:
                        continue  # a header
                    values = []
                if len(values) < 2 or (exact and len(values) > 2) or \
                        not np.isfinite(values).all():
                    raise FloodMeshError(
                        f"{what}, {path.name}, has {','.join(row)!r} on line {line}: each "
                        f"line must be {columns}, {len(columns.split(','))} comma-separated "
                        "numbers (a header line first allowed)")
                rows.append(values[:2])
    except (OSError, UnicodeDecodeError) as exc:
        raise FloodMeshError(f"{what}, {path.name}, cannot be read as text "
                             f"({getattr(exc, 'strerror', None) or exc}): give a CSV of "
                             f"{columns}") from None
    if len(rows) < 2:
        raise FloodMeshError(f"{what}, {path.name}, holds fewer than 2 rows of {columns}")
    return np.array(rows)


def _series(value, base: Path, what: str, columns: str) -> tuple:
    """((time s, value), ...) from a CSV file name or a list of pairs, times increasing."""
    if isinstance(value, str):
        rows = _read_xy_csv(base / value, what, columns, exact=True)
    else:
        try:
            rows = np.asarray(value, float)
        except (TypeError, ValueError):
            rows = np.empty(0)
        if rows.ndim != 2 or rows.shape[1] != 2 or len(rows) < 2 or \
                not np.isfinite(rows).all():
            raise FloodMeshError(f"{what} must be a CSV file name or a list of 2 or more "
                                 f"[{columns}] pairs, got {value!r:.60}")
    late = np.flatnonzero(np.diff(rows[:, 0]) <= 0)
    if len(late):
        k = int(late[0]) + 1
        named = f"{what}, {value}," if isinstance(value, str) else what
        raise FloodMeshError(f"the times in {named} must increase from row to row: row "
                             f"{k + 1} ({rows[k, 0]:g} s) follows row {k} ({rows[k - 1, 0]:g} s)")
    return tuple(map(tuple, rows))


def _circle(spec, where: str = "a circle", n: int = 32) -> np.ndarray:
    if not isinstance(spec, dict) or "centre" not in spec or "radius" not in spec:
        raise FloodMeshError(f"{where} must be {{\"centre\": [x, y], \"radius\": m}}, got "
                             f"{spec!r:.60}")
    (cx, cy), = _points([spec["centre"]], f"{where}'s centre", 1)[:, :2]
    r = _number(spec, "radius", where, positive=True)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)])


_REQUIRED = object()


def _number(entry: dict, key: str, where: str, default=_REQUIRED, positive: bool = False):
    """``entry[key]`` as a finite float (above 0 with ``positive``); ``default`` when it is
    absent or null, an error naming it where there is none."""
    value = entry.get(key)
    if value is None:
        if default is _REQUIRED:
            raise FloodMeshError(f"{where} lacks {key!r}: see the scenario example in "
                                 "docs/user-guide.md")
        return default
    try:
        number = float(value) if not isinstance(value, (bool, list, dict)) else np.nan
    except ValueError:
        number = np.nan
    if not np.isfinite(number) or (positive and number <= 0):
        raise FloodMeshError(f"{where}'s {key} must be a{' positive' * positive} number, got "
                             f"{value!r:.60}")
    return number


def _region(item: dict, where: str, base: Path) -> tuple:
    """An inflow's region (polygon), circle or line (2 points) as coordinates."""
    given = [key for key in ("region", "line", "circle") if item.get(key) is not None]
    if len(given) != 1:
        raise FloodMeshError(f"{where} needs one of region (a polygon), circle or line (2 "
                             f"points) to flow into; it has {' and '.join(given) or 'none'}")
    spec = item[given[0]]
    if given[0] == "circle":
        return tuple(map(tuple, _circle(spec, f"{where}'s circle")))
    if isinstance(spec, dict):
        polygons = _polygon_list(spec, base, f"{where}'s {given[0]}")
        if len(polygons) != 1:
            raise FloodMeshError(f"{where}'s {given[0]} holds {len(polygons)} polygons; an "
                                 "inflow flows into one: give each its own inflow")
        return tuple(map(tuple, polygons[0][:, :2]))
    xy = _points(spec, f"{where}'s {given[0]}", 2 if given[0] == "line" else 3)
    if given[0] == "line" and len(xy) != 2:
        raise FloodMeshError(f"{where}'s line has {len(xy)} points; an inflow line has 2 "
                             "(its ends): give a polygon as region instead")
    return tuple(map(tuple, xy[:, :2]))


def _inflow(item: dict, where: str, base: Path) -> Inflow:
    hydrograph = item.get("hydrograph")
    return Inflow(_region(item, where, base), _number(item, "discharge_m3s", where, None),
                  () if hydrograph is None else
                  _series(hydrograph, base, f"{where}'s hydrograph", "time s, m³/s"))


def _boundary(item: dict, where: str, base: Path) -> Boundary:
    if "kind" not in item:
        raise FloodMeshError(f"{where} lacks 'kind' ({', '.join(BOUNDARY_KINDS)})")
    sides = item.get("sides") or []
    if not isinstance(sides, (str, list)):
        raise FloodMeshError(f"{where}'s sides must be a list of sides ({', '.join(SIDES)} or "
                             f"all), got {sides!r:.60}")
    levels = item.get("levels")
    return Boundary(str(item["kind"]), (sides,) if isinstance(sides, str) else tuple(sides),
                    tuple(map(tuple, _points(item["line"], f"{where}'s line", 2)))
                    if item.get("line") is not None else (),
                    _number(item, "level_m", where, None),
                    _number(item, "snap_m", where, 1.0, positive=True),
                    () if levels is None else
                    _series(levels, base, f"{where}'s levels", "time s, level m"))


def _roughness(zone: dict, where: str, base: Path) -> list:
    n = _number(zone, "manning", where, positive=True)
    if "file" in zone:
        polygons = _polygon_list(zone, base, where)
    elif zone.get("polygons") is not None:
        polygons = _polygon_list(zone["polygons"], base, f"{where}'s polygons")
    else:
        raise FloodMeshError(f"{where} needs its polygons ([[[x, y], ...], ...]) or a file")
    return [(tuple(map(tuple, polygon)), n) for polygon in polygons]


def scenario_from_dict(data: dict, base=".") -> Scenario:
    """A Scenario from its JSON form (see docs/user-guide.md, The scenario); file names are
    relative to ``base``. A key it does not read, at any level, is an error."""
    base = Path(base)
    check_keys(data)
    try:
        inflows = tuple(_inflow(item, f"inflow {k + 1}", base)
                        for k, item in enumerate(entries(data, "inflows", "inflow")))
        boundaries = tuple(_boundary(item, f"boundary {k + 1}", base)
                           for k, item in enumerate(entries(data, "boundaries", "boundary")))
        roughness = tuple(polygon for k, zone in enumerate(
            entries(data, "roughness", "roughness zone"))
            for polygon in _roughness(zone, f"roughness zone {k + 1}", base))
        b = data.get("buildings") or {}
        buildings = Buildings(tuple(tuple(map(tuple, p)) for p in
                                    (_polygon_list(b["polygons"], base, "the buildings' "
                                                   "polygons") if "polygons" in b else [])),
                              b.get("mode", "raised"),
                              _number(b, "height_m", "the buildings", 3.0))
        points = tuple((str(p.get("name", k + 1)), _number(p, "x", f"observation point {k + 1}"),
                        _number(p, "y", f"observation point {k + 1}"))
                       for k, p in enumerate(entries(data, "observation_points",
                                                     "observation point")))
        where = "the scenario"
        return Scenario(duration_s=_number(data, "duration_s", where), inflows=inflows,
                        boundaries=boundaries, manning=_number(data, "manning", where, 0.04),
                        roughness=roughness, buildings=buildings,
                        initial_stage_m=_number(data, "initial_stage_m", where, None),
                        output_interval_s=_number(data, "output_interval_s", where, 10.0),
                        wet_depth_m=_number(data, "wet_depth_m", where, 0.05),
                        unstable_speed_m_s=_number(data, "unstable_speed_m_s", where, 20.0),
                        observation_points=points,
                        cell_size_m=_number(data, "cell_size_m", where, None, positive=True),
                        input_files=_named_files(data, base))
    except (TypeError, ValueError) as exc:
        if isinstance(exc, FloodMeshError):
            raise
        raise FloodMeshError(f"the scenario has a value of the wrong type ({exc})") from None


def _named_files(data, base: Path) -> tuple:
    """The files a scenario's JSON names (its ``file``, ``hydrograph`` and ``levels`` given as
    file names or patterns, relative to ``base``), as paths."""
    found = []

    def walk(value, key=None):
        if isinstance(value, dict):
            for k, v in value.items():
                walk(v, k)
        elif isinstance(value, list):
            for v in value:
                walk(v, key)
        elif isinstance(value, str) and key in ("file", "hydrograph", "levels"):
            found.extend(sorted(glob.glob(str(base / value))) or [str(base / value)])
    walk(data)
    return tuple(found)


def load_scenario(path) -> Scenario:
    """Read a scenario JSON file (see ``scenario_from_dict``)."""
    path = Path(path)
    if not path.is_file():
        raise FloodMeshError(f"the scenario {path} does not exist: check the path")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FloodMeshError(f"the scenario {path.name} is not valid JSON ({exc})") from None
    scenario = scenario_from_dict(data, path.parent)
    return replace(scenario, input_files=(str(path), *scenario.input_files))


# ---------------------------------------------------------------------------------------------
# the flood environment
ANUGA = "anuga==4.2.0"  # what make setup installs (scripts/setup.sh)


def flood_python(own_env=None) -> str | None:
    """The Python that runs ANUGA: ``FLOODMESH_FLOOD_PYTHON`` when set, else the project's
    ``.venv-flood``, the front end's ``own_env`` (a venv folder: the QGIS plugin's, beside its
    profile) or this Python, whichever imports anuga; None if none does."""
    named = os.environ.get("FLOODMESH_FLOOD_PYTHON")
    candidates = [named] if named else [
        str(Path(__file__).resolve().parents[2] / ".venv-flood" / "bin" / "python")]
    if not named and own_env:
        candidates.append(str(Path(own_env) / "bin" / "python"))
    if not named and Path(sys.executable).name.startswith("python"):  # not qgis.bin
        candidates.append(sys.executable)
    for python in candidates:
        if Path(python).exists():
            probe = subprocess.run([python, "-c", "import anuga"], capture_output=True,
                                   env=_worker_env())
            if probe.returncode == 0:
                return python
    return None


def require_flood_python(own_env=None) -> str:
    """``flood_python(own_env)``, or a FloodMeshError saying how to install ANUGA: into
    ``own_env`` where the front end has one (QGIS: a ZIP install has no Makefile)."""
    python = flood_python(own_env)
    if python is not None:
        return python
    named = os.environ.get("FLOODMESH_FLOOD_PYTHON")
    where = (f"FLOODMESH_FLOOD_PYTHON ({named}) does not import it" if named
             else "it is not installed")
    if own_env:  # QGIS: a ZIP install has no Makefile; the environment beside its profile
        env = shlex.quote(str(own_env))
        make = (f"(a few minutes and some 600 MB, with the internet): `/usr/bin/python3 -m venv "
                f"{env} && {env}/bin/pip install {ANUGA}`")
        raise FloodMeshError(
            f"running a flood needs the ANUGA solver, but {where}: point it at a Python that "
            f"imports anuga, or unset it and make FloodMesh's own ANUGA environment once {make}"
            if named else
            f"running a flood needs the ANUGA solver, in an environment of its own, but {where}"
            f": make it once {make}, where FloodMesh finds it; or point FLOODMESH_FLOOD_PYTHON "
            "at a Python that imports anuga")
    raise FloodMeshError(
        f"running a flood needs the ANUGA solver, but {where}: run `make setup` (it builds "
        ".venv-flood with numpy 2 and anuga 4.2), or `python3 -m venv .venv-flood && "
        ".venv-flood/bin/pip install anuga`, or point FLOODMESH_FLOOD_PYTHON at a Python "
        "that imports anuga")


def _worker_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env.setdefault("OMP_NUM_THREADS", "1")  # two threads on a busy 2-core machine are slower
    return env


# ---------------------------------------------------------------------------------------------
# geometry before the run
def tag_boundary(nodes, triangles, boundaries, left_out=None) -> tuple[np.ndarray, list,
                                                                     dict, list]:
    """(edges (k, 3) rows triangle, edge, tag index; tag names; tag → kind spec; notes) for
    every boundary edge. ``sides`` pick edges of the mesh's outer rings only, never a hole's
    rim; the rims of ``left_out`` (xy, triangles: buildings left out as holes) stay walls
    whatever names them. Edges no boundary names are walls; tags that end up with no edge
    are dropped (ANUGA refuses a tag no edge has)."""
    # lazy: GEOS loads only when this runs
    import shapely

    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import containing_triangle

    edges = boundary_edges(triangles)
    pairs = edge_nodes(triangles, edges)
    a, b = nodes[pairs[:, 0], :2], nodes[pairs[:, 1], :2]
    d = b - a
    normal = np.column_stack([d[:, 1], -d[:, 0]])  # outward: the outside is to the right
    mid = (a + b) / 2
    side_of = np.where(np.abs(normal[:, 0]) >= np.abs(normal[:, 1]),
                       np.where(normal[:, 0] > 0, 0, 1), np.where(normal[:, 1] > 0, 2, 3))
    side_names = ("east", "west", "north", "south")
    outer = _outer_ring_edges(nodes, triangles, pairs)
    rim = np.zeros(len(edges), bool)
    if left_out is not None and len(left_out[1]):
        step = 1e-3 * normal  # a thousandth of the edge off its middle, to either side
        for sign in (1, -1):
            rim |= containing_triangle(left_out[0], left_out[1], mid + sign * step) >= 0
    tags, kinds = ["wall"], {"wall": {"kind": "wall"}}
    tag = np.zeros(len(edges), np.int64)
    for k, boundary in enumerate(boundaries):
        name = f"{boundary.kind}_{k + 1}"
        if boundary.sides:
            pick = np.zeros(len(edges), bool)
            for side in boundary.sides:
                pick |= True if side == "all" else side_of == side_names.index(side)
            pick &= outer
        else:
            line = shapely.LineString(np.asarray(boundary.line)[:, :2])
            pick = shapely.distance(shapely.points(mid), line) <= boundary.snap_m
        if not (pick & ~rim).any():
            where = (f"sides {', '.join(boundary.sides)}" if boundary.sides
                     else f"within {boundary.snap_m} m of its line")
            walls = (", only the walls of buildings left out as holes, which stay walls"
                     if pick.any() else "")
            raise FloodMeshError(f"the {boundary.kind} boundary {k + 1} meets no boundary edge "
                                 f"of the mesh ({where}{walls}): check its coordinates and CRS, "
                                 "or give a larger snap_m")
        tags.append(name)
        kinds[name] = {"kind": boundary.kind, "level_m": boundary.level_m,
                       "levels": [list(p) for p in boundary.levels]}
        tag[pick & ~rim] = len(tags) - 1
    used = np.isin(np.arange(len(tags)), tag)
    notes = [f"the {kinds[name]['kind']} boundary {k} is overridden on all its edges by later "
             "boundaries: it has no effect" for k, name in enumerate(tags) if not used[k] and k]
    edges[:, 2] = np.cumsum(used)[tag] - 1
    tags = [name for name, u in zip(tags, used) if u]
    return edges, tags, {name: kinds[name] for name in tags}, notes


def _outer_ring_edges(nodes, triangles, pairs) -> np.ndarray:
    """Which boundary edges (node pairs) lie on a ring around the mesh (counter-clockwise), not
    around a hole in it."""
    # lazy: GEOS loads only when this runs
    import shapely

    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import boundary_loops

    n = len(nodes)
    outer = []
    for loop in boundary_loops(nodes, triangles):
        if shapely.LinearRing(nodes[loop, :2]).is_ccw:
            outer.append(np.column_stack([loop, np.roll(loop, -1)]))
    ring = np.sort(np.concatenate(outer), axis=1) if outer else np.empty((0, 2), np.int64)
    key = np.sort(pairs, axis=1)
    return np.isin(key[:, 0] * n + key[:, 1], ring[:, 0] * n + ring[:, 1])


def _inside(polygons, xy: np.ndarray, buffer: float = 0.0) -> np.ndarray:
    """Which of ``xy`` lie inside (or within ``buffer`` of) any polygon; the index of the last
    polygon containing each (-1: none)."""
    # lazy: GEOS loads only when this runs
    import shapely

    which = np.full(len(xy), -1)
    points = shapely.points(xy[:, :2])
    for k, coords in enumerate(polygons):
        polygon = shapely.Polygon(np.asarray(coords)[:, :2])
        if buffer:
            polygon = polygon.buffer(buffer)
        which[shapely.contains(polygon, points) | shapely.touches(polygon, points)] = k
    return which


def merge_wall_fans(nodes, triangles, max_rounds: int = 100_000) -> tuple[np.ndarray, int]:
    """Triangles without ``collinear_wall_stencils``: in each, the boundary node it shares with
    a neighbour on the same straight wall (a node of those two triangles only) is dropped and
    the two merge into one. The boundary's shape does not change. Returns (triangles, how many
    nodes were dropped); the dropped nodes stay in ``nodes``, unreferenced."""
    tri = np.array(triangles, np.int64)
    xy = nodes[:, :2]
    removed = 0
    for _ in range(max_rounds):
        nb = neighbours(tri)
        merge = next((m for m in (_wall_merge(tri, nb, xy, t) for t in
                                  collinear_wall_stencils(nodes, tri)) if m), None)
        if merge is None:
            break
        t, p, r, n1 = merge
        tri[t][tri[t] == p] = r
        tri = np.delete(tri, n1, axis=0)
        removed += 1
    return tri, removed


def _wall_merge(tri, nb, xy, t):
    """(t, p, r, n1): triangle t's wall node p, used by t and its neighbour n1 only, lies on
    the straight wall between t's other wall node and n1's r; None if t has no such node."""
    e = int(np.nonzero(nb[t] < 0)[0][0])
    wall = [tri[t, (e + 1) % 3], tri[t, (e + 2) % 3]]
    for k, p in enumerate(wall):
        users = np.nonzero((tri == p).any(axis=1))[0]
        if len(users) != 2:
            continue
        n1 = users[users != t][0]
        e1 = np.nonzero(nb[n1] < 0)[0]
        if len(e1) != 1:
            continue
        ends = {tri[n1, (e1[0] + 1) % 3], tri[n1, (e1[0] + 2) % 3]}
        if p not in ends:
            continue
        r = (ends - {p}).pop()
        d1, d2 = xy[wall[1 - k]] - xy[p], xy[r] - xy[p]
        if abs(d1[0] * d2[1] - d1[1] * d2[0]) <= 1e-9 * np.hypot(*d1) * np.hypot(*d2):
            return t, p, r, n1
    return None


def _drop_unused(nodes, triangles):
    used = np.unique(triangles)
    index = np.full(len(nodes), -1)
    index[used] = np.arange(len(used))
    return nodes[used], index[triangles]


def prepare(nodes, triangles, scenario: Scenario) -> dict:
    """Everything the worker needs as arrays, and what was done, for the report."""
    nodes = np.asarray(nodes, float).copy()
    triangles = np.asarray(triangles, np.int64)
    notes = scenario_notes(scenario)
    houses = scenario.buildings.polygons
    left_out = None  # the buildings' triangles, whose rims stay walls
    if houses and scenario.buildings.mode == "holes":
        centroids = nodes[triangles][:, :, :2].mean(axis=1)
        keep = _inside(houses, centroids) < 0
        left_out = (nodes[:, :2].copy(), triangles[~keep])
        nodes, triangles = _drop_unused(nodes, triangles[keep])
        notes.append(f"{len(houses)} buildings left out as holes with walls "
                     f"({int((~keep).sum())} triangles removed)")
    elif houses:
        lifted = _inside(houses, nodes, buffer=1e-6) >= 0
        nodes[lifted, 2] += scenario.buildings.height_m
        notes.append(f"{len(houses)} buildings raised {scenario.buildings.height_m} m "
                     f"({int(lifted.sum())} nodes)")
    triangles, merged = merge_wall_fans(nodes, triangles)
    if merged:
        nodes, triangles = _drop_unused(nodes, triangles)
        notes.append(f"{merged} boundary nodes dropped where a node fanned over three straight "
                     "boundary segments (ANUGA's gradient there is singular and gives NaN)")
    order, triangles = spatial_order(nodes, triangles)
    nodes = nodes[order]
    edges, tags, kinds, tag_notes = tag_boundary(nodes, triangles, scenario.boundaries,
                                                 left_out)
    notes += tag_notes
    centroids = nodes[triangles][:, :, :2].mean(axis=1)
    manning = np.full(len(triangles), scenario.manning)
    if scenario.roughness:
        zone = _inside([p for p, _ in scenario.roughness], centroids)
        values = np.array([n for _, n in scenario.roughness])
        manning[zone >= 0] = values[zone[zone >= 0]]
    arrays = {"nodes": nodes, "triangles": triangles, "vertex_z": nodes[triangles][:, :, 2],
              "manning": manning, "boundary_edges": edges}
    inflows = []
    for k, inflow in enumerate(scenario.inflows):
        region = np.asarray(inflow.region, float)[:, :2]
        if len(region) >= 3 and not (_inside([region], centroids) >= 0).any():
            raise FloodMeshError(f"inflow {k + 1}'s region holds no triangle centre of the "
                                 "mesh: make it larger than a triangle, or check its "
                                 "coordinates and CRS")
        arrays[f"inflow_{k}"] = region
        if inflow.hydrograph:
            series = np.asarray(inflow.hydrograph, float)
            notes += series_notes(f"inflow {k + 1}'s hydrograph", series, "m³/s",
                                  scenario.duration_s, zero_is_off=True)
            inflows.append({"times_s": series[:, 0].tolist(), "rates_m3s": series[:, 1].tolist()})
        else:
            inflows.append({"discharge_m3s": float(inflow.discharge_m3s)})
    for k, boundary in enumerate(scenario.boundaries):
        if boundary.levels:
            notes += series_notes(f"the level boundary {k + 1}'s levels",
                                  np.asarray(boundary.levels, float), "m", scenario.duration_s)
    arrays["observation_triangles"] = observation_triangles(nodes, triangles, scenario,
                                                            left_out)
    job = {"duration_s": scenario.duration_s, "output_interval_s": scenario.output_interval_s,
           "wet_depth_m": scenario.wet_depth_m, "initial_stage_m": scenario.initial_stage_m,
           "unstable_speed_m_s": scenario.unstable_speed_m_s,
           "boundary_tags": tags, "boundary_kinds": kinds, "inflows": inflows,
           "flow_algorithm": "DE0"}
    counts = {name: int((edges[:, 2] == k).sum()) for k, name in enumerate(tags)}
    return {"arrays": arrays, "job": job, "notes": notes, "boundary_edges": counts}


def series_notes(what: str, series: np.ndarray, unit: str, duration: float,
                 zero_is_off: bool = False) -> list[str]:
    """Notes on a (time s, value) series that starts after the run does or ends before it
    (the worker holds its first and last values there; no note for a held 0 where
    ``zero_is_off``: an inflow that is off); its times increase (``_series``)."""
    t = series[:, 0]
    notes = []
    if t[0] > 0 and not (zero_is_off and series[0, 1] == 0):
        notes.append(f"{what} starts at {t[0]:g} s: held at its first value, "
                     f"{series[0, 1]:g} {unit}, before")
    if t[-1] < duration and not (zero_is_off and series[-1, 1] == 0):
        notes.append(f"{what} ends at {t[-1]:g} s, before the run's {duration:g} s: held at its "
                     f"last value, {series[-1, 1]:g} {unit}, to the end")
    return notes


def observation_triangles(nodes, triangles, scenario: Scenario, left_out=None) -> np.ndarray:
    """The triangle holding each observation point; a FloodMeshError naming a point that no
    triangle holds (outside the mesh, in a hole of it, or in a building ``left_out``)."""
    points = scenario.observation_points
    if not points:
        return np.empty(0, np.int64)
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import containing_triangle

    xy = np.array([[x, y] for _, x, y in points])
    found = containing_triangle(nodes[:, :2], triangles, xy)
    if (found >= 0).all():
        return np.asarray(found, np.int64)
    k = int(np.flatnonzero(found < 0)[0])
    name, x, y = points[k]
    lo, hi = nodes[:, :2].min(axis=0), nodes[:, :2].max(axis=0)
    where = (f"outside the mesh (x {lo[0]:.0f} to {hi[0]:.0f}, y {lo[1]:.0f} to {hi[1]:.0f})"
             ": check its coordinates and CRS")
    if left_out is not None and containing_triangle(left_out[0], left_out[1], xy[k:k + 1])[0] >= 0:
        where = ("in a building left out of the mesh as a hole: move it off the building, or "
                 "give the buildings mode raised")
    elif (lo <= xy[k]).all() and (xy[k] <= hi).all():
        where = "in a hole of the mesh, where no triangle is: move it onto the mesh"
    raise FloodMeshError(f"observation point {name} ({x}, {y}) lies {where}")


# ---------------------------------------------------------------------------------------------
# the run
def run_anuga(prepared: dict, *, work_dir=None, python: str | None = None,
              progress: Callable[[float], None] | None = None,
              cancelled: Callable[[], bool] | None = None,
              log: Callable[[str], None] | None = None) -> dict:
    """Run the worker on ``prepare``'s output in a child process; returns its result arrays
    (per triangle and per output time) and the wall time. Cancel ends the child."""
    python = python or require_flood_python()
    own = work_dir is None
    work = Path(tempfile.mkdtemp(prefix="floodmesh-anuga-") if own else work_dir)
    work.mkdir(parents=True, exist_ok=True)
    try:
        np.savez(work / "job.npz", **prepared["arrays"])
        (work / "job.json").write_text(json.dumps(prepared["job"]))
        duration = prepared["job"]["duration_s"]
        start = time.perf_counter()
        with open(work / "stderr.txt", "w") as errors, subprocess.Popen(
                [python, "-u", str(WORKER), str(work)], env=_worker_env(),
                stdout=subprocess.PIPE, stderr=errors, text=True) as child:
            lines = queue.Queue()
            threading.Thread(target=lambda: [lines.put(line) for line in child.stdout],
                             daemon=True).start()
            try:
                while child.poll() is None or not lines.empty():
                    poll(cancelled)
                    try:
                        line = lines.get(timeout=0.2)
                    except queue.Empty:
                        continue
                    if line.startswith("progress ") and progress:
                        progress(min(float(line.split()[1]) / duration, 1.0))
            except BaseException:
                child.kill()
                raise
        if (work / "unstable.json").is_file():
            raise FloodMeshError(unstable_message(
                json.loads((work / "unstable.json").read_text()), prepared))
        if child.returncode != 0:
            tail = (work / "stderr.txt").read_text().strip().splitlines()[-3:]
            raise FloodMeshError("ANUGA stopped with an error: " + " | ".join(tail))
        with np.load(work / "result.npz") as result:
            out = {k: result[k] for k in result.files}
        out["wall_s"] = time.perf_counter() - start
        return out
    finally:
        if own:
            shutil.rmtree(work, ignore_errors=True)


def unstable_message(found: dict, prepared: dict) -> str:
    """The error for a run the worker stopped (``anuga_worker._unstable``): when, where (the
    triangle's centre, its inradius, the nearest boundary) and what to do."""
    # lazy: GEOS loads only when this runs
    import shapely

    arrays, job = prepared["arrays"], prepared["job"]
    nodes, triangles = arrays["nodes"][:, :2], arrays["triangles"]
    k = found["triangle"]
    x, y = nodes[triangles[k]].mean(axis=0)
    edges = arrays["boundary_edges"]
    gap = shapely.distance(shapely.points(x, y),
                           shapely.linestrings(nodes[edge_nodes(triangles, edges)]))
    near = int(np.argmin(gap))
    tag = job["boundary_tags"][int(edges[near, 2])]
    kind = job["boundary_kinds"][tag]["kind"]
    boundary = {"wall": "a wall", "outflow": "an outflow", "level": "a level"}[kind]
    where = (f"in the triangle at ({x:.1f}, {y:.1f}) (inradius "
             f"{float(inradii(nodes, triangles[k:k + 1])[0]):.2f} m, {gap[near]:.1f} m from "
             f"{boundary}{'' if tag == kind else f' ({tag})'})")
    if not (np.isfinite(found["depth_m"]) and np.isfinite(found["speed_ms"])):
        return (f"ANUGA's solution broke down (NaN) by t = {found['time_s']:g} s {where}; "
                "nothing was written. Check the report figures of the mesh (`hydraulics`) and "
                "the scenario's inflow for a region of one or two triangles")
    return (f"ANUGA's solution went unstable by t = {found['time_s']:g} s: water "
            f"{found['depth_m']:.2f} m deep ran at {found['speed_ms']:.1f} m/s {where}, at a time "
            f"step of {found['time_step_s']:.2g} s; nothing was written. Look "
            "at the mesh, the terrain and the boundary there; if such speeds are real (a dam "
            "break on steep ground), raise the scenario's unstable_speed_m_s (now "
            f"{job['unstable_speed_m_s']:g})")


def mass_balance(result: dict, area_m2: float) -> dict:
    """Volumes (m³): initial, final, inflow applied, net boundary inflow, and the error
    final − initial − inflow − boundary; and its share of the volume that came in (or was
    there), None where that volume is under ``FILM_M`` of water over the mesh's ``area_m2``
    (m²): the share of a film's volume measures round-off, not the flood."""
    v0, v1 = float(result["volume_m3"][0]), float(result["volume_m3"][-1])
    inflow = float(result["inflow_applied_m3"][-1])
    boundary = float(result["boundary_flux_m3"][-1])
    error = v1 - v0 - inflow - boundary
    scale = max(abs(inflow) + abs(boundary), v0)
    floor = max(FILM_M * area_m2, 1e-9)
    return {"initial_volume_m3": v0, "final_volume_m3": v1, "inflow_volume_m3": inflow,
            "boundary_inflow_volume_m3": boundary, "outflow_volume_m3": -boundary,
            "error_m3": error, "relative_error": error / scale if scale >= floor else None,
            "relative_error_floor_m3": floor}


def time_step_setters(nodes, triangles, result: dict, most: int = 5) -> list[dict]:
    """The triangles that set the solver's time step (ANUGA's: the least inradius over the
    fastest wave of a triangle's edges) at the worker's checks, those that set it for the most
    steps first: centroid (m), inradius (m), share of the run's steps (those of the intervals
    whose last step each set), the flood's max depth (m) and speed (m/s) there; ``z`` is the
    bed's mean at the triangle's corners (m)."""
    steps = np.asarray(result["step_setter_steps"], float)
    total = max(float(steps.sum()), 1.0)
    radius = inradii(nodes, triangles)
    centre = nodes[triangles, :2].mean(axis=1)
    found = np.flatnonzero(result["step_setter_checks"])
    order = found[np.lexsort((-result["step_setter_checks"][found], -steps[found]))][:most]
    return [{"x": float(centre[k, 0]), "y": float(centre[k, 1]),
             "z": float(nodes[triangles[k], 2].mean()) if nodes.shape[1] > 2 else 0.0,
             "inradius_m": float(radius[k]), "share_of_steps": float(steps[k] / total),
             "checks": int(result["step_setter_checks"][k]),
             "max_depth_m": float(result["max_depth"][k]),
             "max_speed_ms": float(result["max_speed"][k])} for k in order]


def outflow_hydrograph(result: dict) -> np.ndarray:
    """(k, 2) time (s) and discharge out through the open boundaries (m³/s), per interval."""
    t = np.asarray(result["times_s"], float)
    out = -np.asarray(result["boundary_flux_m3"], float)
    q = np.diff(out) / np.maximum(np.diff(t), 1e-12)
    return np.column_stack([t[1:], q])


def result_grids(nodes, triangles, result: dict, crs, cell_size: float) -> dict:
    """The per-triangle maxima as Grids (cell centres take the value of their triangle; NaN
    outside the mesh; dry cells 0 depth and speed, NaN arrival, and NaN level where the
    water never got ``DRY_BELOW_M`` deep)."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import containing_triangle

    transform, (rows, cols), xy = cell_centres(nodes[:, :2].min(axis=0),
                                               nodes[:, :2].max(axis=0), cell_size)
    tri = containing_triangle(nodes[:, :2], triangles, xy).reshape(rows, cols)
    inside = tri >= 0
    wet = np.asarray(result["max_depth"]) >= DRY_BELOW_M
    grids = {}
    for name in RESULT_RASTERS:
        values = np.asarray(result[name], float).copy()
        if name in ("max_stage",):
            values[~wet] = np.nan
        grid = np.full((rows, cols), np.nan)
        grid[inside] = values[tri[inside]]
        grids[name] = Grid(grid.astype(np.float32), transform, crs)
    return grids


def cell_centres(lo, hi, cell_size: float):
    """(transform, (rows, cols), centres (rows·cols, 2)) of a north-up grid of ``cell_size``
    aligned to its multiples and covering the box ``lo``–``hi`` (m)."""
    # lazy: affine loads only when this runs
    from affine import Affine

    x0, y1 = np.floor(lo[0] / cell_size) * cell_size, np.ceil(hi[1] / cell_size) * cell_size
    cols = max(int(np.ceil((hi[0] - x0) / cell_size)), 1)
    rows = max(int(np.ceil((y1 - lo[1]) / cell_size)), 1)
    gx, gy = np.meshgrid(x0 + (np.arange(cols) + 0.5) * cell_size,
                         y1 - (np.arange(rows) + 0.5) * cell_size)
    return (Affine(cell_size, 0, x0, 0, -cell_size, y1), (rows, cols),
            np.column_stack([gx.ravel(), gy.ravel()]))


def default_cell_size(nodes, triangles) -> float:
    """Half the side of the median triangle's square, rounded to 0.25 m, at least 0.25 m."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import triangle_areas

    side = np.sqrt(np.median(np.abs(triangle_areas(nodes, triangles))))
    return max(0.25, round(side / 2 * 4) / 4)


def run_flood(mesh_path, scenario: Scenario, out_dir, *, crs=None, own_env=None,
              progress: Callable[[float], None] | None = None,
              cancelled: Callable[[], bool] | None = None,
              log: Callable[[str], None] | None = None) -> dict:
    """Run ``scenario`` on the SMS 2DM mesh ``mesh_path`` with ANUGA and write ``FLOOD_FILES``
    into ``out_dir``: max depth, max water level, max speed and arrival time as GeoTIFFs in
    the mesh's CRS (``crs``, else that of a ``mesh.gpkg`` or ``dem.tif`` beside the mesh), the
    outflow hydrograph, the stage at the observation points and ``report.json`` (hydraulic
    checks of the mesh, mass balance, cost); ANUGA's Python as ``flood_python(own_env)``.
    Returns the report."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import triangle_areas

    inputs = [mesh_path, *scenario.input_files]
    crs = check_flood_inputs(mesh_path, scenario, out_dir, crs=crs)
    python = require_flood_python(own_env)
    mesh = io.read_2dm(mesh_path)
    prepared = prepare(mesh.nodes, mesh.triangles, scenario)
    arrays = prepared["arrays"]
    checks = hydraulic_checks(arrays["nodes"], arrays["triangles"])
    if log:
        log(f"ANUGA on {len(arrays['triangles'])} triangles; estimated time step "
            f"{checks['cfl_time_step_s']:.3g} s at 1 m depth")
    result = run_anuga(prepared, python=python, progress=progress, cancelled=cancelled, log=log)
    cell = scenario.cell_size_m or default_cell_size(arrays["nodes"], arrays["triangles"])
    grids = result_grids(arrays["nodes"], arrays["triangles"], result, crs, cell)
    observations = observation_series(scenario, result)
    depth = np.asarray(result["max_depth"])
    area = np.abs(triangle_areas(arrays["nodes"], arrays["triangles"]))
    steps = int(result["steps"][-1])
    report = {
        "mesh": str(mesh_path), "crs": crs.to_string(),
        "nodes": int(len(arrays["nodes"])), "triangles": int(len(arrays["triangles"])),
        "scenario": _jsonable_scenario(scenario),
        "solver": {"name": "ANUGA", "version": str(result["anuga_version"]),
                   "flow_algorithm": "DE0", "omp_num_threads": _worker_env()["OMP_NUM_THREADS"]},
        "hydraulics": checks,
        "boundary_edges": prepared["boundary_edges"],
        "cpu_s": float(result["cpu_s"]), "wall_s": float(result["wall_s"]),
        "time_steps": steps, "mean_time_step_s": scenario.duration_s / max(steps, 1),
        "time_step_set_by": time_step_setters(arrays["nodes"], arrays["triangles"], result),
        "mass_balance": mass_balance(result, float(area.sum())),
        "flooded_area_m2": float(area[depth > scenario.wet_depth_m].sum()),
        "max_depth_m": float(depth.max()),
        "max_speed_ms": float(np.max(result["max_speed"])),
        "observations": observations["peaks"],
        "raster_cell_size_m": cell,
        "notes": prepared["notes"] + observations["notes"],
        "files": sorted(FLOOD_FILES),
    }
    setters = report["time_step_set_by"]
    names = [name for name, _, _ in scenario.observation_points]
    # the folder is replaced as a whole (an interrupt leaves the last flood's files or these),
    # without the last flood's files that this one does not write; the user's own stay
    with staged_folder(out_dir, own=FLOOD_FILES + FLOW_FIELD_FILES, keep=inputs) as out:
        for name, filename in RESULT_RASTERS.items():
            io.write_raster(out / filename, grids[name], quantity=name)
        write_table(out / "hydrograph.csv", ("time_s", "outflow_m3s"),
                    outflow_hydrograph(result))
        write_table(out / "observations.csv", ["time_s"] + [f"stage_{n}" for n in names]
                    + [f"depth_{n}" for n in names], observations["table"])
        io.write_points_gpkg(out / "time_step.gpkg",
                             np.array([[k["x"], k["y"], k["z"]] for k in setters]).reshape(-1, 3),
                             crs, layer="time_step_set_by", attributes={
                                 "rank": list(range(1, len(setters) + 1)),
                                 **{name: [k[name] for k in setters] for name in SETTER_FIELDS}})
        np.savez(out / "triangles.npz", nodes=arrays["nodes"], triangles=arrays["triangles"],
                 **{k: result[k] for k in ("max_depth", "max_stage", "max_speed", "arrival_s")})
        io.write_json(out / "report.json", report)
    return report


def check_flood_inputs(mesh_path, scenario: Scenario, out_dir, *, crs=None):
    """What ``run_flood`` refuses before ANUGA runs: an output folder ``out_dir`` it cannot
    write or whose files would replace an input or a run's report, and a mesh without a CRS in
    metres (``crs``, else the mesh's, ``mesh_crs``). Returns that CRS; callers running several
    floods check them all first, so that no flood runs for minutes before another is refused."""
    check_output_folder(out_dir, [mesh_path, *scenario.input_files], FLOOD_FILES)
    _refuse_others_report(Path(out_dir))
    return require_metric_crs(crs or mesh_crs(mesh_path), f"the mesh {Path(mesh_path).name}")


def _refuse_others_report(out: Path) -> None:
    """Refuse an output folder holding a report.json that no flood wrote (a run's, beside its
    mesh), which the flood's own would replace."""
    earlier = out / "report.json"
    if not earlier.is_file():
        return
    try:
        flood = "solver" in json.loads(earlier.read_text())
    except (OSError, ValueError, TypeError):
        flood = False
    if not flood:
        raise FloodMeshError(f"the output folder {out} holds a report.json that no flood wrote "
                             "(a run's), which the flood's would replace: give the flood a "
                             f"folder of its own, e.g. {out / 'flood'}")


def observation_series(scenario: Scenario, result: dict) -> dict:
    """The observation points' series and peaks: ``table`` rows of time (s), the water level
    at each point (m; NaN while dry, under ``DRY_BELOW_M`` deep) and the depth at each (m);
    ``peaks`` per point its ground (m), peak depth (m), peak stage (m; None if never wet) and
    ``dry``; ``notes`` on the points that stay dry."""
    depth = np.asarray(result["observation_depth_m"], float)
    depth[depth < DRY_BELOW_M] = 0.0
    stage = np.where(depth > 0, result["observation_stage_m"], np.nan)
    peaks, notes = [], []
    for k, (name, x, y) in enumerate(scenario.observation_points):
        dry = not (depth[:, k] > 0).any()
        ground = float(result["observation_bed_m"][k])
        peaks.append({"name": name, "x": x, "y": y, "ground_m": ground,
                      "peak_depth_m": float(depth[:, k].max()), "dry": dry,
                      "peak_stage_m": None if dry else float(np.nanmax(stage[:, k]))})
        if dry:
            notes.append(f"observation point {name} stays dry (ground {ground:.2f} m): no peak "
                         "stage")
    return {"table": np.column_stack([result["times_s"], stage, depth]), "peaks": peaks,
            "notes": notes}


def _jsonable_scenario(scenario: Scenario) -> dict:
    data = asdict(scenario)
    data["buildings"] = {"mode": scenario.buildings.mode, "height_m": scenario.buildings.height_m,
                         "count": len(scenario.buildings.polygons)}
    data["roughness"] = [{"manning": n, "points": len(p)} for p, n in scenario.roughness]
    return data


def write_table(path, header, rows) -> None:
    """A CSV of ``header`` and numeric ``rows``, written atomically."""
    with io.atomic_output(Path(path)) as tmp:
        with open(tmp, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            for row in np.asarray(rows, float).reshape(-1, len(header)):
                writer.writerow([f"{v:.6g}" if np.isfinite(v) else "" for v in row])


def mesh_crs(mesh_path):
    """The CRS of a 2DM (which has no place for one) from its own sidecar ``.prj``, else from a
    ``mesh.gpkg`` or ``dem.tif`` beside it, or None."""
    own = io.read_prj(mesh_path)
    if own:
        return own
    folder = Path(mesh_path).parent
    gpkg = Path(mesh_path).with_suffix(".gpkg")
    for candidate in (gpkg, folder / "mesh.gpkg"):
        if candidate.is_file():
            return io.vector_crs(candidate)
    dem = folder / "dem.tif"
    if dem.is_file():
        # lazy: GDAL loads only when this runs
        import rasterio
        with rasterio.open(dem) as src:
            return src.crs.to_wkt() if src.crs else None
    return None
