"""The flow area (m²) in QGIS: Build mesh and LiDAR to mesh give triangles of that size on the
low ground by the drainage lines (height above the nearest drainage) where its relief needs
them, headless in ``qgis_process.bin`` and through ``processing.run``."""
import json
import subprocess

import numpy as np
from scipy.ndimage import binary_erosion

from floodmesh.core import io
from floodmesh.core.steps.drainage import flow_size

from ..conftest import low_ground_triangles, swaled


def test_flow_area_in_lidar_to_mesh_then_build_mesh_headless(processing, qgis_process,
                                                             demo_points_file, tmp_path):
    """LiDAR to mesh passes the flow area to the chain (its report says so and where it
    refined: nowhere much on the demo's plane low ground); Build mesh in qgis_process, on the
    run's DEM with swales cut into the west half of its low ground, gives those swales
    triangles of the flow area asked (empty: the default 23 cells, 0: none) and leaves the
    plane east half its larger ones."""
    run_dir = tmp_path / "run"
    result = processing.run("floodmesh:lidartomesh", {
        "INPUT": str(demo_points_file), "FLOW_AREA": 20.0, "HOLDOUT": 0.01,
        "OUTPUT_FOLDER": str(run_dir)})
    report = json.loads((run_dir / "report.json").read_text())
    assert report["nodes"] == result["NODES"] and report["options"]["flow_area"] == 20.0
    assert report["flow_zone"]["low_ground_share"] > 0.2
    assert report["flow_zone"]["refined_share"] < 0.01

    dem, _ = swaled(io.read_raster(run_dir / "dem.tif"))
    io.write_raster(tmp_path / "swaled.tif", dem)
    low = binary_erosion(np.isfinite(flow_size(dem, flow_area=23.0).values), iterations=5)
    half = np.arange(dem.shape[1]) < dem.shape[1] // 2
    exe, env = qgis_process
    found = {}
    for name, extra in (("plain", ["FLOW_AREA=0"]), ("default", []),
                        ("flow", ["FLOW_AREA=15"])):
        run = subprocess.run(
            [exe, "run", "floodmesh:buildmesh", "--json", "--", f"DEM={tmp_path / 'swaled.tif'}",
             f"BREAKLINES={run_dir / 'breaklines.gpkg'}", *extra,
             f"OUTPUT={tmp_path / name}.2dm"], env=env, capture_output=True, text=True,
            timeout=300)
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
        mesh = tmp_path / f"{name}.2dm"
        found[name] = (np.quantile(low_ground_triangles(mesh, dem, low & half), 0.95),
                       low_ground_triangles(mesh, dem, low & ~half).max())
    # empty: the default, 23 cells of the demo's 1 m grid, as in LiDAR to mesh and the CLI
    assert found["flow"][0] <= 15.0 * 1.05 < found["default"][0] <= 23.0 * 1.05
    assert found["plain"][0] > 50 and min(east for _, east in found.values()) > 50
