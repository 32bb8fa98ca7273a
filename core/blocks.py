"""Block-by-block processing of raster steps with a halo, so tiles can stream."""
from __future__ import annotations

from typing import Callable

import numpy as np

DEFAULT_BLOCK_ROWS = 2048


def map_overlap(values: np.ndarray, func: Callable[[np.ndarray], np.ndarray], *, halo: int,
                block_rows: int = DEFAULT_BLOCK_ROWS, fill=np.nan, dtype=None,
                cancelled: Callable[[], bool] | None = None) -> np.ndarray:
    """Apply a neighbourhood function to row blocks of ``values`` with ``halo`` cells of context.

    ``func`` receives a block padded by ``halo`` on every side (``fill`` beyond the raster) and
    returns the block's interior. The result equals applying ``func`` to the whole padded raster.
    """
    from .errors import Cancelled

    rows, cols = values.shape
    out = None
    for r0 in range(0, rows, block_rows):
        if cancelled is not None and cancelled():
            raise Cancelled()
        r1 = min(rows, r0 + block_rows)
        lo, hi = max(0, r0 - halo), min(rows, r1 + halo)
        block = np.full((r1 - r0 + 2 * halo, cols + 2 * halo), fill,
                        dtype=np.result_type(values.dtype, np.asarray(fill).dtype))
        top = halo - (r0 - lo)
        block[top:top + hi - lo, halo:halo + cols] = values[lo:hi]
        result = func(block)
        if out is None:
            out = np.empty((rows, cols), dtype=dtype or result.dtype)
        out[r0:r1] = result
    if out is None:
        out = np.empty((rows, cols), dtype=dtype or values.dtype)
    return out
