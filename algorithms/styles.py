"""How FloodMesh's results look when they load: break lines by component, residuals by class,
the mesh shaded by elevation."""
from qgis.core import (QgsCategorizedSymbolRenderer, QgsProcessingContext,
                       QgsProcessingException, QgsProcessingLayerPostProcessorInterface,
                       QgsRendererCategory, QgsSymbol)
from qgis.PyQt.QtGui import QColor

from ..core.options import OUTSIDE_MESH_COLOUR, RESIDUAL_CLASS_COLOURS as COLOURS

RESIDUAL_CLASSES = ((0, "< 10 cm", COLOURS[0]), (1, "10–25 cm", COLOURS[1]),
                    (2, "> 25 cm", COLOURS[2]), (-1, "outside the mesh", OUTSIDE_MESH_COLOUR))


def _categorised(layer, field, categories, width=None):
    renderer = QgsCategorizedSymbolRenderer(field)
    for value, label, colour in categories:
        symbol = QgsSymbol.defaultSymbol(layer.geometryType())
        symbol.setColor(QColor(colour))
        if width is not None:
            symbol.setWidth(width)
        renderer.addCategory(QgsRendererCategory(value, symbol, label))
    layer.setRenderer(renderer)


def style_breaklines(layer):
    """A distinct colour per connected break-line system (``component_id``)."""
    index = layer.fields().indexOf("component_id")
    values = sorted(layer.uniqueValues(index)) if index >= 0 else []
    colours = [QColor.fromHsv(int(137.508 * k) % 360, 200, 210).name() for k in range(len(values))]
    _categorised(layer, "component_id", [(v, f"system {v}", c) for v, c in zip(values, colours)],
                 width=0.6)


def style_residuals(layer):
    _categorised(layer, "class", RESIDUAL_CLASSES)


def style_mesh(layer):
    """Shade the faces by the nodes' elevation (the mesh's first dataset group)."""
    settings = layer.rendererSettings()
    settings.setActiveScalarDatasetGroup(0)
    layer.setRendererSettings(settings)


class _StyleOnLoad(QgsProcessingLayerPostProcessorInterface):
    def __init__(self, style):
        super().__init__()
        self.style = style

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802
        self.style(layer)
        layer.triggerRepaint()


_PENDING = []  # QGIS holds post-processors by pointer only: keep them alive here


def style_when_loaded(context, output_path: str, style) -> None:
    """Apply ``style`` to the layer QGIS loads from ``output_path`` when the algorithm ends (a
    destination parameter the user asked to open)."""
    if context.willLoadLayerOnCompletion(output_path):
        styler = _StyleOnLoad(style)
        _PENDING.append(styler)
        del _PENDING[:-16]
        context.layerToLoadOnCompletionDetails(output_path).setPostProcessor(styler)


def load_on_completion(context, layer, output_name):
    """Hand a finished layer to QGIS to add to the project when the algorithm ends."""
    if not layer.isValid():
        raise QgsProcessingException(f"the output {layer.source()} could not be opened by QGIS")
    context.temporaryLayerStore().addMapLayer(layer)
    context.addLayerToLoadOnCompletion(
        layer.id(), QgsProcessingContext.LayerDetails(layer.name(), context.project(), output_name))


def load_mesh(context, path: str, name: str, output_name: str) -> None:
    """Load a 2DM mesh as a QGIS mesh layer, shaded by elevation, when the algorithm ends."""
    from qgis.core import QgsMeshLayer

    layer = QgsMeshLayer(path, name, "mdal")
    load_on_completion(context, layer, output_name)
    style_mesh(layer)
