"""A run folder opens in QGIS without the plugin: run.qlr (written by core as plain XML) loads
in QGIS's own reader as one group named after the run, break lines above residuals above the
mesh, every layer valid, in the run's CRS, styled as the plugin styles them; the folder can be
moved (relative paths)."""
import shutil
import subprocess
import sys

from qgis.core import (QgsLayerDefinition, QgsMapLayerType, QgsProject, QgsRenderContext)

from floodmesh.core.options import BREAKLINE_COLOUR, RESIDUAL_CLASS_COLOURS


def test_run_qlr_opens_the_run_styled_in_its_crs(demo_points_file, tmp_path):
    run = subprocess.run([sys.executable, "-m", "floodmesh.core.frontends.cli", "run",
                          str(demo_points_file), "--out", str(tmp_path / "levee run"),
                          "--max-area", "400"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    moved = shutil.move(str(tmp_path / "levee run"), str(tmp_path / "elsewhere"))
    project = QgsProject()
    ok, message = QgsLayerDefinition.loadLayerDefinition(f"{moved}/run.qlr", project,
                                                          project.layerTreeRoot())
    assert ok, message
    groups = project.layerTreeRoot().children()
    assert len(groups) == 1 and groups[0].name() == "levee run"
    nodes = groups[0].findLayers()
    assert [n.name() for n in nodes] == ["Break lines", "Residuals", "Mesh", "DEM", "Slope",
                                         "Breakpoints"]
    assert [n.isVisible() for n in nodes] == [True, True, True, False, False, False]
    for node in nodes:
        layer = node.layer()
        assert layer.isValid(), node.name()
        assert layer.crs().authid() == "EPSG:25832", (node.name(), layer.crs().authid())
    lines, residuals, mesh = (n.layer() for n in nodes[:3])
    symbol = lines.renderer().symbol()
    assert symbol.symbolLayerCount() == 2
    assert symbol.symbolLayer(1).color().name() == BREAKLINE_COLOUR
    assert residuals.renderer().type() == "categorizedSymbol"
    colours = [s.color().name() for s in residuals.renderer().symbols(QgsRenderContext())]
    assert colours[:3] == list(RESIDUAL_CLASS_COLOURS)
    assert mesh.type() == QgsMapLayerType.MeshLayer and mesh.dataProvider().faceCount() > 100
    settings = mesh.rendererSettings()
    assert settings.nativeMeshSettings().isEnabled() and settings.activeScalarDatasetGroup() == 0
