"""Solver exports: one triangular mesh written as the files solvers read.

| format | file | solvers |
|---|---|---|
| ``2dm`` | SMS 2DM with material ids and node strings | BASEMENT, TUFLOW FV, SRH-2D |
| ``slf`` | TELEMAC Selafin (double precision) + boundary conditions ``.cli`` | TELEMAC-2D |
| ``14`` | ADCIRC fort.14 (depth positive down, open and land boundaries) | ADCIRC |
| ``gr3`` | SCHISM hgrid.gr3 (the fort.14 layout with SCHISM's boundary flags) | SCHISM |
| ``nc`` | UGRID-1.0 netCDF (classic) with the CRS | D-Flow FM, QGIS |
| ``gpkg`` | GeoPackage layers triangles, nodes, boundary, breaklines | HEC-RAS (and any GIS) |

Every boundary is land (a solid wall) unless an open-boundary line (an inflow or outflow
section) passes within the snapping distance of its nodes. Every file is written under a
temporary name and renamed when complete (``io.atomic_output``); the same input gives the same
bytes (the GeoPackage aside, which stamps its time).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import io
from ..engine.arrays import unique_rows
from ..engine.progress import along, report
from ..errors import FloodMeshError
from ..options import EXPORT_EXTENSIONS as EXTENSIONS, export_format, parse_formats
from ..points import xyz_array
from ..raster import (check_scale, corners_and_centre, parse_crs, require_metric_crs,
                      same_place)
from .accuracy import tin_elevation
from .mesh import boundary_loops

ADCIRC_MAINLAND, ADCIRC_ISLAND = 20, 21  # no normal flow, natural (weak), free tangential slip
SCHISM_EXTERIOR, SCHISM_ISLAND = 0, 1
TELEMAC_WALL = (2, 2, 2, 2)   # LIHBOR LIUBOR LIVBOR LITBOR: solid boundary
TELEMAC_FREE = (4, 4, 4, 4)   # free depth, velocity and tracer: set 4 5 5 or 5 4 4 per section


@dataclass(frozen=True)
class Segment:
    """A run of boundary nodes, in boundary order (mesh on the left). ``closed``: the whole
    loop, its last node joining its first."""

    kind: str          # "open" or "land"
    nodes: np.ndarray
    loop: int
    island: bool
    closed: bool


@dataclass(frozen=True)
class Boundary:
    """Boundary loops (outer rings counter-clockwise, then holes clockwise), each starting where
    its first segment starts, and their segments loop by loop."""

    loops: list
    islands: list
    segments: list

    @property
    def numbering(self) -> np.ndarray:
        """Boundary nodes in TELEMAC's boundary numbering (loop after loop)."""
        return np.concatenate(self.loops)

    def of_kind(self, kind: str) -> list:
        return [s for s in self.segments if s.kind == kind]


@dataclass(frozen=True)
class SolverMesh:
    """What the writers take: ``nodes`` (n, 3) with the datum offset applied, ``triangles``
    counter-clockwise, one ``materials`` id per triangle, the ``boundary`` and the ``crs``."""

    nodes: np.ndarray
    triangles: np.ndarray
    materials: np.ndarray
    boundary: Boundary
    crs: object = None


# ---------------------------------------------------------------------------------------------
# formats
def format_of(path, fmt: str | None = None) -> str:
    """The format ``fmt`` names, else the one ``path``'s extension names."""
    if fmt:
        return export_format(fmt.strip().lower().lstrip("."))
    suffix = Path(path).suffix.lower()
    for name, ext in EXTENSIONS.items():
        if suffix == ext:
            return name
    raise FloodMeshError(f"cannot tell the mesh format of {Path(path).name} from its extension "
                         f"{suffix or '(none)'!r}; use one of "
                         f"{' '.join(EXTENSIONS.values())} or give the format (--format)")


