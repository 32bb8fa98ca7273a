"""How FloodMesh's results look when they load: break lines in one readable style above the
mesh, residuals by class, the mesh shaded by elevation with its edges drawn, a flood's maxima on
colour ramps with dry cells clear, in the run's CRS, the view zoomed to it."""
import math

from qgis.core import (QgsCategorizedSymbolRenderer, QgsCoordinateReferenceSystem,
                       QgsCoordinateTransform, QgsLayerTree, QgsMapLayerType, QgsProcessingContext,
                       QgsProcessingException, QgsProcessingLayerPostProcessorInterface,
                       QgsProcessingOutputLayerDefinition, QgsRendererCategory,
                       QgsSimpleLineSymbolLayer, QgsSingleSymbolRenderer, QgsSymbol)
from qgis.PyQt.QtGui import QColor

from ..core.options import (BREAKLINE_COLOUR, DRY_BELOW_M, HALO_COLOUR, MESH_EDGE_COLOUR,
                            OUTSIDE_MESH_COLOUR, RESIDUAL_CLASS_COLOURS, RESIDUAL_CLASS_LABELS)
from .compat import LINE_GEOMETRY, USER_DEFINED_LIMITS

RESIDUAL_CLASSES = tuple(zip((0, 1, 2, -1), RESIDUAL_CLASS_LABELS,
                             (*RESIDUAL_CLASS_COLOURS, OUTSIDE_MESH_COLOUR)))


def _categorised(layer, field, categories):
    renderer = QgsCategorizedSymbolRenderer(field)
    for value, label, colour in categories:
        symbol = QgsSymbol.defaultSymbol(layer.geometryType())
        symbol.setColor(QColor(colour))
        renderer.addCategory(QgsRendererCategory(value, symbol, label))
    layer.setRenderer(renderer)


def style_breaklines(layer):
    """One style for every break line, readable on the mesh's colour ramp: a magenta line on a
    white halo (the attributes, e.g. ``mean_slope_deg`` or ``component_id``, stay there to
    colour by)."""
    symbol = QgsSymbol.defaultSymbol(layer.geometryType())
    halo = QgsSimpleLineSymbolLayer(QColor(HALO_COLOUR), 1.0)
    line = QgsSimpleLineSymbolLayer(QColor(BREAKLINE_COLOUR), 0.5)
    symbol.changeSymbolLayer(0, halo)
    symbol.appendSymbolLayer(line)
    layer.setRenderer(QgsSingleSymbolRenderer(symbol))


def style_residuals(layer):
    _categorised(layer, "class", RESIDUAL_CLASSES)


def style_triangles(layer):
    """Triangles as polygons (Build mesh's, an exported GeoPackage's) drawn as the mesh's edges,
    unfilled, so that what lies below shows through."""
    from qgis.core import QgsSimpleFillSymbolLayer
    from qgis.PyQt.QtCore import Qt

    fill = QgsSimpleFillSymbolLayer(QColor(0, 0, 0, 0), Qt.NoBrush, QColor(MESH_EDGE_COLOUR),
                                    Qt.SolidLine, 0.1)
    symbol = QgsSymbol.defaultSymbol(layer.geometryType())
    symbol.changeSymbolLayer(0, fill)
    layer.setRenderer(QgsSingleSymbolRenderer(symbol))


def style_mesh(layer):
    """Shade the faces by the nodes' elevation (the mesh's first dataset group) and draw the
    edges, thin and grey, so that it reads as a mesh."""
    settings = layer.rendererSettings()
    settings.setActiveScalarDatasetGroup(0)
    edges = settings.nativeMeshSettings()
    edges.setEnabled(True)
    edges.setColor(QColor(MESH_EDGE_COLOUR))
    edges.setLineWidth(0.1)
    settings.setNativeMeshSettings(edges)
    layer.setRendererSettings(settings)


