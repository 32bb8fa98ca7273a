"""A run's input, its kind decided once where it enters: one point file, one DEM, point tiles or
DEM tiles. The steps after ask the ``Source`` for what they need instead of asking the path
again."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..engine.tiles import (TileSet, expand_tiles, first_names, is_large_copc, is_tile_set,
                            listed_as_tiles, tile_kind)
from ..errors import FloodMeshError
from ..io import RASTER_EXTENSIONS, require_file
from ..options import is_point_source

POINTS, DEM, POINT_TILES, DEM_TILES = "points", "dem", "point tiles", "dem tiles"


@dataclass(frozen=True)
class Source:
    """What a run reads: ``kind`` (``POINTS``, ``DEM``, ``POINT_TILES``, ``DEM_TILES``),
    ``paths`` (the one file, or the tiles as a ``tiles.TileSet`` with its notes and rule for
    unreadable tiles) and ``given``, the input as the user named it."""

    kind: str
    paths: tuple | TileSet
    given: object

    @property
    def tiled(self) -> bool:
        return self.kind in (POINT_TILES, DEM_TILES)

    @property
    def path(self) -> Path:
        """The one file of an untiled source."""
        if self.tiled:
            raise FloodMeshError(f"{self.kind} are many files, not one: give a single file")
        return self.paths[0]

    @property
    def named(self) -> str | list[str]:
        """The input as the user named it: a path, or the list of folders, patterns, files."""
        if isinstance(self.given, (str, os.PathLike)):
            return str(self.given)
        return [str(p) for p in self.given]


def open_source(given, *, skip_unreadable: bool = False) -> Source:
    """The ``Source`` of a file, folder, glob pattern or list of these (or a ``Source``, as it
    is): a folder, pattern or several files are tiles (``tiles.expand_tiles``; with
    ``skip_unreadable`` an unreadable tile is left out with a note), one file a point file
    (LAS/LAZ, COPC, EPT, XYZ/CSV) or a DEM raster by its name; a COPC file whose points would
    not fit in memory is read in windows, as tiles (``tiles.is_large_copc``)."""
    if isinstance(given, Source):
        if given.tiled and skip_unreadable:
            return Source(given.kind, expand_tiles(given.paths, skip_unreadable=True),
                          given.given)
        return given
    if is_tile_set(given):
        tiles = expand_tiles(given, skip_unreadable=skip_unreadable)
        kind = POINT_TILES if tile_kind(tiles[0]) == "points" else DEM_TILES
        return Source(kind, tiles, given)
    if not isinstance(given, (str, os.PathLike)):  # one file, given as a list of tiles
        if not given:
            raise FloodMeshError("no input given: give a point file (LAS/LAZ, XYZ/CSV), a DEM, "
                                 "or tiles (a folder, a pattern or several files)")
        (given,) = given
    path = Path(given)
    if path.suffix.lower() in RASTER_EXTENSIONS:
        return Source(DEM, (path,), given)
    if is_point_source(path):
        if is_large_copc(path):  # read in windows, as tiles
            return Source(POINT_TILES, TileSet([path], (), skip_unreadable), given)
        return Source(POINTS, (path,), given)
    require_file(path, "input")
    raise FloodMeshError(f"{path.name}: unknown input type '{path.suffix.lower()}'; give a "
                         "LAS/LAZ or XYZ/CSV point file, or a GeoTIFF/ASCII-grid DEM")


def check_outputs_apart(source: Source, outputs) -> None:
    """Refuse, before any work, ``outputs`` (paths) that would land among the tiles the input
    names (a run written into its own tile folder): the next run on it would read the DEM,
    slope and breakpoint rasters as tiles."""
    among = listed_as_tiles(source.given, outputs) if source.tiled else []
    if among:
        raise FloodMeshError(
            f"{first_names([p.name for p in among])} would be written into the tile folder "
            f"{among[0].parent}, and the next run on it would read "
            f"{'them' if len(among) > 1 else 'it'} as tiles: write the outputs into another "
            "folder (beside the tile folder, or one inside it)")
