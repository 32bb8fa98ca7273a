"""Entwine Point Tile indexes written from a LAS/LAZ file for the tests: the point-cloud layer
format that Debian's QGIS (built without PDAL) opens, as Entwine and untwine write it (ept.json,
LAZ nodes in ept-data, their point counts in ept-hierarchy)."""
import json

import numpy as np


def write_ept(laz, folder, nodes: int = 1):
    """An EPT index of ``laz`` in ``folder``: ``nodes`` LAZ nodes (the root and, for more, its
    children at depth 1), each point in exactly one. Returns the path of ept.json."""
    import laspy

    (folder / "ept-data").mkdir(parents=True)
    (folder / "ept-hierarchy").mkdir()
    las = laspy.read(laz)
    header = las.header
    low, high = header.mins, header.maxs
    half, middle = float(max(high - low)) / 2 + 1, (low + high) / 2
    keys = ["0-0-0-0"] + [f"1-{k % 2}-{k // 2 % 2}-0" for k in range(nodes - 1)]
    counts = {}
    for k, part in enumerate(np.array_split(np.arange(len(las.points)), nodes)):
        node = laspy.LasData(header)
        node.points = las.points[part]
        node.write(folder / "ept-data" / f"{keys[k]}.laz")
        counts[keys[k]] = len(part)
    axes = [{"name": n, "type": "signed", "size": 4, "scale": float(s), "offset": float(o)}
            for n, s, o in zip("XYZ", header.scales, header.offsets)]
    meta = {"bounds": [*map(float, middle - half), *map(float, middle + half)],
            "boundsConforming": [*map(float, low), *map(float, high)], "dataType": "laszip",
            "hierarchyType": "json", "points": int(header.point_count), "span": 128,
            "schema": axes + [{"name": "Classification", "type": "unsigned", "size": 1}],
            "srs": {"wkt": header.parse_crs().to_wkt()}, "version": "1.0.0"}
    (folder / "ept.json").write_text(json.dumps(meta))
    (folder / "ept-hierarchy" / "0-0-0-0.json").write_text(json.dumps(counts))
    return folder / "ept.json"
