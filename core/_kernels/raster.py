"""The compiled loops of the raster steps: slope's 3x3 kernel (``slope``) and the block engine's
nodata conversions (``blocks``).

numba compiles them on first use and caches the machine code (``warmup``); ``compiled`` builds
the file-to-file ones ahead of time too, so that ``floodmesh slope`` need not import numba.
Neighbours are named as in ``slope``'s kernel figure (z1…z8 around the centre z9).
"""
from __future__ import annotations

import math

import numba
import numpy as np

SQRT2 = math.sqrt(2.0)


@numba.njit(inline="always")
def _max_slope(z1, z2, z3, z4, z5, z6, z7, z8, z9, d, diagonal):
    """Shanholtz: max |z9 − zi| / L over the 8 neighbours, L = d, or √2·d on diagonals."""
    g = max(abs(z9 - z2), abs(z9 - z4), abs(z9 - z6), abs(z9 - z8)) / d
    return max(g, max(abs(z9 - z1), abs(z9 - z3), abs(z9 - z5), abs(z9 - z7)) / diagonal)


@numba.njit(inline="always")
def _one_over_distance(z1, z2, z3, z4, z5, z6, z7, z8, d):
    """NOAA: neighbours weighted 1, √2, 1 on each side."""
    w = (4.0 + 2.0 * SQRT2) * d
    return (((z3 + SQRT2 * z4 + z5) - (z1 + SQRT2 * z8 + z7)) / w,
            ((z1 + SQRT2 * z2 + z3) - (z7 + SQRT2 * z6 + z5)) / w)


@numba.njit(inline="always")
def _sharpnack_akin(z1, z2, z3, z4, z5, z6, z7, z8, d):
    """Sharpnack & Akin (= Horn): weights 1, 2, 1."""
    return (((z3 + 2.0 * z4 + z5) - (z1 + 2.0 * z8 + z7)) / (8.0 * d),
            ((z1 + 2.0 * z2 + z3) - (z7 + 2.0 * z6 + z5)) / (8.0 * d))


@numba.njit(inline="always")
def _wood(z1, z2, z3, z4, z5, z6, z7, z8, d):
    """Wood: least-squares (constrained) quadratic, equal weights."""
    return (((z3 + z4 + z5) - (z1 + z8 + z7)) / (6.0 * d),
            ((z1 + z2 + z3) - (z7 + z6 + z5)) / (6.0 * d))


@numba.njit(inline="always")
def _zevenbergen_thorne(z1, z2, z3, z4, z5, z6, z7, z8, d):
    """Zevenbergen & Thorne: central differences of the partial quartic."""
    return (z4 - z8) / (2.0 * d), (z2 - z6) / (2.0 * d)


@numba.njit(inline="always")
def _ritter(z1, z2, z3, z4, z5, z6, z7, z8, d):
    """Ritter: central differences along the two diagonals (orthogonal axes at 45°)."""
    return (z3 - z7) / (2.0 * SQRT2 * d), (z1 - z5) / (2.0 * SQRT2 * d)


@numba.njit(inline="always")
def _fill(zk, zopp, z9):
    if not math.isnan(zk):
        return zk
    if math.isnan(zopp):
        return z9
    return 2.0 * z9 - zopp


@numba.njit(inline="always")
def _fill_diagonal(zk, zopp, za, zb, z9):
    """A diagonal neighbour: itself, else through the centre, else from its two orthogonal
    neighbours ``za``, ``zb`` (already filled)."""
    if not math.isnan(zk):
        return zk
    if not math.isnan(zopp):
        return 2.0 * z9 - zopp
    return za + zb - z9


# Cephes' atan (Moshier), to 1 ulp of libm's in float64: written as selects, not calls, so
# that the compiler vectorises a row of it (about 4x faster than a libm call per cell).
_TAN_3PI_8 = 2.41421356237309504880
_MOREBITS = 6.123233995736765886130e-17