# a flood's maxima: (fraction of the range, colour) stops; depth and speed from light to dark over
# the wet range with dry cells (0) transparent, the water level and arrival time over their range
DEPTH_STOPS = ((0.0, "#c6dbef"), (0.5, "#4292c6"), (1.0, "#08306b"))
LEVEL_STOPS = ((0.0, "#edf8b1"), (0.5, "#41b6c4"), (1.0, "#253494"))
SPEED_STOPS = ((0.0, "#ffffb2"), (0.5, "#fd8d3c"), (1.0, "#bd0026"))
ARRIVAL_STOPS = ((0.0, "#bd0026"), (0.5, "#fd8d3c"), (1.0, "#ffffb2"))  # first reached: darkest


def _pseudocolour(layer, stops, unit: str, dry: bool = False) -> None:
    """Shade a one-band raster through ``stops`` over its values (``unit`` in the legend); with
    ``dry``, cells of 0 (dry: no depth, no speed) are transparent and the ramp spans the rest."""
    from qgis.core import (QgsColorRampShader, QgsRasterShader,
                           QgsSingleBandPseudoColorRenderer)

    stats = layer.dataProvider().bandStatistics(1)
    low, high = stats.minimumValue, stats.maximumValue
    if dry:
        low = min(high, DRY_BELOW_M)
    if not (math.isfinite(low) and math.isfinite(high)) or high <= low:
        low, high = (low, low + 1.0) if math.isfinite(low) else (0.0, 1.0)
    items = [QgsColorRampShader.ColorRampItem(0.0, QColor(0, 0, 0, 0), "dry")] if dry else []
    for fraction, colour in stops:
        value = low + fraction * (high - low)
        items.append(QgsColorRampShader.ColorRampItem(value, QColor(colour),
                                                      f"{value:.3g} {unit}"))
    ramp = QgsColorRampShader(low, high)
    ramp.setColorRampItemList(items)
    shader = QgsRasterShader()
    shader.setRasterShaderFunction(ramp)
    renderer = QgsSingleBandPseudoColorRenderer(layer.dataProvider(), 1, shader)
    renderer.setClassificationMin(low)
    renderer.setClassificationMax(high)
    layer.setRenderer(renderer)


def style_max_depth(layer):
    """Maximum depth: light to dark blue over the wet cells, dry ones (0 m) transparent."""
    _pseudocolour(layer, DEPTH_STOPS, "m", dry=True)


def style_max_level(layer):
    """Maximum water level: over its range (never wet: no data, transparent)."""
    _pseudocolour(layer, LEVEL_STOPS, "m")


def style_max_speed(layer):
    """Maximum speed: yellow to red over the wet cells, dry ones (0 m/s) transparent."""
    _pseudocolour(layer, SPEED_STOPS, "m/s", dry=True)


def style_arrival(layer):
    """Arrival time: red where the water came first to yellow where it came last (never:
    no data, transparent)."""
    _pseudocolour(layer, ARRIVAL_STOPS, "s")


# the order results stack in, top first: lines above points above rasters above the mesh
def _rank(layer) -> int:
    if layer.type() == QgsMapLayerType.MeshLayer:
        return 3
    if layer.type() == QgsMapLayerType.RasterLayer:
        return 2
    return 0 if layer.geometryType() == LINE_GEOMETRY else 1


class _StyleOnLoad(QgsProcessingLayerPostProcessorInterface):
    """Styles a result as QGIS adds it; with ``run`` (one run's shared state: the name of its
    group) it also moves the layer into that run's group, in the readable order, and zooms the
    map to it."""

    def __init__(self, style, run=None):
        super().__init__()
        self.style, self.run = style, run

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802
        if self.style:
            self.style(layer)
        if self.run is not None and self.run.get("name"):
            _into_group(context.project(), layer, self.run)
            _after_group(context.project(), self.run["group"])
        else:
            _among_results(context.project(), layer)
        if self.run is not None:
            _zoom_to(layer, context.project())
        layer.triggerRepaint()


