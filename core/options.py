"""Names of the methods, the chain's options and the checks of their ranges: plain Python,
importable (like the QGIS algorithms that declare their parameters from it) before any numerical
package is.

Every range check lives here, once: ``RunOptions.validate`` calls them for the whole chain, and
the step functions in core (gridding, breakpoints, meshing, …) call the same ones, so the
command line, the pipeline and QGIS all give the same message for the same mistake.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from pathlib import Path

from .errors import FloodMeshError

SLOPE_METHOD_NAMES = ("max-slope", "one-over-distance", "sharpnack-akin", "wood",
                      "zevenbergen-thorne", "ritter")
BREAKPOINT_METHODS = (*SLOPE_METHOD_NAMES, "log")
LOG_KERNELS = ("pratt", "analytic")
TRACING_MODES = ("auto", "flat", "steep")
SIMPLIFY_METHODS = ("keep-every", "douglas-peucker", "spline")
# node elevations: a local least-squares plane of the measured points, or bilinear from the DEM
NODE_ELEVATIONS = ("plane", "dem")
# colours of the residual classes <10 cm, 10–25 cm, >25 cm and of points outside the mesh, in
# the QGIS style (algorithms/styles.py) and the report's pictures (core/io/report.py)
RESIDUAL_CLASS_COLOURS = ("#1a9641", "#fdae61", "#d7191c")
OUTSIDE_MESH_COLOUR = "#9e9e9e"
# break lines: a magenta line on a white halo, readable on the mesh's colour ramp; mesh edges
BREAKLINE_COLOUR, HALO_COLOUR, MESH_EDGE_COLOUR = "#b0006e", "#ffffff", "#404040"
RESIDUAL_CLASS_LABELS = ("< 10 cm", "10–25 cm", "> 25 cm", "outside the mesh")  # classes 0-2, -1
# point files FloodMesh reads (LAS/LAZ, COPC too, and XYZ/CSV text) and an Entwine Point Tile
# index, as QGIS's point-cloud layers open them
POINT_EXTENSIONS = (".las", ".laz", ".xyz", ".txt", ".csv", ".pts")
EPT_NAME = "ept.json"
# the flood's result rasters by what they hold, as run_flood writes them and QGIS loads them;
# water thinner than DRY_BELOW_M (m; ANUGA's minimum_storable_height: round-off) is dry there
DRY_BELOW_M = 1e-3
RESULT_RASTERS = {"max_depth": "max_depth.tif", "max_stage": "max_water_level.tif",
                  "max_speed": "max_speed.tif", "arrival_s": "arrival_time.tif"}
# a vector layer's geometries as messages name them, and how QGIS turns a layer into each kind
GEOMETRY_KINDS = {"Point": "points", "MultiPoint": "points", "LineString": "lines",
                  "MultiLineString": "lines", "Polygon": "polygons", "MultiPolygon": "polygons"}
MAKE_GEOMETRY = {("lines", "points"): "Extract vertices", ("polygons", "points"):
                 "Extract vertices", ("points", "lines"): "Points to path",
                 ("polygons", "lines"): "Polygons to lines", ("lines", "polygons"):
                 "Lines to polygons"}


def wrong_geometry(name: str, has: str, needed: str) -> FloodMeshError:
    """The error for the layer ``name`` of ``has`` (points, lines, polygons, as GEOMETRY_KINDS
    names them) given where ``needed`` are needed."""
    make = MAKE_GEOMETRY.get((has, needed))
    return FloodMeshError(f"{name} has {has}; {needed} are needed here: give a layer of "
                          f"{needed}{f' (QGIS: {make} makes one of {has})' if make else ''}")


# solver export formats (core.steps.export), named by the extension each writes
EXPORT_FORMATS = ("2dm", "slf", "14", "gr3", "nc", "gpkg")
EXPORT_EXTENSIONS = {f: f".{f}" for f in EXPORT_FORMATS}
EXPORT_FORMAT_LABELS = ("SMS 2DM: BASEMENT, TUFLOW FV, SRH-2D (.2dm)",
                        "TELEMAC Selafin with boundary conditions (.slf, .cli)",
                        "ADCIRC fort.14 (.14)", "SCHISM hgrid.gr3 (.gr3)",
                        "UGRID netCDF: D-Flow FM, QGIS (.nc)",
                        "GeoPackage layers: HEC-RAS (.gpkg)")



def is_point_source(path) -> bool:
    """True for a point file FloodMesh reads: LAS/LAZ (COPC too), XYZ/CSV text, or an EPT."""
    path = Path(path)
    return path.suffix.lower() in POINT_EXTENSIONS or path.name == EPT_NAME

def export_format(name: str) -> str:
    """``name`` if it is one of EXPORT_FORMATS, else a FloodMeshError listing them."""
    if name not in EXPORT_FORMATS:
        raise FloodMeshError(f"unknown mesh format {name!r}; choose from "
                             f"{', '.join(EXPORT_FORMATS)}")
    return name


def parse_formats(text) -> tuple[str, ...]:
    """``"2dm,slf"`` (or a sequence of names) → ``("2dm", "slf")``, each checked, no repeats."""
    names = text.split(",") if isinstance(text, str) else list(text)
    names = [n.strip().lower().lstrip(".") for n in names]
    return tuple(dict.fromkeys(export_format(n) for n in names if n))

MAX_MIN_ANGLE = 34.0  # Triangle's refinement stops terminating reliably above about 33.8 degrees
DEFAULT_MAX_TRIANGLES = 5_000_000
DEFAULT_CELL_SIZE = 1.0  # m: the grid of points; a DEM keeps its own cells
# localised break-line pieces are joined across gaps of up to this many cell sizes (--join-gap);
# chosen on the evaluation corpus (benchmarks/RESULTS.md, "The evaluation corpus")
JOIN_GAP_CELLS = 10.0
# ... and bridged across crossings and junctions of up to this many, where the hinge fits find
# the line's kink along the gap (localise.localise_traced; 0 join gap: neither)
BRIDGE_GAP_CELLS = 30.0
# misfit refinement (RunOptions.misfit_passes): a triangle whose points' mean square residual
# exceeds their noise² by more than MISFIT_EXCESS² (m) is split, down to MISFIT_FLOOR_CELLS
# cells² a quarter; chosen on the evaluation corpus and its floods (benchmarks/RESULTS.md,
# "Misfits split where features cross and meet")
MISFIT_EXCESS, MISFIT_FLOOR_CELLS = 0.05, 2.0
MISFIT_DENSITY = 2.0  # points a m² the misfit pass measures (every k-th of denser surveys)
# ... and no more than MISFIT_SHARE of the mesh's triangles a pass, the worst first (an urban
# DEM misfits at every building: uncapped, Merewether's mesh tripled and flooded at 2.7x the CPU)
MISFIT_SHARE = 0.02
# on low ground (the flow zone's), where the smallest wet triangle sets a flood model's time
# step, no split below MISFIT_LOW_FLOOR times that floor (the corpus floods: 1x took 21-43 %
# more time steps, 2x within 5 % of none, 4x none and lost the crossings' gains)
MISFIT_LOW_FLOOR = 2.0
# ... but within MISFIT_CROSSING_CELLS cells of a crossing or a junction (two lines meeting at more
# than 30 degrees), where the two features' slopes overlap in folds no line carries, the floor
# is the high ground's (the corpus: crossings at the reference options 22.1x -> 30.7x, no case
# worse than 0.99x; the corpus floods' time steps +15 % on the crossings, the same on the others
# and Merewether; 6 to 15 cells split the same triangles: RESULTS.md, "Crossings on low
# ground")
MISFIT_CROSSING_CELLS = 10.0
# The FEMA/NSSDA test wants at least 20 check points (FGDC-STD-007.3-1998, 3.2.1).
MIN_CHECK_POINTS = 20


def _number(value, what: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise FloodMeshError(f"{what} must be a number, got {value!r}") from None
    if math.isnan(value):
        raise FloodMeshError(f"{what} must be a number, got NaN")
    return value


def _positive(value, what: str, unit: str, fix: str = "", *, zero: bool = False) -> float:
    """``value`` as a finite number above 0 (or at least 0 with ``zero``), else the message
    '<what> must be a positive number of <unit>, got …[: <fix>]'."""
    value = _number(value, what)
    if not ((0 <= value) if zero else (0 < value)) or not value < math.inf:
        raise FloodMeshError(f"{what} must be {'zero or ' if zero else ''}a positive number of "
                             f"{unit}, got {value:g}{': ' + fix if fix else ''}")
    return value


def check_cell_size(value) -> float:
    return _positive(value, "cell size", "metres",
                     "give the grid spacing d in metres (1 is the method's reference)")


def check_max_gap(value) -> float | None:
    if value is None:
        return None
    return _positive(value, "max gap", "metres", "leave it out for the default of 10 cell sizes")


def check_s_crit(value) -> float:
    value = _number(value, "critical slope S_crit")
    if not 0 < value < 90:
        raise FloodMeshError(f"critical slope S_crit must be above 0 and below 90 degrees, got "
                             f"{value:g}: give it in degrees (10 is the method's reference)")
    return value


def check_min_angle(value) -> float:
    value = _number(value, "minimum angle")
    if not 0 < value:
        raise FloodMeshError(
            f"minimum angle must be above 0 and at most {MAX_MIN_ANGLE:g} degrees, got {value:g}: "
            "give the smallest triangle angle the model may have (25 to 30 is usual)")
    if not value <= MAX_MIN_ANGLE:
        raise FloodMeshError(
            f"minimum angle must be above 0 and at most {MAX_MIN_ANGLE:g} degrees, got {value:g}: "
            "above that Delaunay refinement may never finish (25 to 30 is usual)")
    return value


def check_max_area(value) -> float:
    return _positive(value, "maximum triangle area", "m²",
                     "give the largest element area the model may have")


def check_size_field_area(value) -> float:
    """The triangle area (m²) a flood's size field asks where it was wet (``flood
    --size-field-area``)."""
    return _positive(value, "size field area", "m²",
                     "give the triangle area wanted where the flood was wet")


def check_comparison_cell_size(value) -> float:
    """The cell size (m) of the grid two floods are compared on (``compare --cell-size``)."""
    return _positive(value, "comparison cell size", "metres",
                     "give the spacing of the grid the floods are compared on (default 1)")


def check_max_triangles(value) -> int:
    return check_positive_int(value, "maximum number of triangles")


def check_flow_area(value) -> float | None:
    """The flow area (m²): None (the default, 23 cells) or 0 (off) or more."""
    if value is not None and not (math.isfinite(value) and value >= 0):
        raise FloodMeshError(f"the flow area must be 0 (off) or more m², got {value}; 23 cells "
                             "is the default")
    return value


def check_holdout(fraction) -> float:
    fraction = _number(fraction, "holdout fraction")
    if not 0 <= fraction < 1:
        raise FloodMeshError(f"holdout fraction must be at least 0 and below 1, got {fraction:g}: "
                             "it is the share of points kept back for the accuracy test "
                             "(0.001 is the method's reference, 0 skips the test)")
    return fraction


def holdout_count(fraction: float, n_points: int, note=None) -> int:
    """The number of check points held out of ``n_points``: ``fraction`` of them, raised to the
    FEMA/NSSDA test's minimum of 20 where that keeps fewer (a small survey under the reference
    share of 0.001), said through ``note``; refused only when the points cannot spare 20."""
    fraction = check_holdout(fraction)
    n_out = int(round(fraction * n_points))
    if fraction > 0 and n_out < MIN_CHECK_POINTS:
        if n_points < 2 * MIN_CHECK_POINTS:
            raise FloodMeshError(
                f"a holdout fraction of {fraction:g} keeps {n_out} of {n_points:,} points back, "
                f"but the FEMA/NSSDA accuracy test needs at least {MIN_CHECK_POINTS} check "
                f"points: the file has too few points to hold {MIN_CHECK_POINTS} back; give "
                "holdout 0 to skip the test")
        n_out = MIN_CHECK_POINTS
        if note:
            note(f"a holdout fraction of {fraction:g} keeps {int(round(fraction * n_points))} of "
                 f"{n_points:,} points back; raised to {n_out} ({n_out / n_points:.2g}), the "
                 f"fewest check points the FEMA/NSSDA accuracy test takes")
    return n_out


def check_seed(value) -> int:
    """A random seed: a whole number of at least 0 (numpy's generators take no negative one)."""
    value = whole_number(value, "the random seed")
    if not (isinstance(value, int) and value >= 0):
        raise FloodMeshError(f"the random seed must be a whole number of at least 0, got "
                             f"{value:g}: any such number makes the result reproducible (0 is "
                             "usual)")
    return value


_CLASSES_EXAMPLE = "e.g. 2 (ground) or 2,9 (ground and water)"


def parse_classes(text) -> tuple[int, ...] | None:
    """The LAS classes of ``"2,9"`` (``check_classes``); None for empty text (the default)."""
    text = str(text or "").strip()
    if not text:
        return None
    try:
        classes = tuple(int(c) for c in text.split(","))
    except ValueError:
        raise FloodMeshError(f"LAS classes must be comma-separated class numbers 0-255, got "
                             f"{text!r}: {_CLASSES_EXAMPLE}") from None
    return check_classes(classes)


def check_classes(classes) -> tuple[int, ...] | None:
    """LAS classes to grid: whole numbers 0-255 (a LAS file has no others), or None."""
    if classes is None:
        return None
    try:
        classes = tuple(classes)
    except TypeError:
        raise FloodMeshError(f"LAS classes must be a list of class numbers 0-255, got "
                             f"{classes!r}: {_CLASSES_EXAMPLE}") from None
    bad = [c for c in classes if isinstance(c, bool) or not isinstance(c, numbers.Integral)
           or not 0 <= c <= 255]
    if bad or not classes:
        raise FloodMeshError(f"LAS classes are whole numbers 0-255, got "
                             f"{', '.join(map(str, bad)) if bad else 'none'}: give classes in "
                             f"that range, {_CLASSES_EXAMPLE}")
    return tuple(int(c) for c in classes)


def whole_number(value, what: str) -> int | float:
    """``value`` as an int where it is a whole number: an int, a whole float (3.0) or text ("3",
    "3.0"), one rule for RunOptions, the steps and the command line; else the number it is (3.5,
    inf) for the caller's range check to refuse, or a FloodMeshError for no number."""
    if isinstance(value, bool):
        raise FloodMeshError(f"{what} must be a number, got {value!r}")
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            pass
    number = _number(value, what)
    return int(number) if number.is_integer() else number


def check_positive_int(value, what: str, minimum: int = 1) -> int:
    value = whole_number(value, what)
    if not (isinstance(value, int) and value >= minimum):
        raise FloodMeshError(f"{what} must be a whole number of at least {minimum}, got {value:g}")
    return value


def check_min_points(value) -> int:
    return check_positive_int(value, "minimum points per break line", 2)


def check_tolerance(value) -> float:
    return _positive(value, "simplification tolerance", "metres")


def check_min_distance(value) -> float:
    return _positive(value, "minimum distance between lines", "metres", zero=True)


def check_min_length(value) -> float:
    return _positive(value, "minimum break-line length", "metres", zero=True)


def check_sigma(value) -> float:
    return _positive(value, "LoG sigma", "metres", zero=True)


def check_sigma_fits(sigma: float, rows: int, cols: int, cell_size: float) -> float:
    """Refuse a LoG sigma whose kernel (4σ and one cell each way) is wider than the grid: no
    cell would get a response, and the kernel's cost grows with σ² per cell."""
    sigma = check_sigma(sigma)
    reach = math.ceil(4 * sigma / cell_size) + 1
    if 2 * reach + 1 > min(rows, cols):
        largest = math.floor(((min(rows, cols) - 1) // 2 - 1) * cell_size / 4 * 100) / 100
        fix = (f"give a sigma of at most {largest:g} m (1 to 3 cells is usual)" if largest > 0
               else "the grid is too small for the LoG: use a slope method")
        raise FloodMeshError(f"a LoG sigma of {sigma:g} m reaches 4 sigma = {4 * sigma:g} m each "
                             f"way, more than the grid ({cols * cell_size:g} x "
                             f"{rows * cell_size:g} m) allows: no cell would get a response; "
                             f"{fix}")
    return sigma


def check_sensitivity(value) -> float:
    return _positive(value, "LoG sensitivity", "metres",
                     "the |response| a breakpoint reaches (0.02 is the method's reference)")


def check_refine_bounds(lower, upper) -> tuple[float, float | None]:
    """The refinement's bounds in metres: 0 < ``lower`` <= ``upper`` (None: no point is
    inserted)."""
    lower = _positive(lower, "refinement lower bound", "metres")
    if upper is None:
        return lower, None
    upper = _positive(upper, "refinement upper bound", "metres")
    if lower > upper:
        raise FloodMeshError(f"the refinement lower bound ({lower:g} m) is above the upper bound "
                             f"({upper:g} m); 0.10 and 0.25 are usual")
    return lower, upper


def check_refinement(lower, upper, *, target_rmse=None, target_max=None, noise=None,
                     max_rounds: int = 8, max_nodes: int = 1_000_000) -> None:
    """A refinement's bounds (``check_refine_bounds``), targets (m; None: none), the points'
    noise (m; 0: exact points, None: estimated) and budget of rounds and nodes."""
    check_refine_bounds(lower, upper)
    for value, what in ((target_rmse, "target RMSE"), (target_max, "target maximum residual")):
        if value is not None:
            _positive(value, what, "metres", "leave it out to refine until the bounds hold")
    if noise is not None:
        _positive(noise, "noise of the points", "metres",
                  "leave it out to estimate it from the points", zero=True)
    check_positive_int(max_rounds, "number of refinement rounds")
    check_positive_int(max_nodes, "node budget", 3)


def check_choice(value, choices, what: str) -> str:
    if value not in choices:
        raise FloodMeshError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")
    return value


def _field_value(name: str, kind: str, value):
    """One RunOptions field's value in the type the chain uses: True or False for a switch (a
    string such as "False" is truthy, so it is refused); a number given as text ("1.0", as a
    config file or argv gives it) converted, as the step functions' checks convert it (a whole
    number, 3, 3.0, "3" or "3.0", is the int an integer field takes: ``whole_number``); formats
    and classes as ``"2dm,slf"`` and ``"2,9"`` (or one class number) as the command line takes
    them. Anything else is left for ``validate`` to check."""
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if type(value).__name__ == "bool_":  # numpy's
            return bool(value)
        raise FloodMeshError(f"{name} must be True or False, got {value!r}: give {name}=True "
                             f"or {name}=False (a string such as 'False' would count as True)")
    if value is None:
        return value
    if kind.startswith(("float", "int")):
        if isinstance(value, bool):
            raise FloodMeshError(f"{name} must be a number, got {value!r}")
        if kind.startswith("int"):
            return whole_number(value, name)
        number = _number(value, name)
        return number if isinstance(value, str) else value
    if name == "formats" and isinstance(value, str):
        return parse_formats(value)
    if name == "classes":
        if isinstance(value, str):
            return parse_classes(value)
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):
            return (int(value),)
        return check_classes(value)
    return value


# --scheduler's value for a local Dask cluster even where the tiles fit in memory
LOCAL_CLUSTER = "local"


@dataclass(frozen=True)
class RunOptions:
    """Parameters of the whole chain; the defaults are the method's reference case."""

    cell_size: float = DEFAULT_CELL_SIZE  # d, m
    slope_method: str = "one-over-distance"  # or "log": breakpoints from the LoG response
    s_crit: float = 10.0            # critical slope, degrees
    sigma: float = 1.0              # LoG smoothing, m
    sensitivity: float = 0.02       # LoG response threshold, m
    log_kernel: str = "pratt"
    zero_crossings: bool = False    # LoG breakpoints at zero crossings instead of |response|
    keep_every: int | None = None   # keep every n-th break-line point (default 4) ...
    tolerance: float | None = None  # ... or Douglas–Peucker within this many metres ...
    spline: float | None = None     # ... or a cubic smoothing spline within this many metres
    min_distance: float | None = None  # m between lines and vertices; default Δ = d/2
    min_spacing: float | None = None   # m: smallest spacing a flood model affords; default d, 0 off
    flow_zone: str | None = None       # polygon file: detected lines kept only there (wet_zone.gpkg)
    min_angle: float = 25.0         # degrees
    max_area: float = 100.0         # m²
    holdout: float = 0.001          # fraction of points held out for assessment
    seed: int = 0
    max_gap: float | None = None    # m; default 10 cell sizes
    tracing_mode: str = "auto"
    min_points: int = 3
    min_length: float = 0.0         # m; shorter break lines are dropped
    crs: str | None = None
    classes: tuple[int, ...] | None = None
    size_field: str | None = None   # raster of local maximum areas (m²), or "slope"
    min_area: float | None = None   # m², the slope size field's smallest (default max_area/25)
    boundary: str | None = None     # polygon file: the model domain (holes allowed)
    user_lines: str | None = None   # line file: the modeller's own break / structure lines
    formats: tuple[str, ...] = ()   # solver exports written beside mesh.2dm (EXPORT_FORMATS)
    max_triangles: int = DEFAULT_MAX_TRIANGLES  # refuse meshes estimated to be larger
    refine: bool = False            # refine until the residual bounds hold (step 9)
    refine_lower: float = 0.10      # m: refine where points' RMS residual exceeds noise by it
    refine_upper: float = 0.25      # m: insert points whose residual exceeds it
    # passes refining where the mesh misfits the points beyond their noise (a fold no line
    # describes: crossings, junctions, rounded ends; refine.refine_mesh), without --refine
    misfit_passes: int = 1
    localise: bool = True           # break-line vertices onto a two-plane (hinge) fit's kink
    node_elevation: str = "plane"   # NODE_ELEVATIONS: other nodes' z from a local plane fit
    node_radius: float | None = None  # m, the plane fit's radius; default from density, noise
    join_gap: float | None = None   # m: localised pieces joined across gaps; default 10 d, 0 off
    conforming: bool = False        # conforming Delaunay (Triangle's switch D)
    far_field_area: float | None = None  # m², larger triangles away from the break lines
    flow_area: float | None = None  # m², smaller triangles on low ground by drainage lines
    # (HAND); None: 23 cells (drainage.flow_area_for), 0: off
    workers: int | None = None      # point tiles: threads or local Dask workers (default: cores)
    # point tiles: a running dask.distributed scheduler's address, or LOCAL_CLUSTER; None: read
    # in memory where they fit (``tiles.read_point_tiles``), else a local cluster
    scheduler: str | None = None
    processes: bool = True          # point tiles: local workers are processes (False: threads)

    def __post_init__(self):
        for field in fields(self):
            value = _field_value(field.name, field.type, getattr(self, field.name))
            if value is not getattr(self, field.name):
                object.__setattr__(self, field.name, value)
        self.validate()

    def validate(self) -> None:
        """Check every option's range before any file is read or written."""
        check_choice(self.slope_method, BREAKPOINT_METHODS, "slope method")
        check_choice(self.log_kernel, LOG_KERNELS, "LoG kernel")
        check_choice(self.tracing_mode, TRACING_MODES, "tracing mode")
        check_cell_size(self.cell_size)
        check_max_gap(self.max_gap)
        if self.slope_method == "log":
            check_sigma(self.sigma)
            check_sensitivity(self.sensitivity)
        check_s_crit(self.s_crit)  # the tracer uses it with LoG breakpoints too
        self.simplification()
        if self.min_distance is not None:
            check_min_distance(self.min_distance)
        if self.min_spacing is not None and not (math.isfinite(self.min_spacing)
                                                 and self.min_spacing >= 0):
            raise FloodMeshError(f"the minimum spacing must be 0 (off) or more metres, got "
                                 f"{self.min_spacing}; the cell size is a good choice")
        check_min_length(self.min_length)
        check_min_angle(self.min_angle)
        check_max_area(self.max_area)
        if self.min_area is not None:
            _positive(self.min_area, "minimum area of the size field", "m²")
        check_max_triangles(self.max_triangles)
        if self.refine:
            check_refine_bounds(self.refine_lower, self.refine_upper)
        if not (isinstance(self.misfit_passes, int) and 0 <= self.misfit_passes <= 8):
            raise FloodMeshError(f"the misfit refinement passes must be a whole number from 0 "
                                 f"(off) to 8, got {self.misfit_passes}; 1 is the default")
        check_holdout(self.holdout)
        check_seed(self.seed)
        check_classes(self.classes)
        if self.workers is not None:
            check_positive_int(self.workers, "number of Dask workers")
        check_min_points(self.min_points)
        check_choice(self.node_elevation, NODE_ELEVATIONS, "node elevation")
        if self.node_radius is not None:
            _positive(self.node_radius, "node elevation radius", "metres")
        if self.join_gap is not None and not (math.isfinite(self.join_gap)
                                              and self.join_gap >= 0):
            raise FloodMeshError(f"the join gap must be 0 (off) or more metres, got "
                                 f"{self.join_gap}; ten cell sizes is the default")
        check_flow_area(self.flow_area)
        if self.far_field_area is not None:
            far = _positive(self.far_field_area, "far-field area", "m²")
            if far < self.max_area:
                raise FloodMeshError(f"the far-field area ({far:g} m²) is below the maximum "
                                     f"area ({self.max_area:g} m²); give a larger one (or "
                                     "leave it out)")
            if self.size_field not in (None, "slope"):
                raise FloodMeshError("give a size-field raster or a far-field area, not both "
                                     "(the slope size field combines with it)")
        for name in self.formats:
            export_format(name)

    def simplification(self) -> tuple[str, float]:
        """(method, amount): keep-every n, or douglas-peucker / spline within metres."""
        given = [(name, value) for name, value in (("keep-every", self.keep_every),
                                                   ("douglas-peucker", self.tolerance),
                                                   ("spline", self.spline)) if value is not None]
        if len(given) > 1:
            raise FloodMeshError("give one simplification (keep-every, tolerance or spline), not "
                                 + " and ".join(name for name, _ in given))
        name, value = given[0] if given else ("keep-every", 4)
        if name == "keep-every":
            return name, float(check_positive_int(value, "keep-every"))
        return name, check_tolerance(value)
