"""Property-based tests of the meshing step: thousands of random and adversarial PSLGs and
rasters, each meshed in a child process with a time bound, so that a crash in Triangle's C code
or a refinement that never ends is caught and reported instead of taking the test run down.

Each case must either give a valid mesh (every triangle counter-clockwise, the angle rule of
``core.steps.mesh.below_angle_bound`` kept, no triangle above the area bound, every input segment a
chain of mesh edges) or raise FloodMeshError. The number of cases run is printed at the end of
the session (tests/conftest.py).

With CI set the cases are the same on every run (derandomised); otherwise every run draws new
ones. ``make fuzz`` draws ten times as many; what it finds goes into test_mesh_regressions.py.
"""
from __future__ import annotations

import math
import multiprocessing
import os
import traceback

import numpy as np
import pytest
import shapely
from affine import Affine
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from pyproj import CRS

from floodmesh.core.errors import FloodMeshError
from floodmesh.core.steps.mesh import (below_angle_bound, build_mesh, build_pslg, domain_from_dem,
                                       triangle_angles, triangulate_pslg)
from floodmesh.core.raster import Grid

from .. import fuzz_stats

TIME_BOUND_S = 30.0          # per case, on a loaded 2-core machine; cases take well under 1 s
MAX_TRIANGLES = 60_000       # keeps each case small: larger meshes are refused (a clear error)
# cases per property; FUZZ_PSLG=... etc. change them (more to search harder, fewer while working)
EXAMPLES = {kind: int(os.environ.get(f"FUZZ_{kind.upper()}", n))
            for kind, n in (("pslg", 1500), ("raster", 600), ("raw", 900))}


def fuzz(kind):
    """Hypothesis settings of one property: no deadline (the sandbox bounds each case), no
    example database, and the same examples on every CI run."""
    return settings(max_examples=EXAMPLES[kind], deadline=None, database=None,
                    suppress_health_check=list(HealthCheck),
                    derandomize=bool(os.environ.get("CI")),
                    # shrinking re-runs cases that may each take the whole time bound: report
                    # the failing case as drawn instead
                    phases=[Phase.explicit, Phase.generate])
UTM = CRS.from_epsg(32633)


# ---------------------------------------------------------------------------------------------
# the sandbox: one forked worker process, restarted after a crash or a time-out
class Sandbox:
    def __init__(self):
        self.context = multiprocessing.get_context("fork")
        self.process = None

    def _start(self):
        self.conn, child = self.context.Pipe()
        self.process = self.context.Process(target=_serve, args=(child,), daemon=True)
        self.process.start()
        child.close()

    def run(self, func, *args):
        """("ok", value) | ("error", FloodMeshError message) | ("exception", traceback) |
        ("crash", exit code) | ("timeout", seconds)."""
        if self.process is None or not self.process.is_alive():
            self._start()
        self.conn.send((func, args))
        if not self.conn.poll(TIME_BOUND_S):
            self.process.kill()
            self.process.join()
            self.process = None
            return "timeout", TIME_BOUND_S
        try:
            return self.conn.recv()
        except EOFError:
            self.process.join()
            code = self.process.exitcode
            self.process = None
            return "crash", code

    def close(self):
        if self.process is not None:
            self.process.kill()
            self.process.join()


def _serve(conn):
    while True:
        try:
            func, args = conn.recv()
        except EOFError:
            return
        try:
            answer = ("ok", func(*args))
        except FloodMeshError as exc:
            answer = ("error", str(exc))
        except Exception:  # noqa: BLE001 - reported as a failure of the property
            answer = ("exception", traceback.format_exc())
        conn.send(answer)


@pytest.fixture(scope="module")
def sandbox():
    box = Sandbox()
    yield box
    box.close()


def _expect_mesh_or_clear_error(sandbox, kind, func, *args):
    outcome, value = sandbox.run(func, *args)
    fuzz_stats.record(kind, outcome)
    assert outcome in ("ok", "error"), f"{outcome}: {value}"
    if outcome == "error":
        assert value and "\n" not in value and len(value) < 600, value
        # build_pslg's output always passes triangulate_pslg's own soundness checks
        assert kind == "raw" or "PSLG cannot be meshed" not in value, value
    else:
        assert value == "valid", value