# ---------------------------------------------------------------------------------------------
# preparing the mesh
def prepare(nodes, triangles, *, crs=None, open_lines=(), snap: float = 1.0, regions=(),
            materials=None, datum_offset: float = 0.0) -> SolverMesh:
    """Check the mesh, orient its triangles counter-clockwise, add ``datum_offset`` (m) to every
    elevation, find its boundary and the open sections on it, and set material ids.

    ``open_lines``: (k, 2+) coordinate arrays; ``regions``: (polygon, material id) pairs, later
    ones over earlier ones, by triangle centroid; ``materials``: ids to start from (default 1).
    """
    nodes = xyz_array(nodes, "the mesh's nodes")
    triangles = np.array(triangles, dtype=np.int64).reshape(-1, 3)
    if len(triangles) == 0:
        raise FloodMeshError("the mesh has no triangles: nothing to export")
    if triangles.min() < 0 or triangles.max() >= len(nodes):
        raise FloodMeshError("the mesh's triangles refer to nodes it does not have")
    if not np.isfinite(nodes).all():
        raise FloodMeshError(f"{int((~np.isfinite(nodes).all(axis=1)).sum())} mesh nodes have no "
                             "valid x, y or z; fill them before exporting")
    unused = len(nodes) - np.unique(triangles).size
    if unused:
        raise FloodMeshError(f"{unused} mesh nodes belong to no triangle; solvers refuse such "
                             "nodes: remove them from the mesh")
    if not np.isfinite(datum_offset):
        raise FloodMeshError(f"the vertical datum offset must be a number of metres, got "
                             f"{datum_offset}")
    p = nodes[triangles][:, :, :2]
    cross = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
             - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    _refuse_flat_triangles(p, cross)
    triangles = np.where((cross < 0)[:, None], triangles[:, [0, 2, 1]], triangles)
    shifted = nodes.copy()
    shifted[:, 2] += datum_offset
    boundary = mesh_boundary(nodes, triangles, open_lines, snap=snap)
    _refuse_pinched(boundary, nodes)
    mats = (np.ones(len(triangles), np.int64) if materials is None
            else np.asarray(materials, np.int64).copy())
    if len(mats) != len(triangles):
        raise FloodMeshError(f"{len(mats)} material ids for {len(triangles)} triangles")
    mats = region_materials(nodes, triangles, regions, mats)
    crs = _crs(crs)
    if crs is not None:  # the snapping distance and the solvers' lengths are metres on the ground
        check_scale(crs, *corners_and_centre(*nodes[:, :2].min(axis=0), *nodes[:, :2].max(axis=0)),
                    "the mesh")
    return SolverMesh(shifted, triangles, mats, boundary, crs)


def _refuse_flat_triangles(corners: np.ndarray, cross: np.ndarray) -> None:
    """Refuse triangles without area (three nodes on one line): solvers divide by the area."""
    longest = np.max([np.hypot(*(corners[:, (k + 1) % 3] - corners[:, k]).T) for k in range(3)],
                     axis=0)
    flat = np.abs(cross) <= 1e-9 * longest ** 2
    if flat.any():
        first = int(np.argmax(flat))
        x, y = corners[first].mean(axis=0)
        raise FloodMeshError(
            f"{int(flat.sum())} triangles of the mesh have no area (their three nodes lie on one "
            f"line; the first is triangle {first + 1}, at {x:.2f}, {y:.2f}): solvers fail on "
            "them; mesh again (floodmesh mesh) or remove them in the mesh editor")


def _refuse_pinched(boundary: "Boundary", nodes: np.ndarray) -> None:
    """Refuse a boundary that touches itself at a node: solvers number each boundary node
    once (TELEMAC's IPOBO) and take each boundary for a simple ring (ADCIRC, SCHISM)."""
    numbering = boundary.numbering
    ids, counts = np.unique(numbering, return_counts=True)
    if (counts > 1).any():
        node = int(ids[np.argmax(counts > 1)])
        x, y = np.asarray(nodes)[node, :2]
        more = int((counts > 1).sum()) - 1
        others = f" and {more} other node{'s' if more > 1 else ''}" if more else ""
        raise FloodMeshError(
            f"the mesh boundary touches itself at node {node + 1} ({x:.2f}, {y:.2f}){others}: "
            "solvers need boundaries that do not; "
            "separate the parts of the domain that touch there (remove a triangle at the node, "
            "or mesh again with a domain polygon that keeps them apart)")


def _crs(crs):
    """The mesh's CRS: projected, in metres, as FloodMesh's meshes are."""
    if crs is None:
        return None
    parsed = parse_crs(crs, "the mesh's CRS")
    try:
        return require_metric_crs(parsed, f"the mesh's CRS {parsed.name}")
    except FloodMeshError:
        raise FloodMeshError(
            f"the mesh's CRS cannot be {parsed.name}: it is not a projected CRS in metres, and a "
            "mesh's x, y and z are metres (as FloodMesh makes them); give the CRS of the data the "
            "mesh was made from, e.g. its UTM zone (EPSG:25832)") from None


