"""A QGIS layer definition file (``run.qlr``) for a run folder: the mesh, the residuals and the
break lines in one group named after the run, in the run's CRS and styled as the plugin styles
them, so that the folder opens in QGIS (Layer › Add from Layer Definition File, or dragged onto
the map) without the plugin. An SMS 2DM has no place for a CRS and MDAL reads none for it: the
.qlr carries it.

Written as plain XML (core never imports QGIS); paths are relative to the .qlr, so the folder can
be moved. The layout is QGIS's own (``QgsLayerDefinition``), kept to the elements that carry
the CRS and the style; QGIS fills in the rest with its defaults.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ..options import (BREAKLINE_COLOUR, HALO_COLOUR, MESH_EDGE_COLOUR, OUTSIDE_MESH_COLOUR,
                       RESIDUAL_CLASS_COLOURS, RESIDUAL_CLASS_LABELS)

QLR_NAME = "run.qlr"
# the mesh's elevation ramp (QGIS's default for meshes, viridis-like: low blue, high yellow)
ELEVATION_RAMP = ("#0d0887", "#7e03a8", "#cc4778", "#f89540", "#f0f921")


def _rgba(colour: str) -> str:
    colour = colour.lstrip("#")
    return ",".join(str(int(colour[i:i + 2], 16)) for i in (0, 2, 4)) + ",255"


def _options(parent, values: dict) -> None:
    """QGIS's property map of a symbol layer (``<Option type="Map">``)."""
    options = ET.SubElement(parent, "Option", type="Map")
    for name, value in values.items():
        ET.SubElement(options, "Option", type="QString", name=name, value=str(value))


def _symbol(parent, name: str, kind: str, layers: list[tuple[str, dict]]) -> None:
    symbol = ET.SubElement(parent, "symbol", type=kind, name=name, alpha="1",
                           clip_to_extent="1", force_rhr="0")
    for layer_class, values in layers:
        layer = ET.SubElement(symbol, "layer", {"class": layer_class, "enabled": "1",
                                                "locked": "0", "pass": "0"})
        _options(layer, values)


def _line(colour: str, width_mm: float) -> tuple[str, dict]:
    return ("SimpleLine", {"line_color": _rgba(colour), "line_width": width_mm,
                           "line_width_unit": "MM", "line_style": "solid",
                           "capstyle": "round", "joinstyle": "round"})


def _marker(colour: str) -> tuple[str, dict]:
    return ("SimpleMarker", {"name": "circle", "color": _rgba(colour), "size": 2,
                             "size_unit": "MM", "outline_color": "35,35,35,255",
                             "outline_width": 0, "outline_style": "solid"})


def _map_layer(maplayers, *, layer_id: str, name: str, source: str, provider: str,
               crs_wkt: str, kind: str, geometry: str | None = None):
    attributes = {"type": kind, "styleCategories": "AllStyleCategories"}
    if geometry:
        attributes["geometry"] = geometry
    layer = ET.SubElement(maplayers, "maplayer", attributes)
    ET.SubElement(layer, "id").text = layer_id
    ET.SubElement(layer, "datasource").text = source
    ET.SubElement(layer, "layername").text = name
    srs = ET.SubElement(ET.SubElement(layer, "srs"), "spatialrefsys")
    ET.SubElement(srs, "wkt").text = crs_wkt
    ET.SubElement(layer, "provider").text = provider
    return layer


