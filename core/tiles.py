"""A survey delivered as tiles: LAS/LAZ/XYZ point tiles gridded tile by tile on Dask, and DEM
tiles (several GeoTIFFs) read as one grid.

Point tiles are gridded in two rounds of Dask tasks. Round one reads each tile, draws its
holdout points (seeded by the run's seed and the tile's file name, so the same tile always holds
back the same points, whatever the other tiles) and keeps the tile's edge band: its points
within two halos of its outline, in a scratch file on a local cluster (on a running scheduler's
workers, in their memory). Round two grids the DEM in blocks of about one tile
(``grid.grid_window``): each block re-reads the tile under it and takes its neighbours' edge
bands, so every TIN triangle that can cover a block cell is formed as in one TIN of all the
points, and the DEM equals gridding the whole cloud at once (to round-off) with no seam. A
worker holds one tile's points and one block of cells at a time: peak memory depends on the
tile size, not on the area.

The tasks run on a ``dask.distributed`` cluster: a local one (``workers`` processes, or threads
where processes cannot be started) or a running scheduler's (``scheduler`` address), whose
workers must see the tile files at the same paths and have FloodMesh installed.
"""
from __future__ import annotations

import contextlib
import glob
import math
import os
import tempfile
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from affine import Affine
from pyproj import CRS

from .errors import Cancelled, FloodMeshError
from .raster import Grid, require_metric_crs

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


def is_tile_set(inputs) -> bool:
    """True for several inputs, a folder or a glob pattern; False for one file."""
    items = _items(inputs)
    return len(items) > 1 or any(Path(i).is_dir() or any(ch in i for ch in GLOB_CHARACTERS)
                                 for i in items)


def expand_tiles(inputs) -> list[Path]:
    """The tile files of a folder (its point or DEM files, not recursive), a glob pattern, a file,
    or a list of these; sorted, each once."""
    from .io import POINT_EXTENSIONS, RASTER_EXTENSIONS

    known = POINT_EXTENSIONS + RASTER_EXTENSIONS
    paths = []
    for item in _items(inputs):
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in known)
            if not found:
                raise FloodMeshError(f"the folder {path} holds no LAS/LAZ/XYZ point tiles or "
                                     "GeoTIFF DEM tiles: check the path")
            paths += found
        elif any(ch in item for ch in GLOB_CHARACTERS) and not path.exists():
            found = sorted(Path(p) for p in glob.glob(item) if Path(p).is_file())
            if not found:
                raise FloodMeshError(f"no file matches {item}: check the pattern (quote it so "
                                     "the shell does not expand it)")
            paths += found
        else:
            if not path.is_file():
                raise FloodMeshError(f"tile {path} does not exist or is not a file: check the "
                                     "path")
            paths.append(path)
    unique = list(dict.fromkeys(p.resolve() for p in paths))
    kinds = {tile_kind(p) for p in unique}
    if len(kinds) > 1:
        raise FloodMeshError("the tiles mix point files and DEM rasters: give one kind (a folder "
                             "or pattern of LAS/LAZ/XYZ tiles, or of GeoTIFF DEM tiles)")
    return unique


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