@numba.njit(inline="always", error_model="numpy")
def _atan(x):
    """atan(x) for x >= 0 (NaN gives NaN)."""
    big, mid = x > _TAN_3PI_8, x > 0.66
    xr = (-1.0 if big else (x - 1.0 if mid else x)) / (x if big else (x + 1.0 if mid else 1.0))
    y0 = math.pi / 2 if big else (math.pi / 4 if mid else 0.0)
    extra = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    z = xr * xr
    p = ((((-8.750608600031904122785e-1 * z - 1.615753718733365076637e1) * z
           - 7.500855792314704667340e1) * z - 1.228866684490136173410e2) * z
         - 6.485021904942025371773e1)
    q = (((((z + 2.485846490142306297962e1) * z + 1.650270098316988542046e2) * z
           + 4.328810604912902668951e2) * z + 4.853903996359136964868e2) * z
         + 1.945506571482613964425e2)
    return y0 + (xr * (z * p / q) + xr + extra)


@numba.njit(inline="always", error_model="numpy")
def _gradient(z1, z2, z3, z4, z5, z6, z7, z8, z9, d, method, diagonal):
    """|∇z| by ``method`` (for max-slope: the steepest drop ratio)."""
    if method == 0:
        return _max_slope(z1, z2, z3, z4, z5, z6, z7, z8, z9, d, diagonal)
    if method == 1:
        dzdx, dzdy = _one_over_distance(z1, z2, z3, z4, z5, z6, z7, z8, d)
    elif method == 2:
        dzdx, dzdy = _sharpnack_akin(z1, z2, z3, z4, z5, z6, z7, z8, d)
    elif method == 3:
        dzdx, dzdy = _wood(z1, z2, z3, z4, z5, z6, z7, z8, d)
    elif method == 4:
        dzdx, dzdy = _zevenbergen_thorne(z1, z2, z3, z4, z5, z6, z7, z8, d)
    else:
        dzdx, dzdy = _ritter(z1, z2, z3, z4, z5, z6, z7, z8, d)
    return math.sqrt(dzdx * dzdx + dzdy * dzdy)


@numba.njit(inline="always", error_model="numpy")
def _filled_gradient(padded, i, j, d, method, diagonal):
    """The gradient at interior cell (i, j) with missing neighbours filled (module docstring)."""
    z9 = np.float64(padded[i + 1, j + 1])
    a1, a2 = np.float64(padded[i, j]), np.float64(padded[i, j + 1])
    a3, a8 = np.float64(padded[i, j + 2]), np.float64(padded[i + 1, j])
    a4, a7 = np.float64(padded[i + 1, j + 2]), np.float64(padded[i + 2, j])
    a6, a5 = np.float64(padded[i + 2, j + 1]), np.float64(padded[i + 2, j + 2])
    z2, z6 = _fill(a2, a6, z9), _fill(a6, a2, z9)
    z4, z8 = _fill(a4, a8, z9), _fill(a8, a4, z9)
    z1, z5 = _fill_diagonal(a1, a5, z2, z8, z9), _fill_diagonal(a5, a1, z4, z6, z9)
    z3, z7 = _fill_diagonal(a3, a7, z2, z4, z9), _fill_diagonal(a7, a3, z6, z8, z9)
    return _gradient(z1, z2, z3, z4, z5, z6, z7, z8, z9, d, method, diagonal)


@numba.njit(inline="always", error_model="numpy")
def _raw_gradient_row(r0, r1, r2, g, d, method, diagonal):
    """``g[j]``: the gradient of cell j of row ``r1`` from its raw neighbours in rows ``r0``,
    ``r1``, ``r2`` (NaN where any of the nine is missing). Inlined with ``method`` a literal,
    so that the loop has no branch and vectorises (2-3x faster than a run-time ``method``)."""
    for j in range(g.shape[0]):
        a1, a2, a3 = np.float64(r0[j]), np.float64(r0[j + 1]), np.float64(r0[j + 2])
        a8, a9, a4 = np.float64(r1[j]), np.float64(r1[j + 1]), np.float64(r1[j + 2])
        a7, a6, a5 = np.float64(r2[j]), np.float64(r2[j + 1]), np.float64(r2[j + 2])
        missing = (a1 + a2 + a3 + a4 + a5 + a6 + a7 + a8 + a9) * 0.0  # NaN if any is
        g[j] = _gradient(a1, a2, a3, a4, a5, a6, a7, a8, a9, d, method, diagonal) + missing