# ---------------------------------------------------------------------------------------------
# checks, run inside the worker
def _check(vertices, triangles, pslg, min_angle, max_area, corners=None) -> str:
    """'valid', or what is wrong with the mesh. ``corners``: the input segments as indices of
    ``vertices`` (default the PSLG's, whose vertices triangulate_pslg returns first; build_mesh
    numbers the nodes anew and gives them as Mesh.segments)."""
    origin = vertices.min(axis=0)
    xy = vertices - origin
    p = xy[triangles]
    signed = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                    - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    if not (signed > 0).all():
        return f"{int((signed <= 0).sum())} triangles not counter-clockwise"
    if signed.max() > max_area * (1 + 1e-6):
        return f"largest triangle {signed.max()} above {max_area}"
    # the one angle rule of core.steps.mesh: below the bound only at input corners sharper than 60°
    corners = pslg.segments if corners is None else corners
    defects, _ = below_angle_bound(xy, triangles, corners, min_angle)
    if defects.any():
        smallest = triangle_angles(xy, triangles[defects]).min()
        return (f"{int(defects.sum())} triangles below {min_angle} degrees away from "
                f"sharp input corners (smallest {smallest:.2f})")
    # every input segment is a chain of mesh edges: the vertices on it, in order, are joined
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [2, 0]]]), axis=1)
    n = len(vertices)
    edge_keys = np.unique(edges[:, 0] * n + edges[:, 1])
    local_pslg = pslg.vertices - origin
    scale = max(float(np.ptp(xy, axis=0).max()), 1e-9)
    lines = shapely.linestrings(local_pslg[pslg.segments])
    # on a segment: within a rounding error of the extent, and far less than the segment's
    # length (Steiner points beside a very short segment are not on it)
    tol = np.minimum(1e-7 * scale, 1e-3 * shapely.length(lines))
    tree = shapely.STRtree(shapely.points(xy))
    seg_idx, vert_idx = tree.query(lines, predicate="dwithin", distance=tol)
    # the mesh vertices at an input vertex (to the rounding of the coordinates' shifts): such a
    # vertex lies on no segment but its own (the PSLG check refuses a segment touched inside),
    # however near one it passes (a 6 µm segment at a right angle to another, in a 100 m PSLG)
    at_input = np.full(len(xy), -1)
    rounding = 4 * np.spacing(np.abs(vertices).max()) + 1e-12 * scale
    mesh_at, input_at = shapely.STRtree(shapely.points(local_pslg)).query(
        shapely.points(xy), predicate="dwithin", distance=rounding)
    at_input[mesh_at] = input_at
    for s in np.unique(seg_idx):
        on = vert_idx[seg_idx == s]
        on = on[(at_input[on] < 0) | np.isin(at_input[on], pslg.segments[s])]
        a, b = local_pslg[pslg.segments[s]]
        t = (xy[on] - a) @ (b - a) / ((b - a) @ (b - a))
        chain = on[np.argsort(t)]
        keys = np.sort(np.column_stack([chain[:-1], chain[1:]]), axis=1)
        if len(chain) < 2 or not np.isin(keys[:, 0] * n + keys[:, 1], edge_keys).all():
            return f"input segment {s} is not a chain of mesh edges"
    if len(np.unique(seg_idx)) < len(pslg.segments):
        return "an input segment has no mesh vertices on it"
    return "valid"


def _mesh_pslg_case(lines, domain, snap, min_angle, max_area):
    pslg = build_pslg(lines, domain, snap=snap)
    vertices, triangles = triangulate_pslg(pslg, min_angle=min_angle, max_area=max_area,
                                           max_triangles=MAX_TRIANGLES, area=domain.area)
    return _check(vertices, triangles, pslg, min_angle, max_area)


def _mesh_raster_case(values, cell, origin, lines, min_angle, max_area):
    dem = Grid(values, Affine(cell, 0, origin[0], 0, -cell, origin[1]), UTM)
    domain = domain_from_dem(dem)
    pslg = build_pslg(lines, domain, snap=cell / 4)
    mesh = build_mesh(dem, lines, min_angle=min_angle, max_area=max_area,
                      max_triangles=MAX_TRIANGLES, domain=domain)
    return _check(mesh.nodes[:, :2], mesh.triangles, pslg, min_angle, max_area, mesh.segments)


