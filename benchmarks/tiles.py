"""A river reach as 1 km² LAZ tiles: wall time and peak memory of gridding it tile by tile on a
local Dask cluster as the area grows, one file against tiles of the same 4 km² (identical
DEMs), the whole chain on the same 4 km² as tiles read in memory (the default where they fit)
against one file, and the 100 km² survey projected from the largest area measured. Prints a
table.

    nice .venv/bin/python benchmarks/tiles.py [--areas 1,4,16,36] [--run 1,4]
                 [--data /var/tmp/floodmesh-bench] [--workers 2] [--density 9] [--clean]

The synthetic floodplain (9 ground points/m², 5 cm noise: a sinuous river with levees in every
1 km band, a road embankment every 2 km, undulating ground) is generated once into ``--data``
(outside the repository; about 60 MB per 1 km² tile, 2.2 GB for 36 km²) and kept there, so a
rerun measures the chain, not the generator; ``--clean`` removes it at the end. Each area is
gridded on a local cluster (``floodmesh grid --scheduler local``); the areas of ``--run`` also
go through the whole chain (``floodmesh run --scheduler local``), whose report's step times are
printed too. With 4 km² in ``--run``, ``floodmesh run`` of its tiles by default (read in memory)
and of one LAZ file of the same points are timed in turn. Peak memory is the largest sum
of the resident memory of the command and its Dask worker processes, sampled every 0.1 s, and
the command's own peak beside it (the part that grows with the area: after gridding it holds
the whole-raster state); CPU seconds are theirs too (user + system), the measure of work when
the machine is shared.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

FLOODMESH = str(Path(sys.executable).parent / "floodmesh")
CRS = "EPSG:25832"
ORIGIN = (600_000.0, 5_700_000.0)
TILE = 1000.0
LOCAL = ["--scheduler", "local"]  # the tile rows measure the local cluster, whatever fits


def ground(x, y):
    """Elevation (m) at local x, y (m): river with levees each 1 km band, roads every 2 km."""
    z = 20.0 + 0.001 * x + 0.15 * np.sin(x / 23.0) * np.cos(y / 31.0)
    centre = 500.0 + 120.0 * np.sin(2 * np.pi * x / 1700.0)
    r = np.abs((y % TILE) - centre)  # across-channel distance (vertical, close enough)
    z += np.where(r < 60, -2.5 * np.clip((12.0 - r) / 5.0, 0, 1), 0.0)        # channel 1:2
    z += 1.8 * np.clip(1 - np.abs(r - 47.0) / 5.4, 0, 1)                      # levees 1:3
    road = np.abs((x % 2000.0) - 1000.0 - 0.1 * (y % 2000.0))
    z += 1.5 * np.clip((7.0 - road) / 3.0, 0, 1)                                # roads 1:2
    return z


def make_tile(path: Path, col: int, row: int, density: float, seed: int):
    import laspy

    rng = np.random.default_rng([seed, col, row])
    n = int(density * TILE * TILE)
    x = rng.uniform(0, TILE, n) + col * TILE
    y = rng.uniform(0, TILE, n) + row * TILE
    z = ground(x, y) + rng.normal(0, 0.05, n)
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.offsets = [ORIGIN[0] + col * TILE, ORIGIN[1] + row * TILE, 0.0]
    header.scales = [0.001, 0.001, 0.001]
    from pyproj import CRS as PyCRS

    header.add_crs(PyCRS.from_user_input(CRS))
    las = laspy.LasData(header)
    las.x, las.y, las.z = x + ORIGIN[0], y + ORIGIN[1], z
    las.classification = np.full(n, 2, np.uint8)
    tmp = path.with_suffix(".partial.laz")
    las.write(str(tmp))
    tmp.rename(path)


TILE_BYTES = 62e6  # one 9 points/m² LAZ tile, as generated


def tiles_for(data: Path, area_km2: int, density: float) -> list[Path]:
    """The tiles of a square of ``area_km2`` (generated where missing, after checking the
    disk has room for them)."""
    side = int(math.isqrt(area_km2))
    if side * side != area_km2:
        raise SystemExit(f"areas are squares (1, 4, 9, 16, 25, 36 km²), got {area_km2}")
    missing = sum(not (data / f"tile_{c:02d}_{r:02d}.laz").exists()
                  for c in range(side) for r in range(side))
    need = missing * TILE_BYTES * density / 9 + 2e9  # tiles, outputs and a margin
    free = shutil.disk_usage(data).free
    if missing and free < need:
        raise SystemExit(f"{data} has {free / 1e9:.1f} GB free, the {missing} missing tiles of "
                         f"{area_km2} km² and the outputs need about {need / 1e9:.1f} GB: give "
                         "--data on a larger disk or fewer --areas")
    paths = []
    for col in range(side):
        for row in range(side):
            path = data / f"tile_{col:02d}_{row:02d}.laz"
            if not path.exists():
                start = time.perf_counter()
                make_tile(path, col, row, density, seed=0)
                print(f"  generated {path.name} in {time.perf_counter() - start:.0f} s",
                      file=sys.stderr, flush=True)
            paths.append(path)
    return paths


def tile_folder(data: Path, area_km2: int, tiles: list[Path]) -> Path:
    """A folder of links to the tiles of one area: the tile route even for a single tile."""
    folder = data / f"area_{area_km2}"
    folder.mkdir(exist_ok=True)
    for path in tiles:
        link = folder / path.name
        if not link.exists():
            link.symlink_to(path)
    return folder


def one_file(data: Path, tiles: list[Path]) -> Path:
    """The tiles' points as one LAZ file (written once, kept with the tiles)."""
    import laspy

    single = data / "single_4km2.laz"
    if not single.exists():
        with laspy.open(tiles[0]) as first:
            header = first.header
        with laspy.open(single, mode="w", header=header) as writer:
            for path in tiles:
                with laspy.open(path) as reader:
                    for chunk in reader.chunk_iterator(2_000_000):
                        writer.write_points(chunk)
    return single


