"""Break lines scored against reference lines (known exactly, or digitised by hand).

recall: the share of reference length within ``tolerance`` of a traced line; precision: the share
of traced length within ``tolerance`` of a reference line; pieces: for each reference line, the
number of traced lines that follow it for at least ``3 * tolerance`` (shorter overlaps are lines
crossing it, not pieces of it).
"""
from __future__ import annotations

import numpy as np
import shapely


def score_breaklines(traced, reference, tolerance: float) -> dict:
    """Recall, precision and pieces per reference line. ``traced`` and ``reference`` are
    sequences of (k, 2+) coordinate arrays or shapely lines in the same CRS; ``tolerance`` in
    metres (the method's bar uses 2 cells)."""
    traced = [_line(g) for g in traced]
    reference = [_line(g) for g in reference]
    all_traced = shapely.MultiLineString(traced) if traced else shapely.MultiLineString()
    all_reference = shapely.union_all(reference)
    traced_length = all_traced.length
    recall = (all_reference.intersection(all_traced.buffer(tolerance)).length / all_reference.length
              if all_reference.length else float("nan"))
    precision = (all_traced.intersection(all_reference.buffer(tolerance)).length / traced_length
                 if traced_length else float("nan"))
    tree = shapely.STRtree(traced)
    pieces = []
    for ref in reference:
        zone = ref.buffer(tolerance)
        near = tree.query(zone, predicate="intersects")
        overlap = shapely.intersection(np.asarray(traced, dtype=object)[near], zone)
        pieces.append(int((shapely.length(overlap) >= 3 * tolerance).sum()))
    return {"recall": recall, "precision": precision, "pieces": pieces,
            "mean_pieces": float(np.mean(pieces)) if pieces else float("nan"),
            "max_pieces": max(pieces, default=0), "n_traced": len(traced),
            "traced_length_m": traced_length, "reference_length_m": all_reference.length}


def _line(geometry) -> shapely.LineString:
    if isinstance(geometry, shapely.Geometry):
        return geometry
    return shapely.LineString(np.asarray(geometry)[:, :2])