@numba.njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def slope_kernel(padded, out, d, method, diagonal):
    """Slope (degrees) of the interior of ``padded`` (float32 or float64) into ``out``; the
    arithmetic is float64 whatever the input, so float32 files give the float64 result.

    Per row: the gradient of every cell from its raw neighbours in one branch-free loop (NaN
    where any of the nine is missing), the slope of the row in a second, then the few cells
    with a missing neighbour again with the neighbours filled; a NaN centre stays NaN."""
    rows, cols = padded.shape[0] - 2, padded.shape[1] - 2
    for i in numba.prange(rows):
        g = np.empty(cols)
        r0, r1, r2 = padded[i], padded[i + 1], padded[i + 2]
        if method == 0:  # one loop per method (``_raw_gradient_row``)
            _raw_gradient_row(r0, r1, r2, g, d, 0, diagonal)
        elif method == 1:
            _raw_gradient_row(r0, r1, r2, g, d, 1, diagonal)
        elif method == 2:
            _raw_gradient_row(r0, r1, r2, g, d, 2, diagonal)
        elif method == 3:
            _raw_gradient_row(r0, r1, r2, g, d, 3, diagonal)
        elif method == 4:
            _raw_gradient_row(r0, r1, r2, g, d, 4, diagonal)
        else:
            _raw_gradient_row(r0, r1, r2, g, d, 5, diagonal)
        for j in range(cols):
            out[i, j] = _atan(g[j]) * (180.0 / math.pi)
        for j in range(cols):
            if math.isnan(g[j]):
                if math.isnan(padded[i + 1, j + 1]):
                    out[i, j] = np.nan
                else:
                    out[i, j] = _atan(_filled_gradient(padded, i, j, d, method,
                                                       diagonal)) * (180.0 / math.pi)
    return out


@numba.njit(cache=True, nogil=True)
def missing_to_nan(values, low, high, lowest, highest, halo, implausible):
    """NaN, in place in a 2-D float array, for the nodata tag's values (``low`` to ``high``;
    NaN: none), ±inf, and values outside ``lowest`` to ``highest``, of which those at least
    ``halo`` cells in from every edge are gathered into ``implausible`` (float64: count, least,
    greatest); whether a finite cell is left. (Selects, not branches: the row loops
    vectorise.)"""
    nan = values.dtype.type(np.nan)
    rows, cols = values.shape
    for i in range(rows):
        row = values[i]
        for j in range(cols):
            v = row[j]
            row[j] = nan if ((v >= low) & (v <= high)) | (v - v != 0) else v  # v - v: ±inf
    count = 0
    for i in range(halo, rows - halo):
        row = values[i, halo:cols - halo]
        for j in range(row.shape[0]):
            count += (row[j] < lowest) | (row[j] > highest)
    if count:  # seldom: the extremes, for the note
        implausible[0] += count
        for i in range(halo, rows - halo):
            row = values[i, halo:cols - halo]
            for j in range(row.shape[0]):
                if (row[j] < lowest) | (row[j] > highest):
                    implausible[1] = min(implausible[1], row[j])
                    implausible[2] = max(implausible[2], row[j])
    for i in range(rows):
        row = values[i]
        for j in range(cols):
            v = row[j]
            row[j] = nan if (v < lowest) | (v > highest) else v
    for i in range(rows):
        for j in range(cols):
            if values[i, j] == values[i, j]:
                return True
    return False


@numba.njit(cache=True, nogil=True)
def nan_to_value(values, value):
    """``value`` for NaN in a 2-D float array, in place; returns it."""
    for i in range(values.shape[0]):
        row = values[i]
        for j in range(values.shape[1]):
            v = row[j]
            row[j] = value if v != v else v
    return values
