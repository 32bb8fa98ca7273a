"""The tile parameters LiDAR to mesh and Grid LiDAR points share: several point (or DEM) tiles
instead of one file, and the Dask workers or scheduler that grid them."""
from qgis.core import (QgsProcessingException, QgsProcessingParameterBoolean,
                       QgsProcessingParameterDefinition,
                       QgsProcessingParameterFile, QgsProcessingParameterMultipleLayers,
                       QgsProcessingParameterNumber, QgsProcessingParameterString)

from .compat import FILE_SOURCE, FOLDER, INTEGER

TILES, TILE_FOLDER, WORKERS, SCHEDULER = "TILES", "TILE_FOLDER", "WORKERS", "SCHEDULER"
SKIP_UNREADABLE = "SKIP_UNREADABLE"


def add_tile_parameters(algorithm, what: str):
    """Add TILES (files; ``what`` they are), TILE_FOLDER (a folder of them), SKIP_UNREADABLE,
    WORKERS and SCHEDULER (advanced) to ``algorithm``."""
    tr = algorithm.tr
    algorithm.addParameter(QgsProcessingParameterMultipleLayers(
        TILES, tr(f"Tiles instead of one file: {what}"), layerType=FILE_SOURCE,
        optional=True))
    algorithm.addParameter(QgsProcessingParameterFile(
        TILE_FOLDER, tr("… or a folder of tiles (its point or DEM files)"), behavior=FOLDER,
        optional=True))
    for parameter in (
            QgsProcessingParameterBoolean(
                SKIP_UNREADABLE, tr("Tiles: leave out unreadable tiles (a truncated or corrupt "
                                    "file), with a note naming them"), defaultValue=False),
            QgsProcessingParameterNumber(
                WORKERS, tr("Tiles: parallel threads or Dask workers (empty: one per core)"),
                INTEGER, None, optional=True, minValue=1),
            QgsProcessingParameterString(
                SCHEDULER, tr("Tiles: address of a running Dask scheduler (tcp://HOST:8786; "
                              "'local': a local cluster; empty: in memory where the tiles fit, "
                              "else a local cluster)"), optional=True)):
        parameter.setFlags(parameter.flags() | QgsProcessingParameterDefinition.FlagAdvanced)
        algorithm.addParameter(parameter)


def input_or_tiles(algorithm, parameters, context, input_name: str):
    """The point-cloud layer's file, the one input file (or folder of tiles), or the list of
    tiles; exactly one of them must be given."""
    from .base import point_cloud_file

    # QGIS 3.22 gives [''] for an absent list
    tiles = [t for t in algorithm.parameterAsFileList(parameters, TILES, context) if t]
    given = [g for g in (point_cloud_file(algorithm, parameters, context),
                         algorithm.parameterAsFile(parameters, input_name, context),
                         tiles, algorithm.parameterAsFile(parameters, TILE_FOLDER, context))
             if g]
    if len(given) > 1:
        raise QgsProcessingException("give one of a point cloud layer, an input file, tiles or "
                                     "a folder of tiles, not several")
    if not given:
        raise QgsProcessingException("give a point cloud layer, an input file, or tiles "
                                     "(several files or a folder)")
    return given[0]


def skip_unreadable(algorithm, parameters, context) -> dict:
    """The worker's ``skip_unreadable`` argument (leave out tiles that cannot be read)."""
    return {"skip_unreadable": algorithm.parameterAsBool(parameters, SKIP_UNREADABLE, context)}


def dask_settings(algorithm, parameters, context) -> dict:
    """workers and scheduler for core (which runs in FloodMesh's worker process, so local Dask
    workers can be processes there)."""
    workers = (algorithm.parameterAsInt(parameters, WORKERS, context)
               if parameters.get(WORKERS) not in (None, "") else None)
    scheduler = algorithm.parameterAsString(parameters, SCHEDULER, context).strip() or None
    return {"workers": workers, "scheduler": scheduler}
