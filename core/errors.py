"""The one family of errors FloodMesh raises for bad input: each message names the problem and the fix."""

import _thread
import signal
import sys
import threading
from contextlib import contextmanager


class FloodMeshError(ValueError):
    """Bad input or parameters; the message says what was received and what to do."""


class Cancelled(Exception):
    """The user cancelled the run (QGIS Cancel, Ctrl-C); nothing half-written is left behind."""

    def __init__(self, message: str = "cancelled by the user"):
        super().__init__(message)


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
    traceback; and an interrupt leaves numba's and llvmlite's locks free
    (``compiler_locks_freed``)."""
    try:
        yield
    except KeyboardInterrupt:
        compiler_locks_freed()
        raise
    except Exception as exc:
        cause = interrupt_behind(exc)
        if cause is None:
            raise
        compiler_locks_freed()
        raise cause.with_traceback(None) from None


def compiler_locks_freed() -> None:
    """Release numba's compiler lock and llvmlite's lock on LLVM's C API where this thread
    holds them outside any compile or LLVM call.

    Both are RLocks taken in a context manager's ``__enter__`` and given back in its
    ``__exit__``; a signal whose handler raises (Ctrl-C, ``Terminated``) just after the lock is
    taken leaves ``__enter__`` before it returns, so no ``__exit__`` gives it back. Every other
    thread that then compiles, loads or links a kernel waits for it forever: the run's
    background thread did, and the run, joining it, never ended (SIGTERM at random moments hung
    1 of 40 worker runs, either lock). Called once the interrupt has left every numba and
    llvmlite frame of this thread."""
    compiler = sys.modules.get("numba.core.compiler_lock")
    if compiler is not None:
        while compiler.global_compiler_lock.is_locked():  # held by this thread
            compiler.global_compiler_lock.release()
    ffi = sys.modules.get("llvmlite.binding.ffi")
    if ffi is not None:
        llvm = ffi.lib._lock._lock  # the RLock inside llvmlite's _LLVMLock
        while llvm._is_owned():
            llvm.release()


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
RETRY_S = 0.01  # s: how soon a signal that arrived in numba's own code is taken again
_COMPILER_PACKAGES = ("numba", "llvmlite")


def stop_signals_as_interrupts() -> None:
    """From now on (main thread only) SIGINT raises ``KeyboardInterrupt``, SIGTERM and SIGHUP
    ``Terminated``, at the first moment the main thread runs none of numba's or llvmlite's own
    Python code.

    A compiled kernel calls back into numba's Python code as it runs (``_numba_unpickle``, for
    the objects it returns, on every call); an interrupt raised there gives the kernel nothing
    where it expects an object, and at times it goes on with it: the QGIS worker, given
    SIGTERM at random moments, ended with a segmentation fault 5 times in 150 (Ctrl-C likewise:
    numba/numba#2324). A signal that arrives there is taken again ``RETRY_S`` later
    (``_thread.interrupt_main``), until it arrives in other code: after the kernel returns,
    or after the compile it came in."""
    def interrupt(signum, frame):
        if _in_compiler_code(frame):
            retry = threading.Timer(RETRY_S, _thread.interrupt_main, (signum,))
            retry.daemon = True
            retry.start()
            return
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise Terminated(signum)

    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            signal.signal(signum, interrupt)


def _in_compiler_code(frame) -> bool:
    """Whether ``frame`` or a frame that called it is numba's or llvmlite's."""
    while frame is not None:
        package = frame.f_globals.get("__name__", "").partition(".")[0]
        if package in _COMPILER_PACKAGES:
            return True
        frame = frame.f_back
    return False
