"""Small array helpers shared by the steps."""
from __future__ import annotations

import importlib
from contextlib import contextmanager

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


def true_runs(mask) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in a 1-D bool array."""
    padded = np.zeros(np.size(mask) + 2, np.int8)  # np.r_ cost 40 µs a call: 0.1 s a run
    padded[1:-1] = mask
    edges = np.flatnonzero(padded[1:] != padded[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def distance_along(coords) -> np.ndarray:
    """Distance (m) along a polyline ((n, 2+) x, y first) at each of its vertices, 0 first."""
    coords = np.asarray(coords)
    along = np.zeros(max(len(coords), 1))  # np.r_ cost 20 µs a call
    np.cumsum(np.hypot(*np.diff(coords[:, :2], axis=0).T), out=along[1:])
    return along


def spatial_order(nodes, triangles, bits: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """(the nodes' new order, the triangles renumbered): triangles in Z (Morton) order of their
    centres, nodes in the order the triangles first use them (``nodes[order]``; a node no
    triangle uses is left out), so that neighbours lie close in memory and in the file.

    Solvers sweep the triangles and their neighbours every time step: a mesh refined through a
    size field comes out of Triangle scattered, and cost ANUGA 1.3x the CPU per step of a
    uniform mesh of the same size (3.16 against 2.44 ms on Merewether, the same mesh
    reordered). The order depends only on the geometry, so ordering twice changes nothing."""
    triangles = np.asarray(triangles)
    if not len(triangles):
        return np.arange(0), triangles
    xy = np.asarray(nodes)[triangles][:, :, :2].mean(axis=1)
    span = float(np.ptp(xy, axis=0).max()) or 1.0
    q = ((xy - xy.min(axis=0)) / span * (2 ** bits - 1)).astype(np.uint64)
    code = np.zeros(len(xy), np.uint64)
    for b in range(bits):
        for axis in (0, 1):
            code |= ((q[:, axis] >> np.uint64(b)) & np.uint64(1)) << np.uint64(2 * b + axis)
    triangles = triangles[np.argsort(code, kind="stable")]
    used, first = np.unique(triangles.ravel(), return_index=True)
    order = used[np.argsort(first)]
    number = np.full(len(nodes), -1, np.int64)
    number[order] = np.arange(len(order))
    return order, number[triangles]


def boundary_edges(triangles: np.ndarray) -> np.ndarray:
    """(k, 3) rows (triangle, edge, 0) of the edges that belong to one triangle only; edge e of
    a triangle is the one opposite its vertex e (ANUGA's convention)."""
    tri = np.asarray(triangles)
    m = len(tri)
    if not m:
        return np.zeros((0, 3), np.intp)
    a = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    b = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    key = np.minimum(a, b).astype(np.int64) * (tri.max() + 1) + np.maximum(a, b)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    once = np.nonzero(counts[inverse] == 1)[0]
    return np.column_stack([once % m, once // m, np.zeros_like(once)])


def edge_nodes(triangles: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The two node indices (k, 2) of edges given as (triangle, edge) rows, in the triangle's
    counter-clockwise order (so the outside lies to the right)."""
    t, e = edges[:, 0], edges[:, 1]
    return np.column_stack([triangles[t, (e + 1) % 3], triangles[t, (e + 2) % 3]])


@contextmanager
def without_huge_pages():
    """Within the block, numpy allocates its large arrays on ordinary 4 KiB pages.

    numpy asks the kernel for transparent huge pages on every array over 4 MiB
    (``madvise(MADV_HUGEPAGE)``). Where the kernel defragments on such a request, Debian's and
    Ubuntu's default (``/sys/kernel/mm/transparent_hugepage/defrag`` = madvise), a page fault
    in a fresh array can stall while memory is compacted: the TIN gridding of 9 M points spent
    2.7-3.7 s where it spends 2.7 s without, the difference all in the kernel, and the
    triangulation gained nothing from the larger pages once warm. Same as running with
    ``NUMPY_MADVISE_HUGEPAGE=0``; the previous setting is restored on leaving."""
    switch = huge_page_switch()
    if switch is None:  # a numpy without the switch: nothing to change
        yield
        return
    before = switch(False)
    try:
        yield
    finally:
        switch(before)


def huge_page_switch():
    """numpy's switch of its huge-page request (``switch(on)`` sets it and returns the setting
    before), or None where this numpy has none."""
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):  # numpy 2, numpy 1
        try:
            return importlib.import_module(name)._set_madvise_hugepage
        except (ImportError, AttributeError):
            continue
    return None
