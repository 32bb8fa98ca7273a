"""A survey delivered as tiles: LAS/LAZ/XYZ point tiles gridded tile by tile on Dask, and DEM
tiles (several GeoTIFFs) read as one grid.

Point tiles are gridded in two rounds of Dask tasks. Round one reads each tile, hashes its
points by where they lie and the run's seed and sends the client the few of least hash, from
which it draws the survey's check points: the points one file of all the tiles holds out
(``points.held_out_by_place``), whatever the tiles' names, formats, order or cut. It keeps the
tile's edge band: its points within two halos of its outline, in a scratch file on a local
cluster (on a running scheduler's workers, in their memory). Round two grids the DEM, check
points left out, in blocks of about one tile (``grid.grid_window``): each block re-reads the
tile under it and takes its neighbours' edge bands, so every TIN triangle that can cover a block
cell is formed as in one TIN of all the points, and the DEM equals gridding the whole cloud at
once (to round-off) with no seam. A worker holds one tile's points and one block of cells at a
time: peak memory depends on the tile size, not on the area.

A folder is read as a surveyor delivers it: its LAS/LAZ (or DEM) files are the tiles, XYZ text
only by its numbers, and the rest (a README, a tile index, a .prj) is named in a note and left
out. An empty tile, a sliver of one or two points, a tile over water or without ground go
through with a note: a sparse tile's points are all edge band, gridded in its neighbours'
blocks, so the DEM is still the one of all the points. A tile repeating another's points (the
same tile under two names) is counted once, and so are the points overlapping tiles share (a
buffered delivery), dropped from the later tile before the check points are drawn, in memory
and on the cluster (``_repeats_of``, ``_cluster_repeats``); an unreadable tile is refused by
name, or left out with a note (``skip_unreadable``). A task's FloodMeshError comes back to the
client as a value, so the user sees the one message, never a Dask log.

The tasks run on a ``dask.distributed`` cluster: a local one (``workers`` processes, or threads
where processes cannot be started) or a running scheduler's (``scheduler`` address), whose
workers must see the tile files at the same paths and have FloodMesh installed.
"""
from __future__ import annotations

import contextlib
import glob
import logging
import math
import os
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from affine import Affine
from pyproj import CRS

from ..errors import FloodMeshError
from ..io import (ELEVATION, GROUND_CLASS, atomic_output, band_scaling, classes_kept,
                  describe_band, drop_implausible, file_format, held_quantity, las_classes,
                  las_crs, las_fields_read, las_xyz, read_band, read_las, read_xyz)
from ..io.rasters import named_instead
from ..io.outputs import remove_stale_scratch, scratch_folder
from ..options import LOCAL_CLUSTER, check_cell_size, check_holdout, check_max_gap, holdout_count
from ..points import clean_points, holdout_candidates, least_hash, place_hashes, usable_points
from ..raster import (Grid, check_scale, check_transform, chosen_crs, corners_and_centre,
                      extent_words, holds_instead, require_metre_elevations, require_metric_crs,
                      same_place)
from ..steps.slope import slope_block
from .blocks import cell_size, map_raster
from .limits import BYTES_PER_FITTED_CELL, check_memory, fits_in_memory, footprint
from .progress import poll

LAS_EXTENSIONS = (".las", ".laz")
XYZ_EXTENSIONS = (".xyz", ".txt", ".csv", ".pts")
DEM_EXTENSIONS = (".tif", ".tiff", ".vrt", ".asc", ".img")
GLOB_CHARACTERS = "*?["


# ---------------------------------------------------------------------------------------------
# which files
def _items(inputs) -> list[str]:
    if isinstance(inputs, (str, os.PathLike)):
        return [str(inputs)]
    return [str(item) for item in inputs]


class TileSet(list):
    """The tile files (Paths) ``expand_tiles`` found, sorted, each once, with its ``notes`` on
    the files it left out and ``skip_unreadable``: whether an unreadable tile is left out with a
    note rather than refused. Passed on whole, it keeps both to the gridding."""

    def __init__(self, paths=(), notes=(), skip_unreadable: bool = False):
        super().__init__(paths)
        self.notes, self.skip_unreadable = list(notes), skip_unreadable


def is_tile_set(inputs) -> bool:
    """True for several inputs, a folder or a glob pattern; False for one file."""
    if isinstance(inputs, TileSet):
        return True
    items = _items(inputs)
    return len(items) > 1 or any(Path(i).is_dir() or _is_pattern(i) for i in items)


def is_tile(path: Path) -> bool:
    """A tile by its name and content: LAS/LAZ and DEM rasters by their extension (one that does
    not hold what its extension says is a broken tile, named when read), XYZ text only where its
    first lines are x, y, z numbers (``io.file_format``); hidden files never."""
    ext = path.suffix.lower()
    if path.name.startswith("."):
        return False
    return ext in LAS_EXTENSIONS + DEM_EXTENSIONS or (ext in XYZ_EXTENSIONS
                                                      and file_format(path) == "xyz")


def _is_pattern(item: str) -> bool:
    """Whether an input is a glob pattern: it holds ``GLOB_CHARACTERS`` and names no file or
    folder (one named "survey [1].laz" is that file)."""
    return any(ch in item for ch in GLOB_CHARACTERS) and not Path(item).exists()


def _listed(item: str) -> list[Path]:
    """The files one input names: a folder's (not recursive), a glob pattern's, or the file."""
    path = Path(item)
    if path.is_dir():
        return sorted(p for p in path.iterdir() if p.is_file())
    if _is_pattern(item):
        found = sorted(Path(p) for p in glob.glob(item) if Path(p).is_file())
        if not found:
            raise FloodMeshError(f"no file matches {item}: check the pattern (quote it so the "
                                 "shell does not expand it)")
        return found
    if not path.is_file():
        raise FloodMeshError(f"tile {path} does not exist or is not a file: check the path")
    return [path]


def listed_as_tiles(inputs, outputs) -> list[Path]:
    """Those of the ``outputs`` (paths, written or not) that the folders and glob patterns of
    ``inputs`` take as tiles by their name alone (LAS/LAZ, DEM rasters): written there, they
    would be read as tiles by the next run on the same input."""
    found = []
    for item in ([] if isinstance(inputs, TileSet) else _items(inputs)):
        for path in map(Path, outputs):
            if path.suffix.lower() not in LAS_EXTENSIONS + DEM_EXTENSIONS or path in found:
                continue
            if (Path(item).is_dir() and Path(path.absolute().parent).resolve()
                    == Path(item).resolve()
                    or _is_pattern(item) and path.absolute().match(os.path.abspath(item))):
                found.append(path)
    return found


def first_names(names: Sequence[str], shown: int = 3) -> str:
    """The first ``shown`` names, and how many more."""
    more = len(names) - shown
    return ", ".join(names[:shown]) + (f" and {more} more" if more > 0 else "")


def _listing(names: list[str]) -> str:
    """The names, those of an extension shared by more than three files counted instead."""
    groups = {}
    for name in names:
        groups.setdefault(Path(name).suffix.lower() or name, []).append(name)
    return ", ".join(", ".join(group) if len(group) <= 3 else f"{len(group)} {ext} files"
                     for ext, group in groups.items())


def expand_tiles(inputs, *, skip_unreadable: bool = False) -> TileSet:
    """The tiles of a folder, a glob pattern, a file, or a list of these, sorted, each once
    (``TileSet``): the files ``is_tile`` takes, but no XYZ text beside LAS/LAZ tiles (check
    points, a tile index); the others (a README, a .prj, LAStools' .lax) are named in one note
    and left out. A TileSet is returned as it is."""
    if isinstance(inputs, TileSet):
        return inputs if inputs.skip_unreadable or not skip_unreadable else TileSet(
            inputs, inputs.notes, True)
    tiles, others = {}, []
    for item in _items(inputs):
        listed = [p.resolve() for p in _listed(item)]
        found = [p for p in listed if is_tile(p)]
        if not found and (len(listed) > 1 or Path(item).is_dir()):
            raise FloodMeshError(f"{item} holds no LAS/LAZ/XYZ point tiles or GeoTIFF DEM "
                                 "tiles: check the path")
        for path in found:  # each tile once, with the first input that names it
            tiles.setdefault(path, item)
        others += [p for p in listed if p not in found]
    if any(p.suffix.lower() in LAS_EXTENSIONS for p in tiles):
        others += [p for p in tiles if p.suffix.lower() in XYZ_EXTENSIONS]
        tiles = {p: item for p, item in tiles.items() if p.suffix.lower() not in XYZ_EXTENSIONS}
    if not tiles:
        raise FloodMeshError(f"none of {', '.join(_items(inputs))} is a LAS/LAZ/XYZ point tile "
                             "or GeoTIFF DEM tile: check the paths")
    others = sorted(p.name for p in dict.fromkeys(others) if p not in tiles)
    if len({tile_kind(p) for p in tiles}) > 1:
        raise FloodMeshError(_mixed_kinds(tiles))
    notes = [f"{len(others)} files beside the tiles are not tiles (LAS/LAZ, GeoTIFF or XYZ text "
             f"of x, y, z) and were left out: {_listing(others)}"] if others else []
    return TileSet(list(tiles), notes, skip_unreadable)


def _mixed_kinds(tiles: dict) -> str:
    """The error for point tiles beside DEM rasters (``tiles``: each tile and the input, as
    given, that named it): the fewer kind named (a DEM or overview beside LAS tiles, or LAS
    files beside DEM tiles), and the fix for where they came from: those a folder or pattern
    took, moved out of its folder or a pattern that takes the others; those listed by name,
    taken out of the list. As many of each kind: both named, and the fix is to give one."""
    rasters = [p for p in tiles if tile_kind(p) == "dem"]
    points = [p for p in tiles if tile_kind(p) == "points"]
    if len(rasters) == len(points):
        folders = [_folder(item) for item in dict.fromkeys(tiles.values())
                   if _takes_several(item)]
        fix = ("give one kind: keep the point files and the DEM rasters in separate folders and "
               "give the folder of the kind to read" if folders else
               "give one kind: list the point files or the DEM rasters, not both")
        if folders:
            fix += (f", or give one kind by quoted patterns: {_patterns(folders[0], points)} "
                    f"for the point files, {_patterns(folders[0], rasters)} for the DEM rasters")
        return (f"the tiles mix point files and DEM rasters, as many of each: "
                f"{_counted(points, 'point file')} and {_counted(rasters, 'DEM raster')}: {fix}")
    if len(rasters) < len(points):
        stray, kept, what, others = rasters, points, "DEM raster", "point tiles"
    else:
        stray, kept, what, others = points, rasters, "point file", "DEM tiles"
    fixes = []
    by_name = [p for p in stray if not _takes_several(tiles[p])]
    if by_name:
        fixes.append(f"take {_them(by_name)} out of the list of tiles (keep "
                     f"{first_names([p.name for p in kept])})")
    found = [p for p in stray if _takes_several(tiles[p])]
    for item in dict.fromkeys(tiles[p] for p in found):
        folder = _folder(item)
        fixes.append(f"move {_them([p for p in found if tiles[p] == item])} out of {folder}, "
                     f"or give the {others} as {_patterns(folder, kept, 'quoted pattern')}")
    return (f"the tiles mix point files and DEM rasters: {_counted(stray, what)} beside "
            f"{len(kept)} {others}: " + "; ".join(fixes))


