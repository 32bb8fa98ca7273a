"""The flow area (m²) in QGIS: Build mesh and LiDAR to mesh give triangles of that size on the
low ground by the drainage lines (height above the nearest drainage), headless in
``qgis_process.bin`` and through ``processing.run``."""
import json
import subprocess

import numpy as np

from floodmesh.core import io
from floodmesh.core.steps.drainage import flow_size
from floodmesh.core.steps.mesh import triangle_areas


def _in_zone(mesh, dem, flow_area):
    nodes, tri = io.read_mesh_2dm(mesh)
    zone = flow_size(dem, flow_area=flow_area).values
    centre = nodes[tri][:, :, :2].mean(axis=1)
    cols, rows = ~dem.transform * (centre[:, 0], centre[:, 1])
    inside = np.isfinite(zone[rows.astype(int), cols.astype(int)])
    return np.abs(triangle_areas(nodes, tri)), inside


def test_flow_area_in_lidar_to_mesh_then_build_mesh_headless(processing, qgis_process,
                                                             demo_points_file, tmp_path):
    run_dir = tmp_path / "run"
    result = processing.run("floodmesh:lidartomesh", {
        "INPUT": str(demo_points_file), "FLOW_AREA": 20.0, "HOLDOUT": 0.01,
        "OUTPUT_FOLDER": str(run_dir)})
    dem = io.read_raster(run_dir / "dem.tif")
    areas, inside = _in_zone(result["MESH"], dem, 20.0)
    assert inside.mean() > 0.2 and areas[inside].max() <= 20.0 * 1.05
    assert json.loads((run_dir / "report.json").read_text())["nodes"] == result["NODES"]

    exe, env = qgis_process
    found = {}
    for name, extra in (("plain", ["FLOW_AREA=0"]), ("default", []),
                        ("flow", ["FLOW_AREA=15"])):
        run = subprocess.run(
            [exe, "run", "floodmesh:buildmesh", "--json", "--", f"DEM={run_dir / 'dem.tif'}",
             f"BREAKLINES={run_dir / 'breaklines.gpkg'}", *extra,
             f"OUTPUT={tmp_path / name}.2dm"], env=env, capture_output=True, text=True,
            timeout=300)
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
        found[name] = _in_zone(tmp_path / f"{name}.2dm", dem, 15.0)
    (flow, inside), (plain, plain_inside) = found["flow"], found["plain"]
    default, default_inside = found["default"]
    assert inside.mean() > 0.2
    # empty: the default, 23 cells of the demo's 1 m grid, as in LiDAR to mesh and the CLI
    assert (flow[inside].max() <= 15.0 * 1.05 < default[default_inside].max() <= 23.0 * 1.05
            < plain[plain_inside].max())
