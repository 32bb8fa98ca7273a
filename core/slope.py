"""Slope in degrees from a 3x3 neighbourhood, named as in the method's kernel figure::

    z1 z2 z3
    z8 z9 z4
    z7 z6 z5

with north up and cell size d. Missing neighbours (raster edges, nodata) are filled by linear
extrapolation through the centre (2·z9 − z_opposite, or z9 if the opposite is missing too), so a
plane keeps its exact slope up to the edge and no artificial cliff appears; a nodata centre gives
nodata.

References: Shanholtz et al. (1981) maximum slope; NOAA one-over-distance (Unwin 1981);
Sharpnack & Akin (1969) (= Horn 1981); Wood (1996) constrained quadratic; Zevenbergen &
Thorne (1987) doi:10.1002/esp.3290120107; Ritter (1987) diagonal differences.
"""
from __future__ import annotations

import numpy as np

from .blocks import map_overlap
from .errors import FloodMeshError
from .raster import Grid

SQRT2 = np.sqrt(2.0)
# (row offset, col offset) of z1..z8 around z9, and the index of the opposite neighbour.
OFFSETS = {1: (-1, -1), 2: (-1, 0), 3: (-1, 1), 4: (0, 1), 5: (1, 1), 6: (1, 0), 7: (1, -1),
           8: (0, -1)}
OPPOSITE = {1: 5, 2: 6, 3: 7, 4: 8, 5: 1, 6: 2, 7: 3, 8: 4}


def neighbourhood(padded: np.ndarray) -> dict[int, np.ndarray]:
    """z1..z9 for the interior of a block padded by one cell, missing neighbours filled."""
    rows, cols = padded.shape[0] - 2, padded.shape[1] - 2
    z = {k: padded[1 + dr:1 + dr + rows, 1 + dc:1 + dc + cols] for k, (dr, dc) in OFFSETS.items()}
    z9 = padded[1:-1, 1:-1]
    filled = {}
    for k, zk in z.items():
        opposite = z[OPPOSITE[k]]
        extrapolated = np.where(np.isnan(opposite), z9, 2.0 * z9 - opposite)
        filled[k] = np.where(np.isnan(zk), extrapolated, zk)
    filled[9] = z9
    return filled


def _degrees(dzdx, dzdy):
    return np.degrees(np.arctan(np.hypot(dzdx, dzdy)))


def slope_max(z, d, *, diagonal_distance=True):
    """Maximum slope to any neighbour (Shanholtz): max |z9 − zi| / L, L = d or √2·d on diagonals.

    With ``diagonal_distance=False`` the diagonal neighbours are also taken at L = d.
    """
    diag = SQRT2 * d if diagonal_distance else d
    gradient = np.zeros_like(z[9])
    for k in range(1, 9):
        length = diag if k % 2 == 1 else d
        gradient = np.fmax(gradient, np.abs(z[9] - z[k]) / length)
    return np.degrees(np.arctan(gradient))


def slope_one_over_distance(z, d):
    """One-over-distance weighted (NOAA): neighbours weighted 1, √2, 1 on each side."""
    w = 4.0 + 2.0 * SQRT2
    dzdx = ((z[3] + SQRT2 * z[4] + z[5]) - (z[1] + SQRT2 * z[8] + z[7])) / (w * d)
    dzdy = ((z[1] + SQRT2 * z[2] + z[3]) - (z[7] + SQRT2 * z[6] + z[5])) / (w * d)
    return _degrees(dzdx, dzdy)


def slope_sharpnack_akin(z, d):
    """Neighbourhood method (Sharpnack & Akin 1969), identical to Horn (1981): weights 1, 2, 1."""
    dzdx = ((z[3] + 2.0 * z[4] + z[5]) - (z[1] + 2.0 * z[8] + z[7])) / (8.0 * d)
    dzdy = ((z[1] + 2.0 * z[2] + z[3]) - (z[7] + 2.0 * z[6] + z[5])) / (8.0 * d)
    return _degrees(dzdx, dzdy)


def slope_wood(z, d):
    """Constrained quadratic surface (Wood 1996): least-squares quadratic, equal weights."""
    dzdx = ((z[3] + z[4] + z[5]) - (z[1] + z[8] + z[7])) / (6.0 * d)
    dzdy = ((z[1] + z[2] + z[3]) - (z[7] + z[6] + z[5])) / (6.0 * d)
    return _degrees(dzdx, dzdy)


def slope_zevenbergen_thorne(z, d):
    """Quadratic (partial quartic) surface (Zevenbergen & Thorne 1987): central differences."""
    return _degrees((z[4] - z[8]) / (2.0 * d), (z[2] - z[6]) / (2.0 * d))


def slope_ritter(z, d):
    """Diagonal central differences (Ritter 1987): the two diagonals as orthogonal axes."""
    return _degrees((z[3] - z[7]) / (2.0 * SQRT2 * d), (z[1] - z[5]) / (2.0 * SQRT2 * d))


SLOPE_METHODS = {
    "max-slope": slope_max,
    "one-over-distance": slope_one_over_distance,
    "sharpnack-akin": slope_sharpnack_akin,
    "wood": slope_wood,
    "zevenbergen-thorne": slope_zevenbergen_thorne,
    "ritter": slope_ritter,
}


def slope(dem: Grid, method: str = "one-over-distance", *, cancelled=None) -> Grid:
    """Slope of a DEM in degrees by one of ``SLOPE_METHODS``, computed block by block."""
    try:
        kernel = SLOPE_METHODS[method]
    except KeyError:
        raise FloodMeshError(f"unknown slope method {method!r}; choose one of "
                             f"{', '.join(SLOPE_METHODS)}") from None
    d = dem.cell_size

    def block(padded):
        out = kernel(neighbourhood(padded), d)
        return np.where(np.isnan(padded[1:-1, 1:-1]), np.nan, out)

    values = map_overlap(dem.values.astype(np.float64), block, halo=1, cancelled=cancelled)
    return dem.with_values(values)
