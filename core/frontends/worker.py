"""Run one FloodMesh step in a process of its own: the QGIS plugin's worker.

QGIS loads its own GEOS (and GDAL, PROJ) into ``qgis.bin`` and ``qgis_process.bin``; shapely's
PyPI wheel brings another GEOS, and Triangle or numba can fail hard on their own. As QGIS's
GRASS, SAGA and point-cloud (``pdal_wrench``) algorithms do, the plugin therefore never imports
the numerical core: it starts ``python -m floodmesh.core.frontends.worker`` and talks to it in JSON.

Protocol. The job arrives on stdin as one JSON object ``{"step": NAME, "args": {...}}`` (NAME
one of ``STEPS``; args plain JSON: paths, numbers, strings). The worker answers on stdout with
one JSON object per line:

``{"progress": 0.42}``   fraction done (0–1), at most every 0.1 s and 0.5 %
``{"info": "..."}``      a line for the log
``{"note": "..."}``      something assumed or repaired on the user's behalf
``{"result": {...}}``    the step's outputs (last line, exit code 0)
``{"error": "..."}``     bad input: core's one-line message (last line, exit code 2)

Anything else the libraries print goes to stderr. A crash or a kill ends the process without a
result line; every output is written atomically (``io.atomic_output``), so what remains is a
previous file or none, and the hidden ``.*.partial*`` files a killed worker leaves are the
caller's to remove (``PARTIAL_GLOB``).
"""
from __future__ import annotations

import faulthandler
import json
import os
import sys
import time

from ..chain import files as steps
from ..engine.compiles import CompileWatch
from ..errors import (Cancelled, FloodMeshError, Terminated, interrupts_unwrapped,
                      stop_signals_as_interrupts)
from ..flood.model import load_scenario, run_flood
from ..options import RunOptions
from .dependencies import install_hint, missing_dependencies
from .process import end_process, keep_freed_memory

PARTIAL_GLOB = ".*.partial*"  # the temporary names io.atomic_output writes under


class Channel:
    """The worker's side of the protocol: JSON lines on a private copy of stdout."""

    def __init__(self, stream):
        self.stream = stream
        self._last = (-1.0, 0.0)

    def send(self, **message) -> None:
        self.stream.write(json.dumps(message, default=str) + "\n")
        self.stream.flush()

    def progress(self, fraction: float) -> None:
        fraction = min(max(float(fraction), 0.0), 1.0)
        last, when = self._last
        now = time.monotonic()
        if fraction >= 1.0 or (fraction - last >= 0.005 and now - when >= 0.1):
            self._last = (fraction, now)
            self.send(progress=round(fraction, 4))

    def info(self, text: str) -> None:
        self.send(info=str(text))

    def note(self, text: str) -> None:
        self.send(note=str(text))

    @staticmethod
    def cancelled() -> bool:
        return False  # the caller cancels by ending the process


# ---------------------------------------------------------------------------------------------
# the steps: core.steps' file-level functions, with the worker's progress and notes
def _file_step(func, describe=None):
    """``func`` (one of ``core.steps``) with the worker's progress and notes; its summary (or
    ``describe`` of its result, where the summary is the command line's JSON) goes to QGIS's
    log."""
    def run(ch, **args):
        result = func(**args, progress=ch.progress, cancelled=ch.cancelled, note=ch.note)
        summary = result.pop("summary")
        ch.info(describe(result) if describe else summary)
        return result
    return run


def _accuracy_text(result):
    # lazy: numpy loads only when this runs
    from ..steps.accuracy import accuracy_text

    return accuracy_text(result["statistics"])


def step_run(ch, *, input, output_folder, options, skip_unreadable=False):
    # lazy: numba, PROJ and GEOS load only when this runs
    from ..chain.pipeline import run_pipeline
    from ..chain.source import open_source

    input = open_source(input, skip_unreadable=skip_unreadable)
    options = dict(options)
    for key in ("formats", "classes"):
        if options.get(key) is not None:
            options[key] = tuple(options[key])
    report = run_pipeline(input, output_folder, RunOptions(**options), progress=ch.progress,
                          cancelled=ch.cancelled, log=_pipeline_log(ch))
    # lazy: PROJ loads only when this runs
    from pyproj import CRS

    return {"nodes": report["nodes"], "triangles": report["triangles"],
            "rmse_m": report["rmse_m"], "crs": CRS.from_user_input(report["crs"]).to_wkt()}


def step_flood(ch, *, mesh, scenario, output, crs=None, own_env=None):
    report = run_flood(mesh, load_scenario(scenario), output, crs=crs, own_env=own_env,
                       progress=ch.progress, log=ch.info)
    for message in report["notes"]:
        ch.note(message)
    return {key: report[key] for key in ("cpu_s", "time_steps", "flooded_area_m2",
                                         "mass_balance", "time_step_set_by")}


def _pipeline_log(ch):
    """run_pipeline's log: its notes (``note: …``) as notes, the rest as info."""
    def log(text):
        text = str(text)
        if text.startswith("note: "):
            ch.note(text[len("note: "):])
        else:
            ch.info(text)
    return log


STEPS = {"grid": _file_step(steps.grid), "slope": _file_step(steps.slope),
         "breakpoints": _file_step(steps.breakpoints), "trace": _file_step(steps.trace),
         "simplify": _file_step(steps.simplify), "build_mesh": _file_step(steps.mesh),
         "refine_mesh": _file_step(steps.refine),
         "assess": _file_step(steps.assess, _accuracy_text), "export": _file_step(steps.export),
         "run": step_run, "flood": step_flood}


def run_job(job: dict, ch: Channel) -> int:
    """Run one job, answering on ``ch``; the exit code (0 done, 2 bad input, 130 cancelled)."""
    missing = missing_dependencies()
    if missing:
        ch.send(error=install_hint(missing))
        return 2
    step = STEPS.get(job.get("step"))
    if step is None:
        ch.send(error=f"unknown FloodMesh worker step {job.get('step')!r}; one of "
                      f"{', '.join(STEPS)}")
        return 2
    # numba's first-run compile said when it really happens (run_pipeline says its own)
    compiles = CompileWatch(ch.info if step is not step_run else None)
    try:
        with compiles.watching(), interrupts_unwrapped():
            result = step(ch, **job.get("args", {}))
        if compiles.summary():
            ch.info(compiles.summary())
        ch.send(result=result)
    except FloodMeshError as exc:
        ch.send(error=str(exc))
        return 2
    except Terminated as exc:  # QGIS ending the worker with SIGTERM: unwound, nothing left
        ch.send(error=f"stopped by {exc}; no partial output was written")
        return 128 + exc.signum
    except Cancelled:
        ch.send(error="Cancelled; no partial output was written")
        return 130
    return 0


def main() -> int:
    # the protocol owns the real stdout; whatever else prints goes to stderr
    channel = Channel(os.fdopen(os.dup(1), "w", encoding="utf-8"))
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    faulthandler.enable()  # a crash in GEOS, Triangle or numba leaves its trace on stderr
    stop_signals_as_interrupts()  # SIGINT/SIGTERM/SIGHUP unwind: temporaries and scratch go
    keep_freed_memory()
    try:
        job = json.loads(sys.stdin.read())
    except ValueError as exc:
        channel.send(error=f"the FloodMesh worker got a job that is not JSON ({exc})")
        return 2
    return run_job(job, channel)


if __name__ == "__main__":
    end_process(main())
