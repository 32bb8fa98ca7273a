"""Speed and quality figures, each against a peer in the same run. Prints a table per topic.

    .venv/bin/python benchmarks/run.py [--only slopefile,gridfile,run,codec,grid,slope,...]
                                       [--file-sizes 6000,10000] [--grid-points N]
                                       [--run-points N] [--codec-size N] [--points N]
                                       [--size N] [--breakpoints N]

slopefile: `floodmesh slope` file to file vs `gdaldem slope` on the same DEM file, whole
           processes (start-up included), alternating, best of 3, with peak RSS of both.
gridfile:  `floodmesh grid` vs `gdal_grid -a linear` on the same CSV points and 1 m grid.
run:       `floodmesh run` on one LAZ (9 M points: 1 km² at 9 points/m²), per step and whole,
           with peak RSS, against laspy reading the file (the floor) and two peers' TIN
           gridding of it (whitebox_workflows, startinpy).
codec:     GeoTIFF codecs and predictors on DEM, slope and breakpoints (how the output codec
           was chosen).
grid:  FloodMesh TIN gridding vs scipy.interpolate.griddata (linear, the same Qhull TIN).
slope: every slope method vs GDAL's own slope (Horn, ZevenbergenThorne) on one grid, in memory.
trace: break-line tracing throughput (breakpoints per second) vs scipy's component labelling.
lines: recall, precision and pieces per true line against the demo's known break lines.
mesh:  break-line mesh vs a uniform Triangle mesh on the demo floodplain (nodes and RMSE).

Whole-process timings are wall-clock on a machine others may share: the commands alternate and
the best of 3 counts; CPU seconds (user + system, all threads) are printed beside them.
"""
from __future__ import annotations

import argparse
import contextlib
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from affine import Affine
from pyproj import CRS

sys.path.insert(0, str(Path(__file__).resolve().parent.parent.parent))

from floodmesh.core.raster import Grid  # noqa: E402

CRS_M = CRS.from_epsg(25832)


def timed(func, *args, repeat=1, **kwargs):
    best, result = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = func(*args, **kwargs)
        best = min(best, time.perf_counter() - start)
    return best, result


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def bench_grid(n_points):
    from scipy.interpolate import griddata

    from floodmesh.core.frontends.demo import ground_elevation
    from floodmesh.core.steps.grid import grid_points_linear
    from floodmesh.core.points import PointCloud

    side = np.sqrt(n_points / 9.0)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, side, n_points), rng.uniform(0, side, n_points)
    xyz = np.column_stack([x + 400_000, y + 5_600_000, ground_elevation(x % 300, y % 240)])
    cloud = PointCloud(xyz, CRS_M)
    corner = (x < 20) & (y < 20)  # compile outside the timing, on points as dense as the rest
    grid_points_linear(PointCloud(xyz[corner], CRS_M), 1.0)
    t_ours, dem = timed(grid_points_linear, cloud, 1.0)
    rows, cols = dem.shape
    gx, gy = dem.cell_centres(*np.indices((rows, cols)))
    peer_n = min(n_points, 1_000_000)  # Qhull needs minutes for millions of points
    sub = xyz[:peer_n]
    t_peer, ref = timed(griddata, sub[:, :2] - sub[0, :2], sub[:, 2], (gx - sub[0, 0], gy - sub[0, 1]),
                        method="linear")
    ours_sub = grid_points_linear(PointCloud(sub, CRS_M), 1.0, max_gap=1e9)
    sub_dem_ok = ours_sub.shape == dem.shape
    both = np.isfinite(ref) & np.isfinite(ours_sub.values) if sub_dem_ok else None
    print(f"\n## Gridding {n_points:,} points ({side:.0f} m square, 9 points/m²) to a 1 m grid")
    print(f"{'method':<34}{'seconds':>10}{'Mpoints/s':>12}")
    print(f"{'floodmesh grid_points_linear':<34}{t_ours:>10.2f}{n_points / t_ours / 1e6:>12.3f}")
    print(f"{'scipy griddata linear (peer)':<34}{t_peer:>10.2f}{peer_n / t_peer / 1e6:>12.3f}"
          f"   ({peer_n:,} points)")
    diff = (f"{np.abs(ref[both] - ours_sub.values[both]).max():.2e} m" if sub_dem_ok
            else "n/a (different extent)")
    print(f"speed ratio ours/peer {(n_points / t_ours) / (peer_n / t_peer):.1f}; max |difference| "
          f"on the peer's points {diff}; peak RSS "
          f"{peak_rss_mb():.0f} MB")