def _mesh_raw_case(pslg, min_angle, max_area):
    vertices, triangles = triangulate_pslg(pslg, min_angle=min_angle, max_area=max_area,
                                           max_triangles=MAX_TRIANGLES)
    return _check(vertices, triangles, pslg, min_angle, max_area)


# ---------------------------------------------------------------------------------------------
# strategies
ORIGINS = st.sampled_from([(0.0, 0.0), (500_000.0, 5_700_000.0), (-3_000.0, 250.0),
                           (321_987.654, 4_456_789.123)])
SIZES = st.sampled_from([1.0, 10.0, 100.0, 1_000.0, 10_000.0])
VALID_MIN_ANGLE = st.floats(5.0, 34.0)
BAD_MIN_ANGLE = st.sampled_from([-10.0, 0.0, 34.001, 40.0, 90.0, math.nan, math.inf])
BAD_MAX_AREA = st.sampled_from([0.0, -1.0, math.nan, math.inf, -math.inf])


def dice():
    """A uniform number in [0, 1): Hypothesis favours the ends of ranges, not a share."""
    return st.integers(0, 2**32 - 1).map(lambda seed: np.random.default_rng(seed).random())


def min_angles():
    """Valid nine times in ten."""
    return dice().flatmap(lambda u: BAD_MIN_ANGLE if u < 0.1 else VALID_MIN_ANGLE)


def area_fractions():
    """Max area as a fraction of the domain's area (from a few triangles to more than the
    triangle limit allows), or, one time in ten, an invalid value (in a 1-tuple)."""
    return dice().flatmap(
        lambda u: BAD_MAX_AREA.map(lambda v: (v,)) if u < 0.1
        else st.floats(1e-9, 2e-4) if u < 0.2 else st.floats(2e-4, 2.0))


def _max_area(fraction, area):
    return fraction[0] if isinstance(fraction, tuple) else fraction * area


@st.composite
def star(draw, centre=(0.5, 0.5), radius=0.5):
    """A simple star-shaped polygon (concave as often as not) in unit coordinates."""
    n = draw(st.integers(3, 12))
    angles = np.sort(draw(st.lists(st.floats(0, 2 * np.pi, exclude_max=True), min_size=n,
                                   max_size=n, unique=True)))
    radii = np.array(draw(st.lists(st.floats(0.15, 1.0), min_size=n, max_size=n))) * radius
    xy = np.column_stack([centre[0] + radii * np.cos(angles), centre[1] + radii * np.sin(angles)])
    polygon = shapely.Polygon(xy)
    if not polygon.is_valid or polygon.area < 1e-3 * radius ** 2:
        polygon = shapely.box(centre[0] - radius, centre[1] - radius, centre[0] + radius,
                              centre[1] + radius)
    return polygon


@st.composite
def domains(draw):
    kind = draw(st.sampled_from(["star", "star-with-hole", "two-parts", "thin", "square"]))
    if kind == "square":
        return shapely.box(0, 0, 1, 1)
    if kind == "thin":
        aspect = draw(st.sampled_from([0.1, 0.01, 0.002]))
        return shapely.box(0, 0, 1, aspect)
    outer = draw(star())
    if kind == "star-with-hole":
        hole = shapely.Point(outer.centroid).buffer(draw(st.floats(0.02, 0.07)), quad_segs=3)
        if outer.contains(hole.buffer(0.02)):
            return outer.difference(hole)
        return outer
    if kind == "two-parts":
        other = draw(star(centre=(1.8, 0.5), radius=0.4))
        return shapely.MultiPolygon([outer, other])
    return outer


