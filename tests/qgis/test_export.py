"""Solver exports read back by QGIS's own readers: MDAL opens the 2DM, Selafin and UGRID files
as meshes with our node and face counts, coordinates, connectivity and elevations; OGR opens
the GeoPackage layers. Through processing.run ("Export mesh", "LiDAR to mesh") and qgis_process."""
import json
import subprocess

import numpy as np
import pytest
from pyproj import CRS
from qgis.core import (QgsMesh, QgsMeshDatasetGroupMetadata, QgsMeshDatasetIndex, QgsMeshLayer,
                       QgsProcessingException, QgsVectorLayer)
from floodmesh.algorithms.compat import LINESTRING_Z, POINT_Z, POLYGON_Z

from floodmesh.core import io
from floodmesh.core.steps.mesh import triangle_areas

from ..conftest import UTM_ORIGIN, write_export_inputs

X0, Y0 = UTM_ORIGIN
UTM32 = CRS.from_epsg(25832)
FORMATS = ("2dm", "slf", "14", "gr3", "nc", "gpkg")


def read_mdal(path):
    """Vertices (n, 3), faces (m, 3) and {dataset group name: values} as MDAL reads them."""
    layer = QgsMeshLayer(str(path), "mesh", "mdal")
    assert layer.isValid(), f"QGIS cannot open {path} as a mesh"
    provider = layer.dataProvider()
    mesh = QgsMesh()
    provider.populateMesh(mesh)
    vertices = np.array([[mesh.vertex(i).x(), mesh.vertex(i).y(), mesh.vertex(i).z()]
                         for i in range(mesh.vertexCount())])
    faces = np.array([mesh.face(i) for i in range(mesh.faceCount())])
    groups = {}
    for g in range(provider.datasetGroupCount()):
        meta = provider.datasetGroupMetadata(g)
        on_vertices = meta.dataType() == QgsMeshDatasetGroupMetadata.DataOnVertices
        n = provider.vertexCount() if on_vertices else provider.faceCount()
        block = provider.datasetValues(QgsMeshDatasetIndex(g, 0), 0, n)
        groups[meta.name().strip()] = np.array([block.value(i).scalar() for i in range(n)])
    assert (provider.vertexCount(), provider.faceCount()) == (len(vertices), len(faces))
    return vertices, faces, groups, layer.crs().authid()


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A mesh with a hole as mesh.2dm, an open-boundary line on its west edge, and a region
    polygon with material id 8 over its western 30 m."""
    t = tmp_path_factory.mktemp("export-inputs")
    _, tris = write_export_inputs(t, material=8)
    nodes = io.read_2dm(t / "mesh.2dm").nodes  # what the export starts from: 0.1 mm steps
    ccw = np.where((triangle_areas(nodes, tris) < 0)[:, None], tris[:, [0, 2, 1]], tris)
    centroid_x = nodes[tris][:, :, 0].mean(axis=1) - X0
    return t, nodes, ccw, np.where(centroid_x < 30, 8, 1)


def export(processing, inputs, fmt, name, **extra):
    t = inputs[0]
    params = {"INPUT": str(t / "mesh.2dm"), "FORMAT": FORMATS.index(fmt), "CRS": "EPSG:25832",
              "OPEN_BOUNDARIES": str(t / "open.gpkg"), "REGIONS": str(t / "regions.gpkg"),
              "MATERIAL_FIELD": "mat", "OUTPUT": str(t / name), **extra}
    return processing.run("floodmesh:exportmesh", params)


def test_2dm_through_mdal(processing, inputs):
    """Counts, coordinates, faces and node elevations (+ datum offset) as written; MDAL shows the
    material ids and BASEMENT 3's element elevations as face datasets."""
    _, nodes, tris, materials = inputs
    result = export(processing, inputs, "2dm", "out.2dm", DATUM_OFFSET=0.75,
                    ELEMENT_ELEVATIONS=True)
    vertices, faces, groups, _ = read_mdal(result["OUTPUT"])
    np.testing.assert_allclose(vertices[:, :2], nodes[:, :2], atol=0.5e-4)
    np.testing.assert_allclose(vertices[:, 2], nodes[:, 2] + 0.75, atol=0.5e-4)
    np.testing.assert_array_equal(faces, tris)
    np.testing.assert_allclose(groups["Bed Elevation"], nodes[:, 2] + 0.75, atol=0.5e-4)
    np.testing.assert_array_equal(groups["Material ID"], materials)
    np.testing.assert_allclose(groups["Bed Elevation (Face)"],
                               nodes[tris, 2].mean(axis=1) + 0.75, atol=0.5e-4)


def test_selafin_through_mdal(processing, inputs):
    """MDAL reads the double-precision Selafin to the last bit of the UTM coordinates, with its
    BOTTOM variable; the .cli is written beside it, one line per boundary node."""
    t, nodes, tris, _ = inputs
    result = export(processing, inputs, "slf", "geo.slf")
    vertices, faces, groups, _ = read_mdal(result["OUTPUT"])
    np.testing.assert_array_equal(vertices[:, :2], nodes[:, :2])
    np.testing.assert_array_equal(faces, tris)
    np.testing.assert_array_equal(groups["bottom          m"], nodes[:, 2])
    assert result["CLI"] == str(t / "geo.cli")
    rows = (t / "geo.cli").read_text().splitlines()
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    assert len(rows) == int((np.unique(e, axis=0, return_counts=True)[1] == 1).sum())
    assert sum(r.startswith("4 4 4") for r in rows) >= 3


