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
    tolerance: float | None = None  # ... or Douglas–Peucker within this many metres
    min_angle: float = 25.0         # degrees
    max_area: float = 100.0         # m²
    holdout: float = 0.001          # fraction of points held out for assessment
    seed: int = 0
    max_gap: float | None = None    # m; default 10 cell sizes
    tracing_mode: str = "auto"
    min_points: int = 3
    crs: str | None = None
    classes: tuple[int, ...] | None = None

    def __post_init__(self):
        if self.slope_method not in BREAKPOINT_METHODS:
            raise FloodMeshError(f"unknown slope method {self.slope_method!r}; choose one of "
                                 f"{', '.join(BREAKPOINT_METHODS)}")
        if self.log_kernel not in LOG_KERNELS:
            raise FloodMeshError(f"unknown LoG kernel {self.log_kernel!r}; choose pratt or "
                                 "analytic")

    def simplification(self) -> tuple[str, float]:
        if self.keep_every is not None and self.tolerance is not None:
            raise FloodMeshError("give either keep-every or tolerance for simplification, not both")
        if self.tolerance is not None:
            return "douglas-peucker", float(self.tolerance)
        return "keep-every", float(4 if self.keep_every is None else self.keep_every)
