"""The one family of errors FloodMesh raises for bad input: each message names the problem and the fix."""


class FloodMeshError(ValueError):
    """Bad input or parameters; the message says what was received and what to do."""


class Cancelled(Exception):
    """The user cancelled the run (QGIS Cancel, Ctrl-C); nothing half-written is left behind."""
