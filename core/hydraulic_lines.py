"""Break lines a flood model can afford, applied to the lines before the PSLG is built.

An explicit solver's time step is set by its smallest triangle (see ``hydraulics``). Detected
break lines make tiny triangles in three places: where they run within a fraction of a metre
of the domain edge, where they cross or nearly touch the modeller's own lines or each other,
and where simplification left vertices closer together than the mesh can resolve. With a
smallest spacing s (default: the cell size d):

- detected lines are clipped back ``clearance`` (default 2 s) from the domain edge;
- the parts of a detected line within s of an own line, or of a longer detected line, are cut
  away (near-parallel lines merge into the longer one; crossings keep one line through them);
- vertices closer than s to the previous kept vertex are dropped (the end points stay);
- what is left shorter than 2 s is dropped.

The modeller's own lines are kept as given.
"""
from __future__ import annotations

import numpy as np


def thin_vertices(coords: np.ndarray, spacing: float) -> np.ndarray:
    """``coords`` (k, 2+) without vertices closer than ``spacing`` to the previous kept one;
    both ends stay (the last kept inner vertex gives way to the end)."""
    coords = np.asarray(coords, float)
    if len(coords) <= 2:
        return coords
    keep = [0]
    for i in range(1, len(coords) - 1):
        if np.hypot(*(coords[i, :2] - coords[keep[-1], :2])) >= spacing:
            keep.append(i)
    while len(keep) > 1 and np.hypot(*(coords[-1, :2] - coords[keep[-1], :2])) < spacing:
        keep.pop()
    keep.append(len(coords) - 1)
    return coords[keep]


def lines_for_hydraulics(lines, domain, *, spacing: float, clearance: float | None = None,
                         own_lines=()) -> tuple[list[np.ndarray], dict]:
    """Detected ``lines`` ((k, 3) arrays) made affordable for a flood model inside ``domain``
    (a shapely (Multi)Polygon), as the module says; returns (lines, counts of what was done)."""
    import shapely

    clearance = 2 * spacing if clearance is None else clearance
    inner = domain.buffer(-clearance) if domain is not None else None
    taken = [shapely.LineString(np.asarray(c)[:, :2]) for c in own_lines if len(c) >= 2]
    order = sorted(range(len(lines)), key=lambda k: -_length(lines[k]))
    out, stats = [], {"lines_in": len(lines), "vertices_in": int(sum(len(c) for c in lines)),
                      "clipped_at_edge": 0, "cut_near_other_lines": 0}
    for k in order:
        line = shapely.LineString(np.asarray(lines[k], float))
        if inner is not None:
            clipped = shapely.intersection(line, inner)
            stats["clipped_at_edge"] += clipped.length < line.length - 1e-9
            line = clipped
        if taken and not line.is_empty:
            near = shapely.union_all(taken).buffer(spacing)
            cut = shapely.difference(line, near)
            stats["cut_near_other_lines"] += cut.length < line.length - 1e-9
            line = cut
        for part in _parts(line):
            coords = thin_vertices(shapely.get_coordinates(part, include_z=True), spacing)
            if _length(coords) >= 2 * spacing and len(coords) >= 2:
                out.append(coords)
                taken.append(shapely.LineString(coords[:, :2]))
    stats.update(lines_out=len(out), vertices_out=int(sum(len(c) for c in out)),
                 spacing_m=spacing, clearance_m=clearance)
    return out, stats


def _length(coords) -> float:
    c = np.asarray(coords, float)
    return float(np.hypot(*np.diff(c[:, :2], axis=0).T).sum()) if len(c) > 1 else 0.0


def _parts(geometry):
    if geometry.is_empty:
        return []
    if geometry.geom_type == "LineString":
        return [geometry]
    return [g for g in getattr(geometry, "geoms", []) if g.geom_type == "LineString"]