@st.composite
def line_sets(draw, domain):
    """Lines in unit coordinates: random, along the boundary, duplicated, nearly duplicated,
    nearly collinear, at tiny angles, with repeated points, very short, and outside."""
    xmin, ymin, xmax, ymax = domain.bounds
    span = max(xmax - xmin, ymax - ymin)
    point = st.tuples(st.floats(xmin - 0.2 * span, xmax + 0.2 * span),
                      st.floats(ymin - 0.2 * span, ymax + 0.2 * span))
    lines = []
    for _ in range(draw(st.integers(0, 8))):
        kind = draw(st.sampled_from(["random", "random", "boundary", "duplicate", "near-duplicate",
                                     "collinear", "tiny-angle", "repeated", "short", "outside"]))
        if kind == "random" or (kind in ("duplicate", "near-duplicate") and not lines):
            lines.append(np.array(draw(st.lists(point, min_size=2, max_size=6))))
        elif kind == "boundary":
            ring = np.asarray(getattr(domain, "geoms", [domain])[0].exterior.coords)
            start = draw(st.integers(0, len(ring) - 2))
            lines.append(ring[start:start + draw(st.integers(2, 4))])
        elif kind == "duplicate":
            line = lines[draw(st.integers(0, len(lines) - 1))]
            lines.append(line[::-1] if draw(st.booleans()) else line.copy())
        elif kind == "near-duplicate":
            line = lines[draw(st.integers(0, len(lines) - 1))]
            eps = draw(st.sampled_from([1e-12, 1e-9, 1e-6, 1e-4, 1e-2])) * span
            lines.append(line + eps * np.array(draw(st.tuples(st.floats(-1, 1),
                                                               st.floats(-1, 1)))))
        elif kind == "collinear":
            a, b = np.array(draw(point)), np.array(draw(point))
            t = np.sort(np.array(draw(st.lists(st.floats(0, 1), min_size=3, max_size=8))))
            noise = draw(st.sampled_from([0.0, 1e-12, 1e-8, 1e-5])) * span
            normal = np.array([-(b - a)[1], (b - a)[0]])
            wiggle = noise * np.array(draw(st.lists(st.floats(-1, 1), min_size=len(t),
                                                    max_size=len(t))))
            lines.append(a + t[:, None] * (b - a) + wiggle[:, None] * normal)
        elif kind == "tiny-angle":
            apex = np.array(draw(point))
            heading = draw(st.floats(0, 2 * np.pi))
            angle = np.radians(draw(st.sampled_from([1e-6, 0.01, 0.5, 3.0, 15.0, 45.0])))
            length = draw(st.floats(0.05, 1.0)) * span
            for h in (heading, heading + angle):
                lines.append(np.array([apex, apex + length * np.array([np.cos(h), np.sin(h)])]))
        elif kind == "repeated":
            p, q = draw(point), draw(point)
            lines.append(np.array([p, p, q, q, q]))
        elif kind == "short":
            p = np.array(draw(point))
            lines.append(np.array([p, p + draw(st.sampled_from([1e-12, 1e-8, 1e-4])) * span]))
        else:
            lines.append(np.array([[xmax + 0.5 * span, ymin], [xmax + 0.7 * span, ymax]]))
    return lines


def _place(geometry_or_lines, origin, size):
    """From unit coordinates to map coordinates at ``origin`` with ``size`` metres per unit."""
    if isinstance(geometry_or_lines, list):
        return [np.asarray(line) * size + origin for line in geometry_or_lines]
    return shapely.transform(geometry_or_lines, lambda c: c * size + np.asarray(origin))


# ---------------------------------------------------------------------------------------------
# the properties
@fuzz("pslg")
@given(data=st.data())
def test_random_pslgs_mesh_or_fail_clearly(sandbox, data):
    """Random domains (concave, with holes, in two parts, thin) and break lines of every kind."""
    unit = data.draw(domains(), label="domain")
    lines = data.draw(line_sets(unit), label="lines")
    origin, size = data.draw(ORIGINS, label="origin"), data.draw(SIZES, label="size")
    domain = _place(unit, origin, size)
    snap = size * data.draw(st.sampled_from([1e-3, 5e-3, 2e-2]), label="snap")
    min_angle = data.draw(min_angles(), label="min_angle")
    max_area = _max_area(data.draw(area_fractions(), label="max_area"), domain.area)
    _expect_mesh_or_clear_error(sandbox, "pslg", _mesh_pslg_case, _place(lines, origin, size),
                                domain, snap, min_angle, max_area)


