"""Every FloodMesh step on real data inside QGIS's own binary, ``qgis_process.bin``, where QGIS
has loaded its GEOS before any plugin runs (the place where shapely's wheel, with another GEOS,
crashed or returned garbage): Topography.laz with its lakes, a DEM with nodata holes meshed in a
domain with a hole, refinement from the LAZ, export with regions, and a worker killed mid-run."""
import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest
from pyproj import CRS
from shapely.geometry import Polygon, box

from floodmesh.core import io
from floodmesh.core.raster import Grid

from ..conftest import REAL_DATA, child_processes
from .conftest import write_ept

TOPOGRAPHY_CRS = CRS.from_epsg(2949)


def _run(qgis_process, algorithm, **parameters):
    exe, env = qgis_process
    run = subprocess.run([exe, "run", f"floodmesh:{algorithm}", "--json", "--",
                          *(f"{k}={v}" for k, v in parameters.items())],
                         env=env, capture_output=True, text=True, timeout=400)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return json.loads(run.stdout[run.stdout.index("{"):])["results"]


def _write_polygons(path, polygons, crs, attributes=None):
    import fiona
    from shapely.geometry import mapping

    schema = {"geometry": "Polygon", "properties": {"mat": "int"}}
    with fiona.open(path, "w", driver="GPKG", schema=schema, crs_wkt=crs.to_wkt()) as dst:
        for k, polygon in enumerate(polygons):
            dst.write({"geometry": mapping(polygon),
                       "properties": {"mat": (attributes or {}).get(k, k + 2)}})


@pytest.fixture(scope="module")
def topography(qgis_process, tmp_path_factory):
    """LiDAR to mesh on Topography.laz, ground and water (classes 2 and 9), 2 m cells."""
    if not REAL_DATA.is_dir():
        pytest.skip("../shared/data/real is not beside this checkout")
    real_data = REAL_DATA
    out = tmp_path_factory.mktemp("topography") / "run"
    results = _run(qgis_process, "lidartomesh", INPUT=real_data / "Topography.laz",
                   CLASSES="2,9", CELL_SIZE=2.0, MAX_AREA=100, HOLDOUT=0.002,
                   OUTPUT_FOLDER=out)
    return out, results


def test_lidar_to_mesh_on_a_laz_with_lakes(topography):
    out, results = topography
    report = json.loads((out / "report.json").read_text())
    mesh = io.read_2dm(results["MESH"])
    assert results["NODES"] == len(mesh.nodes) > 500 and np.isfinite(mesh.nodes).all()
    assert report["min_angle_deg"] >= 25.0 - 1e-6
    # the mesh carries its CRS in the sidecar, for the CLI and QGIS after this run
    assert CRS.from_wkt(mesh.crs).to_epsg() == 2949


def test_build_mesh_on_a_dem_with_nodata_holes_in_a_domain_with_a_hole(qgis_process, real_data,
                                                                        tmp_path):
    dem = io.read_raster(real_data / "merewether_topography1.asc", crs="EPSG:32756")
    values = dem.values.copy()
    rows, cols = np.indices(values.shape)
    for r, c, radius in ((120, 150, 12), (300, 80, 8)):  # two interior lakes without returns
        values[(rows - r) ** 2 + (cols - c) ** 2 < radius ** 2] = np.nan
    holed = Grid(values, dem.transform, dem.crs)
    io.write_raster(tmp_path / "dem.tif", holed)
    x0, y1 = dem.transform.c, dem.transform.f
    width, height = values.shape[1] * dem.cell_size, values.shape[0] * dem.cell_size
    outer = box(x0 + 20, y1 - height + 20, x0 + width - 20, y1 - 20)
    hole = box(x0 + 200, y1 - 250, x0 + 240, y1 - 210)  # a building left out
    _write_polygons(tmp_path / "domain.gpkg", [Polygon(outer.exterior, [hole.exterior])],
                    dem.crs)
    results = _run(qgis_process, "buildmesh", DEM=tmp_path / "dem.tif",
                   BOUNDARY=tmp_path / "domain.gpkg", MAX_AREA=200, OUTPUT=tmp_path / "m.2dm")
    mesh = io.read_2dm(results["OUTPUT"])
    assert results["NODES"] == len(mesh.nodes) > 100
    centroids = mesh.nodes[mesh.triangles, :2].mean(axis=1)
    inside_hole = ((centroids[:, 0] > x0 + 200) & (centroids[:, 0] < x0 + 240)
                   & (centroids[:, 1] > y1 - 250) & (centroids[:, 1] < y1 - 210))
    assert not inside_hole.any()
    lake = np.hypot(centroids[:, 0] - (x0 + 150.5), centroids[:, 1] - (y1 - 120.5)) < 8
    assert not lake.any()  # the nodata lake stays a hole