def bench_slope(size):
    from osgeo import gdal

    from floodmesh.core import io
    from floodmesh.core.steps.slope import SLOPE_METHODS, slope

    gdal.UseExceptions()
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    z = 20 + 3 * np.sin(xx / 37) * np.cos(yy / 53) + rng.normal(0, 0.05, (size, size))
    dem = Grid(z, Affine(1.0, 0, 400000, 0, -1.0, 5600000 + size), CRS_M)
    with tempfile.TemporaryDirectory() as tmp:
        src = str(Path(tmp) / "dem.tif")
        io.write_raster(src, dem)
        # both sides work memory to memory: GDAL reads an in-memory copy and writes to MEM
        mem = gdal.Translate("", src, format="MEM")
        gdal_times = {}
        for alg in ("Horn", "ZevenbergenThorne"):
            gdal_times[alg], _ = timed(gdal.DEMProcessing, "", mem, "slope", alg=alg,
                                       computeEdges=True, format="MEM", repeat=3)
        print(f"\n## Slope on a {size} x {size} grid, in memory (best of 3)")
        print(f"{'method':<22}{'seconds':>10}{'GDAL peer':>12}{'GDAL/ours':>12}")
        peers = {"sharpnack-akin": "Horn", "zevenbergen-thorne": "ZevenbergenThorne"}
        slope(Grid(z[:8, :8], dem.transform, CRS_M))  # compile outside the timing
        for method in SLOPE_METHODS:
            t, _ = timed(slope, dem, method, repeat=3)
            peer = peers.get(method)
            if peer:
                print(f"{method:<22}{t:>10.2f}{gdal_times[peer]:>12.2f}{gdal_times[peer] / t:>12.2f}")
            else:
                print(f"{method:<22}{t:>10.2f}{'-':>12}{'-':>12}")


def synthetic_dem_file(path, size, *, noise=0.02, strip=500):
    """A smooth float32 DEM (rolling ground, 2 cm noise) of ``size``² 1 m cells, written in
    strips in FloodMesh's own GeoTIFF format, as ``floodmesh grid`` writes it."""
    import rasterio

    from floodmesh.core.io import raster_profile

    rng = np.random.default_rng(0)
    transform = Affine(1.0, 0, 400000, 0, -1.0, 5600000 + size)
    with rasterio.open(path, "w", **raster_profile((size, size), transform, CRS_M, "float32",
                                                   -9999.0)) as dst:
        for r0 in range(0, size, strip):
            h = min(strip, size - r0)
            yy, xx = np.mgrid[r0:r0 + h, 0:size].astype(np.float32)
            z = 20 + 3 * np.sin(xx / 37) * np.cos(yy / 53) + rng.normal(0, noise, (h, size))
            dst.write(z.astype(np.float32), 1, window=rasterio.windows.Window(0, r0, size, h))


def run_process(args):
    """(wall seconds, CPU seconds, peak RSS MB) of one whole process, start-up included.

    Linux counts the forking parent's resident memory into a child's peak (ru_maxrss survives
    exec), so the parent stays small: big inputs are made in a child (``in_child``)."""
    import os
    import subprocess

    start = time.perf_counter()
    proc = subprocess.Popen([str(a) for a in args], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"{args[0]} failed with exit code {proc.returncode}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def in_child(func_name, *args):
    """Run this module's ``func_name(*args)`` in a child process (keeps this one small)."""
    import subprocess

    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import run; "
            f"run.{func_name}(*{tuple(str(a) for a in args)!r})")
    sys.stdout.flush()  # its lines after ours
    subprocess.run([sys.executable, "-c", code], check=True)


def make_dem_file(path, size):
    synthetic_dem_file(Path(path), int(size))


def print_difference(ours, peer):
    """Max |ours − peer| over interior cells of rows 1-500 (in a child: keeps this one small)."""
    import rasterio

    with rasterio.open(ours) as a, rasterio.open(peer) as b:
        window = rasterio.windows.Window(1, 1, a.width - 2, min(500, a.height - 2))
        diff = np.abs(a.read(1, window=window).astype(float) - b.read(1, window=window))
    print(f"{'':<13}max |difference| from gdaldem in rows 1-500: {diff.max():.1e}°", flush=True)


def floodmesh_command():
    exe = Path(sys.executable).with_name("floodmesh")
    return [exe] if exe.exists() else [sys.executable, "-m", "floodmesh.core.frontends.cli"]