def _counted(paths: list, what: str) -> str:
    """'2 DEM rasters (a.tif, b.tif)': how many ``paths`` of a kind, and the first names."""
    return f"{len(paths)} {what}{'s' if len(paths) > 1 else ''} " \
           f"({first_names([p.name for p in paths])})"


def _folder(item: str) -> str:
    """The folder a folder or glob pattern given as tiles reads, spelled as given."""
    folder = item if Path(item).is_dir() else os.path.dirname(item) or "."
    return folder.rstrip("/") or folder


def _patterns(folder: str, paths: list, said: str | None = None) -> str:
    """The quoted glob patterns that take ``paths`` from ``folder``: one per extension among
    them, the most common first (ties by name), so that one run reads them all; after ``said``
    ("quoted pattern": 'a quoted pattern, e.g. ...', 'quoted patterns, e.g. ...') where given."""
    suffixes = [p.suffix for p in paths]
    kinds = sorted(set(suffixes), key=lambda ext: (-suffixes.count(ext), ext))
    quoted = " ".join(f"'{os.path.join(folder, '*' + ext)}'" for ext in kinds)
    if said is None:
        return quoted
    return f"{said}s, e.g. {quoted}" if len(kinds) > 1 else f"a {said}, e.g. {quoted}"


def _takes_several(item: str) -> bool:
    """Whether an input is a folder or a glob pattern, not a file named one by one."""
    return Path(item).is_dir() or _is_pattern(item)


def _them(paths: list) -> str:
    return "them" if len(paths) > 1 else "it"


def tile_kind(path: Path) -> str:
    ext = Path(path).suffix.lower()
    if ext in LAS_EXTENSIONS + XYZ_EXTENSIONS:
        return "points"
    if ext in DEM_EXTENSIONS:
        return "dem"
    raise FloodMeshError(f"tile {Path(path).name}: unknown file type '{ext}'; tiles are LAS/LAZ "
                         "or XYZ point files, or GeoTIFF DEMs")


# ---------------------------------------------------------------------------------------------
# checks before any work: every tile readable, one CRS in metres
@dataclass(frozen=True)
class PointTile:
    path: str
    count: int          # points in the file (all classes; for text an estimate from its size)
    bounds: tuple | None = None  # (xmin, ymin, xmax, ymax) m from a LAS header; None for text


# the option that leaves unreadable tiles out, on the command line and in QGIS
SKIP_UNREADABLE = "--skip-unreadable-tiles; in QGIS: Tiles: leave out unreadable tiles"


class _Unreadable(FloodMeshError):
    """A tile that cannot be read: refused, or left out with a note (``SKIP_UNREADABLE``)."""


def _unreadable_note(exc: _Unreadable, skip: bool) -> str:
    """The note on an unreadable tile left out; without ``skip`` it is refused, naming the option
    that leaves it out."""
    if not skip:
        raise FloodMeshError(f"{exc}: replace it, or leave out the unreadable tiles "
                             f"({SKIP_UNREADABLE})") from None
    return f"{exc}: the tile was left out ({SKIP_UNREADABLE})"


# A COPC file (cloud-optimised LAZ) of more points than this is read in windows of about as
# many, each a tile of its own (``copc_windows``): a reach larger than memory needs no re-tiling
WINDOW_POINTS = 10_000_000
_WINDOW = "#window="  # a COPC window's tile path: FILE#window=XMIN,YMIN,XMAX,YMAX (whole metres)


def is_copc(header) -> bool:
    """Whether a LAS header (laspy's) is a COPC file's: its first VLR is COPC's info record."""
    return bool(header.vlrs) and (header.vlrs[0].user_id, header.vlrs[0].record_id) == ("copc", 1)


def copc_windows(path: str, count: int, bounds: tuple) -> list[PointTile]:
    """The windows of a COPC file of ``count`` points over ``bounds`` (m): a grid of squares
    about ``WINDOW_POINTS`` points each (by the mean density), half-open on whole metres so
    that every point lies in one; each a ``PointTile`` whose path names the window."""
    xmin, ymin, xmax, ymax = bounds
    side = math.sqrt((xmax - xmin) * (ymax - ymin) * WINDOW_POINTS / max(count, 1)) or 1.0
    cols = max(1, math.ceil((xmax - xmin) / side))
    rows = max(1, math.ceil((ymax - ymin) / side))
    xs = np.linspace(math.floor(xmin), math.floor(xmax) + 1, cols + 1).round()
    ys = np.linspace(math.floor(ymin), math.floor(ymax) + 1, rows + 1).round()
    share = count / (cols * rows)
    return [PointTile(f"{path}{_WINDOW}{xs[c]:.0f},{ys[r]:.0f},{xs[c + 1]:.0f},{ys[r + 1]:.0f}",
                      math.ceil(share), (float(xs[c]), float(ys[r]), float(xs[c + 1]),
                                         float(ys[r + 1])))
            for r in range(rows) for c in range(cols)]


def is_large_copc(path: Path) -> bool:
    """Whether ``path`` is a COPC file of more than ``WINDOW_POINTS`` points, more than memory
    holds (``limits.fits_in_memory``): read in windows as tiles, not whole."""
    # lazy: laspy loads only when this runs
    import laspy

    if path.suffix.lower() != ".laz" or not path.is_file():
        return False
    try:
        with laspy.open(path) as reader:
            count = int(reader.header.point_count)
            return (is_copc(reader.header) and count > WINDOW_POINTS
                    and not fits_in_memory(points=count))
    except Exception:  # read and named as one file
        return False


