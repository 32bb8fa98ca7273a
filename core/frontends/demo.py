"""A synthetic floodplain with known break lines, for the demo, tests and benchmarks.

A sinuous river (trapezoidal channel, 1:2 banks) with a tributary joining it, a levee along the
south bank (1:3 sides), a road embankment (1:2 sides) and a terrace step on the north floodplain,
on a gently sloping, gently undulating plain. Points are scattered at LiDAR density with Gaussian
noise; a share of vegetation points (class 1) sits above the ground points (class 2).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from ..points import PointCloud

DEMO_CRS = "EPSG:25832"  # ETRS89 / UTM zone 32N
DEMO_ORIGIN = (412_000.0, 5_652_000.0)
WIDTH, HEIGHT = 300.0, 240.0


@dataclass(frozen=True)
class Profile:
    """A cross-section by distance r from a centreline: flat top ``half_top`` wide, then a linear
    side to ``half_base``; ``height`` is positive for embankments, negative for channels."""

    height: float
    half_top: float
    half_base: float

    def __call__(self, r):
        side = np.clip((self.half_base - r) / (self.half_base - self.half_top), 0.0, 1.0)
        return self.height * side

    @property
    def break_offsets(self):
        return (self.half_top, self.half_base)


def _river_centreline():
    x = np.linspace(-20, WIDTH + 20, 400)
    return shapely.LineString(np.column_stack([x, 120 + 25 * np.sin(2 * np.pi * x / WIDTH)]))


FEATURES = {
    # name: (centreline, profile)
    "river": (_river_centreline(), Profile(-2.5, 7.0, 12.0)),
    "tributary": (shapely.LineString([(205, HEIGHT + 20), (178, 190), (158, 140), (150, 122)]),
                  Profile(-1.8, 3.0, 6.6)),
    "levee": (_river_centreline().offset_curve(-40.0), Profile(1.8, 2.0, 7.4)),
    "road": (shapely.LineString([(-10, 14), (WIDTH + 10, 46)]), Profile(1.5, 4.0, 7.0)),
}
TERRACE_LINE = shapely.LineString([(-10, 205), (100, 198), (200, 212), (WIDTH + 10, 204)])
TERRACE_STEP, TERRACE_HALF_WIDTH = 1.0, 2.0


@dataclass(frozen=True)
class Floodplain:
    """A floodplain's geometry: ``features`` name → (centreline, Profile) (the plain rises gently
    away from "river"), a terrace step north of ``terrace`` (None: no terrace)."""

    features: dict
    terrace: shapely.LineString | None = TERRACE_LINE


DEMO = Floodplain(FEATURES, TERRACE_LINE)


def _distance(line: shapely.LineString, xy: np.ndarray, *, within: float,
              spacing: float = 0.02) -> np.ndarray:
    """Distance (m) from points to a line, inf beyond ``within`` metres; exact to spacing²/8
    through a KD-tree of the line resampled every ``spacing`` metres (fast for millions of points)."""
    # lazy: SciPy loads only when this runs
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(shapely.segmentize(line, spacing).coords))
    # Query only points in 2 m blocks near the line: far queries are what makes a KD-tree slow.
    block = 2.0
    ij = np.floor(xy / block).astype(np.int64)
    ij -= ij.min(axis=0)
    shape = ij.max(axis=0) + 1
    centres = (np.indices(shape).reshape(2, -1).T + 0.5) * block + np.floor(xy.min(axis=0) / block) * block
    near_block = np.isfinite(tree.query(centres, distance_upper_bound=within + block)[0])
    near = near_block[ij[:, 0] * shape[1] + ij[:, 1]]
    out = np.full(len(xy), np.inf)
    out[near] = tree.query(xy[near], distance_upper_bound=within)[0]
    return out


def ground_elevation(x, y, floodplain: Floodplain = DEMO) -> np.ndarray:
    """Noise-free ground elevation (m) at local coordinates (x, y) in metres."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    xy = np.column_stack([x.ravel(), y.ravel()])
    z = 20.0 + 0.001 * x + 0.15 * np.sin(x / 23.0) * np.cos(y / 31.0)
    # the plain rises gently away from the river
    z += 0.004 * np.abs(y - np.interp(x, *floodplain.features["river"][0].xy))
    terrace = floodplain.terrace
    if terrace is not None:  # a 1 m step over 4 m, north of the terrace line up
        above = y > np.interp(x, *terrace.xy)
        near = _distance(terrace, xy, within=2 * TERRACE_HALF_WIDTH).reshape(z.shape)
        signed = near * np.where(above, 1, -1)
        z += TERRACE_STEP * np.clip((signed + TERRACE_HALF_WIDTH) / (2 * TERRACE_HALF_WIDTH),
                                    0, 1)
    carve = np.zeros_like(z)
    for name, (line, profile) in floodplain.features.items():
        offset = profile(_distance(line, xy, within=profile.half_base + 1).reshape(z.shape))
        if profile.height < 0:
            carve = np.minimum(carve, offset)
        else:
            z += offset
    return z + carve


def true_breaklines(floodplain: Floodplain = DEMO) -> list[shapely.LineString]:
    """The exact break lines of the noise-free terrain, clipped to the demo area (local coords)."""
    area = shapely.box(0, 0, WIDTH, HEIGHT)
    lines = []
    for line, profile in floodplain.features.values():
        for r in profile.break_offsets:
            for side in (r, -r):
                lines.append(line.offset_curve(side))
    if floodplain.terrace is not None:
        for side in (TERRACE_HALF_WIDTH, -TERRACE_HALF_WIDTH):
            lines.append(floodplain.terrace.offset_curve(side))
    clipped = [shapely.intersection(g, area) for g in lines]
    return [g for g in clipped if not g.is_empty]


def synthetic_floodplain(*, density: float = 9.0, noise: float = 0.05, vegetation: float = 0.1,
                         seed: int = 0, floodplain: Floodplain = DEMO
                         ) -> tuple[PointCloud, np.ndarray]:
    """Points of the demo floodplain in ``DEMO_CRS``: (ground and vegetation points, classes).

    ``density`` ground points per m², Gaussian ``noise`` (m) on z, ``vegetation`` extra points per
    ground point 0.5–12 m above the ground (class 1).
    """
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    rng = np.random.default_rng(seed)
    n_ground = int(round(density * WIDTH * HEIGHT))
    n_veg = int(round(vegetation * n_ground))
    x = rng.uniform(0, WIDTH, n_ground + n_veg)
    y = rng.uniform(0, HEIGHT, n_ground + n_veg)
    z = ground_elevation(x, y, floodplain) + rng.normal(0, noise, x.size)
    z[n_ground:] += rng.uniform(0.5, 12.0, n_veg)
    classes = np.r_[np.full(n_ground, 2, np.uint8), np.full(n_veg, 1, np.uint8)]
    xyz = np.column_stack([x + DEMO_ORIGIN[0], y + DEMO_ORIGIN[1], z])
    return PointCloud(xyz, CRS.from_user_input(DEMO_CRS)), classes
