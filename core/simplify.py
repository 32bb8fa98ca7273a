"""Break-line simplification within a tolerance α·Δ (Δ = d/2, the scale of detail)."""
from __future__ import annotations

import numpy as np

from .breaklines import BreakLine
from .options import check_positive_int, check_tolerance


def simplify_keep_every(lines: list[BreakLine], n: int) -> list[BreakLine]:
    """Keep every ``n``-th point of each line, and always both ends."""
    n = check_positive_int(n, "keep-every")
    out = []
    for line in lines:
        keep = np.zeros(len(line.coords), bool)
        keep[::int(n)] = True
        keep[-1] = True
        out.append(BreakLine(line.coords[keep], line.slopes[keep], line.component))
    return out


def simplify_douglas_peucker(lines: list[BreakLine], tolerance: float) -> list[BreakLine]:
    """Douglas–Peucker: no dropped point lies farther than ``tolerance`` (m) from the simplified
    line, horizontally or vertically."""
    tolerance = check_tolerance(tolerance)
    out = []
    for line in lines:
        keep = douglas_peucker_mask(line.coords, tolerance)
        out.append(BreakLine(line.coords[keep], line.slopes[keep], line.component))
    return out


def douglas_peucker_mask(coords: np.ndarray, tolerance: float) -> np.ndarray:
    """Boolean mask of the vertices Douglas–Peucker keeps (horizontal and vertical deviation)."""
    n = len(coords)
    keep = np.zeros(n, bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        horizontal, vertical = _deviation(coords[i], coords[j], coords[i + 1:j])
        worst = np.maximum(horizontal, vertical)
        k = int(np.argmax(worst))
        if worst[k] > tolerance:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return keep


def _deviation(a, b, pts):
    """Horizontal distance of ``pts`` to segment a–b and their z departure from it there."""
    ab = b[:2] - a[:2]
    length2 = float(ab @ ab)
    if length2 == 0:
        t = np.zeros(len(pts))
    else:
        t = np.clip(((pts[:, :2] - a[:2]) @ ab) / length2, 0.0, 1.0)
    foot = a[:2] + t[:, None] * ab
    horizontal = np.hypot(*(pts[:, :2] - foot).T)
    vertical = np.abs(pts[:, 2] - (a[2] + t * (b[2] - a[2])))
    vertical = np.where(np.isfinite(vertical), vertical, 0.0)
    return horizontal, vertical


def max_deviation(original: BreakLine, simplified: BreakLine) -> float:
    """Largest horizontal distance (m) from an original vertex to the simplified polyline."""
    from shapely import LineString, points, distance

    if len(simplified.coords) < 2:
        return 0.0
    return float(distance(LineString(simplified.coords[:, :2]),
                          points(original.coords[:, :2])).max())