def project(rows: list, area: int = 100) -> None:
    """The survey of ``area`` km² (1 km² tiles) projected from the largest area measured of each
    kind on a local cluster: wall and CPU linear in the area; for the gridding, the command's own
    memory linear through the two largest and the workers' flat. The whole chain's memory is
    not projected: past what memory holds its terrain fits leave the points read back for the
    DEM's cell centres (see RESULTS.md)."""
    for kind in ("grid tiles", "run tiles"):
        measured_rows = sorted((r for r in rows if r[0] == kind), key=lambda r: r[1])
        if len(measured_rows) < 2:
            continue
        (_, a0, _, w0, c0, p0, o0), (_, a1, n1, w1, c1, p1, o1) = measured_rows[-2:]
        memory = ""
        if kind == "grid tiles":
            own = o1 + (o1 - o0) / (a1 - a0) * (area - a1)
            memory = (f", the command {own:,.0f} MB, command and workers "
                      f"{p1 - o1 + own:,.0f} MB")
        print(f"{kind} projected to {area} km² ({area} tiles, {n1 / a1 * area / 1e6:,.0f} M "
              f"points) from {a1} km² (the largest measured): wall {w1 / a1 * area:,.0f} s, "
              f"CPU {c1 / a1 * area:,.0f} s{memory}")


