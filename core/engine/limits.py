"""Size guards: estimate a run's points, grid cells and triangles before the work starts, and
refuse up front, with the estimate, what would exceed the triangle limit or the memory
available, instead of running for hours or being killed by the operating system.

The bytes per point, cell and triangle are peak figures measured on the development machine
(Debian 12, numpy 1.24) with ``/usr/bin/time``-style peak RSS over the whole chain:
gridding 2 M points on 1 M cells took 124 B/point over the points' own 24 B, the chain on a
2.25 M-cell DEM 56 B/cell, and meshing plus writing 0.7 M triangles (2DM, GeoPackage,
residuals) 1.5 kB/triangle.
"""
from __future__ import annotations

import math
import os

import numpy as np

from ..errors import FloodMeshError

BYTES_PER_POINT = 160       # read (laspy records + x, y, z), holdout split, bucket sort, tile TINs
BYTES_PER_CELL = 64         # DEM, slope, breakpoints, tracing masks, GeoTIFF copies
# The chain after gridding where the terrain fits take the DEM's cell centres (point tiles, a
# DEM): the DEM, the centres (24 B) and their index (4 B), the flow zone's grids. With
# benchmarks/tiles.py the command's peak grew 65 MB per km² of 1 m cells from 1 to 36 km²,
# its mesh at the flow area included: 100 B a cell, with the mesh term, is on the safe side.
BYTES_PER_FITTED_CELL = 100
BYTES_PER_TRIANGLE = 1600   # Triangle, nodes/triangles, quality, 2DM and GeoPackage records
# Triangle's quality refinement leaves triangles of about 0.64 of the area bound on open ground
# (measured: 1.94 M triangles over 249 001 m² at 0.2 m²) and refines around input vertices.
TRIANGLES_PER_AREA_BOUND = 1.6
TRIANGLES_PER_INPUT_VERTEX = 8
# A cell stays nodata unless a TIN triangle with edges up to the max gap covers it: with random
# points s apart, a gap of 1.5 s covers about 30 % of the cells, 2 s about 65 %, 3 s 97 %.
MIN_GAP_IN_SPACINGS = 1.5


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping (Linux MemAvailable),
    or None where that cannot be read."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _gb(n_bytes: float) -> str:
    return f"{n_bytes / 1e9:.1f} GB" if n_bytes >= 1e8 else f"{n_bytes / 1e6:.0f} MB"


def estimate_triangles(area: float, max_area: float, input_vertices: int = 0) -> int:
    """Triangles a quality mesh of ``area`` m² with area bound ``max_area`` will about have."""
    return int(math.ceil(TRIANGLES_PER_AREA_BOUND * area / max_area
                         + TRIANGLES_PER_INPUT_VERTEX * input_vertices))


def check_triangles(area: float, max_area: float, max_triangles: int, input_vertices: int = 0,
                    *, memory: int | None = None, local: str | None = None) -> int:
    """Refuse, before meshing, a mesh estimated above ``max_triangles`` triangles or above the
    memory available (``memory`` bytes; by default what the system has free). ``local`` names
    what asks for triangles below the maximum area (``max_area`` is then their mean area, as a
    size field or refinement asks), for the advice."""
    estimate = estimate_triangles(area, max_area, input_vertices)
    if local:
        larger = {"the size field": "a larger --flow-area (0: none) or a coarser --size-field",
                  "refinement": "looser refinement bounds (--lower, --upper)"}.get(local, "")
        advice = (f"{local} asks for triangles of {max_area:.3g} m² on average over "
                  f"{area:,.0f} m²: ask for larger ones ({larger}) or mesh the area in parts")
    else:
        advice = "give a larger maximum area or mesh the area in tiles"
    if estimate > max_triangles:
        if not local:
            larger = max_area * estimate / max_triangles
            advice = f"give a maximum area of at least {larger:.3g} m², mesh the area in tiles"
        raise FloodMeshError(
            f"the mesh would have about {estimate:,} triangles ({area:,.0f} m² at a "
            f"{'mean' if local else 'maximum'} area of {max_area:.3g} m²), more than the limit of "
            f"{max_triangles:,}: {advice}, or raise the limit (--max-triangles, 'Maximum number "
            "of triangles' in QGIS) if the machine can take it")
    check_memory(triangles=estimate, memory=memory, advice=advice)
    return estimate


def memory_needed(*, points: int = 0, cells: int = 0, triangles: int = 0,
                  cell_bytes: int = BYTES_PER_CELL) -> int:
    """Estimated peak bytes of ``points`` points, ``cells`` grid cells at ``cell_bytes`` a cell
    and ``triangles`` triangles."""
    return points * BYTES_PER_POINT + cells * cell_bytes + triangles * BYTES_PER_TRIANGLE


def fits_in_memory(*, points: int = 0, cells: int = 0, triangles: int = 0,
                   memory: int | None = None, cell_bytes: int = BYTES_PER_CELL) -> bool:
    """Whether ``memory_needed`` is within ``memory`` bytes (by default what the system has
    available; True where that cannot be read): ``check_memory``'s test, for work that has a
    lighter alternative instead of a refusal."""
    memory = available_memory() if memory is None else memory
    return memory is None or memory_needed(points=points, cells=cells, triangles=triangles,
                                           cell_bytes=cell_bytes) <= memory


def check_memory(*, points: int = 0, cells: int = 0, triangles: int = 0,
                 memory: int | None = None, cell_bytes: int = BYTES_PER_CELL,
                 advice: str) -> int:
    """Refuse a run whose estimated peak memory exceeds ``memory`` bytes (by default what the
    system has available), at ``cell_bytes`` a grid cell; returns the estimate in bytes."""
    need = memory_needed(points=points, cells=cells, triangles=triangles, cell_bytes=cell_bytes)
    memory = available_memory() if memory is None else memory
    if memory is not None and need > memory:
        parts = [f"{n:,} {name}" for n, name in ((points, "points"), (cells, "grid cells"),
                                                 (triangles, "triangles")) if n]
        raise FloodMeshError(
            f"this run would need about {_gb(need)} of memory ({', '.join(parts)}) but "
            f"{_gb(memory)} is available: {advice}")
    return need


def footprint(xy: np.ndarray, bounds=None) -> tuple[float, float]:
    """(area in m², mean point spacing in m) of the ground the points cover; ``bounds``: their
    (xmin, ymin, xmax, ymax) where known.

    The points are binned at four times the spacing their bounding box would give; the occupied
    bins' area leaves out large voids (water, buildings), so the spacing is that of the data,
    not of the box.
    """
    # lazy: numba loads only where points are read
    import numba

    from .._kernels.points import extent_on_threads, occupied_bins

    n = len(xy)
    xmin, ymin, xmax, ymax = (extent_on_threads(xy[:, 0], xy[:, 1], numba.get_num_threads())
                              if bounds is None else bounds)
    lo, hi = np.array([xmin, ymin]), np.array([xmax, ymax])
    span = np.maximum(hi - lo, 1e-9)
    size = max(4.0 * math.sqrt(span[0] * span[1] / n), float(span.max()) / 4096, 1e-9)
    cols = int(span[0] / size) + 1
    rows = int(span[1] / size) + 1
    area = occupied_bins(xy[:, 0], xy[:, 1], float(lo[0]), float(lo[1]), size, cols,
                         rows, numba.get_num_threads()) * size * size
    return area, math.sqrt(area / n)
