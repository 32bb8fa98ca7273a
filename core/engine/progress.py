"""A step's progress in stages: the plain ``progress`` (fraction done, 0–1) and ``cancelled``
(polled) callables the front ends pass (the command line's bar, QGIS's worker), told and
polled between a step's stages and along its loops."""
from __future__ import annotations

from ..errors import Cancelled

REPORTS = 100  # about as many reports along a loop: the bar moves by the percent


def poll(cancelled) -> None:
    """Stop (``Cancelled``) where ``cancelled()`` says so; None: never."""
    if cancelled is not None and cancelled():
        raise Cancelled()


def report(progress, cancelled, fraction: float) -> None:
    """Stop where ``cancelled()`` says so (``poll``), else tell ``progress`` that ``fraction``
    (0–1) of the step is done; either may be None."""
    poll(cancelled)
    if progress is not None:
        progress(fraction)


def part(progress, start: float, end: float):
    """``progress`` for a part of a step, from ``start`` to ``end`` (fractions of the step)
    of the whole; None where ``progress`` is None."""
    if progress is None:
        return None
    return lambda fraction: progress(start + (end - start) * fraction)


def along(items, progress=None, cancelled=None):
    """The sequence ``items`` one by one, ``cancelled`` polled and ``progress`` told the share
    done some ``REPORTS`` times on the way, and 1 at the end."""
    every = max(1, -(-len(items) // REPORTS))
    for k, item in enumerate(items):
        if k % every == 0:
            report(progress, cancelled, k / len(items))
        yield item
    report(progress, cancelled, 1.0)