def bench_slope_file(sizes, repeat=3):
    """``floodmesh slope`` file to file against ``gdaldem slope`` on the same DEM file, each a
    whole process (start-up included), alternating, best of ``repeat``, with peak RSS."""
    print(f"\n## Slope file to file, whole processes, alternating, best of {repeat} "
          "(bar: 2x faster than gdaldem, peak RSS at most gdaldem's + 50 %)")
    print(f"{'DEM':<13}{'command':<44}{'wall s':>8}{'CPU s':>7}{'peak MB':>9}"
          f"{'speed vs gdaldem':>18}{'RSS vs gdaldem':>16}")
    pairs = (("sharpnack-akin", "Horn"), ("zevenbergen-thorne", "ZevenbergenThorne"))
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as tmp:
        for size in sizes:
            dem = Path(tmp) / "dem.tif"
            in_child("make_dem_file", dem, size)
            for method, alg in pairs[:1] if size > 6000 else pairs:
                ours = floodmesh_command() + ["slope", dem, "--method", method, "--out",
                                              Path(tmp) / "ours.tif"]
                peer = ["gdaldem", "slope", "-alg", alg, "-q", dem, Path(tmp) / "gdal.tif"]
                run_process(ours)  # loads numba's cache and the file into the page cache
                runs = {"ours": [], "peer": []}
                for _ in range(repeat):
                    runs["ours"].append(run_process(ours))
                    runs["peer"].append(run_process(peer))
                best = {k: min(v) for k, v in runs.items()}
                rss = {k: min(r[2] for r in v) for k, v in runs.items()}
                cpu = {k: min(r[1] for r in v) for k, v in runs.items()}
                for key, label in (("ours", f"floodmesh slope --method {method}"),
                                   ("peer", f"gdaldem slope -alg {alg}")):
                    ratio = (f"{best['peer'][0] / best['ours'][0]:>17.2f}x"
                             f"{rss['ours'] / rss['peer']:>15.2f}x" if key == "ours" else "")
                    print(f"{f'{size}²':<13}{label:<44}"
                          f"{best[key][0]:>8.2f}{cpu[key]:>7.2f}{rss[key]:>9.0f}{ratio}")
                    # Linux counts the parent's peak into a child's: it must stay below
                    assert rss[key] > peak_rss_mb(), f"this process's {peak_rss_mb():.0f} MB " \
                        "hides the child's peak RSS"
                in_child("print_difference", Path(tmp) / "ours.tif", Path(tmp) / "gdal.tif")


CODECS = (("none", {}), ("DEFLATE (before)", dict(compress="deflate")),
          ("LZW + predictor", dict(compress="lzw", predictor="PRED")),
          ("ZSTD 1", dict(compress="zstd", zstd_level=1)),
          ("ZSTD 1 + predictor", dict(compress="zstd", zstd_level=1, predictor="PRED")),
          ("ZSTD 3 + predictor", dict(compress="zstd", zstd_level=3, predictor="PRED")))


def bench_codec(size, repeat=3):
    """GeoTIFF codecs on FloodMesh's rasters (DEM, slope, breakpoints): write and read time
    (wall and CPU, GDAL's NUM_THREADS on) and size, best of ``repeat``: how the output codec
    was chosen."""
    import os

    import rasterio

    from floodmesh.core.io import TILE
    from floodmesh.core.steps.breakpoints import classify_breakpoints
    from floodmesh.core.steps.slope import slope

    with tempfile.TemporaryDirectory(dir=Path.cwd()) as tmp:
        synthetic_dem_file(Path(tmp) / "dem.tif", size)
        with rasterio.open(Path(tmp) / "dem.tif") as src:
            z = src.read(1)
        dem = Grid(z, Affine(1.0, 0, 400000, 0, -1.0, 5600000 + size), CRS_M)
        s = slope(dem, "one-over-distance").values.astype(np.float32)
        rasters = {"DEM": (z, 3), "slope": (s, 3),
                   "breakpoints": (classify_breakpoints(dem.with_values(s), 10.0).values, 2)}
        print(f"\n## GeoTIFF codecs, {size}² tiled {TILE}², NUM_THREADS=ALL_CPUS "
              f"(best of {repeat})")
        print(f"{'raster':<13}{'codec':<22}{'write s':>8}{'CPU s':>7}{'read s':>8}{'MB':>8}")
        for name, (values, predictor) in rasters.items():
            for label, options in CODECS:
                options = {k: (predictor if v == "PRED" else v) for k, v in options.items()}
                if name == "breakpoints" and options.get("predictor") == 3:
                    continue
                path = Path(tmp) / "out.tif"
                profile = dict(driver="GTiff", height=size, width=size, count=1,
                               dtype=values.dtype, crs=CRS_M.to_wkt(),
                               transform=dem.transform, tiled=True, blockxsize=TILE,
                               blockysize=TILE, num_threads="ALL_CPUS", **options)
                wall = cpu = read = np.inf
                for _ in range(repeat):
                    t, c = time.perf_counter(), time.process_time()
                    with rasterio.open(path, "w", **profile) as dst:
                        dst.write(values, 1)
                    wall = min(wall, time.perf_counter() - t)
                    cpu = min(cpu, time.process_time() - c)
                    t = time.perf_counter()
                    with rasterio.Env(GDAL_NUM_THREADS="ALL_CPUS"), rasterio.open(path) as src:
                        src.read(1)
                    read = min(read, time.perf_counter() - t)
                print(f"{name:<13}{label:<22}{wall:>8.2f}{cpu:>7.2f}{read:>8.2f}"
                      f"{os.path.getsize(path) / 1e6:>8.0f}")