def _read_window(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xyz, LAS classes, the header's scales: m; x, y, z) of the points of a COPC window
    (``copc_windows``): the octree nodes that reach it decoded, their points within it kept."""
    # lazy: laspy loads only when this runs
    import laspy

    file, box = path.split(_WINDOW)
    x0, y0, x1, y1 = map(float, box.split(","))
    try:
        with laspy.CopcReader.open(file, **las_fields_read(laspy)) as reader:
            points = reader.query(bounds=laspy.Bounds(mins=np.array([x0, y0]),
                                                      maxs=np.array([x1, y1])))
            scales = np.asarray(reader.header.scales, float)
    except Exception as exc:
        raise _Unreadable(f"tile {Path(file).name} is not a readable COPC file ({exc})") from None
    x, y = np.asarray(points.x), np.asarray(points.y)
    inside = (x >= x0) & (x < x1) & (y >= y0) & (y < y1) & ~np.asarray(points.withheld, bool)
    xyz = np.column_stack([x[inside], y[inside], np.asarray(points.z)[inside]])
    return xyz, np.asarray(points.classification)[inside], scales


def _tile_header(path: Path) -> tuple[int, object, tuple | None, bool]:
    """(points in the file, its CRS or None, its bounds (m) or None, whether it is COPC); for
    text, the count is an estimate from its size and the bounds are unknown."""
    # lazy: laspy loads only when this runs
    import laspy

    if path.suffix.lower() not in LAS_EXTENSIONS:
        return max(1, path.stat().st_size // 20), None, None, False
    if file_format(path) != "las":
        raise _Unreadable(f"tile {path.name} is not a readable LAS/LAZ file (it does not begin "
                          "with the LAS signature 'LASF')")
    try:
        with laspy.open(path) as reader:
            header = reader.header
            file_crs = las_crs(header)
            return int(header.point_count), file_crs, (
                float(header.mins[0]), float(header.mins[1]), float(header.maxs[0]),
                float(header.maxs[1])), is_copc(header)
    except Exception as exc:
        raise _Unreadable(f"tile {path.name} is not a readable LAS/LAZ file ({exc})") from None


def check_point_tiles(paths: Sequence[Path], *, crs=None, skip_unreadable: bool = False
                      ) -> tuple[list[PointTile], CRS, list[str]]:
    """Read every tile's header; refuse, naming the tile, one that is unreadable (or leave it out
    with a note, ``skip_unreadable``), without a CRS (unless ``crs`` is given, which replaces
    theirs with a note), in a CRS not in metres, in another horizontal CRS than the first or
    with other heights (``same_place``), or in a CRS not true to scale there. An empty tile is
    left out with a note; a COPC file of more than ``WINDOW_POINTS`` points becomes its windows
    (``copc_windows``). Returns the tiles, their CRS and the notes."""
    tiles, first, notes, replaced, headers = [], None, [], [], []
    for path in map(Path, paths):
        try:
            headers.append((path, *_tile_header(path)))
        except _Unreadable as exc:
            notes.append(_unreadable_note(exc, skip_unreadable))
    _refuse_tiles_in_degrees([(path.name, file_crs) for path, _, file_crs, _, _ in headers],
                             "points")
    for path, count, file_crs, bounds, copc in headers:
        name = path.name
        if count == 0:
            notes.append(f"tile {name} holds no points (its header counts 0): it adds none")
            continue
        tile_crs = require_metric_crs(chosen_crs(crs, file_crs, f"tile {name}", replaced.append),
                                      f"tile {name}", kind="points")
        if first is None:
            first = (name, tile_crs)
        elif not same_place(tile_crs, first[1], heights=True):
            raise FloodMeshError(
                f"tile {name} is in {tile_crs.name}, but tile {first[0]} is in {first[1].name}: "
                f"all tiles must share one CRS; reproject {name} to the others' CRS first (pdal "
                "translate IN OUT -f filters.reprojection --filters.reprojection.out_srs=EPSG:XXXX)")
        if copc and count > WINDOW_POINTS:
            tiles += copc_windows(str(path), count, bounds)
        else:
            tiles.append(PointTile(str(path), count, bounds))
    if not tiles:
        raise FloodMeshError(f"none of the {len(paths)} tiles holds points that can be read: "
                             "check the tiles")
    _check_tiles_scale(first[1], [(Path(t.path).name, t.bounds) for t in tiles], "points")
    return tiles, first[1], notes + _replaced_note(replaced)


def _replaced_note(replaced: list) -> list:
    """The first tile's note that the CRS given replaces its own (``chosen_crs``), and how many
    more it replaces, as one note."""
    n = len(replaced) - 1
    more = f" (and that of {n} more tile{'s' if n > 1 else ''})" if n > 0 else ""
    return [replaced[0] + more] if replaced else []


# A tile whose extent lies farther from the rest than this many sides of the largest tile, and at
# least this far (m), is refused: a tile in another CRS or unit (degrees, feet, a zone number
# before the eastings), which the CRS's area of use, widened for projections' reaches, lets by
FAR_TILE_SIDES, FAR_TILE_MIN_M = 50.0, 10_000.0


def _check_tiles_scale(crs: CRS, named: list, kind: str) -> None:
    """Refuse tiles far from the rest (``_refuse_far_tiles``), then ``check_scale`` over the
    extent of all the tiles, naming the tiles at fault. ``named``: (tile name, bounds: xmin,
    ymin, xmax, ymax m, or None where unknown: text tiles, not read yet, are checked once read,
    ``_check_text_tiles``)."""
    named = [(name, bounds) for name, bounds in named if bounds is not None]
    if not named:
        return
    _refuse_far_tiles(named, crs, kind)
    try:
        check_scale(crs, *corners_and_centre(*_extent([b for _, b in named])), "the tiles", kind)
    except FloodMeshError:
        at_fault = []
        for name, bounds in named:
            try:
                check_scale(crs, *corners_and_centre(*bounds), name, kind)
            except FloodMeshError:
                at_fault.append((name, bounds))
        if not at_fault:
            raise
        check_scale(crs, *corners_and_centre(*_extent([b for _, b in at_fault])),
                    _tiles_words([name for name, _ in at_fault]), kind)


def _extent(bounds: list) -> tuple[float, float, float, float]:
    """The box (xmin, ymin, xmax, ymax; m) round ``bounds``, boxes alike."""
    known = np.array(bounds, float).reshape(-1, 4)
    return (*known[:, :2].min(axis=0), *known[:, 2:].max(axis=0))


def _tiles_words(names: list[str]) -> str:
    """Tiles named as one subject of a sentence: 'tile a.laz', 'tile a.laz (and b.laz alike)',
    'tile a.laz (and 4 more tiles alike)'."""
    more = names[1:]
    if not more:
        return f"tile {names[0]}"
    if len(more) <= 2:
        return f"tile {names[0]} (and {' and '.join(more)} alike)"
    return f"tile {names[0]} (and {len(more)} more tiles alike)"


def _refuse_far_tiles(named: list, crs: CRS, kind: str) -> None:
    """Refuse, naming them and their extent, the tiles (``named``: (name, bounds) pairs) that
    lie apart from the largest group of tiles within ``FAR_TILE_SIDES`` sides of the largest
    tile (at least ``FAR_TILE_MIN_M``) of each other; of groups alike, the one not in degrees,
    else the first tile's, is the survey."""
    # lazy: SciPy loads only when this runs
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    if len(named) < 2:
        return
    boxes = np.array([b for _, b in named], float)
    side = float(np.max(boxes[:, 2:] - boxes[:, :2]))
    far = max(FAR_TILE_SIDES * side, FAR_TILE_MIN_M)
    centres = (boxes[:, :2] + boxes[:, 2:]) / 2
    pairs = cKDTree(centres).query_pairs(far + 2 * side, output_type="ndarray")
    n = len(named)
    links = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, group = connected_components(links, directed=False)
    if count == 1:
        return
    degrees = np.array([_in_degrees(*_extent(boxes[group == g])) for g in range(count)])
    sizes = np.bincount(group)
    survey = max(range(count), key=lambda g: (sizes[g], not degrees[g], g == group[0]))
    apart = [i for i in range(n) if group[i] != survey]
    rest = _extent(boxes[group == survey])
    outside = _extent(boxes[apart])
    gap = math.hypot(max(rest[0] - outside[2], outside[0] - rest[2], 0.0),
                     max(rest[1] - outside[3], outside[1] - rest[3], 0.0))
    code = f"EPSG:{crs.to_epsg() or 'XXXX'}"
    if _in_degrees(*outside):
        where = "x {:.6g} to {:.6g}, y {:.6g} to {:.6g}".format(*outside[::2], *outside[1::2])
        fix = (f"its x, y look like longitude and latitude in degrees: reproject it to the "
               f"others' CRS first ({_reproject(kind, code, 'EPSG:4326')}), or leave it out")
    else:
        where = extent_words(*outside)
        fix = ("check its CRS and units (another CRS, feet, a zone number before the eastings) "
               f"and reproject it to the others' first ({_reproject(kind, code)}), or grid it "
               "apart")
    others = "other tile" if sizes[survey] == 1 else f"{sizes[survey]} other tiles"
    raise FloodMeshError(
        f"{_tiles_words([named[i][0] for i in apart])} lies at {where}, {gap / 1000:,.0f} km "
        f"from the {others} ({extent_words(*rest)}): {fix}")


def _reproject(kind: str, code: str, source: str | None = None) -> str:
    """The command that reprojects a point (``kind`` "points") or DEM tile to ``code``, from
    ``source`` where given."""
    if kind == "points":
        given = f" --filters.reprojection.in_srs={source}" if source else ""
        return f"pdal translate IN OUT -f filters.reprojection{given} " \
               f"--filters.reprojection.out_srs={code}"
    return f"gdalwarp{f' -s_srs {source}' if source else ''} -t_srs {code} IN OUT"


def _in_degrees(xmin: float, ymin: float, xmax: float, ymax: float) -> bool:
    """Whether a box's x, y could be longitude and latitude (degrees)."""
    return -180.0 <= xmin and xmax <= 360.0 and -90.0 <= ymin and ymax <= 90.0


def _check_text_tiles(meta: list, crs: CRS) -> None:
    """``_check_tiles_scale`` over the tiles round one read (``meta``; all those with points,
    their extents from the points) where they hold XYZ text tiles, which no header placed
    before (those with a class column too)."""
    read = [m for m in meta if m.get("bounds")]  # read, with points
    if any(not _is_las(m["path"]) for m in read):
        _check_tiles_scale(crs, [(Path(m["path"]).name, m["bounds"]) for m in read], "points")