def mesh_boundary(nodes, triangles, open_lines=(), *, snap: float = 1.0) -> Boundary:
    """Boundary loops split into open sections (boundary nodes within ``snap`` m of an
    open-boundary line, two or more in a row; a node near two lines goes to the nearer) and
    land between them. Each line makes sections of its own: two lines meeting end to end give
    two sections sharing the node where they meet."""
    loops = boundary_loops(nodes, triangles)
    xy = np.asarray(nodes, float)[:, :2]
    islands = [_signed_area(xy[loop]) < 0 for loop in loops]
    labels = [np.zeros(len(loop), np.int64) for loop in loops]  # 0 land, k: open line k
    if len(open_lines):
        # lazy: GEOS loads only when this runs
        import shapely

        if not snap > 0:
            raise FloodMeshError(f"the snapping distance for open boundaries must be positive "
                                 f"metres, got {snap}")
        points = shapely.points(xy[np.concatenate(loops)])
        starts = np.cumsum([0] + [len(loop) for loop in loops])
        nearest = [np.full(len(loop), np.inf) for loop in loops]
        for number, line in enumerate(open_lines, start=1):
            line = np.asarray(line, float)
            if len(line) < 2:
                raise FloodMeshError(f"open boundary line {number} has fewer than two points")
            distance = shapely.distance(points, shapely.LineString(line[:, :2]))
            touched = False
            for k, label in enumerate(labels):
                d = distance[starts[k]:starts[k + 1]]
                near = _drop_single_nodes(d <= snap)
                touched |= bool(near.any())
                closer = near & (d < nearest[k])
                label[closer] = number
                nearest[k][closer] = d[closer]
            if not touched:
                raise FloodMeshError(
                    f"open boundary line {number} touches the mesh boundary at fewer than two "
                    f"nodes (the nearest boundary node is {distance.min():.2f} m away, the "
                    f"snapping distance {snap:g} m): draw it along the boundary section or raise "
                    "the snapping distance")
    ordered, segments = [], []
    for k, (loop, label) in enumerate(zip(loops, labels)):
        if (label == label[0]).all():
            ordered.append(loop)
            segments.append(Segment("open" if label[0] else "land", loop, k, islands[k], True))
            continue
        # start where an open section starts
        first = int(np.nonzero((label != np.roll(label, 1)) & (label != 0))[0][0])
        loop, label = np.roll(loop, -first), np.roll(label, -first)
        ordered.append(loop)
        ring = np.append(loop, loop[0])
        runs = np.flatnonzero(np.diff(label)) + 1
        bounds = list(zip([0, *runs.tolist()], [*(runs - 1).tolist(), len(loop) - 1]))
        for i, (start, end) in enumerate(bounds):
            after = label[bounds[(i + 1) % len(bounds)][0]]
            if label[start]:
                # an open section ends where the next one starts when they meet end to end
                lo, hi = start, end + 1 + (after != 0)
                segments.append(Segment("open", ring[lo:hi], k, islands[k], False))
            else:  # land shares its end nodes with the open sections on either side
                segments.append(Segment("land", ring[start - 1:end + 2], k, islands[k], False))
    return Boundary(ordered, islands, segments)


def _drop_single_nodes(mask: np.ndarray) -> np.ndarray:
    """Cyclic runs of one True in a row become False: one node makes no section."""
    if mask.all():
        return mask
    return mask & (np.roll(mask, 1) | np.roll(mask, -1))


def _signed_area(xy) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def layers_crs(crs, layers: dict):
    """The CRS to export in: ``crs`` if given, else the one the given vector layers share
    (name → path); a FloodMeshError where they differ from it or from each other."""
    chosen = _crs(crs)
    for name, path in layers.items():
        if not path:
            continue
        wkt = io.vector_crs(path)
        if not wkt:
            continue
        layer = _crs(wkt)
        if chosen is None:
            chosen = layer
        elif not same_place(chosen, layer):
            raise FloodMeshError(f"the {name} layer {Path(path).name} is in {layer.name}, the mesh "
                                 f"in {chosen.name}: reproject the layer to the mesh's CRS")
    return chosen