def synthetic_points(n_points, seed=0):
    """(n, 3) points at 9 per m² over a square, on the demo floodplain's terrain repeated."""
    from floodmesh.core.frontends.demo import ground_elevation

    side = np.sqrt(n_points / 9.0)
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, side, n_points), rng.uniform(0, side, n_points)
    return np.column_stack([x + 400_000, y + 5_600_000, ground_elevation(x % 300, y % 240)
                            + rng.normal(0, 0.03, n_points)])


def bench_grid_file(n_points, repeat=3):
    """``floodmesh grid`` against ``gdal_grid -a linear`` (GDAL's Delaunay TIN) on the same
    CSV points and the same 1 m grid, whole processes, alternating, best of ``repeat``."""
    import rasterio

    from floodmesh.core import io

    xyz = synthetic_points(n_points)
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as tmp:
        tmp = Path(tmp)
        np.savetxt(tmp / "points.csv", xyz, fmt="%.3f", delimiter=",", header="x,y,z",
                   comments="")
        (tmp / "points.vrt").write_text(
            '<OGRVRTDataSource><OGRVRTLayer name="points"><SrcDataSource>'
            f'{tmp / "points.csv"}</SrcDataSource><GeometryType>wkbPoint</GeometryType>'
            '<LayerSRS>EPSG:25832</LayerSRS><GeometryField encoding="PointFromColumns" x="x" '
            'y="y" z="z"/></OGRVRTLayer></OGRVRTDataSource>')
        ours = floodmesh_command() + ["grid", tmp / "points.csv", "--crs", "EPSG:25832",
                                      "--cell-size", 1, "--max-gap", 1e6, "--out",
                                      tmp / "ours.tif"]
        run_process(ours)
        with rasterio.open(tmp / "ours.tif") as src:
            (x0, y0, x1, y1), rows, cols = src.bounds, src.height, src.width
        peer = ["gdal_grid", "-q", "-a", "linear", "-ot", "Float32", "-txe", x0, x1, "-tye", y1,
                y0, "-outsize", cols, rows, "-l", "points", tmp / "points.vrt", tmp / "gdal.tif"]
        runs = {"ours": [], "peer": []}
        for _ in range(repeat):
            runs["ours"].append(run_process(ours))
            runs["peer"].append(run_process(peer))
        a = io.read_raster(tmp / "ours.tif").values
        with rasterio.open(tmp / "gdal.tif") as src:
            b = src.read(1).astype(float)
            b[b == src.nodata] = np.nan
    both = np.isfinite(a) & np.isfinite(b)
    best = {k: min(v) for k, v in runs.items()}
    print(f"\n## Gridding {n_points:,} CSV points (9 points/m²) to a {cols} x {rows} 1 m grid, "
          f"whole processes, alternating, best of {repeat}")
    print(f"{'command':<34}{'wall s':>8}{'CPU s':>7}{'peak MB':>9}")
    for key, label in (("ours", "floodmesh grid"), ("peer", "gdal_grid -a linear (peer)")):
        wall, cpu, rss = best[key]
        print(f"{label:<34}{wall:>8.2f}{cpu:>7.2f}{rss:>9.0f}")
    diff = np.abs(a[both] - b[both])
    print(f"speed ratio gdal_grid/ours {best['peer'][0] / best['ours'][0]:.1f}x; |difference| on "
          f"{both.sum():,} common cells: median {np.median(diff):.1e} m, 99.9 % "
          f"{np.percentile(diff, 99.9):.1e} m, max {diff.max():.1e} m (ours is the points' Delaunay "
          "TIN: scipy griddata's to 1e-7 m, see `grid`; gdal_grid's linear surface is not)")


# laspy's arrays are numpy's, which asks the kernel for huge pages; where the kernel compacts
# memory to give them (defrag = madvise, Debian's default) the read stalls by 0.5-1.5 s in some
# runs. floodmesh runs without the request (engine.arrays.without_huge_pages): the floor is
# also timed so, the stricter bar
SMALL_PAGES = {"NUMPY_MADVISE_HUGEPAGE": "0"}

READ_FLOOR = """
import sys, time
import laspy, numpy as np
start = time.perf_counter()
las = laspy.read(sys.argv[1])  # lazrs, in parallel where installed (laspy's default)
xyz = [np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)]
print(time.perf_counter() - start)
"""

PEER_WHITEBOX = """
import sys, time
import whitebox_workflows as wbw
start = time.perf_counter()
wbe = wbw.WbEnvironment()
wbe.verbose = False
grid = wbe.lidar.interpolation_gridding.lidar_tin_gridding(
    input=wbe.read_lidar(sys.argv[1]), resolution=1.0, max_triangle_edge_length=10.0,
    excluded_classes=[c for c in range(32) if c != 2])
wbe.write_raster(grid, sys.argv[2])
print(time.perf_counter() - start)
"""