# ---------------------------------------------------------------------------------------------
# per-tile work (Dask tasks: plain functions of picklable arguments)
def _read_raw(path: Path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(xyz, LAS classes, or None for text without a class column, the LAS header's scales: m;
    x, y, z, or None for text) of all a tile's points, as stored; a tile that cannot be read
    raises ``_Unreadable`` naming it."""
    if _WINDOW in str(path):
        return _read_window(str(path))
    if path.suffix.lower() not in LAS_EXTENSIONS:
        try:
            return *read_xyz(path), None
        except FloodMeshError as exc:  # not XYZ text (its message begins with the file's name)
            if not str(exc).startswith(path.name):
                raise
            raise _Unreadable(f"tile {exc}") from None
    try:
        las = read_las(path, f"tile {path.name} is not a readable LAS/LAZ file")
    except FloodMeshError as exc:
        raise _Unreadable(str(exc)) from None
    cls = las_classes(las)
    return las_xyz(las, cls), cls, np.asarray(las.header.scales, float)


def _resolution(scales: np.ndarray | None, xyz: np.ndarray) -> np.ndarray:
    """The step (m; x, y, z) to which a tile stores its coordinates: a LAS/LAZ header's
    ``scales`` (``_read_raw``); for text (None), the coarsest of 1 m to 0.1 mm of which its
    numbers (the first 10,000) are whole multiples."""
    if scales is not None:
        return scales
    sample = np.asarray(xyz[:10_000], float)
    steps = np.full(3, 1e-4)
    for axis in range(3):
        for decimals in range(5):
            scaled = sample[:, axis] * 10.0 ** decimals
            if np.all(np.abs(scaled - np.rint(scaled)) < 1e-3):
                steps[axis] = 10.0 ** -decimals
                break
    return steps


def _is_las(path: str) -> bool:
    """Whether a tile (a file, or a COPC window of one) is LAS/LAZ, not XYZ text."""
    return Path(path.split(_WINDOW)[0]).suffix.lower() in LAS_EXTENSIONS


def _which(classes) -> str:
    return "ground points (class 2)" if classes is None else f"points of classes {sorted(classes)}"


def _kept(xyz: np.ndarray, cls, classes, name: str, notes=None) -> tuple[np.ndarray, str]:
    """(the tile's points of ``classes``, or as one file keeps them (``io.classes_kept``: the
    ground, or all of an unclassified tile), what was kept: "given", "ground", "whole" (an
    unclassified tile), "text" (XYZ) or "none" (a tile over water or without ground, with a
    note: its neighbours' points grid its ground))."""
    if cls is None:
        return xyz, "text"
    try:
        kept = classes_kept(xyz, cls, classes, name, notes.append if notes is not None else None)
    except FloodMeshError:
        if notes is not None:
            present = ", ".join(str(c) for c in np.unique(cls))
            notes.append(f"tile {name} holds no {_which(classes)}, only classes {present}: it "
                         "adds none")
        return xyz[:0], "none"
    if classes is not None:
        return kept, "given"
    return kept, "ground" if (cls == GROUND_CLASS).any() else "whole"


def _usable(xyz: np.ndarray, crs_wkt: str, name: str, notes: list) -> tuple[np.ndarray, bool]:
    """(the finite points, whether they are too few or too close to a line to make a terrain
    model alone): ``points.clean_points``' checks and notes, but a sparse tile's points are kept
    for its neighbours' blocks to grid."""
    try:
        return clean_points(xyz, crs_wkt, f"tile {name}", note=notes.append,
                            scale=False).xyz, False  # checked on the headers' extent
    except FloodMeshError:  # fewer than 3, or at one place or on one line
        return usable_points(xyz), True


def _digest(xyz: np.ndarray, chunk: int = 1 << 20) -> tuple[int, int]:
    """(count, hash) of a tile's points to 0.1 mm, whatever their order: two tiles with the same
    digest hold the same points (the sum of ``point_hashes``: points without x, y or z one key
    each). A million points at a time, to hold little beside the tile."""
    # lazy: numba loads only where tiles are read
    from .._kernels.points import point_hashes

    total = 0
    for start in range(0, len(xyz), chunk):
        mixed = point_hashes(np.ascontiguousarray(xyz[start:start + chunk], float), np.uint64(0))
        total = (total + int(mixed.sum(dtype=np.uint64))) % (1 << 64)
    return len(xyz), total


def _tile_read(path: str, crs_wkt: str, classes, holdout: float, seed: int,
               notes: list) -> dict:
    """Round one's read of a tile: the points kept (``_kept``, ``_usable``: ``points``), the
    candidates for the survey's check points among them (``holdout_candidates`` of a
    ``holdout`` fraction, hashed by ``seed``: ``candidates``, their row indices, hashes and
    bound), the digest of all its points, whether it is sparse and the step of its
    coordinates (``_resolution``)."""
    name = Path(path).name
    xyz, cls, scales = _read_raw(Path(path))
    digest, resolution = _digest(xyz), _resolution(scales, xyz)
    kept, kind = _kept(xyz, cls, classes, name, notes)
    del xyz, cls
    kept, sparse = _usable(kept, crs_wkt, name, notes)
    # hashed only where points are held out (``grid`` holds none by default)
    hashes = place_hashes(kept, seed) if holdout > 0 else np.empty(0, np.uint64)
    rows, bound = holdout_candidates(hashes, holdout)
    return {"points": kept, "candidates": {"rows": rows, "hashes": hashes[rows], "bound": bound},
            "kind": kind, "digest": digest, "sparse": sparse, "resolution": resolution}


def _tile_points(path: str, crs_wkt: str, classes, held_below: int | None, seed: int,
                 drop: np.ndarray | None = None):
    """Round two's read of a tile: (its points to grid, its check points: ``_held`` by
    ``held_below``), of the points round one kept (the same classes, the same non-finite points
    dropped), less those in ``drop`` (the points it repeats of an earlier tile it overlaps,
    ``tile_repeats``)."""
    xyz, cls, _ = _read_raw(Path(path))
    kept = _kept(xyz, cls, classes, Path(path).name)[0]
    del xyz, cls
    kept = _not_dropped(usable_points(kept), drop)
    held = _held(kept, held_below, seed)
    return kept[~held], kept[held]


def _held(xyz: np.ndarray, held_below: int | None, seed: int) -> np.ndarray:
    """Which of ``xyz`` are check points: their hash (``place_hashes``) at most ``held_below``
    (the survey's, ``least_hash``; None: none)."""
    if held_below is None or not len(xyz):
        return np.zeros(len(xyz), bool)
    return place_hashes(xyz, seed) <= np.uint64(held_below)


def _kept_rows(xyz: np.ndarray, drop: np.ndarray) -> np.ndarray:
    """Which points of ``xyz`` are none of ``drop``'s (the very same x, y, z: both as one read
    of the tile gives them)."""
    as_rows = np.dtype((np.void, 24))
    rows = np.ascontiguousarray(xyz, np.float64).reshape(-1, 3).view(as_rows).ravel()
    return ~np.isin(rows, np.ascontiguousarray(drop, np.float64).reshape(-1, 3).view(
        as_rows).ravel())


def _not_dropped(xyz: np.ndarray, drop: np.ndarray | None) -> np.ndarray:
    """The points of ``xyz`` less ``drop`` (None: all; ``_kept_rows``)."""
    if drop is None or not len(drop) or not len(xyz):
        return xyz
    return xyz[_kept_rows(xyz, drop)]


def _within(xyz: np.ndarray, box) -> np.ndarray:
    xmin, ymin, xmax, ymax = box
    return ((xyz[:, 0] >= xmin) & (xyz[:, 0] <= xmax) & (xyz[:, 1] >= ymin)
            & (xyz[:, 1] <= ymax))


def _tile_figures(path: str, crs_wkt: str, classes, holdout: float, seed: int
                  ) -> tuple[dict, np.ndarray | None]:
    """(a tile's figures and candidate check points, its points) as round one reads it
    (``_tile_read``); an unreadable tile gives its message (``unreadable``) and no points, for
    the client to decide, which draws the check points (``_check_points``)."""
    notes = []
    try:
        tile = _tile_read(path, crs_wkt, classes, holdout, seed, notes)
    except _Unreadable as exc:
        return {"path": path, "unreadable": str(exc)}, None
    xyz = tile.pop("points")
    candidates = tile.pop("candidates")
    candidates["xyz"] = xyz[candidates["rows"]]
    figures = {"path": path, "bounds": None, "n_points": len(xyz), "n_gridding": len(xyz),
               "area": 0.0, "candidates": candidates, "holdout": None, "notes": notes,
               "edge": None, **tile}
    if len(xyz):
        lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
        figures.update(bounds=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
                       area=footprint(xyz[:, :2])[0])
    return figures, xyz


def read_tile(path: str, crs_wkt: str, classes, holdout: float, seed: int, band: float,
              spill: str | None = None) -> dict:
    """Round one: a tile's figures, candidate check points and edge band (points within ``band``
    m of its outline, check points among them: round two leaves them out): the points, or with
    ``spill`` (a file path) the path of the ``.npy`` file they were written to
    (``_tile_figures``). A sparse tile's points are all edge band: its
    neighbours' blocks grid them."""
    result, xyz = _tile_figures(path, crs_wkt, classes, holdout, seed)
    if xyz is None or not len(xyz):
        return result
    lo_x, lo_y, hi_x, hi_y = result["bounds"]
    inner = (lo_x + band, lo_y + band, hi_x - band, hi_y - band)
    edge = ~_within(xyz, inner) if inner[0] < inner[2] and inner[1] < inner[3] else np.ones(
        len(xyz), bool)
    edge = np.ascontiguousarray(xyz[edge])
    if spill is not None:
        np.save(spill, edge)
        edge = spill
    result["edge"] = edge
    return result


@dataclass(frozen=True)
class _Failed:
    """A task's FloodMeshError, returned as a value (``_task``)."""
    message: str


def _task(function, *args):
    """``function(*args)`` on a worker; its FloodMeshError comes back as a value that the client
    raises again (``_as_completed``), so that Dask logs no failed task: its log and traceback
    would reach the user's terminal or QGIS log before the one clean message."""
    try:
        return function(*args)
    except FloodMeshError as exc:
        return _Failed(str(exc))


def _figures(result):
    return result if isinstance(result, _Failed) else {
        k: v for k, v in result.items() if k != "edge"}


def _edge(result):
    return None if isinstance(result, _Failed) else result.get("edge")


def _band_points(edge) -> np.ndarray:
    """A tile's edge band (``read_tile``): the points, or the ``.npy`` file they wait in."""
    return np.load(edge, mmap_mode="r") if isinstance(edge, str) else edge


def grid_block(window: dict, full: list, edges: list, crs_wkt: str, classes,
               held_below: int | None, seed: int, survey: list) -> np.ndarray:
    """Round two: the cells of one block, from the points within its ``box`` (its halo around
    it): of the tiles under it (``full``: paths, re-read) and its neighbours' edge bands
    (``edges``: arrays, or ``.npy`` files read in place), each with the points it repeats of
    an earlier tile (None: none; ``tile_repeats``), without those and the check points (hash
    at most ``held_below``, ``_held``). Where a triangle that gives a cell has a circle reaching
    past the box (a thin one by a void), the points beyond, which may make it none of the
    whole TIN's, are read from the tiles of the ``survey`` (path, bounds, repeats) that the circle
    reaches, and the block gridded again with them: the cells of one TIN of all the points."""
    # lazy: numba loads only when this runs
    from ..steps.grid import grid_window

    known = window["box"]
    parts = []
    for edge, drop in edges:
        xyz = _band_points(edge)
        xyz = _not_dropped(np.array(xyz[_within(xyz, known)]), drop)
        parts.append(xyz[~_held(xyz, held_below, seed)])
        del xyz
    for path, drop in full:
        xyz = _tile_points(path, crs_wkt, classes, held_below, seed, drop)[0]
        parts.append(xyz[_within(xyz, known)])
    extent = (min(b[0] for _, b, _ in survey), min(b[1] for _, b, _ in survey),
              max(b[2] for _, b, _ in survey), max(b[3] for _, b, _ in survey))
    while True:
        xyz = np.concatenate(parts) if parts else np.empty((0, 3))
        values, needed = grid_window(xyz, window["cell_size"], window["max_gap"], window["x0"],
                                     window["y1"], window["rows"], window["cols"], workers=1,
                                     known=known, extent=extent)
        if needed == tuple(known):  # no circle reaches past it
            return values
        # a side that grows grows by a cell more, past the circles' rounding
        pad = window["cell_size"]
        known = (*[n - pad if n < k else k for n, k in zip(needed[:2], known[:2])],
                 *[n + pad if n > k else k for n, k in zip(needed[2:], known[2:])])
        parts, xyz = [], None
        for path, bounds, drop in survey:
            if (bounds[0] <= known[2] and bounds[2] >= known[0] and bounds[1] <= known[3]
                    and bounds[3] >= known[1]):
                points = _tile_points(path, crs_wkt, classes, held_below, seed, drop)[0]
                parts.append(points[_within(points, known)])


# ---------------------------------------------------------------------------------------------
# the cluster
@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, *,
                processes: bool = True):
    """A ``distributed.Client``: of the running scheduler at ``scheduler`` (tcp://HOST:8786), or
    (None or ``LOCAL_CLUSTER``) of a local cluster of ``workers`` (default: one per core) single-threaded processes
    (``processes=False``: threads, for hosts such as QGIS that cannot start Python processes)."""
    # lazy: Dask loads only when this runs
    import dask
    from distributed import Client, LocalCluster

    if scheduler and scheduler != LOCAL_CLUSTER:
        try:
            client = Client(scheduler, timeout="10s")
        except Exception as exc:
            raise FloodMeshError(f"cannot reach the Dask scheduler at {scheduler} ({exc}): check "
                                 "the address (tcp://HOST:8786) and that `dask scheduler` runs "
                                 "there") from None
        with client:
            yield client
        return
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise FloodMeshError(f"--workers must be at least 1, got {workers}")
    # Nothing of Dask's reaches the user's terminal or QGIS log: a task's FloodMeshError comes
    # back as a value (``_task``); distributed's own logs are silenced below CRITICAL (a failure
    # or a cancel mid-round otherwise logs the workers' closed connections as they stop); no
    # dashboard, and the scheduler's HTTP server on a free local port, not 8787, which may be
    # taken (distributed then warns).
    # the workers' scratch (dask-scratch-space) in a folder of ours, removed with it
    with scratch_folder("dask") as scratch, \
            dask.config.set({"temporary-directory": scratch}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                         dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False},
                         memory_limit=0, silence_logs=logging.CRITICAL,
                         local_directory=scratch) as cluster, \
            Client(cluster) as client:
        yield client