def measured(command: list[str]) -> tuple[float, float, float, float, str]:
    """(wall seconds, CPU seconds of the command and its workers, peak MB of the process tree's
    summed RSS, peak MB of the command's own RSS, stdout) of a command. The command's own peak
    is the part that grows with the area (after gridding it holds the whole-raster state)."""
    import resource

    import psutil

    def cpu():
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    cpu0 = cpu()
    start = time.perf_counter()
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    top = psutil.Process(proc.pid)
    peak = own = 0
    while proc.poll() is None:
        try:
            tree = [top] + top.children(recursive=True)
            peak = max(peak, sum(p.memory_info().rss for p in tree if p.is_running()))
            own = max(own, top.memory_info().rss)
        except psutil.Error:
            pass
        time.sleep(0.1)
    out, err = proc.communicate()
    if proc.returncode:
        raise SystemExit(f"{' '.join(command)} failed:\n{err}")
    return time.perf_counter() - start, cpu() - cpu0, peak / 1e6, own / 1e6, out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--areas", default="1,4,16,36",
                        help="km² gridded, squares (default 1,4,16,36)")
    parser.add_argument("--data", default="/var/tmp/floodmesh-bench",
                        help="tile cache, kept between runs (default /var/tmp/floodmesh-bench)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--density", type=float, default=9.0)
    parser.add_argument("--run", default="1,4",
                        help="km² also run through the whole chain (default 1,4)")
    parser.add_argument("--clean", action="store_true",
                        help="remove the generated tiles at the end")
    args = parser.parse_args()
    data = Path(args.data)
    data.mkdir(parents=True, exist_ok=True)
    out = data / f"out-{os.getpid()}"  # this run's outputs, removed at the end
    out.mkdir(exist_ok=True)
    areas = [int(a) for a in args.areas.split(",") if a]
    chain = [int(a) for a in args.run.split(",") if a]
    rows, steps = [], []
    try:
        for area in sorted(set(areas) | set(chain)):
            tiles = tiles_for(data, area, args.density)
            points = int(args.density * 1e6 * area)
            folder = str(tile_folder(data, area, tiles))
            if area in areas:
                seconds, cpu, peak, own, _ = measured([FLOODMESH, "grid", folder, "--cell-size",
                                                  "1", "--workers", str(args.workers),
                                                  *LOCAL, "--out", str(out / f"dem_{area}.tif")])
                rows.append(("grid tiles", area, points, seconds, cpu, peak, own))
                print(f"  grid {area} km²: {seconds:.0f} s, {peak:.0f} MB", file=sys.stderr,
                      flush=True)
            if area in chain:
                seconds, cpu, peak, own, _ = measured([FLOODMESH, "run", folder,
                                                  "--workers", str(args.workers), *LOCAL,
                                                  "--out", str(out / f"run_{area}")])
                rows.append(("run tiles", area, points, seconds, cpu, peak, own))
                report = json.loads((out / f"run_{area}" / "report.json").read_text())
                steps.append((area, report["seconds"], report["triangles"]))
                shutil.rmtree(out / f"run_{area}")
                print(f"  run {area} km²: {seconds:.0f} s, {peak:.0f} MB", file=sys.stderr,
                      flush=True)
        # one file against tiles: the same 4 km², the same DEM
        compare = None
        if 4 in chain:  # the whole chain: tiles in memory (the default) against one file
            single = one_file(data, tiles_for(data, 4, args.density))
            folder = str(tile_folder(data, 4, tiles_for(data, 4, args.density)))
            for what, source in (("run tiles, in memory", folder), ("run one file (peer)",
                                                                   str(single))):
                seconds, cpu, peak, own, _ = measured([FLOODMESH, "run", source, "--workers",
                                                      str(args.workers), "--out",
                                                      str(out / "run_pair")])
                rows.append((what, 4, int(args.density * 4e6), seconds, cpu, peak, own))
                shutil.rmtree(out / "run_pair")
        if 4 in areas:  # needs the tiles' DEM of 4 km²
            single = one_file(data, tiles_for(data, 4, args.density))
            seconds, cpu, peak, own, _ = measured([FLOODMESH, "grid", str(single), "--cell-size",
                                              "1", "--out", str(out / "dem_single_4.tif")])
            rows.append(("grid one file (peer)", 4, int(args.density * 4e6), seconds, cpu,
                         peak, own))
            from floodmesh.core import io

            a = io.read_raster(out / "dem_single_4.tif")
            b = io.read_raster(out / "dem_4.tif")
            same_nan = a.shape == b.shape and np.array_equal(np.isnan(a.values),
                                                              np.isnan(b.values))
            compare = (a.transform == b.transform, same_nan,
                       float(np.nanmax(np.abs(a.values - b.values))) if same_nan else math.nan,
                       a.shape)
    finally:
        shutil.rmtree(out, ignore_errors=True)
        if args.clean:
            shutil.rmtree(data, ignore_errors=True)
    print(f"\n## A floodplain as 1 km² LAZ tiles, {args.density:g} points/m², 1 m DEM, "
          f"{args.workers} local Dask workers")
    print(f"{'what':<22}{'km²':>5}{'points':>14}{'wall s':>9}{'CPU s':>9}{'CPU s/km²':>11}"
          f"{'peak RSS MB':>13}{'command MB':>12}")
    for what, area, points, seconds, cpu, peak, own in rows:
        print(f"{what:<22}{area:>5}{points:>14,}{seconds:>9.1f}{cpu:>9.1f}{cpu / area:>11.1f}"
              f"{peak:>13.0f}{own:>12.0f}")
    for area, seconds, triangles in steps:
        print(f"run {area} km² ({triangles:,} triangles), seconds per step: " + ", ".join(
            f"{name} {value:.0f}" for name, value in seconds.items() if value >= 0.5))
    project(rows)
    if compare:
        same_transform, same_nan, diff, shape = compare
        print(f"4 km² one file vs tiles: DEM {shape[1]} x {shape[0]} cells, same georeference "
              f"{same_transform}, same nodata cells {same_nan}, max |difference| {diff:.3g} m")


if __name__ == "__main__":
    main()
