"""A step's progress in stages: the plain ``progress`` (fraction done, 0–1) and ``cancelled``
(polled) callables the front ends pass (the command line's bar, QGIS's worker), told and
polled between a step's stages and along its loops."""
from __future__ import annotations

from ..errors import Cancelled

REPORTS = 100  # about as many reports along a loop: the bar moves by the percent
# Shares of shares, summed in another order, round apart by some 1e-16: steps this small are
# rounding, not progress, and are not told as a step back or as short of the end
ROUNDING = 1e-9


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


def steady(progress):
    """``progress`` (None: None) told fractions whose rounding is taken out: a fraction less
    than ``ROUNDING`` below the last one told is told as that one, one within it of 1 as 1, so
    the bar neither steps back nor ends short of 100 % by rounding; a larger step back (a
    defect) goes through as it is."""
    if progress is None:
        return None
    last = 0.0

    def tell(fraction: float) -> None:
        nonlocal last
        if last - ROUNDING < fraction < last:
            fraction = last
        if abs(fraction - 1.0) < ROUNDING:
            fraction = 1.0
        last = fraction
        progress(fraction)
    return tell