def region_materials(nodes, triangles, regions, materials) -> np.ndarray:
    """Material id per triangle: each (polygon, id) of ``regions`` sets the id of the triangles
    whose centroid it contains, later regions over earlier ones."""
    if not len(regions):
        return materials
    # lazy: GEOS loads only when this runs
    import shapely

    centroid = np.asarray(nodes, float)[triangles][:, :, :2].mean(axis=1)
    out = materials.copy()
    for polygon, material in regions:
        out[shapely.contains_xy(polygon, centroid[:, 0], centroid[:, 1])] = int(material)
    return out


# ---------------------------------------------------------------------------------------------
# the whole export
def export_mesh(path, nodes, triangles, *, fmt: str | None = None, crs=None, open_lines=(),
                snap: float = 1.0, regions=(), materials=None, datum_offset: float = 0.0,
                element_elevations: bool = False, breaklines=(),
                title: str = "FloodMesh mesh", progress=None, cancelled=None) -> list[Path]:
    """Write the mesh as ``fmt`` (default: from ``path``'s extension); return the files written
    (Selafin adds the ``.cli`` beside it). See ``prepare`` for the options; ``breaklines`` go
    into the GeoPackage. ``progress`` hears the share done by stages (checked and prepared,
    written), ``cancelled`` is polled before the writing."""
    fmt = format_of(path, fmt)
    mesh = prepare(nodes, triangles, crs=crs, open_lines=open_lines, snap=snap, regions=regions,
                   materials=materials, datum_offset=datum_offset)
    report(progress, cancelled, 0.5)
    written = write(path, mesh, fmt, element_elevations=element_elevations,
                    breaklines=breaklines, title=title)
    report(progress, None, 1.0)
    return written


def export_formats(stem, nodes, triangles, formats, *, progress=None, cancelled=None,
                   **options) -> list[Path]:
    """Write ``stem`` + each format's extension (``mesh`` → ``mesh.slf``, ``mesh.14``, …);
    the mesh is prepared once; ``progress`` hears the share of the formats written,
    ``cancelled`` is polled before each."""
    formats = parse_formats(formats)
    keys = ("element_elevations", "breaklines", "title")
    writing = {k: options.pop(k) for k in keys if k in options}
    mesh = prepare(nodes, triangles, **options)
    written = []
    for fmt in along(formats, progress, cancelled):
        target = Path(f"{stem}{EXTENSIONS[fmt]}")
        written += write(target, mesh, fmt, **writing)
    return written


def write(path, mesh: SolverMesh, fmt: str, *, element_elevations: bool = False,
          breaklines=(), title: str = "FloodMesh mesh") -> list[Path]:
    path = Path(path)
    if fmt in ("nc", "gpkg") and mesh.crs is None:
        raise FloodMeshError(f"{path.name}: the {fmt} format carries the CRS, and none is known "
                             "(an SMS 2DM file has none): give it (--crs EPSG:XXXX)")
    if fmt == "2dm":
        write_2dm(path, mesh, element_elevations=element_elevations)
    elif fmt == "slf":
        return [path, *write_selafin(path, mesh, title=title)]
    elif fmt in ("14", "gr3"):
        write_grid14(path, mesh, schism=fmt == "gr3", title=title)
    elif fmt == "nc":
        write_ugrid(path, mesh, title=title)
    else:
        write_gpkg(path, mesh, breaklines=breaklines)
    return [path]


# ---------------------------------------------------------------------------------------------
# SMS 2DM
def write_2dm(path, mesh: SolverMesh, *, element_elevations: bool = False) -> None:
    """SMS 2DM (Aquaveo's 2D mesh file): material ids, node elevations (BASEMENT 2.8, TUFLOW FV,
    SRH-2D) and optionally element-centre elevations (the mean of the three node elevations)
    as the second material column (BASEMENT 3);
    node strings: each boundary loop (closed, its first node repeated), then each open section."""
    loops = [np.append(loop, loop[0]) for loop in mesh.boundary.loops]
    sections = [np.append(s.nodes, s.nodes[0]) if s.closed else s.nodes
                for s in mesh.boundary.of_kind("open")]
    element_z = (mesh.nodes[mesh.triangles, 2].mean(axis=1) if element_elevations else None)
    io.write_mesh_2dm(path, mesh.nodes, mesh.triangles, materials=mesh.materials,
                      element_z=element_z, node_strings=loops + sections, crs=mesh.crs)