def test_ugrid_through_mdal(processing, inputs):
    """MDAL's UGRID driver finds the mesh topology, the node elevations and the CRS."""
    _, nodes, tris, _ = inputs
    result = export(processing, inputs, "nc", "mesh_net.nc", DATUM_OFFSET=-1.0)
    vertices, faces, groups, authid = read_mdal(result["OUTPUT"])
    np.testing.assert_array_equal(vertices[:, :2], nodes[:, :2])
    np.testing.assert_array_equal(faces, tris)
    np.testing.assert_allclose(vertices[:, 2], nodes[:, 2] - 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(groups["Bed Elevation"], nodes[:, 2] - 1.0, rtol=0, atol=1e-12)
    assert authid == "EPSG:25832"


def test_geopackage_through_ogr(processing, inputs):
    t, nodes, tris, materials = inputs
    result = export(processing, inputs, "gpkg", "layers.gpkg",
                    BREAKLINES=str(t / "open.gpkg"))
    expected = {"triangles": (POLYGON_Z, len(tris)),
                "nodes": (POINT_Z, len(nodes)),
                "boundary": (LINESTRING_Z, 3),
                "breaklines": (LINESTRING_Z, 1)}
    for name, (wkb, count) in expected.items():
        layer = QgsVectorLayer(f"{result['OUTPUT']}|layername={name}", name, "ogr")
        assert layer.isValid() and layer.wkbType() == wkb and layer.featureCount() == count
        assert layer.crs().authid() == "EPSG:25832"
    triangles = QgsVectorLayer(f"{result['OUTPUT']}|layername=triangles", "t", "ogr")
    assert sorted(f["material"] for f in triangles.getFeatures()) == sorted(materials.tolist())
    boundary = QgsVectorLayer(f"{result['OUTPUT']}|layername=boundary", "b", "ogr")
    assert [f["kind"] for f in boundary.getFeatures()] == ["open", "land", "land"]


def test_the_format_decides_the_extension(processing, inputs):
    """An output name without the format's extension gets it: fort.14 from 'fort'."""
    t = inputs[0]
    result = export(processing, inputs, "14", "fort")
    assert result["OUTPUT"] == str(t / "fort.14") and (t / "fort.14").is_file()
    assert (t / "fort.14").read_text().splitlines()[1].split()[:2] == \
        [str(len(inputs[2])), str(len(inputs[1]))]


def test_open_boundary_off_the_mesh_is_a_processing_error(processing, inputs, tmp_path):
    t = inputs[0]
    io.write_lines_gpkg(tmp_path / "far.gpkg", [np.array([[X0 + 500, Y0, 0], [X0 + 600, Y0, 0]])],
                        UTM32, layer="open")
    with pytest.raises(QgsProcessingException, match="fewer than two nodes"):
        export(processing, inputs, "slf", str(tmp_path / "x.slf"),
               OPEN_BOUNDARIES=str(tmp_path / "far.gpkg"))
    assert list(tmp_path.glob("x.*")) == []


def test_lidar_to_mesh_writes_the_chosen_formats(processing, demo_points_file, tmp_path):
    """The one-step algorithm with Selafin and UGRID chosen: mesh.slf, mesh.cli and mesh.nc
    beside mesh.2dm, opening in QGIS with the report's counts."""
    out = tmp_path / "run"
    result = processing.run("floodmesh:lidartomesh", {
        "INPUT": str(demo_points_file), "MAX_AREA": 200.0, "HOLDOUT": 0.01,
        "FORMATS": [FORMATS.index("slf"), FORMATS.index("nc")], "OUTPUT_FOLDER": str(out)})
    report = json.loads((out / "report.json").read_text())
    assert {"mesh.slf", "mesh.cli", "mesh.nc"} <= set(report["files"])
    assert not (out / "mesh.14").exists()
    written = io.read_2dm(out / "mesh.2dm")
    for name in ("mesh.slf", "mesh.nc", "mesh.2dm"):
        vertices, faces, _, _ = read_mdal(out / name)
        assert (len(vertices), len(faces)) == (report["nodes"], report["triangles"])
        # MDAL reads each in the solver's order build_mesh numbered (tests/core/test_mesh_order)
        np.testing.assert_array_equal(faces, written.triangles)
        np.testing.assert_allclose(vertices[:, :2], written.nodes[:, :2], atol=1e-3)
    assert result["NODES"] == report["nodes"]
    assert read_mdal(out / "mesh.nc")[3] == "EPSG:25832"


def test_export_headless_through_qgis_process(qgis_process, inputs, tmp_path):
    exe, env = qgis_process
    t = inputs[0]
    out = tmp_path / "hgrid.gr3"
    run = subprocess.run(
        [exe, "run", "floodmesh:exportmesh", "--json", "--", f"INPUT={t / 'mesh.2dm'}",
         f"FORMAT={FORMATS.index('gr3')}", f"OPEN_BOUNDARIES={t / 'open.gpkg'}",
         "DATUM_OFFSET=0.5", f"OUTPUT={out}"],
        env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert json.loads(run.stdout[run.stdout.index("{"):])["results"]["OUTPUT"] == str(out)
    lines = out.read_text().splitlines()
    n = len(inputs[1])
    depth = np.array([float(line.split()[3]) for line in lines[2:2 + n]])
    np.testing.assert_allclose(depth, -(inputs[1][:, 2] + 0.5), atol=0.5e-4)
