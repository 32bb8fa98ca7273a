"""Small array helpers shared by the steps."""
from __future__ import annotations

import numpy as np


def unique_rows(rows, return_inverse: bool = False):
    """The distinct rows of a 2-D array in lexicographic order, as ``np.unique(rows, axis=0)``,
    and with ``return_inverse`` the index of each row's distinct row.

    It compares plain columns instead of numpy's structured view of the rows: numpy 2 turns a
    KeyboardInterrupt that arrives while it compares structured arrays into ``TypeError: Cannot
    compare structured arrays unless they have a common dtype``, so Ctrl-C there ended a run
    with a traceback instead of exit code 130.
    """
    rows = np.asarray(rows)
    order = np.lexsort(rows.T[::-1]) if rows.shape[1] else np.arange(len(rows))
    ordered = rows[order]
    first = np.ones(len(rows), bool)
    first[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    unique = ordered[first]
    if not return_inverse:
        return unique
    inverse = np.empty(len(rows), np.intp)
    inverse[order] = np.cumsum(first) - 1
    return unique, inverse
