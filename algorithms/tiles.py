"""The tile parameters LiDAR to mesh and Grid LiDAR points share: several point (or DEM) tiles
instead of one file, and the Dask workers or scheduler that grid them."""
from qgis.core import (QgsProcessingException, QgsProcessingParameterDefinition,
                       QgsProcessingParameterMultipleLayers, QgsProcessingParameterNumber,
                       QgsProcessingParameterString)

from .compat import FILE_SOURCE, INTEGER

TILES, WORKERS, SCHEDULER = "TILES", "WORKERS", "SCHEDULER"


def add_tile_parameters(algorithm, what: str):
    """Add TILES (files; ``what`` they are), WORKERS and SCHEDULER (advanced) to ``algorithm``."""
    tr = algorithm.tr
    algorithm.addParameter(QgsProcessingParameterMultipleLayers(
        TILES, tr(f"Tiles instead of one file: {what}"), layerType=FILE_SOURCE,
        optional=True))
    for parameter in (
            QgsProcessingParameterNumber(
                WORKERS, tr("Tiles: parallel Dask workers (empty: one per core)"),
                INTEGER, None, optional=True, minValue=1),
            QgsProcessingParameterString(
                SCHEDULER, tr("Tiles: address of a running Dask scheduler (tcp://HOST:8786; "
                              "empty: workers on this machine)"), optional=True)):
        parameter.setFlags(parameter.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
        algorithm.addParameter(parameter)


def input_or_tiles(algorithm, parameters, context, input_name: str):
    """The one input file, or the list of tiles; exactly one of the two must be given."""
    # QGIS 3.22 gives [''] for an absent list
    tiles = [t for t in algorithm.parameterAsFileList(parameters, TILES, context) if t]
    source = algorithm.parameterAsFile(parameters, input_name, context)
    if tiles and source:
        raise QgsProcessingException("give either one input file or tiles, not both")
    if not tiles and not source:
        raise QgsProcessingException("give an input file, or tiles (several files)")
    return tiles if tiles else source


def dask_settings(algorithm, parameters, context) -> dict:
    """workers and scheduler for core (which runs in FloodMesh's worker process, so local Dask
    workers can be processes there)."""
    workers = (algorithm.parameterAsInt(parameters, WORKERS, context)
               if parameters.get(WORKERS) not in (None, "") else None)
    scheduler = algorithm.parameterAsString(parameters, SCHEDULER, context).strip() or None
    return {"workers": workers, "scheduler": scheduler}
