"""Flood on mesh in QGIS: Build mesh's output chained into the flood algorithm through
processing.run (as the Graphical Modeler chains them); ANUGA runs in its child process and the
maxima load as raster layers in the mesh's CRS, on colour ramps with dry cells clear."""
import json

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS
from qgis.core import QgsProcessingContext, QgsRasterLayer, QgsVectorLayer

from floodmesh.core import io
from floodmesh.core.flood.model import flood_python
from floodmesh.core.raster import Grid

X0, Y0 = 382_000.0, 6_354_000.0


@pytest.mark.skipif(flood_python() is None, reason="ANUGA is not installed (make setup)")
def test_build_mesh_then_flood_on_it(processing, tmp_path, feedback_log):
    x = np.arange(100) + 0.5
    dem = Grid(np.tile(0.02 * (100 - x), (20, 1)).astype(np.float32),
               Affine(1, 0, X0, 0, -1, Y0 + 20), CRS.from_epsg(32756))
    io.write_raster(tmp_path / "dem.tif", dem)
    mesh = processing.run("floodmesh:buildmesh", {
        "DEM": str(tmp_path / "dem.tif"), "MAX_AREA": 2.0, "OUTPUT": str(tmp_path / "m.2dm")})
    (tmp_path / "scenario.json").write_text(json.dumps({
        "duration_s": 60, "output_interval_s": 10, "manning": 0.03,
        "inflows": [{"line": [[X0 + 2, Y0 + 1], [X0 + 2, Y0 + 19]], "discharge_m3s": 2.0}],
        "boundaries": [{"kind": "outflow", "sides": ["east"]}]}))
    context = QgsProcessingContext()
    flood = processing.run("floodmesh:floodonmesh", {
        "MESH": mesh["OUTPUT"], "SCENARIO": str(tmp_path / "scenario.json"),
        "CRS": "EPSG:32756", "OUTPUT_FOLDER": str(tmp_path / "flood")}, context=context,
        feedback=feedback_log)
    depth = QgsRasterLayer(flood["MAX_DEPTH"], "depth")
    assert depth.isValid() and depth.crs().authid() == "EPSG:32756"
    stats = depth.dataProvider().bandStatistics(1)
    assert 0.05 < stats.maximumValue < 1.0
    for name in ("MAX_LEVEL", "MAX_SPEED", "ARRIVAL"):
        assert QgsRasterLayer(flood[name], name).isValid()
    where = QgsVectorLayer(f"{flood['TIME_STEP']}|layername=time_step_set_by", "where")
    assert where.isValid() and where.crs().authid() == "EPSG:32756" and where.featureCount() >= 1
    with open(flood["REPORT"]) as fh:
        report = json.load(fh)
    assert abs(report["mass_balance"]["relative_error"]) < 1e-6
    # the log says where the time step was set, as the command line does
    setter = report["time_step_set_by"][0]
    assert any(f"time step set most by the triangle at ({setter['x']:.1f}, {setter['y']:.1f})"
               in line for line in feedback_log.infos), "\n".join(feedback_log.infos)
    assert report["mass_balance"]["inflow_volume_m3"] == pytest.approx(120, rel=1e-6)
    # the maxima load on colour ramps, not in grey (where a depth of 0 showed black): dry
    # cells (0 depth, 0 speed) are clear, the deepest and fastest water opaque
    loaded = {details.outputName: context.temporaryLayerStore().mapLayer(layer_id)
              for layer_id, details in context.layersToLoadOnCompletion().items()}
    for name in ("MAX_DEPTH", "MAX_LEVEL", "MAX_SPEED", "ARRIVAL"):
        renderer = loaded[name].renderer()
        assert renderer.type() == "singlebandpseudocolor", (name, renderer.type())
        ramp = renderer.shader().rasterShaderFunction()
        assert ramp.shade(renderer.classificationMax())[4] == 255, name
    for name in ("MAX_DEPTH", "MAX_SPEED"):
        ramp = loaded[name].renderer().shader().rasterShaderFunction()
        assert ramp.shade(0.0)[4] == 0, name
    blue = loaded["MAX_DEPTH"].renderer().shader().rasterShaderFunction().shade(stats.maximumValue)
    assert blue[3] > max(blue[1], blue[2]), blue  # deep water is blue
