"""What the command line shows on the terminal: the progress bar and the notes (what FloodMesh
assumed or repaired on the user's behalf)."""
from __future__ import annotations

import sys

from ..engine.compiles import is_compile_message


class ProgressBar:
    """A one-line progress bar on stderr when it is a terminal; silent otherwise."""

    def __init__(self, label: str, stream=None):
        # sys.stderr when called, not when imported: it may have been replaced since
        self.label, self.stream = label, stream or sys.stderr
        self.enabled = self.stream.isatty()
        self.last = -1

    def __call__(self, fraction: float):
        if not self.enabled:
            return
        percent = int(100 * min(max(fraction, 0.0), 1.0))
        if percent != self.last:
            self.last = percent
            bar = "#" * (percent // 4)
            self.stream.write(f"\r{self.label:<12} [{bar:<25}] {percent:3d}%")
            self.stream.flush()

    def log(self, message: str):
        """A step's name shown on the bar; numba's first-run compile said whether or not a
        bar is drawn (it may take minutes)."""
        if is_compile_message(message):
            if self.enabled and self.last >= 0:
                self.stream.write("\n")
            print(f"floodmesh: {message}", file=self.stream)
        elif self.enabled:
            self.label = message.rstrip(".")
            self(max(self.last, 0) / 100)

    def close(self):
        if self.enabled and self.last >= 0:
            self.stream.write("\n")


def print_notes(notes) -> None:
    """What FloodMesh assumed or repaired on the user's behalf, one line each on stderr."""
    for message in notes:
        print_note(message)


def print_note(message: str) -> None:
    print(f"floodmesh: note: {message}", file=sys.stderr)