def test_refine_from_the_laz_then_export_with_regions(qgis_process, topography, real_data,
                                                      tmp_path):
    out, _ = topography
    refined = _run(qgis_process, "refinemesh", DEM=out / "dem.tif",
                   BREAKLINES=out / "breaklines.gpkg", POINTS_FILE=real_data / "Topography.laz",
                   MAX_AREA=100, MAX_ROUNDS=2, OUTPUT=tmp_path / "refined.2dm")
    mesh = io.read_2dm(refined["OUTPUT"])
    assert refined["NODES"] == len(mesh.nodes) > json.loads(
        (out / "report.json").read_text())["nodes"]
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    west = box(x.min() - 1, y.min() - 1, (x.min() + x.max()) / 2, y.max() + 1)
    _write_polygons(tmp_path / "regions.gpkg", [west], TOPOGRAPHY_CRS, {0: 7})
    # UGRID carries the CRS: none is given, the mesh's .prj sidecar supplies it
    exported = _run(qgis_process, "exportmesh", INPUT=refined["OUTPUT"], FORMAT=4,
                    REGIONS=tmp_path / "regions.gpkg", MATERIAL_FIELD="mat",
                    OUTPUT=tmp_path / "model.nc")
    assert exported["OUTPUT"] == str(tmp_path / "model.nc")
    as_2dm = _run(qgis_process, "exportmesh", INPUT=refined["OUTPUT"], FORMAT=0,
                  REGIONS=tmp_path / "regions.gpkg", MATERIAL_FIELD="mat",
                  OUTPUT=tmp_path / "model.2dm")
    materials = io.read_2dm(as_2dm["OUTPUT"]).materials
    assert set(np.unique(materials)) == {1, 7}


def _worker_of(pid):
    """The worker process qgis_process started, if it runs yet."""
    for child in child_processes(pid):
        try:
            with open(f"/proc/{child}/cmdline", "rb") as fh:
                if b"core.frontends.worker" in fh.read():
                    return child
        except OSError:
            continue
    return None

