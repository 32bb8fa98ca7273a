"""Break lines scored against reference lines (known exactly, or digitised by hand).

Each stretch of a traced line within ``tolerance`` of a reference line belongs to the
reference line nearest to it, so that a trace of one of two lines that run close together
(the crest and toe of a narrow embankment, 1 m apart) is not also counted for the other.
recall: the share of reference length within ``tolerance`` of the traced stretches that
belong to it; precision: the share of traced length within ``tolerance`` of a reference line;
pieces: for each reference line, the number of traced lines of which at least
``3 * tolerance`` belongs to it (shorter stretches are lines crossing it, not pieces of it).
"""
from __future__ import annotations

import numpy as np
import shapely

STEP_SHARE = 0.25  # traced lines are judged in steps of this share of the tolerance


def score_breaklines(traced, reference, tolerance: float) -> dict:
    """Recall, precision and pieces per reference line. ``traced`` and ``reference`` are
    sequences of (k, 2+) coordinate arrays or shapely lines in the same CRS; ``tolerance`` in
    metres (the method's bar uses 2 cells). Also, per reference line, its length, the length
    recalled, and each piece's span along it (from, to in metres: where pieces meet)."""
    traced = [_line(g) for g in traced]
    reference = [_line(g) for g in reference]
    claims = _claims(traced, reference, tolerance)
    lengths = shapely.length(np.asarray(reference, dtype=object)) if reference else np.zeros(0)
    recalled = np.array([shapely.intersection(ref, shapely.union_all(
        [run for _, run in claims[i]]).buffer(tolerance)).length if claims[i] else 0.0
        for i, ref in enumerate(reference)])
    traced_length = float(sum(g.length for g in traced))
    near = shapely.union_all(reference).buffer(tolerance) if reference else None
    within = sum(shapely.intersection(g, near).length for g in traced) if near else 0.0
    pieces, spans = [], []
    for i, ref in enumerate(reference):
        by_line = {}
        for j, run in claims[i]:
            by_line.setdefault(j, []).append(run)
        kept = [runs for runs in by_line.values()
                if sum(r.length for r in runs) >= 3 * tolerance]
        pieces.append(len(kept))
        along = [ref.project(shapely.points(np.concatenate([shapely.get_coordinates(r)
                                                            for r in runs]))) for runs in kept]
        spans.append(sorted((float(a.min()), float(a.max())) for a in along))
    total = float(lengths.sum())
    return {"recall": float(recalled.sum()) / total if total else float("nan"),
            "precision": within / traced_length if traced_length else float("nan"),
            "pieces": pieces, "mean_pieces": float(np.mean(pieces)) if pieces else float("nan"),
            "max_pieces": max(pieces, default=0), "n_traced": len(traced),
            "traced_length_m": traced_length, "reference_length_m": total,
            "lengths_m": lengths.tolist(), "recalled_m": recalled.tolist(), "spans_m": spans}


def _claims(traced, reference, tolerance: float) -> list:
    """For each reference line, (traced line's index, stretch) of the traced stretches within
    ``tolerance`` of it and nearer to it than to any other reference line: each traced line is
    cut into steps of ``STEP_SHARE * tolerance``, each step given to the reference line nearest
    its middle, consecutive steps of one owner joined."""
    claims = [[] for _ in reference]
    if not traced or not reference:
        return claims
    refs = np.asarray(reference, dtype=object)
    tree = shapely.STRtree(refs)
    for j, line in enumerate(traced):
        candidates = tree.query(line, predicate="dwithin", distance=tolerance)
        if not len(candidates):
            continue
        xy = shapely.get_coordinates(shapely.segmentize(line, STEP_SHARE * tolerance))
        if len(xy) < 2:
            continue
        middles = shapely.points(0.5 * (xy[1:] + xy[:-1]))
        distance = shapely.distance(middles[:, None], refs[candidates][None, :])
        nearest = np.argmin(distance, axis=1)
        owner = np.where(distance[np.arange(len(middles)), nearest] <= tolerance,
                         candidates[nearest], -1)
        cuts = np.flatnonzero(np.diff(owner)) + 1
        for first, last in zip(np.r_[0, cuts], np.r_[cuts, len(owner)]):
            if owner[first] >= 0:
                claims[owner[first]].append((j, shapely.LineString(xy[first:last + 1])))
    return claims


def _line(geometry) -> shapely.LineString:
    if isinstance(geometry, shapely.Geometry):
        return geometry
    return shapely.LineString(np.asarray(geometry)[:, :2])
