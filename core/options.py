"""Names of the methods and the chain's options: plain Python, importable (like the QGIS
algorithms that declare their parameters from it) before any numerical package is."""
from __future__ import annotations

from dataclasses import dataclass

from .errors import FloodMeshError

SLOPE_METHOD_NAMES = ("max-slope", "one-over-distance", "sharpnack-akin", "wood",
                      "zevenbergen-thorne", "ritter")
BREAKPOINT_METHODS = (*SLOPE_METHOD_NAMES, "log")
LOG_KERNELS = ("pratt", "analytic")
TRACING_MODES = ("auto", "flat", "steep")
SIMPLIFY_METHODS = ("keep-every", "douglas-peucker", "spline")
# colours of the residual classes <10 cm, 10–25 cm, >25 cm and of points outside the mesh, in
# the QGIS style (algorithms/styles.py) and the report's pictures (core/report.py)
RESIDUAL_CLASS_COLOURS = ("#1a9641", "#fdae61", "#d7191c")
OUTSIDE_MESH_COLOUR = "#9e9e9e"
# solver export formats (core.export), named by the extension each writes
EXPORT_FORMATS = ("2dm", "slf", "14", "gr3", "nc", "gpkg")
EXPORT_EXTENSIONS = {f: f".{f}" for f in EXPORT_FORMATS}
EXPORT_FORMAT_LABELS = ("SMS 2DM: BASEMENT, TUFLOW FV, SRH-2D (.2dm)",
                        "TELEMAC Selafin with boundary conditions (.slf, .cli)",
                        "ADCIRC fort.14 (.14)", "SCHISM hgrid.gr3 (.gr3)",
                        "UGRID netCDF: D-Flow FM, QGIS (.nc)",
                        "GeoPackage layers: HEC-RAS (.gpkg)")


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


@dataclass(frozen=True)
class RunOptions:
    """Parameters of the whole chain; the defaults are the method's reference case."""

    cell_size: float = 1.0          # d, m
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

    def __post_init__(self):
        if self.slope_method not in BREAKPOINT_METHODS:
            raise FloodMeshError(f"unknown slope method {self.slope_method!r}; choose one of "
                                 f"{', '.join(BREAKPOINT_METHODS)}")
        if self.log_kernel not in LOG_KERNELS:
            raise FloodMeshError(f"unknown LoG kernel {self.log_kernel!r}; choose pratt or "
                                 "analytic")
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
        return name, float(value)