PEER_STARTIN = """
import sys, time
import laspy, numpy as np, startinpy
start = time.perf_counter()
las = laspy.read(sys.argv[1])
ground = np.asarray(las.classification) == 2
pts = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])[ground]
# inserted in 10 m bands (its walk to each new point is short then: 8x faster than file order)
pts = pts[np.lexsort((pts[:, 0], np.floor(pts[:, 1] / 10.0)))]
dt = startinpy.DT()
dt.insert(pts)
x0, y1 = np.floor(pts[:, 0].min()), np.ceil(pts[:, 1].max())
cols, rows = int(np.ceil(pts[:, 0].max() - x0)), int(np.ceil(y1 - pts[:, 1].min()))
yy, xx = np.mgrid[0:rows, 0:cols]
z = dt.interpolate({"method": "TIN"}, np.column_stack([x0 + xx.ravel() + 0.5,
                                                       y1 - yy.ravel() - 0.5]))
print(time.perf_counter() - start)
"""


def timed_script(script, *args, env=None):
    """(seconds the script prints, whole-process wall s, CPU s, peak RSS MB) of ``script`` run
    by this Python in a process of its own (with ``env`` added to the environment)."""
    import os
    import subprocess

    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", script, *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            env={**os.environ, **(env or {})})
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status):
        return None
    return (float(out.split()[-1]), wall, usage.ru_utime + usage.ru_stime,
            usage.ru_maxrss / 1024)


def bench_run(n_points, repeat=2, peers=True):
    """``floodmesh run`` on one LAZ of ``n_points`` (9 per m²: 1 km² for 9 M) against the floor
    of reading it (laspy with lazrs: the file decompressed and x, y, z scaled), alternating,
    best of ``repeat`` each, with peak RSS and the report's seconds per step; then the TIN
    gridding alone of two peers on the same file, once (whitebox_workflows, startinpy: ``make
    bench`` installs them)."""
    import json
    import os

    import laspy

    # the LAZ takes minutes to write: kept in build/ (ignored by git) for the next run
    laz = Path(__file__).resolve().parent.parent / "build" / "bench" / f"points_{n_points}.laz"
    if not laz.exists() or laspy.open(laz).header.point_count != n_points:
        laz.parent.mkdir(parents=True, exist_ok=True)
        in_child("write_points_laz", laz, n_points)
    load = os.getloadavg()[0]
    floors, small_page_floors, runs = [], [], []
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as tmp:
        tmp = Path(tmp)
        for _ in range(repeat):
            floors.append(timed_script(READ_FLOOR, laz))
            small_page_floors.append(timed_script(READ_FLOOR, laz, env=SMALL_PAGES))
            runs.append(run_process(floodmesh_command() + ["run", laz, "--out", tmp / "out"]))
            report = json.loads((tmp / "out" / "report.json").read_text())
            runs[-1] += (report,)
        peer_rows = []
        for name, script in (("whitebox_workflows lidar_tin_gridding", PEER_WHITEBOX),
                             ("startinpy DT + TIN interpolation", PEER_STARTIN)) if peers else ():
            peer_rows.append((name, timed_script(script, laz, tmp / "peer.tif")))
    floor = min(floors, key=lambda f: f[0])
    small_page_floor = min(small_page_floors, key=lambda f: f[0])
    wall, cpu, rss, report = min(runs, key=lambda r: r[0])
    area = n_points / 9.0 / 1e6
    print(f"\n## floodmesh run, one LAZ of {n_points:,} points ({area:.2f} km², 9 points/m²), "
          f"reference case, against reading the file (goal: at most 6x, at most 3 GB); best of "
          f"{repeat}, alternating; load average {load:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end")
    print(f"{'':<44}{'wall s':>8}{'CPU s':>8}{'peak MB':>9}{'x floor':>9}")
    print(f"{'floor: laspy + lazrs reading x, y, z':<44}{floor[0]:>8.2f}{'':>8}{floor[3]:>9,.0f}"
          f"{1.0:>9.2f}   (whole process {floor[1]:.2f} s)")
    print(f"{'the same, numpy without huge pages':<44}{small_page_floor[0]:>8.2f}{'':>8}"
          f"{small_page_floor[3]:>9,.0f}{small_page_floor[0] / floor[0]:>9.2f}   (as floodmesh "
          f"runs; the run is {wall / small_page_floor[0]:.2f}x this)")
    print(f"{'floodmesh run (whole process)':<44}{wall:>8.2f}{cpu:>8.2f}{rss:>9,.0f}"
          f"{wall / floor[0]:>9.2f}")
    for name, result in peer_rows:
        if result is None:
            print(f"{name + ' (gridding only)':<44}  not installed or failed (make bench installs it)")
        else:
            print(f"{name + ' (gridding only)':<44}{result[1]:>8.2f}{result[2]:>8.2f}"
                  f"{result[3]:>9,.0f}{result[1] / floor[0]:>9.2f}")
    cpu_steps, seconds = report.get("cpu_seconds", {}), report["seconds"]
    background = set(report.get("steps_in_background", ()))
    total = sum(v for step, v in seconds.items() if step not in background)
    print(f"\n{'step of the best run':<28}{'wall s':>8}{'CPU s':>8}{'share':>8}")
    for step, value in seconds.items():
        name = f"{step} (background)" if step in background else step
        print(f"{name:<28}{value:>8.2f}{cpu_steps.get(step, float('nan')):>8.2f}"
              f"{value / wall:>8.0%}")
    print(f"{'start-up and between':<28}{wall - total:>8.2f}{'':>8}{(wall - total) / wall:>8.0%}")
    print("(background: on a second thread beside the steps that follow it; its time is not "
          "added to the whole)")
    print(f"{report['grid']['cols']} x {report['grid']['rows']} cells, {report['n_breaklines']} "
          f"break lines, {report['nodes']:,} nodes")