def layer_definition(*, group: str, crs_wkt: str, mesh: str, elevation_range: tuple,
                     breaklines: str, residuals: str | None, rasters=()) -> str:
    """The .qlr's XML: ``group`` holding break lines above residuals above the mesh above the
    ``rasters`` (``(name, file)``, hidden), files relative to the .qlr, in ``crs_wkt``; the
    mesh shaded over ``elevation_range`` (m)."""
    root = ET.Element("qlr")
    tree = ET.SubElement(ET.SubElement(root, "layer-tree-group", name="", checked="Qt::Checked",
                                       expanded="1"),
                         "layer-tree-group", name=group, checked="Qt::Checked", expanded="1")
    maplayers = ET.SubElement(root, "maplayers")
    layers = [("Break lines", breaklines, "ogr", "vector", "Line"),
              ("Residuals", residuals, "ogr", "vector", "Point"),
              ("Mesh", mesh, "mdal", "mesh", None),
              *((name, source, "gdal", "raster", None) for name, source in rasters)]
    for name, source, provider, kind, geometry in layers:
        if source is None:
            continue
        # QGIS gives every layer a new id as it loads a .qlr: a fixed one keeps runs repeatable
        layer_id = f"floodmesh_{name.replace(' ', '_').lower()}"
        shown = "Qt::Unchecked" if kind == "raster" else "Qt::Checked"  # QGIS's own style
        ET.SubElement(tree, "layer-tree-layer", id=layer_id, name=name, source=source,
                      providerKey=provider, checked=shown, expanded="0")
        layer = _map_layer(maplayers, layer_id=layer_id, name=name, source=source,
                           provider=provider, crs_wkt=crs_wkt, kind=kind, geometry=geometry)
        if name == "Break lines":
            renderer = ET.SubElement(layer, "renderer-v2", type="singleSymbol",
                                     symbollevels="0", enableorderby="0", forceraster="0")
            _symbol(ET.SubElement(renderer, "symbols"), "0", "line",
                    [_line(HALO_COLOUR, 1.0), _line(BREAKLINE_COLOUR, 0.5)])
        elif name == "Residuals":
            renderer = ET.SubElement(layer, "renderer-v2", type="categorizedSymbol",
                                     attr="class", symbollevels="0", enableorderby="0",
                                     forceraster="0")
            categories = ET.SubElement(renderer, "categories")
            symbols = ET.SubElement(renderer, "symbols")
            colours = (*RESIDUAL_CLASS_COLOURS, OUTSIDE_MESH_COLOUR)
            for k, (value, label, colour) in enumerate(zip((0, 1, 2, -1), RESIDUAL_CLASS_LABELS,
                                                           colours)):
                ET.SubElement(categories, "category", value=str(value), label=label,
                              symbol=str(k), render="true")
                _symbol(symbols, str(k), "marker", [_marker(colour)])
        elif kind == "mesh":
            _mesh_renderer(layer, elevation_range)
    ET.indent(root)
    return "<!DOCTYPE qgis-layer-definition>\n" + ET.tostring(root, encoding="unicode") + "\n"


def _mesh_renderer(layer, elevation_range) -> None:
    """The mesh shaded by its nodes' elevation (dataset group 0) with thin grey edges."""
    low, high = (float(v) for v in elevation_range)
    high = high if high > low else low + 1.0
    settings = ET.SubElement(layer, "mesh-renderer-settings")
    ET.SubElement(settings, "active-dataset-group", scalar="0", vector="-1")
    scalar = ET.SubElement(settings, "scalar-settings", group="0", opacity="1",
                           **{"min-val": repr(low), "max-val": repr(high),
                              "interpolation-method": "none"})
    shader = ET.SubElement(scalar, "colorrampshader", colorRampType="INTERPOLATED",
                           classificationMode="1", clip="0", minimumValue=repr(low),
                           maximumValue=repr(high))
    for k, colour in enumerate(ELEVATION_RAMP):
        value = low + (high - low) * k / (len(ELEVATION_RAMP) - 1)
        ET.SubElement(shader, "item", value=repr(value), color=colour, alpha="255",
                      label=f"{value:.2f}")
    ET.SubElement(settings, "mesh-settings-native", enabled="1", color=_rgba(MESH_EDGE_COLOUR),
                  **{"line-width": "0.1", "line-width-unit": "MM"})


def write_layer_definition(folder, *, group: str, crs_wkt: str, elevation_range: tuple,
                           mesh: str = "mesh.2dm", breaklines: str = "breaklines.gpkg",
                           residuals: str | None = "residuals.gpkg",
                           rasters=(("DEM", "dem.tif"), ("Slope", "slope.tif"),
                                    ("Breakpoints", "breakpoints.tif"))) -> Path:
    """Write ``run.qlr`` into ``folder`` for the run's files (names relative to the folder)."""
    path = Path(folder) / QLR_NAME
    path.write_text(layer_definition(
        group=group, crs_wkt=crs_wkt, elevation_range=elevation_range, mesh=f"./{mesh}",
        breaklines=f"./{breaklines}", residuals=residuals and f"./{residuals}",
        rasters=[(name, f"./{file}") for name, file in rasters]), encoding="utf-8")
    return path