@contextlib.contextmanager
def _band_folder(scheduler: str | None):
    """A scratch folder for round one's edge bands where the workers share this disk (a local
    cluster), removed at the end; None for a running scheduler's workers, which may be on other
    machines and keep the bands in their memory."""
    if scheduler and scheduler != LOCAL_CLUSTER:
        yield None
        return
    with scratch_folder("bands") as folder:
        yield folder


def _as_completed(client, futures, *, progress, cancelled, base: float, weight: float):
    """Yield (index, result) as the tasks finish, reporting progress and polling cancellation;
    on a failure or a cancel the remaining tasks are cancelled."""
    pending = dict(enumerate(futures))
    total = max(1, len(futures))
    try:
        while pending:
            poll(cancelled)
            finished = [i for i, f in pending.items() if f.done()]
            if not finished:
                time.sleep(0.05)
                continue
            for i in finished:
                future = pending.pop(i)
                result = future.result()
                if isinstance(result, _Failed):  # a task's FloodMeshError (``_task``)
                    raise FloodMeshError(result.message)
                if progress:
                    progress(base + weight * (1 - len(pending) / total))
                yield i, result
    finally:
        if pending:
            client.cancel(list(pending.values()))


# ---------------------------------------------------------------------------------------------
# gridding a tile set
@dataclass
class TiledDem:
    dem: Grid | None         # the whole DEM in memory (``keep=True``), else None
    holdout: np.ndarray      # (n, 3) held-out points of all tiles (``_check_points``)
    n_points: int            # points read, holdout included
    n_tiles: int
    area: float              # m² the points cover
    notes: list
    crs: CRS
    gridded: tuple = ()      # the tiles with points to grid, as round two re-reads them
    classes: tuple | None = None  # the classes round two gridded
    n_gridding: int = 0      # points gridded (all tiles)
    held_below: int | None = None  # the check points' hashes are at most this (``_held``)
    seed: int = 0            # ... hashed with this seed
    repeats: tuple = ()      # per tile of ``gridded`` the points it repeats of another, or None


def _tiles_counted(meta: list, classes, skip_unreadable: bool, notes: list) -> list[int]:
    """The tiles (indices into round one's ``meta``) whose points count, after leaving out, each
    with a note: unreadable tiles (or refusing them, ``_unreadable_note``), tiles repeating an
    earlier tile's points (a copy under another name), and, where the other tiles are
    classified, tiles without ground taken whole as unclassified (one file of all the points
    keeps only the ground). Their own notes and those on sparse tiles join ``notes``."""
    counted, seen = [], {}
    for i, m in enumerate(meta):
        name = Path(m["path"]).name
        if "unreadable" in m:
            notes.append(_unreadable_note(_Unreadable(m["unreadable"]), skip_unreadable))
        elif m["digest"][0] and m["digest"] in seen:
            first = Path(meta[seen[m["digest"]]]["path"]).name
            notes.append(f"tile {name} repeats the {m['digest'][0]:,} points of tile {first} "
                         f"(the same tile twice): they are counted once, {name} is left out")
        else:
            seen.setdefault(m["digest"], i)
            counted.append(i)
    if classes is None and any(meta[i]["kind"] == "ground" for i in counted):
        for i in [i for i in counted if meta[i]["kind"] == "whole"]:
            counted.remove(i)
            notes.append(f"tile {Path(meta[i]['path']).name} holds no ground points (class "
                         f"{GROUND_CLASS}), unlike the other tiles: its unclassified points are "
                         "left out")
    for i in counted:
        m = meta[i]
        notes += m["notes"]
        if m["sparse"] and m["n_gridding"]:
            n = m["n_gridding"]
            notes.append(f"tile {Path(m['path']).name} holds only {n:,} usable "
                         f"point{'s' * (n > 1)}, too few or too close to a line for a terrain "
                         "model of its own: gridded with its neighbours' points")
    return counted


def _check_points(counted: list, holdout: float, notes: list) -> int | None:
    """The survey's check points drawn from the candidates of the tiles that count
    (``counted``, round one's figures): as one file of all their points holds out
    (``points.split_holdout``: the ``holdout`` share, at least the 20 the FEMA/NSSDA test
    takes, said in ``notes``), the least hashes. Sets each tile's ``holdout`` (xyz),
    ``held_rows`` (indices into its points) and ``n_gridding``; returns the largest hash of a
    check point (None: none)."""
    n_points = sum(m["n_points"] for m in counted)
    n_out = holdout_count(holdout, n_points, notes.append) if n_points else 0
    held_below = least_hash([m["candidates"]["hashes"] for m in counted],
                            [m["candidates"]["bound"] for m in counted], n_out)
    for m in counted:
        candidates = m["candidates"]
        held = (np.zeros(len(candidates["hashes"]), bool) if held_below is None
                else candidates["hashes"] <= np.uint64(held_below))
        m["holdout"], m["held_rows"] = candidates["xyz"][held], candidates["rows"][held]
        m["n_gridding"] = m["n_points"] - int(held.sum())
    return held_below


def _check_enough(n_gridding: int, n_tiles: int, classes) -> None:
    if n_gridding < 3:
        raise FloodMeshError(
            f"the {n_tiles} tiles hold {n_gridding} usable {_which(classes)} together; at "
            "least 3 are needed to make a terrain model: check the tiles and the classes to "
            "grid (--classes, 'LAS classes' in QGIS)")


def _round_one(client, tiles: list, crs_wkt: str, classes, holdout: float, seed: int,
               band: float, bands: str | None, *, progress, cancelled) -> tuple[list, list]:
    """Round one: each tile read on a worker (``read_tile``, its edge band of ``band`` m in a
    file in ``bands`` when given); (each tile's figures, the futures of the edge bands), in the
    order of ``tiles``. Only the bands' futures outlive it: the cluster forgets the rest."""
    firsts = [client.submit(_task, read_tile, t.path, crs_wkt, classes, holdout, seed, band,
                            bands and os.path.join(bands, f"band-{i}.npy"),
                            key=f"read-{i}-{Path(t.path).name}")
              for i, t in enumerate(tiles)]
    figures = [client.submit(_figures, f) for f in firsts]
    edges = [client.submit(_edge, f) for f in firsts]
    meta = [None] * len(tiles)
    for i, result in _as_completed(client, figures, progress=progress, cancelled=cancelled,
                                   base=0.0, weight=0.3):
        meta[i] = result
    return meta, edges


@dataclass
class _Layout:
    """Round two's layout of the DEM over the tiles that count (``_tile_layout``)."""
    counted: list            # round one's figures of the tiles whose points count
    gridded: list            # indices into round one's figures of the tiles with points to grid
    classes: tuple | None    # the classes round two re-reads
    n_points: int            # points of the counted tiles, holdout included
    area: float              # m² the points cover
    block: int               # cells a side of a block of round two
    plan: dict               # ``check_layout``'s
    held_below: int | None   # the check points' hashes are at most this (``_check_points``)
    repeats: dict            # index: the points (n, 3) a tile repeats of an earlier one


def _tile_layout(meta: list, classes, holdout: float, cell_size: float, max_gap: float | None,
                 band: float, *, largest: int, parallel: int, keep: bool,
                 skip_unreadable: bool, notes: list, repeats: Callable[[list], dict]
                 ) -> _Layout:
    """The tiles that count (``_tiles_counted``; their notes join ``notes``), less the points
    each repeats of an earlier one (``repeats`` of their indices: ``_cluster_repeats``) before
    the check points are drawn, and round two's layout over them: bounds, blocks of about a
    tile's width (at least 256 cells) and the plan (``check_layout``); refused where the points
    are too few, or where ``parallel`` blocks (a tile of up to ``largest`` points and its
    neighbours' bands each) or, with ``keep``, the whole DEM would not fit in memory."""
    # lazy: numba loads only when this runs
    from ..steps.grid import check_layout

    indices = _tiles_counted(meta, classes, skip_unreadable, notes)
    repeated = repeats(indices)
    for i, xyz in repeated.items():
        _without_points(meta[i], xyz)
    counted = [meta[i] for i in indices]
    held_below = _check_points(counted, holdout, notes)
    gridded = [i for i in indices if meta[i]["n_gridding"]]  # sparse tiles too
    n_points = sum(m["n_points"] for m in counted)
    n_gridding = sum(m["n_gridding"] for m in counted)
    _check_enough(n_gridding, len(meta), classes)
    if classes is None and any(m["kind"] == "ground" for m in counted):
        classes = (GROUND_CLASS,)  # round two re-reads tiles with ground: their ground
    bounds = (min(meta[i]["bounds"][0] for i in gridded),
              min(meta[i]["bounds"][1] for i in gridded),
              max(meta[i]["bounds"][2] for i in gridded),
              max(meta[i]["bounds"][3] for i in gridded))
    area = sum(m["area"] for m in counted)
    widths = [max(meta[i]["bounds"][2] - meta[i]["bounds"][0],
                  meta[i]["bounds"][3] - meta[i]["bounds"][1]) for i in gridded]
    block = max(256, int(round(float(np.median(widths)) / cell_size)))
    per_block = int(largest * (1 + 8 * band * cell_size * block
                               / max(max(widths), cell_size) ** 2))
    plan = check_layout(bounds, n_gridding, area, cell_size, max_gap,
                        memory_points=per_block * parallel,
                        memory_cells=block * block * parallel, advice=(
                            "give a larger cell size, fewer --workers or smaller tiles"))
    if keep:
        check_memory(cells=plan["rows"] * plan["cols"], points=per_block * parallel,
                     advice="give a larger cell size, or grid the tiles alone "
                            "(floodmesh grid TILES --out dem.tif) and mesh a part")
    return _Layout(counted, gridded, classes, n_points, area, block, plan, held_below, repeated)


def _block_sources(box: tuple, gridded: list, meta: list, tiles: list, edges: list,
                   band: float, drops: dict) -> tuple[list, list]:
    """What the block within ``box`` (m) grids: the paths of the tiles it reaches more than
    ``band`` m inside, re-read whole, and the edge bands (futures) of the others it reaches,
    each with the points it repeats of an earlier tile (``drops``' future, or None)."""
    full, near = [], []
    for i in gridded:
        tb = meta[i]["bounds"]
        if tb[0] > box[2] or tb[2] < box[0] or tb[1] > box[3] or tb[3] < box[1]:
            continue
        inner = (tb[0] + band, tb[1] + band, tb[2] - band, tb[3] - band)
        reaches_inner = (inner[0] < inner[2] and inner[1] < inner[3]
                         and box[0] <= inner[2] and box[2] >= inner[0]
                         and box[1] <= inner[3] and box[3] >= inner[1])
        if reaches_inner:
            full.append((tiles[i].path, drops.get(i)))
        else:
            near.append((edges[i], drops.get(i)))
    return full, near


