"""The file-to-file raster kernels compiled ahead of time, so that streaming steps start without
numba.

Importing numba and loading its cache costs about 0.6 s of CPU per process, a third of what
``gdaldem slope`` spends on a whole 6000² DEM. ``make setup`` (``warmup``) therefore also builds
the float32 kernels of ``raster_kernels`` with numba's ahead-of-time compiler into an extension
module beside this file, for this CPU, NumPy and source (all three in its name: a stale or
foreign build is never loaded). ``kernel(name)`` gives that build, or the same kernel compiled by
numba on first use when there is none (no C compiler, a read-only folder, another machine). Both
are the same source and give the same values; the ahead-of-time build runs in one thread and
releases the GIL.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib
import importlib.util
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
# name → (numba signature, the kernel in raster_kernels); float32 C arrays, as map_raster has them
EXPORTS = {
    "slope_f32": ("f4[:,::1](f4[:,::1], f4[:,::1], f8, i8, f8)", "slope_kernel"),
    "missing_to_nan_f32": ("b1(f4[:,::1], f4, f4, f4, f4, i8, f8[::1])", "missing_to_nan"),
    "nan_to_value_f32": ("f4[:,::1](f4[:,::1], f4)", "nan_to_value"),
}
PREFIX = "_raster_aot_"
_loaded: dict = {}


def module_name() -> str | None:
    """The extension's name for this source, NumPy and CPU; None where the CPU is unknown."""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            flags = next(line for line in cpuinfo if line.startswith("flags"))
    except (OSError, StopIteration):
        return None
    key = hashlib.sha1()
    for part in ((HERE / "raster.py").read_bytes(), Path(__file__).read_bytes(),
                 np.__version__.encode(), flags.encode()):
        key.update(part)
    return PREFIX + key.hexdigest()[:16]


def _module():
    if "module" not in _loaded:
        name = module_name()
        try:
            _loaded["module"] = importlib.import_module(f"{__package__}.{name}") if name else None
        except ImportError:
            _loaded["module"] = None
    return _loaded["module"]


def kernel(name: str):
    """The kernel ``name`` of ``EXPORTS``: the ahead-of-time build when there is one, else the
    numba kernel of ``raster_kernels`` (compiled or loaded from numba's cache on first use)."""
    module = _module()
    if module is not None:
        return getattr(module, name)
    # lazy: numba loads only when this runs
    from . import raster as raster_kernels

    return getattr(raster_kernels, EXPORTS[name][1])


def ahead_of_time() -> bool:
    """Whether the ahead-of-time build for this source, NumPy and CPU is here."""
    return _module() is not None


def build(log=None) -> bool:
    """Build the extension into this folder (seconds; a C compiler is needed) unless it is
    there; remove stale builds. Returns whether the build is in place. Never raises: without
    it the numba kernels serve."""
    name = module_name()
    if name is None:
        return False
    if not any(HERE.glob(f"{name}.*")):
        if importlib.util.find_spec("numpy.distutils") is None:
            if log:  # numba.pycc builds through numpy.distutils, gone for Python >= 3.12
                log("no ahead-of-time raster kernels: numba's ahead-of-time compiler needs "
                    "numpy.distutils, which this NumPy lacks; numba's kernels serve")
            return False
        try:
            _compile(name)
        except Exception as exc:  # noqa: BLE001 - any failure leaves the JIT kernels in use
            if log:
                log(f"no ahead-of-time raster kernels ({type(exc).__name__}: {exc}); "
                    "numba's serve")
            return False
    for stale in HERE.glob(f"{PREFIX}*"):
        if not stale.name.startswith(name):
            with contextlib.suppress(OSError):
                stale.unlink()
    _loaded.clear()
    return ahead_of_time()


def _compile(name: str) -> None:
    # lazy: numba loads only when this runs
    import numba.pycc.compiler as pycc_compiler
    from numba.pycc import CC

    # lazy: numba loads only when this runs
    from . import raster as raster_kernels

    class Flags(pycc_compiler.Flags):
        """As numba.njit(nogil=True, error_model="numpy"), which the kernels are written for:
        the GIL released, and no division check that would keep a row loop from vectorising."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.error_model = "numpy"
            self.release_gil = True

    saved, pycc_compiler.Flags = pycc_compiler.Flags, Flags
    try:
        cc = CC(name)
        cc.output_dir = str(HERE)
        cc.target_cpu = "host"  # AVX2 and wider where the CPU has them; the name holds its flags
        cc.verbose = False
        for export, (signature, jit_name) in EXPORTS.items():
            cc.export(export, signature)(getattr(raster_kernels, jit_name).py_func)
        cc.compile()
    finally:
        pycc_compiler.Flags = saved


if __name__ == "__main__":
    print("built" if build(print) else "not built", file=sys.stderr)