RUN_GROUP = "floodmesh/run"  # the custom property that marks a run's group: its folder
RESULT = "floodmesh/result"  # ... and a result loaded on its own (a step, a model's outputs)


def _move(node, parent, position: int) -> None:
    """Move a layer tree node: its clone in first, then the original out (QGIS removes a layer
    from the project, in a queued call, when its last tree node goes)."""
    parent.insertChildNode(position, node.clone())
    node.parent().removeChildNode(node)


def _among_results(project, layer) -> None:
    """A result loaded on its own (a step, a model's output, a batch) takes its place in the
    run of FloodMesh results around it, which is kept lines above points above rasters above
    meshes, whatever order QGIS adds them and calls this in (3.22: one by one on top; 3.40:
    all added first)."""
    node = project.layerTreeRoot().findLayer(layer.id())
    if node is None:
        return
    node.setCustomProperty(RESULT, True)
    parent = node.parent()
    siblings = parent.children()
    start = end = siblings.index(node)

    def result(k):
        return (0 <= k < len(siblings) and siblings[k].customProperty(RESULT)
                and getattr(siblings[k], "layer", lambda: None)() is not None)

    while result(start - 1):
        start -= 1
    while result(end + 1):
        end += 1
    ranked = sorted(siblings[start:end + 1], key=lambda n: _rank(n.layer()))  # stable
    for offset, layer_id in enumerate([n.layerId() for n in ranked]):
        moving = parent.findLayer(layer_id)
        if parent.children().index(moving) != start + offset:
            _move(moving, parent, start + offset)


def _folder_group(node, folder):
    """The group under ``node`` of an earlier run into ``folder``, or None."""
    for child in node.children():
        if QgsLayerTree.isGroup(child):
            if folder and child.customProperty(RUN_GROUP) == folder:
                return child
            found = _folder_group(child, folder)
            if found is not None:
                return found
    return None


def _into_group(project, layer, run: dict) -> None:
    """Move ``layer``'s tree node into the run's group, at its place in rank order: the group
    of an earlier run into the same folder (a rerun adds there what it did not reload), else
    one made where the run's first layer was put. The node is cloned in before the original is
    taken out: QGIS removes a layer from the project, in a queued call, when its last tree node
    goes."""
    root = project.layerTreeRoot()
    node = root.findLayer(layer.id())
    if node is None or not run.get("name"):
        return
    group = run.get("group")
    if group is None or root.findGroup(run["name"]) is not group:
        group = run["group"] = _folder_group(root, run.get("folder"))
    if group is None:
        parent, below = node.parent(), node
        # QGIS puts new layers into the selected group: not into an earlier run's group
        while parent.customProperty(RUN_GROUP) and parent.parent() is not None:
            parent, below = parent.parent(), parent
        group = run["group"] = parent.insertGroup(parent.children().index(below), run["name"])
        group.setCustomProperty(RUN_GROUP, run.get("folder") or True)
    rank = _rank(layer)
    position = sum(1 for child in group.children()
                   if QgsLayerTree.isLayer(child) and child.layer() is not None
                   and _rank(child.layer()) <= rank)
    _move(node, group, position)


def _after_group(project, group) -> None:
    """In the desktop QGIS, have the next layers added go where they would without the run: in
    the group's parent, above it, not into the group (QGIS puts them beside the current node,
    which the run left on its last layer)."""
    try:
        from qgis.utils import iface
    except ImportError:
        return
    if iface is None or iface.layerTreeView() is None or group.parent() is None:
        return
    from qgis.core import QgsLayerTreeRegistryBridge
    from qgis.PyQt.QtCore import QModelIndex

    iface.layerTreeView().setCurrentIndex(QModelIndex())
    parent = group.parent()
    project.layerTreeRegistryBridge().setLayerInsertionPoint(
        QgsLayerTreeRegistryBridge.InsertionPoint(parent, parent.children().index(group)))