def write_points_laz(path, n_points):
    from floodmesh.core import io
    from floodmesh.core.points import PointCloud

    io.write_points_las(path, PointCloud(synthetic_points(int(n_points)), CRS_M))


def bench_trace(n_breakpoints):
    """Tracing ``n_breakpoints`` (about) on a dense net of ridges, against scipy's connected
    component labelling of the same breakpoints (one pass over the same cells: a floor)."""
    from scipy import ndimage

    from floodmesh.core.steps.breaklines import trace_breaklines
    from floodmesh.core.steps.breakpoints import classify_breakpoints
    from floodmesh.core.steps.slope import slope

    def ridges(size):
        yy, xx = np.mgrid[0:size, 0:size].astype(float)
        # ridges every 8 cells in both directions: a dense net of breakpoints
        z = 2.0 * np.abs(((xx + 0.5 * yy) % 16) - 8) / 8 + 1.5 * np.abs((yy % 12) - 6) / 6
        dem = Grid(z, Affine(1.0, 0, 0, 0, -1.0, size), CRS_M)
        s = slope(dem, "one-over-distance")
        return dem, s, classify_breakpoints(s, 10.0)

    dem, s, bp = ridges(200)
    trace_breaklines(bp, s, dem, 10.0)  # compile
    while bp.values.sum() < n_breakpoints:
        dem, s, bp = ridges(int(bp.shape[0] * np.sqrt(n_breakpoints / bp.values.sum())) + 8)
    t, lines = timed(trace_breaklines, bp, s, dem, 10.0, repeat=3)
    t_label, _ = timed(ndimage.label, bp.values, np.ones((3, 3)), repeat=3)
    n_bp = int(bp.values.sum())
    print(f"\n## Break-line tracing, {n_bp:,} breakpoints on a {bp.shape[1]} x {bp.shape[0]} grid")
    print(f"{'':<34}{'seconds':>9}{'M breakpoints/s':>17}")
    print(f"{'trace_breaklines (FloodMesh)':<34}{t:>9.2f}{n_bp / t / 1e6:>17.2f}"
          f"   ({len(lines):,} lines)")
    print(f"{'scipy.ndimage.label (peer, floor)':<34}{t_label:>9.2f}{n_bp / t_label / 1e6:>17.2f}")


def bench_lines(seeds=3):
    """Recall, precision and pieces per true line on the demo floodplain with 5 cm noise."""
    import shapely

    from floodmesh.core.frontends import demo
    from floodmesh.core.steps.breaklines import trace_breaklines
    from floodmesh.core.steps.breakpoints import classify_breakpoints
    from floodmesh.core.steps.grid import grid_points_linear
    from floodmesh.core.steps.slope import SLOPE_METHODS, slope
    from floodmesh.core.steps.validation import score_breaklines

    truth = [shapely.affinity.translate(g, *demo.DEMO_ORIGIN) for g in demo.true_breaklines()]
    print(f"\n## Break lines against the truth: demo floodplain, 9 points/m², 5 cm noise, 1 m grid,"
          f" S_crit 10°, within 2 cells, mean over {seeds} noise seeds (bars: 0.9, 0.9, < 3)")
    print(f"{'slope method':<22}{'joined':>7}{'recall':>8}{'precision':>10}{'pieces':>8}"
          f"{'max':>5}{'lines':>7}")
    dems = [grid_points_linear(demo.synthetic_floodplain(vegetation=0.0, seed=k)[0], 1.0)
            for k in range(seeds)]
    for method in SLOPE_METHODS:
        for join in (True, False):
            scores = []
            for dem in dems:
                s = slope(dem, method)
                lines = trace_breaklines(classify_breakpoints(s, 10.0), s, dem, 10.0, join=join)
                scores.append(score_breaklines([line.coords for line in lines], truth, 2.0))
            mean = {k: np.mean([sc[k] for sc in scores])
                    for k in ("recall", "precision", "mean_pieces", "n_traced")}
            worst = max(sc["max_pieces"] for sc in scores)
            print(f"{method:<22}{'yes' if join else 'no':>7}{mean['recall']:>8.3f}"
                  f"{mean['precision']:>10.3f}{mean['mean_pieces']:>8.2f}{worst:>5}"
                  f"{mean['n_traced']:>7.0f}")