def _submit_blocks(client, layout: _Layout, meta: list, tiles: list, edges: list,
                   cell_size: float, halo: float, band: float, crs_wkt: str,
                   seed: int) -> tuple[list, list]:
    """Round two submitted: a ``grid_block`` task (key ``grid-ROW-COL``) for each block of the
    layout, on the points within ``halo`` m of it (``_block_sources``), and the tiles to read
    where a triangle's circle reaches farther (sent to the cluster once); (the tasks, the
    (row, col) of each block's first cell)."""
    plan, block = layout.plan, layout.block
    rows, cols, x0, y1 = plan["rows"], plan["cols"], plan["x0"], plan["y1"]
    survey = client.scatter([[(tiles[i].path, meta[i]["bounds"], layout.repeats.get(i))
                              for i in layout.gridded]], hash=False)[0]
    drops = {i: client.scatter(xyz, hash=False) for i, xyz in layout.repeats.items()}
    tasks, windows = [], []
    for r0 in range(0, rows, block):
        for c0 in range(0, cols, block):
            r1, c1 = min(rows, r0 + block), min(cols, c0 + block)
            bx0, by1 = x0 + c0 * cell_size, y1 - r0 * cell_size
            bx1, by0 = x0 + c1 * cell_size, y1 - r1 * cell_size
            box = (bx0 - halo, by0 - halo, bx1 + halo, by1 + halo)
            full, near = _block_sources(box, layout.gridded, meta, tiles, edges, band, drops)
            window = {"box": box, "x0": bx0, "y1": by1, "rows": r1 - r0, "cols": c1 - c0,
                      "cell_size": cell_size, "max_gap": plan["max_gap"]}
            windows.append((r0, c0))
            tasks.append(client.submit(_task, grid_block, window, full, near, crs_wkt,
                                       layout.classes, layout.held_below, seed, survey,
                                       key=f"grid-{r0}-{c0}"))
    return tasks, windows


def _gather_blocks(client, tasks: list, windows: list, plan: dict, cell_size: float, crs: CRS,
                   out_path, keep: bool, dtype: str, *, progress, cancelled) -> Grid | None:
    """Round two's blocks as they finish, written to ``out_path`` (``_dem_writer``) and, with
    ``keep``, into the DEM in memory, returned (else None); each task is dropped from ``tasks``
    as its block comes, for the cluster to forget it. Refused where no cell is covered."""
    rows, cols = plan["rows"], plan["cols"]
    transform = Affine(cell_size, 0.0, plan["x0"], 0.0, -cell_size, plan["y1"])
    values = np.full((rows, cols), np.nan) if keep else None
    any_valid = False
    with _dem_writer(out_path, rows, cols, transform, crs, dtype) as write:
        for i, block_values in _as_completed(client, tasks, progress=progress,
                                             cancelled=cancelled, base=0.3, weight=0.7):
            r0, c0 = windows[i]
            tasks[i] = None  # let the cluster forget the block
            any_valid = any_valid or bool(np.isfinite(block_values).any())
            if keep:
                values[r0:r0 + block_values.shape[0], c0:c0 + block_values.shape[1]] = \
                    block_values
            write(r0, c0, block_values)
        if not any_valid:
            raise FloodMeshError(
                f"no grid cell is covered by the points at a gap limit of {plan['max_gap']} "
                "m; the points are too sparse for this cell size: raise the cell size or "
                "the max gap")
    return Grid(values, transform, crs) if keep else None


def _point_tiles(inputs, crs, skip_unreadable: bool) -> tuple[list[PointTile], CRS, list, bool]:
    """(the point tiles, their CRS, the notes on the files left out, whether unreadable tiles
    are left out) of ``inputs`` (``expand_tiles``, ``check_point_tiles``); the scratch killed
    runs left is removed first, whichever way the tiles then go."""
    remove_stale_scratch()
    paths = expand_tiles(inputs, skip_unreadable=skip_unreadable)
    if tile_kind(paths[0]) != "points":
        raise FloodMeshError("these tiles are DEM rasters: grid takes point tiles (LAS/LAZ/XYZ); "
                             "give the DEM tiles to run directly")
    tiles, tile_crs, checked = check_point_tiles(paths, crs=crs,
                                                 skip_unreadable=paths.skip_unreadable)
    return tiles, tile_crs, paths.notes + checked, paths.skip_unreadable


@dataclass
class TilePoints:
    """A tile set's points read in memory (``read_point_tiles``)."""
    gridding: np.ndarray     # (n, 3) the points to grid, tile after tile
    holdout: np.ndarray      # (m, 3) the points held out (``_check_points``), tile by tile
    n_points: int            # points of the tiles counted, holdout included
    n_tiles: int             # tiles counted
    notes: list
    crs: CRS


def _cells_estimate(tiles: list[PointTile], cell_size: float) -> int:
    """Grid cells over the tiles' bounds (LAS headers); a text tile without bounds is taken as
    one point a square metre."""
    known = [t.bounds for t in tiles if t.bounds is not None]
    area = 0.0
    if known:
        area = ((max(b[2] for b in known) - min(b[0] for b in known))
                * (max(b[3] for b in known) - min(b[1] for b in known)))
    area += sum(t.count for t in tiles if t.bounds is None)
    return int(area / cell_size ** 2)


def read_point_tiles(inputs, cell_size: float, *, crs=None, classes=None,
                     holdout: float = 0.0, seed: int = 0, workers: int | None = None,
                     skip_unreadable: bool = False, memory: int | None = None,
                     cancelled: Callable[[], bool] | None = None) -> TilePoints | None:
    """The points of a tile set that fits in memory with its grid of ``cell_size`` m
    (``limits.fits_in_memory``; ``memory`` bytes, by default what is available), read here on
    ``workers`` threads, tile by tile as round one
    reads them: the same tiles counted, points held out and notes as ``grid_point_tiles``, so
    that gridding them at once gives its DEM, without a cluster to start; None where they would
    not fit (grid them with ``grid_point_tiles``)."""
    tiles, tile_crs, notes, skip_unreadable = _point_tiles(inputs, crs, skip_unreadable)
    if not fits_in_memory(points=sum(t.count for t in tiles),
                          cells=_cells_estimate(tiles, cell_size),
                          cell_bytes=BYTES_PER_FITTED_CELL, memory=memory):
        return None
    crs_wkt = tile_crs.to_wkt()
    meta, points = [], []
    with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        reads = [pool.submit(_tile_figures, t.path, crs_wkt, classes, holdout, seed)
                 for t in tiles]
        try:
            for read in reads:
                while True:
                    poll(cancelled)
                    with contextlib.suppress(TimeoutError):
                        figures, xyz = read.result(timeout=0.05)
                        break
                meta.append(figures)
                points.append(xyz)
        finally:
            for read in reads:
                read.cancel()
    _check_text_tiles(meta, tile_crs)
    counted = _tiles_counted(meta, classes, skip_unreadable, notes)
    # the points overlapping tiles share counted once before the check points are drawn, as
    # from one file of the tiles' points
    repeats = _repeated_rows([points[i] for i in counted], [meta[i] for i in counted], notes)
    for i, rows in zip(counted, repeats):
        if len(rows):
            points[i] = _without_rows(points[i], meta[i], rows)
    _check_points([meta[i] for i in counted], holdout, notes)
    gridding = []
    for i in counted:  # each tile's points let go as its points to grid are made
        rows = meta[i]["held_rows"]
        gridding.append(np.delete(points[i], rows, axis=0) if len(rows) else points[i])
        points[i] = None
    held = [meta[i]["holdout"] for i in counted]
    n_gridding = sum(len(p) for p in gridding)
    n_points = n_gridding + sum(len(h) for h in held)
    _check_enough(n_gridding, len(meta), classes)
    return TilePoints(np.concatenate(gridding), np.concatenate(held), n_points, len(counted),
                      notes, tile_crs)


def _repeated_rows(points: list, meta: list, notes: list) -> list[np.ndarray]:
    """The rows of each tile's ``points`` that repeat a point of an earlier tile where the two
    overlap (``_repeats_of``), with a note naming both tiles."""
    names = [Path(m["path"]).name for m in meta]
    repeats = []
    for i, xyz in enumerate(points):
        rows, found = _repeats_of(xyz, meta[i], ((j, points[j], meta[j]) for j in range(i)))
        notes += [_repeats_note(names[i], names[j], n, meta[i]["resolution"],
                                meta[j]["resolution"]) for j, n in found]
        repeats.append(rows)
    return repeats


def _step(mine: dict, theirs: dict) -> np.ndarray:
    """How far (m; x, y, z) two tiles' copies of a point may lie apart: a little less than half
    the sum of their coordinate steps (round one's figures' ``resolution``), since two distinct
    points of tiles of one step lie a whole step apart at the least."""
    return 0.999 * (np.asarray(mine["resolution"]) + np.asarray(theirs["resolution"])) / 2


def _padded(box, step: np.ndarray) -> np.ndarray:
    return np.asarray(box, float) + (-step[0], -step[1], step[0], step[1])


def _meet(a, b) -> bool:
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


def _repeats_of(xyz: np.ndarray, figures: dict, earlier) -> tuple[np.ndarray, list]:
    """(the rows of a tile's points ``xyz`` (round one's ``figures``: bounds, resolution) that
    repeat a point of an earlier tile where the two overlap, (index, how many) per earlier tile
    repeated), ``earlier`` giving each earlier tile's (index, points, figures), its points
    wanted only near this tile's bounds (a buffered delivery, a tile cut again with a margin, or
    stored at another LAS scale): the same x, y and z to within ``_pad``, the most that two
    copies of one point stored at those steps differ by. Only the points within the other
    tile's bounds are compared, so tiles that meet without overlapping cost little."""
    # lazy: scipy loads only where tiles overlap
    from scipy.spatial import cKDTree

    repeat, found_in = np.zeros(len(xyz), bool), []
    box = figures["bounds"]
    for j, theirs, other in earlier:
        if box is None or other["bounds"] is None:
            continue
        step = _step(figures, other)
        reach = _padded(other["bounds"], step)
        if not _meet(reach, box):
            continue
        mine = np.flatnonzero(_within(xyz, reach) & ~repeat)
        theirs = theirs[_within(theirs, _padded(box, step))]
        if not len(mine) or not len(theirs):
            continue
        origin = np.array([box[0], box[1], 0.0])
        gap, _ = cKDTree((theirs - origin) / step).query((xyz[mine] - origin) / step,
                                                          p=np.inf, distance_upper_bound=1)
        found = mine[gap <= 1]
        if len(found):
            repeat[found] = True
            found_in.append((j, len(found)))
    return np.flatnonzero(repeat), found_in