def _zoom_to(layer, project) -> None:
    """In the desktop QGIS, show ``layer`` whole (qgis_process has no map)."""
    try:
        from qgis.utils import iface
    except ImportError:
        return
    if iface is None or iface.mapCanvas() is None or not layer.crs().isValid():
        return
    canvas = iface.mapCanvas()
    transform = QgsCoordinateTransform(layer.crs(), canvas.mapSettings().destinationCrs(),
                                       project)
    extent = transform.transformBoundingBox(layer.extent())
    if not extent.isEmpty():
        canvas.setExtent(extent.buffered(extent.width() * 0.02))
        canvas.refresh()


_PENDING = []  # QGIS holds post-processors by pointer only: keep them alive here


def _kept(styler):
    _PENDING.append(styler)
    del _PENDING[:-64]
    return styler


def style_when_loaded(context, output_path: str, style) -> None:
    """Apply ``style`` to the layer QGIS loads from ``output_path`` when the algorithm ends (a
    destination parameter the user asked to open)."""
    if context.willLoadLayerOnCompletion(output_path):
        context.layerToLoadOnCompletionDetails(output_path).setPostProcessor(
            _kept(_StyleOnLoad(style)))


def stack_when_loaded(context) -> None:
    """Every output QGIS loads when the algorithm ends, styled or not (a DEM, a slope, the
    triangles), takes its place among the FloodMesh results around it: without the mark a
    step's mesh, loaded on top, would cover the lines and rasters of earlier steps."""
    for key in context.layersToLoadOnCompletion():
        details = context.layerToLoadOnCompletionDetails(key)
        if details.postProcessor() is None:
            details.setPostProcessor(_kept(_StyleOnLoad(None)))


def load_results(context, crs_wkt, layers, group: str | None = None, folder=None) -> None:
    """Hand one run's finished layers (``(layer, style, output name)``) to QGIS to add to the
    project when the algorithm ends: each in the run's CRS (an SMS 2DM carries none) and
    styled; with ``group``, in one layer group of that name (the group of ``folder``, the run's
    folder or file, where an earlier run into it left one), lines above points above rasters
    above the mesh; the map zoomed to them."""
    import os

    crs = QgsCoordinateReferenceSystem.fromWkt(crs_wkt) if crs_wkt else None
    run = {"name": group, "folder": os.path.realpath(folder) if folder else None}
    for layer, style, output_name in layers:
        if not layer.isValid():
            raise QgsProcessingException(f"the output {layer.source()} could not be opened by "
                                         f"QGIS")
        if crs is not None and crs.isValid() and not layer.crs().isValid():
            layer.setCrs(crs)
        style(layer)
        context.temporaryLayerStore().addMapLayer(layer)
        details = QgsProcessingContext.LayerDetails(layer.name(), context.project(), output_name)
        details.setPostProcessor(_kept(_StyleOnLoad(None, run)))
        context.addLayerToLoadOnCompletion(layer.id(), details)


def drop_unasked_loads(algorithm, parameters, context) -> None:
    """The layers a run handed to QGIS itself (``load_results``: a mesh, a run's folder) load
    only where the user asked QGIS to load the run's layers. A file or folder output reaches the
    algorithm as a plain path, which says nothing; a layer output (a raster, the triangles)
    reaches it as a definition whose destination project is set where its layer is to be
    loaded: the batch dialog's "Load layers on completion" box, the dialog's "Open output file
    after running algorithm" box, processing.runAndLoadResults. With no such definition (the
    dialog of an algorithm with only file outputs, qgis_process, processing.run) they stay."""
    asked = [value.destinationProject is not None
             for value in (parameters.get(d.name())
                           for d in algorithm.destinationParameterDefinitions())
             if isinstance(value, QgsProcessingOutputLayerDefinition)]
    if asked and not any(asked):
        store = context.temporaryLayerStore()
        context.setLayersToLoadOnCompletion({
            key: details for key, details in context.layersToLoadOnCompletion().items()
            if store.mapLayer(key) is None})


