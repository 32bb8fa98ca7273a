"""The one place where FloodMesh's QGIS code differs between the QGIS releases it supports:
3.22 (Debian 12) and 3.40 LTR (Debian 13), Qt5 builds and Qt6 ones.

QGIS 3.30 and 3.36 moved the enums used here into ``Qgis`` (``Qgis.WkbType``,
``Qgis.ProcessingSourceType``, ``Qgis.ProcessingNumberParameterType``) and deprecated the old
names; the scoped ones are what Qt6 builds (QGIS 4) keep. Each name below is the new enum
where this QGIS has it, else the old one. Qt classes come from ``qgis.PyQt``, QGIS's own shim
over PyQt5 and PyQt6.
"""
from qgis.core import Qgis, QgsProcessing, QgsProcessingParameterNumber

if hasattr(Qgis, "ProcessingSourceType"):  # QGIS >= 3.36
    FILE_SOURCE = Qgis.ProcessingSourceType.File
    VECTOR_POINT = Qgis.ProcessingSourceType.VectorPoint
    VECTOR_LINE = Qgis.ProcessingSourceType.VectorLine
    VECTOR_POLYGON = Qgis.ProcessingSourceType.VectorPolygon
else:
    FILE_SOURCE = QgsProcessing.TypeFile
    VECTOR_POINT = QgsProcessing.TypeVectorPoint
    VECTOR_LINE = QgsProcessing.TypeVectorLine
    VECTOR_POLYGON = QgsProcessing.TypeVectorPolygon

if hasattr(Qgis, "ProcessingNumberParameterType"):  # QGIS >= 3.36
    DOUBLE = Qgis.ProcessingNumberParameterType.Double
    INTEGER = Qgis.ProcessingNumberParameterType.Integer
else:
    DOUBLE = QgsProcessingParameterNumber.Double
    INTEGER = QgsProcessingParameterNumber.Integer

if hasattr(Qgis, "WkbType"):  # QGIS >= 3.30
    POINT_Z, LINESTRING_Z, POLYGON_Z = (Qgis.WkbType.PointZ, Qgis.WkbType.LineStringZ,
                                        Qgis.WkbType.PolygonZ)
    LINE_GEOMETRY = Qgis.GeometryType.Line
else:
    from qgis.core import QgsWkbTypes

    POINT_Z, LINESTRING_Z, POLYGON_Z = (QgsWkbTypes.PointZ, QgsWkbTypes.LineStringZ,
                                        QgsWkbTypes.PolygonZ)
    LINE_GEOMETRY = QgsWkbTypes.LineGeometry

if hasattr(Qgis, "DistanceUnit"):  # QGIS >= 3.30
    METRES = Qgis.DistanceUnit.Meters
else:
    from qgis.core import QgsUnitTypes

    METRES = QgsUnitTypes.DistanceMeters

if hasattr(Qgis, "ProcessingFileParameterBehavior"):  # QGIS >= 3.36
    FOLDER = Qgis.ProcessingFileParameterBehavior.Folder
else:
    from qgis.core import QgsProcessingParameterFile

    FOLDER = QgsProcessingParameterFile.Folder

if hasattr(Qgis, "RasterRangeLimit"):  # QGIS >= 3.38
    USER_DEFINED_LIMITS = Qgis.RasterRangeLimit.NotSet
else:
    from qgis.core import QgsRasterMinMaxOrigin

    USER_DEFINED_LIMITS = QgsRasterMinMaxOrigin.None_

if hasattr(Qgis, "InvalidGeometryCheck"):  # QGIS >= 3.36
    SKIP_INVALID = Qgis.InvalidGeometryCheck.SkipInvalid
    OWN_GEOMETRY_CHECK = Qgis.ProcessingFeatureSourceDefinitionFlag.OverrideDefaultGeometryCheck
else:
    from qgis.core import QgsFeatureRequest, QgsProcessingFeatureSourceDefinition

    SKIP_INVALID = QgsFeatureRequest.GeometrySkipInvalid
    OWN_GEOMETRY_CHECK = QgsProcessingFeatureSourceDefinition.FlagOverrideDefaultGeometryCheck


def temporary_file(basename: str, context) -> str:
    """A new temporary file name in the Processing temporary folder: the one set for this run
    (QGIS >= 3.32: Algorithm Settings › Temporary folder) where QGIS has it."""
    from qgis.core import QgsProcessingUtils

    if hasattr(context, "temporaryFolder"):  # QGIS >= 3.32
        return QgsProcessingUtils.generateTempFilename(basename, context)
    return QgsProcessingUtils.generateTempFilename(basename)