def bench_mesh():
    from floodmesh.core.steps.accuracy import residuals
    from floodmesh.core.steps.breaklines import trace_breaklines
    from floodmesh.core.steps.breakpoints import classify_breakpoints
    from floodmesh.core.frontends.demo import synthetic_floodplain
    from floodmesh.core.steps.grid import grid_points_linear
    from floodmesh.core.steps.mesh import build_mesh
    from floodmesh.core.points import PointCloud, split_holdout
    from floodmesh.core.steps.simplify import simplify_keep_every
    from floodmesh.core.steps.slope import slope

    points, classes = synthetic_floodplain()
    ground = PointCloud(points.xyz[classes == 2], points.crs)
    gridding, holdout = split_holdout(ground, 0.01, 0)
    dem = grid_points_linear(gridding, 1.0)
    s = slope(dem, "one-over-distance")
    lines = trace_breaklines(classify_breakpoints(s, 10.0), s, dem, 10.0)
    coords = [line.coords for line in simplify_keep_every(lines, 4)]
    print("\n## Break-line mesh vs uniform mesh on the demo floodplain (25°)")
    print(f"{'mesh':<34}{'max area':>9}{'nodes':>8}{'RMSE cm':>9}{'max cm':>8}")
    results = {}
    for label, lines_used, areas in (("break lines (FloodMesh)", coords, (100, 50)),
                                     ("uniform, no break lines (peer)", [], (100, 25, 10, 5, 2))):
        for area in areas:
            mesh = build_mesh(dem, lines_used, min_angle=25, max_area=area)
            r = residuals(mesh, holdout.xyz)
            r = r[np.isfinite(r)]
            rmse = float(np.sqrt(np.mean(r ** 2)))
            results.setdefault(label, []).append((len(mesh.nodes), rmse))
            print(f"{label:<34}{area:>9}{len(mesh.nodes):>8}{100 * rmse:>9.1f}"
                  f"{100 * np.abs(r).max():>8.1f}")
    ours, uniform = results["break lines (FloodMesh)"][0], results["uniform, no break lines (peer)"]
    nodes_u, rmse_u = np.array([u[0] for u in uniform]), np.array([u[1] for u in uniform])
    order = np.argsort(rmse_u)
    # uniform nodes at our RMSE, interpolated in log-log between the two neighbouring meshes
    needed = np.exp(np.interp(np.log(ours[1]), np.log(rmse_u[order]), np.log(nodes_u[order])))
    print(f"uniform nodes for the break-line mesh's {100 * ours[1]:.1f} cm: about {needed:,.0f}, "
          f"{needed / ours[0]:.1f}x the break-line mesh's {ours[0]:,} (bar: 3x)")
    bench_delatin(dem, coords, holdout)


