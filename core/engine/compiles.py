"""numba's compiles as the user sees them: a run says when numba really compiles FloodMesh's
kernels (the first run of an install: about 2 minutes) and how long it took, never when it only
loads them from its cache (``warmup`` fills the cache at setup)."""
from __future__ import annotations

import time
from contextlib import contextmanager

COMPILE_NOTE = ("compiling FloodMesh's numba kernels: first run only, about 2 minutes; later "
                "runs load them from {where}")
COMPILED_NOTE = "compiled FloodMesh's numba kernels in {seconds:.0f} s (once; cached in {where})"


def is_compile_message(message: str) -> bool:
    """True for CompileWatch's two messages (front ends show them even without a progress bar)."""
    return message.startswith(("compiling FloodMesh's numba", "compiled FloodMesh's numba"))


def _cache_folder(dispatcher) -> str:
    """Where numba keeps ``dispatcher``'s machine code."""
    cache = getattr(dispatcher, "_cache", None)
    return str(getattr(cache, "_cache_path", None) or "numba's cache")


class CompileWatch:
    """Says, through ``log``, when numba really compiles (a cache miss, numba's
    ``numba:compile`` event; loading machine code from the cache raises none): the note once,
    at the first compile, and ``summary()`` the seconds spent compiling in all."""

    def __init__(self, log):
        self.log, self.seconds, self.depth, self.started, self.where = log, 0.0, 0, None, ""

    @contextmanager
    def watching(self):
        """Watch the compiles inside this block (a step of the chain)."""
        if self.log is None:
            yield
            return
        # lazy: numba loads only when this runs
        from numba.core import event

        watch = self

        class Listener(event.Listener):
            def on_start(self, ev):
                if watch.depth == 0:  # a kernel's callees compile inside it
                    if watch.started is None:
                        watch.where = _cache_folder(ev.data.get("dispatcher"))
                        watch.log(COMPILE_NOTE.format(where=watch.where))
                    watch.started = time.perf_counter()
                watch.depth += 1

            def on_end(self, ev):
                watch.depth -= 1
                if watch.depth == 0:
                    watch.seconds += time.perf_counter() - watch.started

        with event.install_listener("numba:compile", Listener()):
            yield

    def summary(self) -> str | None:
        """The compile's real duration, or None when nothing was compiled."""
        if self.started is None:
            return None
        return COMPILED_NOTE.format(seconds=self.seconds, where=self.where)