def _round_one_points(path: str, crs_wkt: str, classes) -> np.ndarray:
    """A tile's points as round one keeps them (``_tile_read``), read again."""
    xyz, cls, _ = _read_raw(Path(path))
    kept = _kept(xyz, cls, classes, Path(path).name)[0]
    del xyz, cls
    return _usable(kept, crs_wkt, Path(path).name, [])[0]


def tile_repeats(mine: tuple, figures: dict, earlier: list, crs_wkt: str, classes
                 ) -> tuple[np.ndarray, list]:
    """On a worker: (the points of a tile that repeat an earlier tile's where they overlap, (index,
    how many) per earlier tile; ``_repeats_of``) from ``mine``, its points near the others:
    ("band", its edge band) where they all lie in the band, else ("tile", path) to read it
    again, and ``earlier``: (index, such a source, figures) of each earlier tile it meets, read
    one at a time."""
    def points(source):
        kind, what = source
        return _round_one_points(what, crs_wkt, classes) if kind == "tile" else \
            _band_points(what)

    xyz = points(mine)
    rows, found = _repeats_of(xyz, figures, ((j, points(source), other)
                                              for j, source, other in earlier))
    return np.array(xyz[rows]), found


def _in_band(region, figures: dict, band: float) -> bool:
    """Whether a tile's points within ``region`` (a box, m) all lie in its edge band (within
    ``band`` m of its bounds: ``read_tile``)."""
    x0, y0, x1, y1 = figures["bounds"]
    inner = (x0 + band, y0 + band, x1 - band, y1 - band)
    return not (inner[0] < inner[2] and inner[1] < inner[3]) or not _meet(region, inner)


def _cluster_repeats(client, counted: list, meta: list, tiles: list, edges: list, band: float,
                     crs_wkt: str, classes, notes: list, *, held: int, cancelled) -> dict:
    """The points each counted tile (indices into round one's ``meta``) repeats of an earlier
    counted tile it overlaps, found on the cluster (``tile_repeats``: from the tiles' edge bands
    where the overlap lies in them, else from the tiles read again, two at a time on a worker,
    ``held`` points of round one's reading at most on the workers together, which the memory
    guard checks twice over then), as ``read_point_tiles`` finds them in memory: {index: points
    (n, 3)}, with the same notes joining ``notes``. Tiles that do not meet cost nothing."""
    tasks, owners = [], []
    for p, i in enumerate(counted):
        m = meta[i]
        if m["bounds"] is None:
            continue
        earlier, whole = [], False
        for j in counted[:p]:
            other = meta[j]
            if other["bounds"] is None:
                continue
            step = _step(m, other)
            if not _meet(_padded(other["bounds"], step), m["bounds"]):
                continue
            in_band = _in_band(_padded(m["bounds"], step), other, band)
            earlier.append((j, ("band", edges[j]) if in_band else ("tile", tiles[j].path),
                            _figures_only(other)))
            whole = whole or not _in_band(_padded(other["bounds"], step), m, band)
        if earlier:
            if whole or any(source[0] == "tile" for _, source, _ in earlier):
                check_memory(points=2 * held, advice="a worker compares two overlapping tiles "
                             "read whole: give fewer --workers, or the tiles without their "
                             "buffer (lastile -remove_buffer)")
            mine = ("tile", tiles[i].path) if whole else ("band", edges[i])
            tasks.append(client.submit(_task, tile_repeats, mine, _figures_only(m), earlier,
                                       crs_wkt, classes, key=f"repeats-{i}"))
            owners.append(i)
    found = {}
    for k, (xyz, repeated) in _as_completed(client, tasks, progress=None, cancelled=cancelled,
                                            base=0.3, weight=0.0):
        found[owners[k]] = (xyz, repeated)
    repeats = {}
    for i in owners:  # the notes in the tiles' order, as in memory
        xyz, repeated = found[i]
        name = Path(meta[i]["path"]).name
        notes += [_repeats_note(name, Path(meta[j]["path"]).name, n, meta[i]["resolution"],
                                meta[j]["resolution"]) for j, n in repeated]
        if len(xyz):
            repeats[i] = xyz
    return repeats


def _figures_only(figures: dict) -> dict:
    """What ``_repeats_of`` reads of a tile's figures, to send to a worker."""
    return {"bounds": figures["bounds"], "resolution": figures["resolution"]}


def _without_points(figures: dict, xyz: np.ndarray) -> None:
    """A tile's figures on the cluster made to count its points less ``xyz`` (those it repeats
    of an earlier tile), its candidate check points too (in place)."""
    candidates = figures["candidates"]
    keep = _kept_rows(candidates["xyz"], xyz)
    figures["candidates"] = {**candidates, "rows": candidates["rows"][keep],
                             "hashes": candidates["hashes"][keep], "xyz": candidates["xyz"][keep]}
    figures["n_points"] -= len(xyz)


def _repeats_note(name: str, first: str, n: int, mine: np.ndarray, theirs: np.ndarray) -> str:
    """The note on the ``n`` points of tile ``name`` that repeat points of tile ``first``, of
    coordinate steps ``mine`` and ``theirs`` (m; how near the copies were found where they
    differ)."""
    said = (f"tile {name} repeats {n:,} point{'s' * (n > 1)} of tile {first} where the two "
            "overlap: they are counted once")
    if np.array_equal(mine, theirs):
        return said
    return (f"{said} (found within {(mine + theirs).max() / 2 * 1000:.3g} mm: the tiles store "
            f"coordinates to {mine.max() * 1000:g} and {theirs.max() * 1000:g} mm)")


def _without_rows(xyz: np.ndarray, figures: dict, rows: np.ndarray) -> np.ndarray:
    """A tile's points (round one's) without ``rows`` (sorted), its ``figures``' count and
    candidate check points made to match them (in place)."""
    candidates = figures["candidates"]
    keep = ~np.isin(candidates["rows"], rows)
    kept_rows = candidates["rows"][keep]
    candidates.update(rows=kept_rows - np.searchsorted(rows, kept_rows),
                      hashes=candidates["hashes"][keep], xyz=candidates["xyz"][keep])
    figures["n_points"] -= len(rows)
    return np.delete(xyz, rows, axis=0)


def grid_point_tiles(inputs, cell_size: float, *, max_gap: float | None = None,
                     crs=None, classes=None, holdout: float = 0.0, seed: int = 0,
                     out_path=None, keep: bool = True, dtype: str = "float32",
                     workers: int | None = None,
                     scheduler: str | None = None, processes: bool = True,
                     progress: Callable[[float], None] | None = None,
                     cancelled: Callable[[], bool] | None = None,
                     check: Callable[[dict], None] | None = None,
                     skip_unreadable: bool = False) -> TiledDem:
    """Grid LAS/LAZ/XYZ tiles (a folder, glob, list or ``TileSet``) to one DEM of ``cell_size``
    m, tile by tile on Dask (see the module). The DEM is written block by block to ``out_path``
    (a tiled GeoTIFF of ``dtype``: float32 compressed, or float64 as gridded) when given, and
    kept in memory when ``keep``. ``check`` receives the layout (``check_layout``'s dict) before
    round two, to refuse a run before its main work. Files that are not tiles, empty and sparse
    tiles, tiles without the classes gridded and repeated tiles go through with a note;
    unreadable tiles are refused by name, or left out with a note with ``skip_unreadable``."""
    # lazy: numba loads only when this runs
    from ..steps.grid import halo_width

    cell_size = check_cell_size(cell_size)
    check_max_gap(max_gap)
    check_holdout(holdout)
    tiles, tile_crs, notes, skip_unreadable = _point_tiles(inputs, crs, skip_unreadable)
    crs_wkt = tile_crs.to_wkt()
    halo = halo_width(cell_size, cell_size * 10 if max_gap is None else max_gap)
    band = 2 * halo
    largest = max(t.count for t in tiles)
    with _band_folder(scheduler) as bands, \
            dask_client(workers, scheduler, processes=processes) as client:
        remote = scheduler and scheduler != LOCAL_CLUSTER
        parallel = 1 if remote else sum(client.nthreads().values()) or 1
        # A worker reads one tile (all classes) and grids a block of about its size.
        check_memory(points=largest * parallel, advice=f"the largest tile holds {largest:,} "
                     "points: give fewer --workers or cut the survey into smaller tiles")
        meta, edges = _round_one(client, tiles, crs_wkt, classes, holdout, seed, band, bands,
                                 progress=progress, cancelled=cancelled)
        _check_text_tiles(meta, tile_crs)
        layout = _tile_layout(
            meta, classes, holdout, cell_size, max_gap, band, largest=largest,
            parallel=parallel, keep=keep, skip_unreadable=skip_unreadable, notes=notes,
            repeats=lambda counted: _cluster_repeats(client, counted, meta, tiles, edges, band,
                                                     crs_wkt, classes, notes,
                                                     held=largest * parallel,
                                                     cancelled=cancelled))
        if check is not None:
            check(layout.plan)
        tasks, windows = _submit_blocks(client, layout, meta, tiles, edges, cell_size, halo,
                                        band, crs_wkt, seed)
        # the edge bands, some 17 MB a km² at 9 points/m² and 1 m cells, are the one term of the
        # gridding that grows with the area: on a local cluster they wait in scratch files;
        # a remote scheduler's workers hold them, each dropped from the cluster when the last
        # block taking it is done
        edges = None
        dem = _gather_blocks(client, tasks, windows, layout.plan, cell_size, tile_crs, out_path,
                             keep, dtype, progress=progress, cancelled=cancelled)
    held = np.concatenate([m["holdout"] for m in layout.counted])
    return TiledDem(dem, held, layout.n_points, len(layout.counted), layout.area, notes,
                    tile_crs, tuple(tiles[i].path for i in layout.gridded), layout.classes,
                    sum(meta[i]["n_gridding"] for i in layout.gridded), layout.held_below, seed,
                    tuple(layout.repeats.get(i) for i in layout.gridded))


