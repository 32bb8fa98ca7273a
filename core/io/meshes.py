"""Meshes: SMS 2DM written and read (``write_mesh_2dm``, ``read_2dm`` → ``Mesh2DM``) with the
CRS in a sidecar ``.prj``, and a mesh's triangles as a GeoPackage layer (``write_mesh_gpkg``)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FloodMeshError
from .outputs import atomic_output, require_file
from .vectors import triangle_features, write_gpkg_layer


def write_mesh_2dm(path, nodes: np.ndarray, triangles: np.ndarray, *, material: int = 1,
                   materials=None, element_z=None, node_strings=(), crs=None) -> None:
    """Write a triangular mesh as SMS 2DM: 1-based ids, ``E3T id n1 n2 n3 matid`` lines, then
    ``ND id x y z`` (m), then node strings.

    ``materials`` (one integer per triangle) replaces the single ``material``; ``element_z``
    (m, one per triangle) adds BASEMENT 3's element elevation as the second material column;
    either writes the ``NUM_MATERIALS_PER_ELEM`` card. ``node_strings`` are sequences of node
    indices, each written as ``NS`` lines of up to 10 ids, the last negative, then its number.
    ``crs`` (a 2DM has no place for it) goes into the sidecar ``<stem>.prj`` (``write_prj``).
    """
    n_tri = len(triangles)
    ids = np.arange(1, n_tri + 1)
    mats = np.full(n_tri, material) if materials is None else np.asarray(materials)
    columns = [ids, triangles + 1, mats]
    fmt = "E3T %d %d %d %d %d"
    if element_z is not None:
        columns.append(np.asarray(element_z, float))
        fmt += " %.4f"
    elements = np.column_stack(columns)
    node_rows = np.column_stack([np.arange(1, len(nodes) + 1), nodes])
    with atomic_output(path) as tmp:
        with open(tmp, "w") as fh:
            fh.write("MESH2D\n")
            if materials is not None or element_z is not None:
                fh.write(f"NUM_MATERIALS_PER_ELEM {1 if element_z is None else 2}\n")
            write_rows(fh, fmt, elements)
            write_rows(fh, "ND %d %.4f %.4f %.4f", node_rows)
            for number, string in enumerate(node_strings, start=1):
                ids_ = np.asarray(string, np.int64) + 1
                for start in range(0, len(ids_), 10):
                    chunk = ids_[start:start + 10].tolist()
                    last = start + 10 >= len(ids_)
                    if last:
                        chunk[-1] = -chunk[-1]
                    fh.write("NS " + " ".join(map(str, chunk)) + (f" {number}\n" if last else "\n"))
    if crs is not None:
        write_prj(path, crs)


def write_rows(fh, fmt: str, rows: np.ndarray, chunk: int = 100_000) -> None:
    """The lines ``np.savetxt`` writes of ``rows`` with the format ``fmt``, ``chunk`` rows
    formatted by one ``%`` at a time: 53 000 triangles and 27 000 nodes in 0.03 s instead of
    0.09 s."""
    for start in range(0, len(rows), chunk):
        part = rows[start:start + chunk]
        fh.write((fmt + "\n") * len(part) % tuple(part.ravel().tolist()))


def write_prj(path, crs) -> None:
    """The CRS of a file that cannot hold one (SMS 2DM) as WKT in ``<stem>.prj`` beside it, as
    shapefiles and ASCII grids carry theirs; ``read_prj`` and the QGIS plugin read it back."""
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    with atomic_output(Path(path).with_suffix(".prj")) as tmp:
        Path(tmp).write_text(CRS.from_user_input(crs).to_wkt() + "\n")


def read_prj(path) -> str | None:
    """The WKT of ``<stem>.prj`` beside ``path``, or None when there is none."""
    prj = Path(path).with_suffix(".prj")
    return prj.read_text().strip() or None if prj.is_file() else None


@dataclass(frozen=True)
class Mesh2DM:
    """What an SMS 2DM file holds: ``nodes`` (n, 3), ``triangles`` (m, 3) zero-based,
    ``materials`` (m,) integers (1 where the file gives none), ``element_z`` (m,) or None,
    ``node_strings`` zero-based node index arrays."""

    nodes: np.ndarray
    triangles: np.ndarray
    materials: np.ndarray
    element_z: np.ndarray | None
    node_strings: list
    crs: str | None = None  # WKT of the sidecar .prj (write_prj), if there is one


def read_2dm(path) -> Mesh2DM:
    """Read an SMS 2DM mesh of triangles (E3T) with its materials and node strings."""
    path = require_file(path, "mesh file")
    nodes, tris, extra, strings, current = {}, [], [], [], []
    n_materials = None
    try:
        with open(path, errors="replace") as fh:
            first = fh.readline().split()
            if not first or first[0] != "MESH2D":
                raise FloodMeshError(f"{path.name} is not an SMS 2DM mesh (no MESH2D line)")
            for line in fh:
                parts = line.split("#", 1)[0].split()
                if not parts:
                    continue
                card = parts[0]
                if card == "ND":
                    nodes[int(parts[1])] = (float(parts[2]), float(parts[3]), float(parts[4]))
                elif card == "E3T":
                    tris.append((int(parts[2]), int(parts[3]), int(parts[4])))
                    extra.append([float(v) for v in parts[5:]])
                elif card in ("E4Q", "E6T", "E8Q", "E9Q"):
                    raise FloodMeshError(f"{path.name} has {card} elements; only triangles (E3T) "
                                         "are supported")
                elif card == "NUM_MATERIALS_PER_ELEM":
                    n_materials = int(parts[1])
                elif card == "NS":
                    for token in parts[1:]:
                        value = int(token)
                        current.append(abs(value))
                        if value < 0:
                            strings.append(current)
                            current = []
                            break
    except FloodMeshError:
        raise
    except (ValueError, IndexError, UnicodeDecodeError) as exc:
        raise FloodMeshError(f"{path.name} is not a readable SMS 2DM mesh ({exc})") from None
    if not tris:
        raise FloodMeshError(f"{path.name} holds no triangles (E3T lines): nothing to export")
    ids = np.array(sorted(nodes))
    index = {nid: i for i, nid in enumerate(ids)}
    try:
        tri_arr = np.array([[index[a], index[b], index[c]] for a, b, c in tris], dtype=np.int64)
        string_arr = [np.array([index[i] for i in s], dtype=np.int64) for s in strings]
    except KeyError as exc:
        raise FloodMeshError(f"{path.name} refers to node {exc} that it does not define") from None
    node_arr = np.array([nodes[i] for i in ids], dtype=float).reshape(-1, 3)
    width = min((len(e) for e in extra), default=0)
    values = np.array([e[:width] for e in extra], float).reshape(len(extra), width)
    materials = (values[:, 0].astype(np.int64) if width >= 1
                 else np.ones(len(tris), np.int64))
    # BASEMENT 3 (and MDAL): the column after the material id is the element's elevation
    has_z = width >= 2 and (n_materials is None or n_materials >= 2)
    element_z = values[:, 1].copy() if has_z else None
    return Mesh2DM(node_arr, tri_arr.reshape(-1, 3), materials, element_z, string_arr,
                   read_prj(path))


def read_mesh_2dm(path) -> tuple[np.ndarray, np.ndarray]:
    """Read nodes (n, 3) and triangles (m, 3, zero-based) of an SMS 2DM file."""
    mesh = read_2dm(path)
    return mesh.nodes, mesh.triangles


def write_mesh_gpkg(path, nodes: np.ndarray, triangles: np.ndarray, crs, *, layer="triangles",
                    attributes=None, atomic: bool = True):
    """Write the mesh's triangles as PolygonZ features (id, area_m2, min_angle_deg, and any
    per-triangle ``attributes``)."""
    # lazy: PROJ and GEOS load only when this runs
    from ..steps.mesh import triangle_angles, triangle_areas

    areas = triangle_areas(nodes, triangles)
    min_angles = triangle_angles(nodes, triangles).min(axis=1)
    columns = {"id": np.arange(1, len(triangles) + 1), "area_m2": areas,
               "min_angle_deg": min_angles, **(attributes or {})}
    write_gpkg_layer(path, layer, "3D Polygon", len(triangles),
                     triangle_features(nodes, triangles), columns, crs, atomic=atomic)
