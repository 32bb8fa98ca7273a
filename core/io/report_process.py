"""The run's pictures (``report.write_report_pngs``) drawn in a Python process of their own:
matplotlib's import and drawing (about 0.6 s on the benchmark run) hold the interpreter, so on a
thread they only took turns with the chain's last steps; in a process they run on the core
those steps leave idle. The process starts early, loads matplotlib while the chain works, and
draws once it is given the mesh and residuals.

    python -m floodmesh.core.io.report_process    (reads "[DATA.npz, FOLDER]" on stdin)
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .report import write_report_pngs


class PicturesApart:
    """A context for the picture process: ``start`` starts it, ``draw`` hands it the
    pictures' arrays, ``wait`` waits for the pictures (drawing them here where the process
    could not: no Python executable to start, or it failed). Leaving the context, or
    ``close``, before ``wait`` ends it."""

    def __init__(self):
        self.child, self.data, self.args = None, None, None

    def __enter__(self):
        return self

    def start(self) -> None:
        python = sys.executable
        if python and Path(python).name.startswith("python"):  # not inside QGIS's own binary
            package = __name__.rsplit(".", 2)[0]  # "floodmesh.core" as installed
            self.child = subprocess.Popen(
                [python, "-m", f"{package}.io.report_process"], stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def draw(self, folder, nodes: np.ndarray, triangles: np.ndarray, xyz: np.ndarray,
             res: np.ndarray, *, dem, lines) -> None:
        """Start drawing ``write_report_pngs``' pictures of these into ``folder``."""
        lines = [np.asarray(line, float)[:, :2] for line in lines]
        self.args = (folder, nodes, triangles, xyz, res, dem, lines)
        if self.child is None:
            return
        fd, self.data = tempfile.mkstemp(prefix="floodmesh-pictures-", suffix=".npz")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, nodes=nodes, triangles=triangles, xyz=xyz, res=res, dem=dem.values,
                     transform=np.array(tuple(dem.transform)[:6]), crs=dem.crs.to_wkt(),
                     lengths=np.array([len(line) for line in lines], np.int64),
                     coords=np.concatenate(lines) if lines else np.empty((0, 2)))
        try:
            self.child.stdin.write(json.dumps([self.data, str(folder)]).encode() + b"\n")
            self.child.stdin.close()
        except OSError:  # it ended already: drawn here at ``wait``
            self.child.kill()

    def wait(self) -> None:
        """The pictures are written once this returns."""
        failed = self.child is None or self.child.wait() != 0
        self._clean()
        if failed:
            folder, nodes, triangles, xyz, res, dem, lines = self.args
            write_report_pngs(folder, nodes, triangles, xyz, res, dem=dem, lines=lines)

    def _clean(self):
        if self.data:
            Path(self.data).unlink(missing_ok=True)
            self.data = None

    def close(self) -> None:
        """End the process if it is still drawing (an error or interrupt before ``wait``)
        and wait for it: before the folder it draws into is removed."""
        if self.child is not None and self.child.poll() is None:
            self.child.kill()  # an error or interrupt before ``wait``, or nothing to draw
            self.child.wait()
        if self.child is not None and self.child.stdin and not self.child.stdin.closed:
            self.child.stdin.close()
        self._clean()

    def __exit__(self, *exc):
        self.close()


def draw_pictures(data, folder) -> None:
    """The pictures of the arrays ``PicturesApart.draw`` saved in ``data``, into ``folder``."""
    # lazy: PROJ and rasterio's Affine load only in the picture process
    from affine import Affine
    from pyproj import CRS

    from ..raster import Grid

    with np.load(data) as saved:
        dem = Grid(saved["dem"], Affine(*saved["transform"]), CRS.from_wkt(str(saved["crs"])))
        lines = np.split(saved["coords"], np.cumsum(saved["lengths"])[:-1])
        write_report_pngs(folder, saved["nodes"], saved["triangles"], saved["xyz"],
                          saved["res"], dem=dem, lines=[line for line in lines if len(line)])


def main() -> None:
    # lazy: matplotlib loads while the chain works, before the arrays come
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401

    line = sys.stdin.readline()
    if line:  # nothing: the chain ended without pictures
        draw_pictures(*json.loads(line))
    os._exit(0)  # written: no teardown of matplotlib's objects to wait for


if __name__ == "__main__":
    main()