@st.composite
def rasters(draw):
    rows, cols = draw(st.integers(3, 60)), draw(st.integers(3, 60))
    pattern = draw(st.sampled_from(["full", "random", "random", "lake", "lake", "checker",
                                    "stripes", "one-cell", "nan"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    values = rng.normal(10, 2, (rows, cols))
    if pattern == "random":
        values[rng.random((rows, cols)) < draw(st.floats(0, 0.6))] = np.nan
    elif pattern == "checker":
        values[(np.add.outer(np.arange(rows), np.arange(cols)) % 2).astype(bool)] = np.nan
    elif pattern == "lake":
        yy, xx = np.mgrid[0:rows, 0:cols]
        r = draw(st.floats(0.1, 0.6)) * min(rows, cols)
        lake = np.hypot(yy - rows / 2, xx - cols / 2) < r
        island = np.hypot(yy - rows / 2, xx - cols / 2) < r * draw(st.floats(0, 0.5))
        values[lake & ~island] = np.nan
    elif pattern == "stripes":
        values[:, ::draw(st.integers(2, 4))] = np.nan
    elif pattern == "one-cell":
        values[:] = np.nan
        values[rows // 2, cols // 2] = 1.0
    elif pattern == "nan":
        values[:] = np.nan
    return values


@fuzz("raster")
@given(data=st.data())
def test_random_rasters_mesh_or_fail_clearly(sandbox, data):
    """Random DEMs with nodata of every shape (holes, islands, checkerboards, stripes, single
    cells, none valid), any cell size and origin, with random break lines over them."""
    values = data.draw(rasters(), label="values")
    cell = data.draw(st.sampled_from([0.01, 0.5, 1.0, 2.0, 30.0]), label="cell")
    origin = data.draw(ORIGINS, label="origin")
    rows, cols = values.shape
    unit = shapely.box(0, 0, cols / max(rows, cols), rows / max(rows, cols))
    size = cell * max(rows, cols)
    lines = _place(data.draw(line_sets(unit), label="lines"), (origin[0], origin[1]), size)
    top_left = (origin[0], origin[1] + rows * cell)
    min_angle = data.draw(min_angles(), label="min_angle")
    max_area = _max_area(data.draw(area_fractions(), label="max_area"), rows * cols * cell ** 2)
    _expect_mesh_or_clear_error(sandbox, "raster", _mesh_raster_case, values, cell, top_left,
                                lines, min_angle, max_area)


@st.composite
def raw_pslgs(draw):
    """PSLGs as they might reach triangulate_pslg from another caller: duplicate vertices,
    crossing or zero-length segments, indices out of range, NaN, holes anywhere."""
    from floodmesh.core.steps.mesh import PSLG

    n = draw(st.integers(0, 12))
    size = draw(SIZES)
    origin = np.array(draw(ORIGINS))
    vertices = np.array(draw(st.lists(st.tuples(st.floats(0, 1), st.floats(0, 1)), min_size=n,
                                      max_size=n, unique=True))).reshape(-1, 2) * size + origin
    if n and draw(dice()) < 0.2:
        vertices = np.vstack([vertices, vertices[draw(st.integers(0, n - 1))]])  # a duplicate
    if n and draw(st.integers(0, 9)) == 0:
        vertices[draw(st.integers(0, n - 1))] = np.nan
    if draw(dice()) < 0.6:  # in angular order about their centre: a simple polygon
        centre = np.nanmean(vertices, axis=0) if np.isfinite(vertices).any() else origin
        vertices = vertices[np.argsort(np.arctan2(*(vertices - centre).T[::-1]))]
    m = len(vertices)
    ring = [(i, (i + 1) % m) for i in range(m)] if m >= 3 else []
    extra = draw(st.lists(st.tuples(st.integers(-1, m + 1), st.integers(-1, m + 1)),
                          max_size=6 if draw(dice()) < 0.3 else 0))
    segments = np.array(ring + extra, dtype=np.int64).reshape(-1, 2)
    holes = np.array(draw(st.lists(st.tuples(st.floats(-0.5, 1.5), st.floats(-0.5, 1.5)),
                                   max_size=2))).reshape(-1, 2) * size + origin
    return PSLG(vertices, segments, holes), size


@fuzz("raw")
@given(data=st.data())
def test_raw_pslgs_reach_triangle_only_when_sound(sandbox, data):
    """triangulate_pslg is the only door to Triangle's C code: whatever it is handed, it meshes
    or refuses with FloodMeshError, and never crashes the process."""
    pslg, size = data.draw(raw_pslgs(), label="pslg")
    min_angle = data.draw(min_angles(), label="min_angle")
    max_area = _max_area(data.draw(area_fractions(), label="max_area"), size * size)
    _expect_mesh_or_clear_error(sandbox, "raw", _mesh_raw_case, pslg, min_angle, max_area)