def read_gridded_points(tiled: TiledDem, *,
                        cancelled: Callable[[], bool] | None = None) -> np.ndarray:
    """(n, 3) the points the tiles' DEM was gridded from, read back tile by tile as round two
    reads them (the same classes, the same points held out): what the terrain fits take, as
    for one file (``grid_point_tiles`` keeps none of them)."""
    crs_wkt, parts = tiled.crs.to_wkt(), []
    for path, drop in zip(tiled.gridded, tiled.repeats or [None] * len(tiled.gridded)):
        poll(cancelled)
        parts.append(_tile_points(path, crs_wkt, tiled.classes, tiled.held_below, tiled.seed,
                                  drop)[0])
    return np.concatenate(parts) if parts else np.empty((0, 3))


@contextlib.contextmanager
def _dem_writer(path, rows: int, cols: int, transform, crs: CRS, dtype: str = "float32"):
    """``write(row0, col0, values)`` into a tiled GeoTIFF (BigTIFF when needed) at ``path``, put
    in place only when complete; a no-op writer without ``path``. float32 is compressed; float64
    (the gridded values themselves, for the raster steps of ``run``) is not, as blocks writes
    floats."""
    if path is None:
        yield lambda r0, c0, values: None
        return
    # lazy: GDAL loads only when this runs
    import rasterio
    from rasterio.windows import Window

    nodata = -9999.0
    profile = dict(driver="GTiff", height=rows, width=cols, count=1, dtype=dtype,
                   crs=crs.to_wkt(), transform=transform, nodata=nodata, tiled=True,
                   blockxsize=256, blockysize=256, BIGTIFF="IF_SAFER",
                   **({"compress": "deflate"} if dtype == "float32" else {}))
    with atomic_output(path) as tmp, rasterio.open(tmp, "w", **profile) as dst:
        describe_band(dst, ELEVATION)

        def write(r0, c0, values):
            out = np.where(np.isfinite(values), values, nodata).astype(dtype)
            dst.write(out, 1, window=Window(c0, r0, out.shape[1], out.shape[0]))
        yield write


def slope_file64(dem_path, slope_path, method: str, *, crs=None, cancelled=None) -> Path:
    """Slope (degrees) of a float64 DEM file into a float64 file, block by block with a one-cell
    halo (``blocks.map_raster``), never holding the whole raster: the very numbers of
    ``slope.slope`` on the DEM in memory, as the kernel is the same and reads float64 (the
    float32 ``slope.slope_file`` rounds the DEM first). ``breakpoints.breakpoints_file`` with
    ``input_dtype=np.float64`` then gives ``classify_breakpoints``' breakpoints."""
    d = cell_size(dem_path)
    map_raster(dem_path, slope_path, lambda padded: slope_block(padded, d, method), halo=1,
               dtype="float64", input_dtype=np.float64, crs=crs, quantity="slope",
               cancelled=cancelled)
    return Path(slope_path)


def read_back(path, crs: CRS) -> Grid:
    """A raster a run wrote (float64 with its nodata, or breakpoints: uint8, nodata 255) as the
    Grid the steps in memory give: float64 with NaN, breakpoints 0 or 1."""
    # lazy: GDAL loads only when this runs
    import rasterio

    with rasterio.open(path) as src:
        if np.dtype(src.dtypes[0]) == np.uint8:
            values = src.read(1)
            values[values == src.nodata] = 0
        else:
            values = read_band(src)
        return Grid(values, src.transform, crs)


def write_front_rasters(files: dict, out) -> None:
    """slope.tif (float32, as ``io.write_raster`` writes the slope in memory) and
    breakpoints.tif of a run into ``out``, block by block from ``files`` (``slope``,
    ``breakpoints``: the float64 slope and the breakpoints files)."""
    map_raster(files["slope"], Path(out) / "slope.tif", lambda padded: padded, halo=0,
               input_dtype=np.float64, quantity="slope")
    shutil.copyfile(files["breakpoints"], Path(out) / "breakpoints.tif")


# ---------------------------------------------------------------------------------------------
# DEM tiles
def _refuse_non_elevations(paths: list, sources: list) -> None:
    """Refuse DEM tiles (``paths``, open as ``sources``) that hold no elevations: rasters
    FloodMesh tagged as a slope, breakpoints or a flood's maps (``io.describe_band``), or,
    untagged, named as it names them (``io.rasters.named_instead``: an earlier run's, written
    before it tagged them), all named in one message."""
    tagged, named = [], []
    for path, src in zip(paths, sources):
        held, name = held_quantity(src), path.name
        said = named_instead(f"tile {name}", path) if held is None else None
        if said:
            named.append(said)
        elif held not in (None, ELEVATION):
            tagged.append(holds_instead(f"tile {name}", held, "elevations"))
    if tagged or named:
        raise FloodMeshError(
            f"{'; '.join(tagged + named)}: take {'them' if len(tagged + named) > 1 else 'it'} "
            "out of the DEM tiles (a run's outputs go into a folder beside them)"
            + (", or rename a tile of elevations so named" if named else ""))


def _refuse_tiles_in_degrees(named: list, kind: str) -> None:
    """Refuse tiles whose own CRS is geographic (degrees) beside tiles in a projected one, naming
    them and the others' CRS to reproject them to (``_reproject``'s command for ``kind``,
    "points" or "raster"); a CRS given replacing theirs would take their degrees for metres.
    ``named``: (tile name, its own CRS, None, or a ``RefusedCRS``, which ``require_metric_crs``
    refuses later with its reason)."""
    degrees = [(name, crs) for name, crs in named if getattr(crs, "is_geographic", False)]
    metres = [(name, crs) for name, crs in named if getattr(crs, "is_projected", False)]
    if not degrees or not metres:
        return
    others = CRS.from_wkt(metres[0][1].to_wkt())
    code = f"EPSG:{others.to_epsg() or 'XXXX'}"
    raise FloodMeshError(
        f"{_tiles_words([name for name, _ in degrees])} is in degrees (a geographic CRS, "
        f"{CRS.from_wkt(degrees[0][1].to_wkt()).name}), but tile {metres[0][0]} is in "
        f"{others.name}, in metres: all tiles must share one CRS in metres; reproject it to the "
        f"others' CRS first ({_reproject(kind, code)})")


def _tiles_scaling(paths, sources) -> tuple[float, float]:
    """The (scale, offset) the DEM tiles' values are packed by (``io.band_scaling``), one for
    all; tiles packed by different ones are refused (they would be merged as stored)."""
    scalings = [band_scaling(src) for src in sources]
    for path, scaling in zip(paths, scalings):
        if scaling != scalings[0]:
            raise FloodMeshError(
                f"tile {path.name} stores its elevations with scale {scaling[0]:g} and offset "
                f"{scaling[1]:g}, tile {paths[0].name} with {scalings[0][0]:g} and "
                f"{scalings[0][1]:g}: unpack them first (gdal_translate -unscale -ot Float32 IN "
                "OUT)")
    return scalings[0]


def read_dem_tiles(inputs, *, crs=None, note=None) -> Grid:
    """Several GeoTIFF DEM tiles (a folder, glob or list) as one Grid, after checking each: one
    CRS in metres (``crs`` replaces theirs, which ``note`` hears of) true to scale there, the
    same cell size, cells aligned across tiles; cells no ground has are nodata, which ``note``
    is told of too (``io.drop_implausible``)."""
    # lazy: GDAL loads only when this runs
    import rasterio
    from rasterio.merge import merge

    paths = expand_tiles(inputs)
    if tile_kind(paths[0]) != "dem":
        raise FloodMeshError("expected DEM tiles (GeoTIFF); these are point tiles")
    first, sources, replaced = None, [], []
    with contextlib.ExitStack() as stack:
        for path in paths:
            try:
                sources.append(stack.enter_context(rasterio.open(path)))
            except rasterio.errors.RasterioIOError as exc:
                raise FloodMeshError(f"tile {path.name} is not a readable raster ({exc}): "
                                     "replace it or leave it out") from None
        _refuse_non_elevations(paths, sources)
        _refuse_tiles_in_degrees([(path.name, src.crs) for path, src in zip(paths, sources)],
                                 "raster")
        for path, src in zip(paths, sources):
            name = path.name
            check_transform(src.transform, f"tile {name}")
            require_metre_elevations(src.units[0], f"tile {name}")
            own = src.crs.to_wkt() if src.crs else None
            tile_crs = require_metric_crs(chosen_crs(crs, own, f"tile {name}", replaced.append),
                                          f"tile {name}", kind="raster")
            if first is None:
                first = (name, tile_crs, src.transform)
            elif not same_place(tile_crs, first[1], heights=True):
                raise FloodMeshError(
                    f"tile {name} is in {tile_crs.name}, but tile {first[0]} is in "
                    f"{first[1].name}: all tiles must share one CRS; reproject {name} first "
                    "(gdalwarp -t_srs EPSG:XXXX IN OUT)")
        xmin = min(s.bounds.left for s in sources)
        xmax = max(s.bounds.right for s in sources)
        ymin = min(s.bounds.bottom for s in sources)
        ymax = max(s.bounds.top for s in sources)
        # where they lie before how their cells line up: a tile in degrees under the CRS given
        # is named as one, not as cells of 1e-05 m off the grid
        _check_tiles_scale(first[1], [(path.name, tuple(src.bounds))
                                      for path, src in zip(paths, sources)], "raster")
        for path, src in zip(paths, sources):
            t, t0 = src.transform, first[2]
            offset = ((t.c - t0.c) / t0.a, (t.f - t0.f) / t0.e)
            if not np.isclose(t.a, t0.a, rtol=1e-9) or not all(
                    abs(o - round(o)) < 1e-6 for o in offset):
                raise FloodMeshError(
                    f"tile {path.name} has cells of {t.a:g} m at ({t.c:g}, {t.f:g}), not on the "
                    f"grid of tile {first[0]} ({t0.a:g} m cells): resample it onto that "
                    f"grid first (gdalwarp -tr {t0.a:g} {t0.a:g} -tap IN OUT)")
        for message in _replaced_note(replaced) if note else ():
            note(message)
        d = first[2].a
        check_memory(cells=int(math.ceil((xmax - xmin) / d) * math.ceil((ymax - ymin) / d)),
                     advice="resample the DEM tiles to larger cells")
        scale, offset = _tiles_scaling(paths, sources)
        mosaic, transform = merge(sources, nodata=np.nan, dtype="float64")
    values = np.asarray(mosaic[0], np.float64)  # merge made it float64: no copy
    values[~np.isfinite(values)] = np.nan
    values = values * scale + offset  # the stored values unpacked, as one tile's are
    drop_implausible(values, "the DEM tiles", "TILE", note)
    if not np.isfinite(values).any():
        raise FloodMeshError("the DEM tiles have no valid cells: check their nodata value")
    return Grid(values, transform, first[1])
