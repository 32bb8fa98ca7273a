"""LiDAR points as an (N, 3) array of x, y, z in metres with their CRS, and the holdout split."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pyproj import CRS

from .errors import FloodMeshError
from .options import check_holdout_count
from .raster import require_metric_crs


@dataclass(frozen=True)
class PointCloud:
    """Ground points: ``xyz`` (N, 3) float64 in metres, ``crs`` projected in metres."""

    xyz: np.ndarray
    crs: CRS

    def __post_init__(self):
        if self.xyz.ndim != 2 or self.xyz.shape[1] != 3:
            raise FloodMeshError(f"points must be an (N, 3) array of x, y, z, got {self.xyz.shape}")

    def __len__(self) -> int:
        return len(self.xyz)


def clean_points(xyz: np.ndarray, crs, source: str, kind: str | None = "points") -> PointCloud:
    """Drop non-finite points and check what is left is usable terrain data."""
    crs = require_metric_crs(crs, source, kind)
    xyz = np.asarray(xyz, dtype=np.float64)
    finite = np.isfinite(xyz).all(axis=1)
    xyz = xyz[finite]
    if len(xyz) < 3:
        raise FloodMeshError(f"{source} has {len(xyz)} usable points (finite x, y, z); at least 3 "
                             "are needed to make a terrain model. Check the file and its classes")
    span = np.ptp(xyz[:, :2], axis=0)
    if span.min() <= 0:
        raise FloodMeshError(f"{source}: all points lie on one line ({span[0]:.3g} x {span[1]:.3g} "
                             "m); a terrain model needs an area")
    return PointCloud(xyz, crs)


def split_holdout(points: PointCloud, fraction: float, seed: int) -> tuple[PointCloud, PointCloud]:
    """Split off a random ``fraction`` of the points for accuracy assessment.

    Returns (points for gridding, held-out points); the same seed gives the same split.
    """
    n = len(points)
    n_out = check_holdout_count(fraction, n)
    rng = np.random.default_rng(seed)
    mask = np.zeros(n, dtype=bool)
    mask[rng.choice(n, size=n_out, replace=False)] = True
    return (PointCloud(points.xyz[~mask], points.crs), PointCloud(points.xyz[mask], points.crs))