@pytest.mark.parametrize("sig, words", [
    (signal.SIGKILL, "FloodMesh's worker process was killed (SIGKILL"),  # as the OOM killer
    (signal.SIGSEGV, "FloodMesh's worker process crashed (SIGSEGV"),  # as Triangle or GEOS
])
def test_a_killed_worker_is_one_clear_error_and_leaves_no_partial_file(qgis_process, real_data,
                                                                         tmp_path, sig, words):
    exe, env = qgis_process
    out = tmp_path / "killed"
    run = subprocess.Popen([exe, "run", "floodmesh:lidartomesh", "--",
                            f"INPUT={real_data / 'Topography.laz'}", "CELL_SIZE=1", "HOLDOUT=0.002",
                            f"OUTPUT_FOLDER={out}"], env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    worker = None
    deadline = time.monotonic() + 120
    while worker is None and time.monotonic() < deadline and run.poll() is None:
        worker = _worker_of(run.pid)
        time.sleep(0.05)
    assert worker is not None, "qgis_process started no worker"
    time.sleep(0.3)  # mid-run (the whole run takes seconds)
    os.kill(worker, sig)
    output, _ = run.communicate(timeout=120)
    assert run.returncode != 0
    message = words
    # one message, once from FloodMesh (QGIS 3.22's qgis_process itself echoes an algorithm's
    # error to its log and as ERROR: too)
    assert message in output and output.count("QGIS is unaffected") <= 3, output
    assert "Traceback" not in output
    assert not (out / "mesh.2dm").exists()
    assert not out.exists() or [p.name for p in out.glob(".*")] == []


def test_a_point_cloud_layer_grids_and_refines_as_its_laz_does(qgis_process, topography,
                                                                real_data, tmp_path):
    """Topography.laz as a point-cloud layer (QGIS's `ept://` source form on the command
    line; in the dialog the layer loaded in the project) and a folder of tiles: the same DEM as
    from the file; refinement takes the layer's points."""
    ept = write_ept(real_data / "Topography.laz", tmp_path / "topography-ept", nodes=3)
    layer = f"ept://{ept}"
    from_layer = _run(qgis_process, "gridpoints", POINT_CLOUD=layer, CELL_SIZE=2.0,
                      OUTPUT=tmp_path / "layer.tif")
    from_file = _run(qgis_process, "gridpoints", INPUT=real_data / "Topography.laz",
                     CELL_SIZE=2.0, OUTPUT=tmp_path / "file.tif")
    (tmp_path / "tiles").mkdir()
    (tmp_path / "tiles" / "Topography.laz").symlink_to(real_data / "Topography.laz")
    from_folder = _run(qgis_process, "gridpoints", TILE_FOLDER=tmp_path / "tiles",
                       CELL_SIZE=2.0, OUTPUT=tmp_path / "folder.tif")
    b = io.read_raster(from_file["OUTPUT"])
    for other in (from_layer, from_folder):
        a = io.read_raster(other["OUTPUT"])
        assert a.transform == b.transform and np.array_equal(a.values, b.values, equal_nan=True)
    out, _ = topography
    refined = _run(qgis_process, "refinemesh", DEM=out / "dem.tif",
                   BREAKLINES=out / "breaklines.gpkg", POINT_CLOUD=layer, MAX_AREA=100,
                   MAX_ROUNDS=1, OUTPUT=tmp_path / "refined.2dm")
    assert refined["NODES"] > json.loads((out / "report.json").read_text())["nodes"]


ECHO_PLUGIN = '''
from qgis.core import (QgsApplication, QgsProcessingAlgorithm, QgsProcessingException,
                       QgsProcessingProvider)
class Fails(QgsProcessingAlgorithm):
    def name(self): return "fails"
    def displayName(self): return "fails"
    def createInstance(self): return Fails()
    def initAlgorithm(self, config=None): pass
    def processAlgorithm(self, parameters, context, feedback):
        raise QgsProcessingException("the one error")
class Provider(QgsProcessingProvider):
    def id(self): return "echo"
    def name(self): return "echo"
    def loadAlgorithms(self): self.addAlgorithm(Fails())
class Plugin:
    def __init__(self, iface): self.provider = None
    def initProcessing(self):
        self.provider = Provider()
        QgsApplication.processingRegistry().addProvider(self.provider)
    def initGui(self): self.initProcessing()
    def unload(self): pass
def classFactory(iface): return Plugin(iface)
'''


@pytest.mark.parametrize("json_mode", [False, True])
def test_an_error_is_echoed_only_as_qgis_process_echoes_any_algorithm_error(
        qgis_process, tmp_path, json_mode):
    """qgis_process (3.22 and 3.40) prints an algorithm's QgsProcessingException three times:
    QgsProcessingAlgorithm::run logs it (Critical) and qgis_process echoes every Critical log
    line to stderr; its console feedback prints `ERROR:\t…`; and QgsProcessingFeedback's
    reportError logs it once more, echoed again (with --json the `ERROR:` line is left out).
    A minimal plugin that raises gives the same count: FloodMesh adds no echo of its own."""
    exe, env = qgis_process
    plugins = tmp_path / "plugins" / "echoplugin"
    plugins.mkdir(parents=True)
    (plugins / "__init__.py").write_text(ECHO_PLUGIN)
    (plugins / "metadata.txt").write_text(
        "[general]\nname=echoplugin\nqgisMinimumVersion=3.22\ndescription=x\nversion=1\n"
        "author=x\nemail=x@example.invalid\nabout=x\nrepository=x\ntracker=x\n"
        "hasProcessingProvider=yes\n")
    env = {**env, "QGIS_PLUGINPATH": f"{env['QGIS_PLUGINPATH']}:{tmp_path / 'plugins'}"}
    subprocess.run([exe, "plugins", "enable", "echoplugin"], env=env, capture_output=True,
                   timeout=120)
    flag = ["--json"] if json_mode else []

    def output(*arguments):
        run = subprocess.run([exe, "run", *arguments[:1], *flag, "--", *arguments[1:]], env=env,
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 1
        return run.stdout + run.stderr

    peer = output("echo:fails")
    missing = tmp_path / "missing.laz"
    ours = output("floodmesh:lidartomesh", f"INPUT={missing}", f"OUTPUT_FOLDER={tmp_path / 'o'}")
    message = f"point file {missing} does not exist: check the path"
    assert ours.count(message) == peer.count("the one error") == (2 if json_mode else 3), ours
    assert ours.count(f"ERROR:\t{message}") == peer.count("ERROR:\tthe one error")
    assert "Traceback" not in ours
