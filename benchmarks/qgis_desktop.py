"""LiDAR to mesh in the desktop QGIS against the command line on the same file (issue 31: within
1.2x). The desktop run is the one a modeller makes: the real ``qgis.bin`` under a virtual display,
the algorithm's dialog with only the input and the output folder set, Run pressed, timed until
its layers are in the project and Qt's events have run; the command line is ``floodmesh run``,
a whole process. They alternate, best of ``--repeat`` each.

    .venv/bin/python benchmarks/qgis_desktop.py [LAZ] [--repeat 2]

LAZ defaults to the run benchmark's 9 M-point file (``benchmarks/run.py --only run`` writes it).
Needs xvfb-run and QGIS (``scripts/setup.sh`` installs both).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

DESKTOP = r"""
import json, os, time, traceback
from qgis.core import QgsProject
from qgis.PyQt.QtCore import QCoreApplication
from qgis.PyQt.QtTest import QTest
out = {}
try:
    import processing
    for _ in range(5):  # QGIS settled before the clock starts
        QCoreApplication.processEvents()
        QTest.qWait(100)
    dialog = processing.createAlgorithmDialog("floodmesh:lidartomesh", {
        "INPUT": os.environ["FM_INPUT"], "OUTPUT_FOLDER": os.environ["FM_OUTPUT"]})
    dialog.show()
    QCoreApplication.processEvents()
    start = time.perf_counter()
    dialog.runAlgorithm()
    while not dialog.results():
        QTest.qWait(20)
    QCoreApplication.processEvents()  # the layers' loading, queued after the task
    out["seconds"] = time.perf_counter() - start
    out["layers"] = sorted(l.name() for l in QgsProject.instance().mapLayers().values())
except Exception:
    out["error"] = traceback.format_exc()
open(os.environ["FM_RESULT"], "w").write(json.dumps(out))
os._exit(0)
"""


def desktop_run(laz: Path, tmp: Path) -> dict:
    """Seconds from Run to the layers in the project, in a fresh profile with the plugin on."""
    profile = tmp / "data" / "QGIS" / "QGIS3" / "profiles" / "default" / "QGIS"
    profile.mkdir(parents=True, exist_ok=True)
    (profile / "QGIS3.ini").write_text("[PythonPlugins]\nfloodmesh=true\nprocessing=true\n")
    (tmp / "run.py").write_text(DESKTOP)
    result = tmp / "result.json"
    result.unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "QT_QPA_PLATFORM")}
    env.update(HOME=str(tmp), XDG_DATA_HOME=str(tmp / "data"),
               QGIS_PLUGINPATH=str(REPO / "build" / "plugins"), FM_RESULT=str(result),
               FM_INPUT=str(laz), FM_OUTPUT=str(tmp / f"desktop {time.time_ns()}"))
    subprocess.run(["xvfb-run", "-a", "qgis.bin", "--noversioncheck", "--nologo", "--code",
                    str(tmp / "run.py")], env=env, capture_output=True, timeout=900)
    seen = json.loads(result.read_text()) if result.exists() else {"error": "no result"}
    if "error" in seen:
        raise SystemExit(f"the desktop run failed: {seen['error']}")
    return seen


def command_run(laz: Path, tmp: Path) -> float:
    start = time.perf_counter()
    subprocess.run([str(REPO / ".venv" / "bin" / "floodmesh"), "run", str(laz), "--out",
                    str(tmp / f"cli {time.time_ns()}")], check=True, capture_output=True)
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("laz", nargs="?", type=Path,
                        default=REPO / "build" / "bench" / "points_9000000.laz")
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args(argv)
    if not args.laz.exists():
        raise SystemExit(f"{args.laz} is missing: benchmarks/run.py --only run writes it")
    desktop, command, layers = [], [], []
    with tempfile.TemporaryDirectory(dir=REPO / "build") as tmp:
        tmp = Path(tmp)
        for _ in range(args.repeat):
            command.append(command_run(args.laz, tmp))
            seen = desktop_run(args.laz, tmp)
            desktop.append(seen["seconds"])
            layers = seen["layers"]
    load = os.getloadavg()[0]
    print(f"## LiDAR to mesh: the desktop's dialog against the command line, {args.laz.name}, "
          f"best of {args.repeat}, alternating (goal: at most 1.2x); load average {load:.1f}")
    print(f"{'':<52}{'s':>8}{'ratio':>8}")
    print(f"{'floodmesh run (whole process)':<52}{min(command):>8.2f}{1.0:>8.2f}")
    print(f"{'QGIS desktop: Run pressed to layers in the project':<52}{min(desktop):>8.2f}"
          f"{min(desktop) / min(command):>8.2f}")
    print(f"layers loaded: {', '.join(layers)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