# ---------------------------------------------------------------------------------------------
# TELEMAC
def write_selafin(path, mesh: SolverMesh, *, title: str = "FloodMesh mesh") -> list[Path]:
    """TELEMAC geometry file in Selafin double precision ('SERAFIND': set GEOMETRY FILE FORMAT
    to SERAFIND), with the variable BOTTOM (m) and the boundary numbering IPOBO, and beside it
    the boundary conditions file (.cli) in the same order. Returns the .cli path.

    Layout (big-endian Fortran records): title (72 + 'SERAFIND'), NBV1 NBV2, variable names
    (32 characters), IPARAM (10), NELEM NPOIN NDP 1, IKLE (1-based), IPOBO, X, Y, then one
    time step: time, BOTTOM.
    """
    numbering = mesh.boundary.numbering  # each node once (prepare refuses pinched boundaries)
    n, m = len(mesh.nodes), len(mesh.triangles)
    ipobo = np.zeros(n, np.int64)
    ipobo[numbering] = np.arange(1, len(numbering) + 1)

    def record(fh, payload: bytes):
        size = struct.pack(">i", len(payload))
        fh.write(size + payload + size)

    cli = Path(path).with_suffix(".cli")
    with io.atomic_output(path) as tmp, io.atomic_output(cli) as tmp_cli:
        with open(tmp, "wb") as fh:
            record(fh, title.encode("ascii", "replace")[:72].ljust(72) + b"SERAFIND")
            record(fh, np.array([1, 0], ">i4").tobytes())
            record(fh, b"BOTTOM".ljust(16) + b"M".ljust(16))
            record(fh, np.array([1] + [0] * 9, ">i4").tobytes())
            record(fh, np.array([m, n, 3, 1], ">i4").tobytes())
            record(fh, (mesh.triangles + 1).astype(">i4").tobytes())
            record(fh, ipobo.astype(">i4").tobytes())
            record(fh, mesh.nodes[:, 0].astype(">f8").tobytes())
            record(fh, mesh.nodes[:, 1].astype(">f8").tobytes())
            record(fh, np.array([0.0], ">f8").tobytes())
            record(fh, mesh.nodes[:, 2].astype(">f8").tobytes())
        sections = [s.nodes for s in mesh.boundary.of_kind("open")]
        open_nodes = {int(i) for nodes in sections for i in nodes}
        # where two sections meet end to end, their shared node is a wall, so that TELEMAC
        # (which joins neighbouring liquid nodes into one boundary) keeps them apart
        shared = np.unique(np.concatenate(sections or [np.empty(0, np.int64)]),
                           return_counts=True)
        open_nodes -= set(shared[0][shared[1] > 1].tolist())
        with open(tmp_cli, "w") as fh:
            for k, node in enumerate(numbering.tolist(), start=1):
                lih, liu, liv, lit = TELEMAC_FREE if node in open_nodes else TELEMAC_WALL
                fh.write(f"{lih} {liu} {liv} 0.000 0.000 0.000 0.000 {lit} 0.000 0.000 0.000 "
                         f"{node + 1} {k}\n")
    return [cli]