def check_point_tiles(paths: Sequence[Path], *, crs=None) -> tuple[list[PointTile], CRS]:
    """Read every tile's header; refuse, naming the tile, one that is unreadable, empty, without
    a CRS (unless ``crs`` is given), in a CRS not in metres, or in another CRS than the first."""
    import laspy

    tiles, first = [], None
    for path in paths:
        name = Path(path).name
        if path.suffix.lower() in LAS_EXTENSIONS:
            try:
                with laspy.open(path) as reader:
                    count = int(reader.header.point_count)
                    try:
                        file_crs = reader.header.parse_crs()
                    except Exception:
                        file_crs = None
            except Exception as exc:
                raise FloodMeshError(f"tile {name} is not a readable LAS/LAZ file ({exc}): "
                                     "replace it or leave it out") from None
            if count == 0:
                raise FloodMeshError(f"tile {name} holds no points (its header counts 0): check "
                                     "that the tiling wrote it, or leave it out")
        else:
            count, file_crs = max(1, path.stat().st_size // 20), None
        tile_crs = require_metric_crs(crs if crs is not None else file_crs, f"tile {name}",
                                      kind="points")
        if first is None:
            first = (name, tile_crs)
        elif not tile_crs.equals(first[1], ignore_axis_order=True):
            raise FloodMeshError(
                f"tile {name} is in {tile_crs.name}, but tile {first[0]} is in {first[1].name}: "
                f"all tiles must share one CRS; reproject {name} to the others' CRS first (pdal "
                "translate IN OUT -f filters.reprojection --filters.reprojection.out_srs=EPSG:XXXX)")
        tiles.append(PointTile(str(path), count))
    return tiles, first[1]


# ---------------------------------------------------------------------------------------------
# per-tile work (Dask tasks: plain functions of picklable arguments)
def holdout_mask(n_points: int, fraction: float, seed: int, name: str) -> np.ndarray:
    """Which of a tile's ``n_points`` are held out: ``fraction`` of them, drawn from a generator
    seeded by ``seed`` and the tile's file ``name``, so reproducible tile by tile."""
    n_out = int(round(fraction * n_points))
    mask = np.zeros(n_points, dtype=bool)
    if n_out:
        rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
        mask[rng.choice(n_points, size=n_out, replace=False)] = True
    return mask


def _tile_points(path: str, crs_wkt: str, classes, holdout: float, seed: int, notes=None, *,
                 checked: bool = False):
    """(gridding xyz, held-out xyz) of one tile; ``checked``: the tile passed ``read_points``'s
    checks in round one, so round two only reads it and drops the same non-finite points."""
    from .io import read_point_file, read_points

    if checked:
        xyz = np.asarray(read_point_file(Path(path), classes)[0], dtype=np.float64)
        xyz = xyz[np.isfinite(xyz).all(axis=1)]
    else:
        xyz = read_points(path, crs=crs_wkt, classes=classes,
                          note=notes.append if notes is not None else None).xyz
    held = holdout_mask(len(xyz), holdout, seed, Path(path).name)
    return xyz[~held], xyz[held]


def _within(xyz: np.ndarray, box) -> np.ndarray:
    xmin, ymin, xmax, ymax = box
    return ((xyz[:, 0] >= xmin) & (xyz[:, 0] <= xmax) & (xyz[:, 1] >= ymin)
            & (xyz[:, 1] <= ymax))


def read_tile(path: str, crs_wkt: str, classes, holdout: float, seed: int, band: float,
              spill: str | None = None) -> dict:
    """Round one: a tile's figures, held-out points and edge band (points within ``band`` m of
    its outline): the points, or with ``spill`` (a file path) the path of the ``.npy`` file
    they were written to."""
    from .limits import footprint

    notes = []
    xyz, held = _tile_points(path, crs_wkt, classes, holdout, seed, notes)
    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    inner = (lo[0] + band, lo[1] + band, hi[0] - band, hi[1] - band)
    edge = ~_within(xyz, inner) if inner[0] < inner[2] and inner[1] < inner[3] else np.ones(
        len(xyz), bool)
    edge = np.ascontiguousarray(xyz[edge])
    if spill is not None:
        np.save(spill, edge)
        edge = spill
    return {"path": path, "bounds": (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
            "n_points": len(xyz) + len(held), "n_gridding": len(xyz),
            "area": footprint(xyz[:, :2])[0], "holdout": held, "notes": notes, "edge": edge}


def _figures(result: dict) -> dict:
    return {k: v for k, v in result.items() if k != "edge"}


def _edge(result: dict) -> np.ndarray:
    return result["edge"]


def grid_block(window: dict, full: list, edges: list, crs_wkt: str, classes, holdout: float,
               seed: int) -> np.ndarray:
    """Round two: the cells of one block, from the tiles under it (``full``: paths, re-read) and
    its neighbours' edge bands (``edges``: arrays, or ``.npy`` files read in place)."""
    from .grid import grid_window

    box = window["box"]
    parts = []
    for edge in edges:
        xyz = np.load(edge, mmap_mode="r") if isinstance(edge, str) else edge
        parts.append(np.array(xyz[_within(xyz, box)]))
        del xyz
    for path in full:
        xyz = _tile_points(path, crs_wkt, classes, holdout, seed, checked=True)[0]
        parts.append(xyz[_within(xyz, box)])
    xyz = np.concatenate(parts) if parts else np.empty((0, 3))
    return grid_window(xyz, window["cell_size"], window["max_gap"], window["x0"], window["y1"],
                       window["rows"], window["cols"], workers=1)


# ---------------------------------------------------------------------------------------------
# the cluster
@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, *,
                processes: bool = True):
    """A ``distributed.Client``: of the running scheduler at ``scheduler`` (tcp://HOST:8786), or
    of a local cluster of ``workers`` (default: one per core) single-threaded processes
    (``processes=False``: threads, for hosts such as QGIS that cannot start Python processes)."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
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
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                      dashboard_address=None, memory_limit=0,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


@contextlib.contextmanager
def _band_folder(scheduler: str | None):
    """A scratch folder for round one's edge bands where the workers share this disk (a local
    cluster), removed at the end; None for a running scheduler's workers, which may be on other
    machines and keep the bands in their memory."""
    if scheduler:
        yield None
        return
    with tempfile.TemporaryDirectory(prefix="floodmesh-bands-") as folder:
        yield folder


def _as_completed(client, futures, *, progress, cancelled, base: float, weight: float):
    """Yield (index, result) as the tasks finish, reporting progress and polling cancellation;
    on a failure or a cancel the remaining tasks are cancelled."""
    pending = dict(enumerate(futures))
    total = max(1, len(futures))
    try:
        while pending:
            if cancelled is not None and cancelled():
                raise Cancelled()
            finished = [i for i, f in pending.items() if f.done()]
            if not finished:
                time.sleep(0.05)
                continue
            for i in finished:
                future = pending.pop(i)
                result = future.result()  # re-raises a task's FloodMeshError here
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
    holdout: np.ndarray      # (n, 3) held-out points of all tiles
    n_points: int            # points read, holdout included
    n_tiles: int
    area: float              # m² the points cover
    notes: list
    crs: CRS


def grid_point_tiles(inputs, cell_size: float, *, max_gap: float | None = None,
                     crs=None, classes=None, holdout: float = 0.0, seed: int = 0,
                     out_path=None, keep: bool = True, dtype: str = "float32",
                     workers: int | None = None,
                     scheduler: str | None = None, processes: bool = True,
                     progress: Callable[[float], None] | None = None,
                     cancelled: Callable[[], bool] | None = None,
                     check: Callable[[dict], None] | None = None) -> TiledDem:
    """Grid LAS/LAZ/XYZ tiles (a folder, glob or list) to one DEM of ``cell_size`` m, tile by
    tile on Dask (see the module). The DEM is written block by block to ``out_path`` (a tiled
    GeoTIFF of ``dtype``: float32 compressed, or float64 as gridded) when given, and kept in
    memory when ``keep``. ``check`` receives the layout
    (``check_layout``'s dict) before round two, to refuse a run before its main work."""
    from .grid import check_layout, halo_width
    from .limits import check_memory
    from .options import check_cell_size, check_holdout, check_holdout_count, check_max_gap

    cell_size = check_cell_size(cell_size)
    check_max_gap(max_gap)
    check_holdout(holdout)
    paths = expand_tiles(inputs)
    if tile_kind(paths[0]) != "points":
        raise FloodMeshError("these tiles are DEM rasters: grid takes point tiles (LAS/LAZ/XYZ); "
                             "give the DEM tiles to run directly")
    tiles, tile_crs = check_point_tiles(paths, crs=crs)
    crs_wkt = tile_crs.to_wkt()
    halo = halo_width(cell_size, cell_size * 10 if max_gap is None else max_gap)
    band = 2 * halo
    largest = max(t.count for t in tiles)
    with _band_folder(scheduler) as bands, \
            dask_client(workers, scheduler, processes=processes) as client:
        parallel = 1 if scheduler else sum(client.nthreads().values()) or 1
        # A worker reads one tile (all classes) and grids a block of about its size.
        check_memory(points=largest * parallel, advice=f"the largest tile holds {largest:,} "
                     "points: give fewer --workers or cut the survey into smaller tiles")
        firsts = [client.submit(read_tile, t.path, crs_wkt, classes, holdout, seed, band,
                                bands and os.path.join(bands, f"band-{i}.npy"),
                                key=f"read-{i}-{Path(t.path).name}")
                  for i, t in enumerate(tiles)]
        figures = [client.submit(_figures, f) for f in firsts]
        edges = [client.submit(_edge, f) for f in firsts]
        meta = [None] * len(tiles)
        for i, result in _as_completed(client, figures, progress=progress, cancelled=cancelled,
                                       base=0.0, weight=0.3):
            meta[i] = result
        del firsts
        n_points = sum(m["n_points"] for m in meta)
        n_gridding = sum(m["n_gridding"] for m in meta)
        check_holdout_count(holdout, n_points)
        bounds = (min(m["bounds"][0] for m in meta), min(m["bounds"][1] for m in meta),
                  max(m["bounds"][2] for m in meta), max(m["bounds"][3] for m in meta))
        area = sum(m["area"] for m in meta)
        widths = [max(m["bounds"][2] - m["bounds"][0], m["bounds"][3] - m["bounds"][1])
                  for m in meta]
        block = max(256, int(round(float(np.median(widths)) / cell_size)))
        per_block = int(largest * (1 + 8 * band * cell_size * block / max(widths) ** 2))
        plan = check_layout(bounds, n_gridding, area, cell_size, max_gap,
                            memory_points=per_block * parallel,
                            memory_cells=block * block * parallel, advice=(
                                "give a larger cell size, fewer --workers or smaller tiles"))
        rows, cols, x0, y1 = plan["rows"], plan["cols"], plan["x0"], plan["y1"]
        if keep:
            check_memory(cells=rows * cols, points=per_block * parallel,
                         advice="give a larger cell size, or grid the tiles alone "
                                "(floodmesh grid TILES --out dem.tif) and mesh a part")
        if check is not None:
            check(plan)
        transform = Affine(cell_size, 0.0, x0, 0.0, -cell_size, y1)
        tasks, windows = [], []
        for r0 in range(0, rows, block):
            for c0 in range(0, cols, block):
                r1, c1 = min(rows, r0 + block), min(cols, c0 + block)
                bx0, by1 = x0 + c0 * cell_size, y1 - r0 * cell_size
                bx1, by0 = x0 + c1 * cell_size, y1 - r1 * cell_size
                box = (bx0 - halo, by0 - halo, bx1 + halo, by1 + halo)
                full, near = [], []
                for t, m, edge in zip(tiles, meta, edges):
                    tb = m["bounds"]
                    if tb[0] > box[2] or tb[2] < box[0] or tb[1] > box[3] or tb[3] < box[1]:
                        continue
                    inner = (tb[0] + band, tb[1] + band, tb[2] - band, tb[3] - band)
                    reaches_inner = (inner[0] < inner[2] and inner[1] < inner[3]
                                     and box[0] <= inner[2] and box[2] >= inner[0]
                                     and box[1] <= inner[3] and box[3] >= inner[1])
                    if reaches_inner:
                        full.append(t.path)
                    else:
                        near.append(edge)
                window = {"box": box, "x0": bx0, "y1": by1, "rows": r1 - r0, "cols": c1 - c0,
                          "cell_size": cell_size, "max_gap": plan["max_gap"]}
                windows.append((r0, c0))
                tasks.append(client.submit(grid_block, window, full, near, crs_wkt, classes,
                                           holdout, seed, key=f"grid-{r0}-{c0}"))
        # the edge bands, some 17 MB a km² at 9 points/m² and 1 m cells, are the one term of the
        # gridding that grows with the area: on a local cluster they wait in scratch files;
        # a remote scheduler's workers hold them, each dropped from the cluster when the last
        # block taking it is done
        edges = near = edge = None
        values = np.full((rows, cols), np.nan) if keep else None
        any_valid = False
        with _dem_writer(out_path, rows, cols, transform, tile_crs, dtype) as write:
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
    held = np.concatenate([m["holdout"] for m in meta]) if meta else np.empty((0, 3))
    notes = [n for m in meta for n in m["notes"]]
    return TiledDem(Grid(values, transform, tile_crs) if keep else None, held, n_points,
                    len(tiles), area, notes, tile_crs)


@contextlib.contextmanager
def _dem_writer(path, rows: int, cols: int, transform, crs: CRS, dtype: str = "float32"):
    """``write(row0, col0, values)`` into a tiled GeoTIFF (BigTIFF when needed) at ``path``, put
    in place only when complete; a no-op writer without ``path``. float32 is compressed; float64
    (the gridded values themselves, for the raster steps of ``run``) is not, as blocks writes
    floats."""
    if path is None:
        yield lambda r0, c0, values: None
        return
    import rasterio
    from rasterio.windows import Window

    from .io import atomic_output

    nodata = -9999.0
    profile = dict(driver="GTiff", height=rows, width=cols, count=1, dtype=dtype,
                   crs=crs.to_wkt(), transform=transform, nodata=nodata, tiled=True,
                   blockxsize=256, blockysize=256, BIGTIFF="IF_SAFER",
                   **({"compress": "deflate"} if dtype == "float32" else {}))
    with atomic_output(path) as tmp, rasterio.open(tmp, "w", **profile) as dst:
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
    from .blocks import cell_size, map_raster
    from .slope import slope_block

    d = cell_size(dem_path)
    map_raster(dem_path, slope_path, lambda padded: slope_block(padded, d, method), halo=1,
               dtype="float64", input_dtype=np.float64, crs=crs, cancelled=cancelled)
    return Path(slope_path)


def read_back(path, crs: CRS) -> Grid:
    """A raster a run wrote (float64 with its nodata, or breakpoints: uint8, nodata 255) as the
    Grid the steps in memory give: float64 with NaN, breakpoints 0 or 1."""
    import rasterio

    from .io import _read_band

    with rasterio.open(path) as src:
        if np.dtype(src.dtypes[0]) == np.uint8:
            values = src.read(1)
            values[values == src.nodata] = 0
        else:
            values = _read_band(src)
        return Grid(values, src.transform, crs)


def write_front_rasters(files: dict, out) -> None:
    """slope.tif (float32, as ``io.write_raster`` writes the slope in memory) and
    breakpoints.tif of a run into ``out``, block by block from ``files`` (``slope``,
    ``breakpoints``: the float64 slope and the breakpoints files)."""
    import shutil

    from .blocks import map_raster

    map_raster(files["slope"], Path(out) / "slope.tif", lambda padded: padded, halo=0,
               input_dtype=np.float64)
    shutil.copyfile(files["breakpoints"], Path(out) / "breakpoints.tif")


# ---------------------------------------------------------------------------------------------
# DEM tiles
def read_dem_tiles(inputs, *, crs=None) -> Grid:
    """Several GeoTIFF DEM tiles (a folder, glob or list) as one Grid, after checking each: one
    CRS in metres, the same cell size, cells aligned across tiles."""
    import rasterio
    from rasterio.merge import merge

    from .limits import check_memory
    from .raster import check_transform

    paths = expand_tiles(inputs)
    if tile_kind(paths[0]) != "dem":
        raise FloodMeshError("expected DEM tiles (GeoTIFF); these are point tiles")
    first, sources = None, []
    with contextlib.ExitStack() as stack:
        for path in paths:
            name = path.name
            try:
                src = stack.enter_context(rasterio.open(path))
            except rasterio.errors.RasterioIOError as exc:
                raise FloodMeshError(f"tile {name} is not a readable raster ({exc}): replace it "
                                     "or leave it out") from None
            check_transform(src.transform, f"tile {name}")
            tile_crs = require_metric_crs(crs if crs is not None else
                                          (src.crs.to_wkt() if src.crs else None),
                                          f"tile {name}", kind="raster")
            if first is None:
                first = (name, tile_crs, src.transform)
            else:
                if not tile_crs.equals(first[1], ignore_axis_order=True):
                    raise FloodMeshError(
                        f"tile {name} is in {tile_crs.name}, but tile {first[0]} is in "
                        f"{first[1].name}: all tiles must share one CRS; reproject {name} first "
                        "(gdalwarp -t_srs EPSG:XXXX IN OUT)")
                t, t0 = src.transform, first[2]
                offset = ((t.c - t0.c) / t0.a, (t.f - t0.f) / t0.e)
                if not np.isclose(t.a, t0.a, rtol=1e-9) or not all(
                        abs(o - round(o)) < 1e-6 for o in offset):
                    raise FloodMeshError(
                        f"tile {name} has cells of {t.a:g} m at ({t.c:g}, {t.f:g}), not on the "
                        f"grid of tile {first[0]} ({t0.a:g} m cells): resample it onto that "
                        f"grid first (gdalwarp -tr {t0.a:g} {t0.a:g} -tap IN OUT)")
            sources.append(src)
        xmin = min(s.bounds.left for s in sources)
        xmax = max(s.bounds.right for s in sources)
        ymin = min(s.bounds.bottom for s in sources)
        ymax = max(s.bounds.top for s in sources)
        d = first[2].a
        check_memory(cells=int(math.ceil((xmax - xmin) / d) * math.ceil((ymax - ymin) / d)),
                     advice="resample the DEM tiles to larger cells")
        mosaic, transform = merge(sources, nodata=np.nan, dtype="float64")
    values = mosaic[0].astype(np.float64)
    values[~np.isfinite(values)] = np.nan
    if not np.isfinite(values).any():
        raise FloodMeshError("the DEM tiles have no valid cells: check their nodata value")
    return Grid(values, transform, first[1])
