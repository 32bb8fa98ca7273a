"""The one family of errors FloodMesh raises for bad input: each message names the problem and the fix."""

import signal
import threading


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


def terminate_as_interrupt() -> None:
    """Raise ``Terminated`` on SIGTERM and SIGHUP from now on (in the main thread only)."""
    def terminate(signum, frame):
        raise Terminated(signum)

    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(signum, terminate)