# ---------------------------------------------------------------------------------------------
# ADCIRC fort.14 and SCHISM hgrid.gr3
def write_grid14(path, mesh: SolverMesh, *, schism: bool = False,
                 title: str = "FloodMesh mesh") -> None:
    """ADCIRC fort.14 or SCHISM hgrid.gr3: nodes with depth = −elevation (m, positive down),
    triangles, open boundary segments (elevation specified), land segments.

    ADCIRC: land IBTYPE 20 (mainland) and 21 (islands); a closed land boundary repeats its first
    node at the end. SCHISM: land flag 0 (exterior) and 1 (island); an island is not closed, and
    a boundary loop of one kind only is given as two segments linked end to end.
    """
    opens, lands = [], []
    for seg in mesh.boundary.segments:
        parts = [seg.nodes]
        if seg.closed and schism and not (seg.kind == "land" and seg.island):
            half = len(seg.nodes) // 2
            ring = np.append(seg.nodes, seg.nodes[0])
            parts = [ring[:half + 1], ring[half:]]
        elif seg.closed and not schism:
            parts = [np.append(seg.nodes, seg.nodes[0])]
        for nodes in parts:
            if seg.kind == "open":
                opens.append(nodes)
            elif schism:
                lands.append((nodes, SCHISM_ISLAND if seg.island else SCHISM_EXTERIOR))
            else:
                lands.append((nodes, ADCIRC_ISLAND if seg.island else ADCIRC_MAINLAND))
    n, m = len(mesh.nodes), len(mesh.triangles)
    depth = -mesh.nodes[:, 2]
    with io.atomic_output(path) as tmp:
        with open(tmp, "w") as fh:
            # NE NP alone: adcircpy and pyschism read this line as two integers and nothing else
            fh.write(f"{title[:24]}\n{m} {n}\n")
            np.savetxt(fh, np.column_stack([np.arange(1, n + 1), mesh.nodes[:, :2], depth]),
                       fmt="%d %.4f %.4f %.4f")
            np.savetxt(fh, np.column_stack([np.arange(1, m + 1), np.full(m, 3),
                                            mesh.triangles + 1]), fmt="%d")
            fh.write(f"{len(opens)} ! NOPE: open boundaries\n"
                     f"{sum(map(len, opens))} ! NETA: open boundary nodes\n")
            for k, nodes in enumerate(opens, start=1):
                fh.write(f"{len(nodes)}{'' if schism else ' 0'} ! open boundary {k}\n")
                np.savetxt(fh, nodes + 1, fmt="%d")
            fh.write(f"{len(lands)} ! NBOU: land boundaries\n"
                     f"{sum(len(nodes) for nodes, _ in lands)} ! NVEL: land boundary nodes\n")
            for k, (nodes, flag) in enumerate(lands, start=1):
                fh.write(f"{len(nodes)} {flag} ! land boundary {k}\n")
                np.savetxt(fh, nodes + 1, fmt="%d")


# ---------------------------------------------------------------------------------------------
# UGRID netCDF
def write_ugrid(path, mesh: SolverMesh, *, title: str = "FloodMesh mesh") -> None:
    """UGRID-1.0 netCDF (classic, 64-bit offsets): the topology variable ``mesh2d``, node x/y/z
    (z: bed elevation, m, standard name altitude), edge and face node connectivity (1-based),
    and the CRS in ``projected_coordinate_system`` (EPSG code, WKT and CF grid mapping), as
    D-Flow FM's net files and QGIS (MDAL) read them."""
    # lazy: SciPy loads only when this runs
    from scipy.io import netcdf_file

    crs = mesh.crs
    tri = mesh.triangles
    edges = unique_rows(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]),
                                axis=1))
    n, m = len(mesh.nodes), len(tri)
    gm = "projected_coordinate_system"

    def attrs(var, **values):
        for key, value in values.items():
            if isinstance(value, bool):
                value = np.int32(value)
            elif isinstance(value, (int, np.integer)):
                value = np.int32(value)
            elif isinstance(value, (float, np.floating)):
                value = np.float64(value)
            elif isinstance(value, (list, tuple)):
                value = np.asarray(value, np.float64)
            elif isinstance(value, str):
                value = value.encode("utf-8")
            setattr(var, key, value)

    with io.atomic_output(path) as tmp:
        nc = netcdf_file(tmp, "w", version=2)
        try:
            attrs(nc, Conventions="CF-1.8 UGRID-1.0 Deltares-0.10", title=title,
                  source="FloodMesh")
            for name, size in (("mesh2d_nNodes", n), ("mesh2d_nEdges", len(edges)),
                               ("mesh2d_nFaces", m), ("mesh2d_nMax_face_nodes", 3), ("Two", 2)):
                nc.createDimension(name, size)
            topology = nc.createVariable("mesh2d", "i4", ())
            # a dummy, but written: unset, scipy writes stale memory. Not assignValue: scipy
            # >= 1.14 indexes the scalar's 0-d array with [:] there, which fails
            topology.data[...] = 0
            attrs(topology, cf_role="mesh_topology", long_name="Topology data of 2D mesh",
                  topology_dimension=2, node_coordinates="mesh2d_node_x mesh2d_node_y",
                  node_dimension="mesh2d_nNodes", edge_node_connectivity="mesh2d_edge_nodes",
                  edge_dimension="mesh2d_nEdges", face_node_connectivity="mesh2d_face_nodes",
                  face_dimension="mesh2d_nFaces", max_face_nodes_dimension="mesh2d_nMax_face_nodes")
            for axis, column in (("x", 0), ("y", 1)):
                var = nc.createVariable(f"mesh2d_node_{axis}", "f8", ("mesh2d_nNodes",))
                var[:] = mesh.nodes[:, column]
                attrs(var, standard_name=f"projection_{axis}_coordinate",
                      long_name=f"{axis}-coordinate of mesh nodes", units="m", mesh="mesh2d",
                      location="node", grid_mapping=gm)
            var = nc.createVariable("mesh2d_node_z", "f8", ("mesh2d_nNodes",))
            var[:] = mesh.nodes[:, 2]
            attrs(var, standard_name="altitude", long_name="bed elevation at mesh nodes",
                  units="m", positive="up", mesh="mesh2d", location="node",
                  coordinates="mesh2d_node_x mesh2d_node_y", grid_mapping=gm)
            var = nc.createVariable("mesh2d_edge_nodes", "i4", ("mesh2d_nEdges", "Two"))
            var[:] = edges + 1
            attrs(var, cf_role="edge_node_connectivity", long_name="start and end nodes of "
                  "mesh edges", mesh="mesh2d", location="edge", start_index=1)
            var = nc.createVariable("mesh2d_face_nodes", "i4",
                                    ("mesh2d_nFaces", "mesh2d_nMax_face_nodes"))
            var[:] = tri + 1
            attrs(var, cf_role="face_node_connectivity", long_name="nodes of each face, "
                  "counter-clockwise", mesh="mesh2d", location="face", start_index=1,
                  _FillValue=-999)
            var = nc.createVariable(gm, "i4", ())
            var.data[...] = 0  # as the topology's dummy
            cf = {k: v for k, v in crs.to_cf().items() if v is not None}
            epsg = crs.to_epsg()
            wkt = crs.to_wkt()
            attrs(var, name=crs.name, **{"crs_wkt": wkt, **cf}, wkt=wkt, epsg=epsg or 0,
                  EPSG_code=f"EPSG:{epsg}" if epsg else "")
            nc.flush()
        finally:
            nc.close()