def bench_delatin(dem, coords, holdout):
    """The break-line mesh against a pure terrain-approximation TIN (pydelatin: greedy point
    insertion, no angle bound) allowed the same maximum vertical error against the DEM."""
    from floodmesh.core.steps.accuracy import residuals
    from floodmesh.core.steps.mesh import Mesh, build_mesh, triangle_angles

    try:
        from pydelatin import Delatin
    except ImportError:
        print("\n(pydelatin is not installed: pip install pydelatin for the TIN comparison)")
        return
    mesh = build_mesh(dem, coords, min_angle=25, max_area=100)
    rows, cols = np.indices(dem.shape)
    x, y = dem.cell_centres(rows.ravel(), cols.ravel())
    cells = np.column_stack([x, y, dem.values.ravel()])
    cells = cells[np.isfinite(cells[:, 2])]
    max_error = float(np.nanmax(np.abs(residuals(mesh, cells))))
    z = np.where(np.isfinite(dem.values), dem.values, np.nanmean(dem.values)).astype(np.float32)

    def delatin(error):
        tin = Delatin(z, width=dem.shape[1], height=dem.shape[0], max_error=error)
        # pydelatin's y counts rows from the bottom
        vx, vy = dem.cell_centres(dem.shape[0] - 1 - tin.vertices[:, 1], tin.vertices[:, 0])
        return Mesh(np.column_stack([vx, vy, tin.vertices[:, 2]]),
                    tin.triangles.astype(np.int64), dem.crs)

    def rmse(m):
        r = residuals(m, holdout.xyz)
        return float(np.sqrt(np.nanmean(r ** 2)))

    ours = rmse(mesh)
    lo, hi = 0.001, max_error  # bisection for pydelatin's error giving our holdout RMSE
    for _ in range(12):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if rmse(delatin(mid)) < ours else (lo, mid)
    print("\n## Against a terrain-approximation TIN (pydelatin: greedy insertion, no angle bound)")
    print(f"{'mesh':<44}{'nodes':>8}{'RMSE cm':>9}{'min angle':>11}")
    for label, m in (("break lines + Triangle (FloodMesh)", mesh),
                     (f"pydelatin, same max error ({100 * max_error:.0f} cm)", delatin(max_error)),
                     ("pydelatin, same holdout RMSE", delatin(lo))):
        angle = triangle_angles(m.nodes, m.triangles).min()
        print(f"{label:<44}{len(m.nodes):>8}{100 * rmse(m):>9.1f}{angle:>10.1f}°")
        if label.startswith("pydelatin"):
            print(f"{'':<4}node ratio pydelatin / FloodMesh: {len(m.nodes) / len(mesh.nodes):.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only",
                        default="slopefile,gridfile,run,codec,grid,slope,trace,lines,mesh")
    parser.add_argument("--grid-points", type=int, default=1_000_000,
                        help="points for gridding against gdal_grid")
    parser.add_argument("--no-peers", action="store_true",
                        help="run: leave out the peers' gridding (minutes and GBs at 9 M points)")
    parser.add_argument("--run-points", type=int, default=9_000_000,
                        help="points of the end-to-end run (9 M: 1 km² at 9 points/m²)")
    parser.add_argument("--codec-size", type=int, default=4000,
                        help="raster side for the codec comparison")
    parser.add_argument("--file-sizes", default="6000,10000",
                        help="DEM sides for file-to-file slope against gdaldem")
    parser.add_argument("--points", type=int, default=1_000_000, help="points to grid")
    parser.add_argument("--size", type=int, default=4000, help="raster side for slope")
    parser.add_argument("--breakpoints", type=int, default=1_000_000,
                        help="breakpoints to trace")
    parser.add_argument("--write", metavar="FILE.md",
                        help="also write the figures, with the date, machine and versions, to "
                             "this Markdown file (make bench: benchmarks/latest.md)")
    args = parser.parse_args()
    benches = {
        "slopefile": lambda: bench_slope_file([int(n) for n in args.file_sizes.split(",")]),
        "gridfile": lambda: bench_grid_file(args.grid_points),
        "run": lambda: bench_run(args.run_points, peers=not args.no_peers),
        "codec": lambda: bench_codec(args.codec_size),
        "grid": lambda: bench_grid(args.points), "slope": lambda: bench_slope(args.size),
        "trace": lambda: bench_trace(args.breakpoints), "lines": bench_lines, "mesh": bench_mesh,
    }
    import os

    chosen = [name for name in args.only.split(",") if name]
    unknown = sorted(set(chosen) - set(benches))
    if unknown:
        parser.error(f"unknown benchmark {', '.join(unknown)}; choose from {', '.join(benches)}")
    with _written(args.write, chosen):
        print(f"machine: {os.cpu_count()} cores shared with other work, load average "
              f"{os.getloadavg()[0]:.1f} at the start")
        for name in chosen:
            benches[name]()
        print(f"\nload average {os.getloadavg()[0]:.1f} at the end")


class _Tee:
    """Standard output also into a file."""

    def __init__(self, *streams):
        self.streams = streams

    def write(self, text):
        for stream in self.streams:
            stream.write(text)

    def flush(self):
        for stream in self.streams:
            stream.flush()


@contextlib.contextmanager
def _written(path, chosen):
    """With ``path``, what the benchmarks print goes into it too, under a header that says when,
    on what and with which versions they ran; written whole at the end (an interrupted run
    leaves the last complete figures)."""
    if not path:
        yield
        return
    import datetime
    import io
    import platform

    import numpy
    import scipy

    buffer, stdout = io.StringIO(), sys.stdout
    sys.stdout = _Tee(stdout, buffer)
    try:
        yield
    finally:
        sys.stdout = stdout
    header = (f"# Benchmark figures: `make bench`\n\nWritten by `benchmarks/run.py --only "
              f"{','.join(chosen)}` on {datetime.date.today()}: {platform.machine()}, "
              f"{platform.python_implementation()} {platform.python_version()}, numpy "
              f"{numpy.__version__}, scipy {scipy.__version__}. Each figure is against a peer "
              f"measured in the same run; what they mean is in [RESULTS.md](RESULTS.md).\n\n")
    Path(path).write_text(header + buffer.getvalue(), encoding="utf-8")

if __name__ == "__main__":
    main()
