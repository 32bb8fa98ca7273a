"""Fixtures shared by all tests: small synthetic point files and the real data in ../shared."""
from pathlib import Path

import numpy as np
import pytest

from floodmesh.core import io
from floodmesh.core.frontends.demo import synthetic_floodplain

REPO = Path(__file__).resolve().parent.parent
REAL_DATA = REPO.parent / "shared" / "data" / "real"


@pytest.fixture(scope="session")
def demo_points_file(tmp_path_factory):
    """The demo floodplain at 2 ground points/m² (fast) as a classified LAZ file."""
    points, classes = synthetic_floodplain(density=2.0, seed=1)
    path = tmp_path_factory.mktemp("demo") / "floodplain.laz"
    io.write_points_las(path, points, classes=classes)
    return path


def survey_tiles(root, density=4.0):
    """The demo floodplain (ground points, ``density`` per m²) as 4 LAZ tiles of 150 x 120 m in
    ``root``/tiles and as one LAZ file of the same points, ``root``/single.laz; returns root."""
    from floodmesh.core.frontends.demo import DEMO_ORIGIN
    from floodmesh.core.points import PointCloud

    points, classes = synthetic_floodplain(density=density, seed=2)
    ground = points.xyz[classes == 2]
    (root / "tiles").mkdir()
    x0, y0 = DEMO_ORIGIN
    for xs in (0, 150):
        for ys in (0, 120):
            inside = ((ground[:, 0] >= x0 + xs) & (ground[:, 0] < x0 + xs + 150)
                      & (ground[:, 1] >= y0 + ys) & (ground[:, 1] < y0 + ys + 120))
            io.write_points_las(root / "tiles" / f"tile_{xs}_{ys}.laz",
                                PointCloud(ground[inside], points.crs))
    tiles = sorted((root / "tiles").glob("*.laz"))
    merged = np.concatenate([io.read_points(p).xyz for p in tiles])
    io.write_points_las(root / "single.laz", PointCloud(merged, points.crs))
    return root


@pytest.fixture
def real_data():
    if not REAL_DATA.is_dir():
        pytest.skip("../shared/data/real is not beside this checkout")
    return REAL_DATA


def child_processes(pid: int) -> set:
    """The processes whose parent is ``pid`` and that it has not reaped (zombies too)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(stat.parent.name))
    return found

def plane_points(a=0.1, b=-0.05, c=12.0, size=40.0, density=4.0, seed=0, origin=(500000.0, 6e6)):
    """Random points on the plane z = a·x + b·y + c (local x, y), as an (N, 3) array."""
    rng = np.random.default_rng(seed)
    n = int(size * size * density)
    x, y = rng.uniform(0, size, n), rng.uniform(0, size, n)
    return np.column_stack([x + origin[0], y + origin[1], a * x + b * y + c])


UTM_ORIGIN = (412_000.0, 5_652_000.0)


def hole_mesh(max_area=40.0):
    """A 100 x 60 m rectangle with a 20 x 20 m square hole (x 40–60, y 20–40, local metres),
    meshed by Triangle, at UTM coordinates, z = 10 + 0.01·x + 0.02·y: (nodes (n, 3), triangles)."""
    from floodmesh.core.steps.mesh import PSLG, triangulate_pslg

    corners = np.array([[0, 0], [100, 0], [100, 60], [0, 60],
                        [40, 20], [60, 20], [60, 40], [40, 40]], float) + UTM_ORIGIN
    segments = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4]])
    hole = np.array([[50.0, 30.0]]) + UTM_ORIGIN
    xy, triangles = triangulate_pslg(PSLG(corners, segments, hole), min_angle=25.0,
                                     max_area=max_area)
    local = xy - UTM_ORIGIN
    z = 10.0 + 0.01 * local[:, 0] + 0.02 * local[:, 1]
    return np.column_stack([xy, z]), triangles


def write_regions(path, regions, crs="EPSG:25832"):
    """A GeoPackage of polygons with an integer field ``mat`` and a text field ``label``:
    ``regions`` is a list of (shapely polygon, material id)."""
    import fiona
    import shapely.geometry
    from pyproj import CRS

    schema = {"geometry": "Polygon", "properties": {"mat": "int", "label": "str"}}
    with fiona.open(path, "w", driver="GPKG", schema=schema,
                    crs_wkt=CRS.from_user_input(crs).to_wkt()) as dst:
        for k, (polygon, material) in enumerate(regions):
            dst.write({"geometry": shapely.geometry.mapping(polygon),
                       "properties": {"mat": material, "label": f"r{k}"}})


def write_export_inputs(folder, material):
    """hole_mesh() as mesh.2dm, an open-boundary line along its west edge (y 10–50 m) as
    open.gpkg and a region over its western 30 m with material id ``material`` as
    regions.gpkg, all in EPSG:25832; returns the mesh's (nodes, triangles)."""
    import shapely
    from pyproj import CRS

    from floodmesh.core import io

    nodes, tris = hole_mesh()
    io.write_mesh_2dm(folder / "mesh.2dm", nodes, tris)
    x0, y0 = UTM_ORIGIN
    io.write_lines_gpkg(folder / "open.gpkg", [np.array([[x0, y0 + 10, 0], [x0, y0 + 50, 0]])],
                        CRS.from_epsg(25832), layer="open")
    write_regions(folder / "regions.gpkg", [(shapely.box(x0, y0, x0 + 30, y0 + 60), material)])
    return nodes, tris


def pytest_terminal_summary(terminalreporter):
    """Say how many random meshing cases ran (tests/core/test_mesh_fuzz.py)."""
    from . import fuzz_stats

    line = fuzz_stats.summary()
    if line:
        terminalreporter.write_line(line)


def swaled(dem, amplitude=0.15, wavelength=6.0):
    """``dem`` with swales (``amplitude`` m, ``wavelength`` m, across x) on its west half's
    low ground (less than 1 m above a drainage line): relief a shallow flood follows that a
    100 m² triangle does not; the east half's low ground stays as it was."""
    from floodmesh.core.steps.drainage import height_above_drainage

    hand, _ = height_above_drainage(dem, channel_area=5000.0)
    rows, cols = np.indices(dem.shape)
    x, _ = dem.cell_centres(rows, cols)
    west = (cols < dem.shape[1] // 2) & (np.nan_to_num(hand.values, nan=9) <= 1.0)
    return dem.with_values(np.where(west, dem.values + amplitude * np.sin(
        2 * np.pi * x / wavelength), dem.values).astype(np.float32)), west


def low_ground_triangles(mesh_2dm, dem, zone):
    """The areas (m²) of the triangles of the mesh in ``mesh_2dm`` whose centre lies in
    ``zone`` (a mask of the cells of ``dem``)."""
    from floodmesh.core.steps.mesh import triangle_areas

    nodes, tri = io.read_mesh_2dm(mesh_2dm)
    centre = nodes[tri][:, :, :2].mean(axis=1)
    cols, rows = ~dem.transform * (centre[:, 0], centre[:, 1])
    inside = zone[rows.astype(int), cols.astype(int)]
    return np.abs(triangle_areas(nodes, tri))[inside]