# ---------------------------------------------------------------------------------------------
# GeoPackage
def write_gpkg(path, mesh: SolverMesh, *, breaklines=()) -> None:
    """One GeoPackage with the layers ``triangles`` (PolygonZ: id, area, smallest angle,
    material), ``nodes`` (PointZ: id, z), ``boundary`` (LineStringZ: kind open/land) and, when
    given, ``breaklines`` (LineStringZ), all in the mesh's CRS: what HEC-RAS needs to build its
    own mesh (break lines, terrain, boundary)."""
    nodes = mesh.nodes
    segments = mesh.boundary.segments
    lines = [nodes[np.append(s.nodes, s.nodes[0]) if s.closed else s.nodes] for s in segments]
    with io.atomic_output(path) as tmp:
        io.write_mesh_gpkg(tmp, nodes, mesh.triangles, mesh.crs, layer="triangles",
                           attributes={"material": mesh.materials}, atomic=False)
        io.write_points_gpkg(tmp, nodes, mesh.crs, layer="nodes", atomic=False,
                             attributes={"id": np.arange(1, len(nodes) + 1),
                                         "z": nodes[:, 2]})
        io.write_lines_gpkg(tmp, lines, mesh.crs, layer="boundary", atomic=False, attributes={
            "kind": np.array([s.kind for s in segments]),
            "loop": np.array([s.loop + 1 for s in segments]),
            "island": np.array([s.island for s in segments]),
            "n_nodes": np.array([len(s.nodes) for s in segments])})
        if len(breaklines):
            io.write_lines_gpkg(tmp, [_with_mesh_z(b, mesh) for b in breaklines], mesh.crs,
                                layer="breaklines", atomic=False)


def _with_mesh_z(line, mesh: SolverMesh) -> np.ndarray:
    """A break line (k, 2|3) as x, y, z, where it has no z (a 2-D line, read with NaN z) the
    mesh's TIN z there (NaN outside the mesh): HEC-RAS takes break lines' z as terrain."""
    line = np.asarray(line, float)
    xyz = np.column_stack([line[:, :2], line[:, 2] if line.shape[1] > 2
                           else np.full(len(line), np.nan)])
    missing = ~np.isfinite(xyz[:, 2])
    if missing.any():
        xyz[missing, 2] = tin_elevation(mesh, xyz[missing, 0], xyz[missing, 1])
    return xyz