def _file_of(source: str) -> tuple:
    """A layer source's file, resolved, and its layer name within it (a GeoPackage's), if any."""
    import os

    path, _, options = (source or "").partition("|")
    layer = [o.split("=", 1)[1] for o in options.split("|") if o.startswith("layername=")]
    return os.path.realpath(path) if path else "", layer[0] if layer else None


def _same_file(one: str, other: str) -> bool:
    (path, layer), (other_path, other_layer) = _file_of(one), _file_of(other)
    return bool(path) and path == other_path and (layer == other_layer
                                                  or None in (layer, other_layer))


def reload_rewritten(context) -> None:
    """A run that rewrote a file already in the project shows the new file once: each layer on
    it is reloaded where it is (its place, group and style kept) and the run does not load that
    output again (QGIS 3.22 would hand back the loaded layer, stale, or add a second one)."""
    project = context.project()
    if project is None:
        return
    loaded = list(project.mapLayers().values())
    keep = {}
    for key, details in context.layersToLoadOnCompletion().items():
        layer = context.temporaryLayerStore().mapLayer(key)
        source = layer.source() if layer is not None else key
        stale = [old for old in loaded if _same_file(old.source(), source)]
        if not stale:
            keep[key] = details
        for old in stale:
            old.reload()
            if old.type() == QgsMapLayerType.RasterLayer:
                _restretch(old)
            if old.dataProvider() is not None:
                old.setExtent(old.dataProvider().extent())
            old.triggerRepaint()
    context.setLayersToLoadOnCompletion(keep)


def _restretch(layer) -> None:
    """A raster reloaded on its rewritten file, stretched over the new values as a fresh load
    would be (its renderer and the kind of stretch kept; user-defined min/max stay). The
    statistics of the old file go first: QGIS's handle on it, closed by the reload, wrote them
    to the new file's ``.aux.xml``, and its provider caches them."""
    import os

    from qgis.core import QgsContrastEnhancement, QgsDataProvider

    aux = _file_of(layer.source())[0] + ".aux.xml"
    if os.path.exists(aux):
        os.remove(aux)
    options = QgsDataProvider.ProviderOptions()
    options.transformContext = layer.transformContext()
    layer.setDataSource(layer.source(), layer.name(), layer.providerType(), options, False)
    renderer = layer.renderer()
    if renderer is None or not layer.isValid():
        return
    limits = renderer.minMaxOrigin().limits()
    if limits == USER_DEFINED_LIMITS:
        return
    enhancement = (getattr(renderer, "contrastEnhancement", None)
                   or getattr(renderer, "redContrastEnhancement", lambda: None))()
    algorithm = (enhancement.contrastEnhancementAlgorithm() if enhancement is not None
                 else QgsContrastEnhancement.StretchToMinimumMaximum)
    layer.setContrastEnhancement(algorithm, limits)


def run_group_name(folder, source=None) -> str:
    """A run's layer group: its output folder's name, or where QGIS chose a temporary folder
    (named after the parameter, OUTPUT_FOLDER), the input's."""
    from pathlib import Path

    name = Path(folder).name
    if name == "OUTPUT_FOLDER" and source and isinstance(source, str):
        name = Path(source).stem or Path(source).name
    return name


def load_mesh(context, path: str, name: str, output_name: str, crs_wkt=None) -> None:
    """Load a 2DM mesh as a QGIS mesh layer in ``crs_wkt``, shaded by elevation with its edges
    drawn, when the algorithm ends."""
    from qgis.core import QgsMeshLayer

    load_results(context, crs_wkt, [(QgsMeshLayer(path, name, "mdal"), style_mesh,
                                     output_name)])
