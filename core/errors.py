"""The one family of errors FloodMesh raises for bad input: each message names the problem and the fix."""

import signal
import threading
from contextlib import contextmanager


class FloodMeshError(ValueError):
    """Bad input or parameters; the message says what was received and what to do."""


class Cancelled(Exception):
    """The user cancelled the run (QGIS Cancel, Ctrl-C); nothing half-written is left behind."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP (a scheduler's time limit, a closed terminal, QGIS ending a stuck
    worker) taken as Ctrl-C is: every step unwinds, removing its temporaries and scratch."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def interrupt_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C (``KeyboardInterrupt``, or ``Terminated``) that ``exc`` was raised while
    handling, if any. Ctrl-C inside an extension can reach Python as another error: a
    SystemError from a compiled (numba) call, at times through a second one (a parallel
    kernel calls back into Python on every call); a ValueError from shapely's Cython buffer
    code. It is the interrupt all the same."""
    cause = exc.__cause__ or exc.__context__
    while cause is not None and not isinstance(cause, KeyboardInterrupt):
        cause = cause.__cause__ or cause.__context__
    return cause


@contextmanager
def interrupts_unwrapped():
    """Within it, an error raised while handling Ctrl-C or SIGTERM (``interrupt_behind``) is
    raised as that interrupt, so that the run unwinds and says so instead of failing with a
    traceback."""
    try:
        yield
    except Exception as exc:
        cause = interrupt_behind(exc)
        if cause is None:
            raise
        raise cause.with_traceback(None) from None


def terminate_as_interrupt() -> None:
    """Raise ``Terminated`` on SIGTERM and SIGHUP from now on (in the main thread only)."""
    def terminate(signum, frame):
        raise Terminated(signum)

    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(signum, terminate)
