"""Cloud Optimized Point Cloud (COPC 1.0, https://copc.io) files written for the tests, since
no COPC writer is installed (laspy reads COPC but cannot write it; there is no PDAL): a LAS 1.4
file of point format 6, LAZ-compressed in variable-size chunks, one chunk per octree node, with
the COPC info VLR first and the hierarchy in an EVLR. As real COPC writers do, a node keeps one
point per cell of a 128³ grid and passes the rest to its children, so every level is a level of
detail. Checked by laspy's own COPC reader (``laspy.CopcReader``: whole, by spatial query and by
resolution) and by laspy reading it as plain LAZ."""
import io
import struct
from pathlib import Path

import numpy as np

VLR_HEADER, EVLR_HEADER = 54, 60  # bytes of a VLR's and an EVLR's header (LAS 1.4)
GRID = 128  # cells along a node's edge: a node keeps at most one point per cell
MAX_LEVEL = 24  # a node this deep keeps all its points (thousands of equal points end there)


def _octree(xyz, corner, side: float, max_node_points: int) -> dict:
    """{(level, i, j, k): point indices} of the nodes holding points, in a cube of edge ``side``
    from ``corner``: a node of more than ``max_node_points`` keeps the first point of each of
    its grid's cells and passes the others to its eight children."""
    nodes, stack = {}, [((0, 0, 0, 0), np.arange(len(xyz)))]
    while stack:
        key, index = stack.pop()
        level, ijk = key[0], np.array(key[1:])
        if len(index) <= max_node_points or level == MAX_LEVEL:
            nodes[key] = index
            continue
        size = side / 2 ** level  # a power of two: the cells' edges are exact, as the readers'
        cell = np.floor((xyz[index] - (corner + ijk * size)) / (size / GRID)).astype(np.int64)
        cell = cell.clip(0, GRID - 1)  # a point on the node's upper faces
        _, first = np.unique(cell @ [GRID * GRID, GRID, 1], return_index=True)
        keep = np.zeros(len(index), bool)
        keep[first] = True
        nodes[key] = index[keep]
        child = cell[~keep] // (GRID // 2)  # 0 or 1 along each axis
        for c in np.unique(child, axis=0):
            stack.append(((level + 1, *map(int, 2 * ijk + c)),
                          index[~keep][(child == c).all(axis=1)]))
    return nodes


def _vlr(user_id: str, record_id: int, data: bytes, *, extended: bool = False) -> bytes:
    length = struct.pack("<Q" if extended else "<H", len(data))
    return (struct.pack("<H16sH", 0, user_id.encode(), record_id) + length
            + b"COPC test writer".ljust(32, b"\0") + data)


def write_copc(path, xyz, classes=None, *, crs_wkt: str, max_node_points: int = 20_000) -> Path:
    """``xyz`` (n, 3, m) with LAS ``classes`` (default 2, ground) as a COPC file at ``path``,
    in the CRS ``crs_wkt``; each point in one octree node. Returns the path."""
    import laspy
    import lazrs
    from pyproj import CRS

    xyz = np.asarray(xyz, dtype=np.float64)
    offsets, scale = np.floor(xyz.min(axis=0)), 0.001
    stored = np.round((xyz - offsets) / scale).astype(np.int32)
    xyz = stored * scale + offsets  # the points as readers see them, placed in their nodes
    corner = np.floor(xyz.min(axis=0))
    side = 2.0 ** np.ceil(np.log2(float((xyz.max(axis=0) - corner).max()) + 1))
    nodes = _octree(xyz, corner, side, max_node_points)
    order = np.concatenate(list(nodes.values()))
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets, header.scales = offsets, np.full(3, scale)
    header.vlrs.append(laspy.VLR("copc", 1, "COPC info", bytes(160)))  # filled below
    header.add_crs(CRS.from_wkt(crs_wkt))  # a WKT VLR, and the WKT bit of the global encoding
    las = laspy.LasData(header)
    las.X, las.Y, las.Z = stored[order, 0], stored[order, 1], stored[order, 2]
    las.classification = (np.full(len(xyz), 2, np.uint8) if classes is None
                          else np.asarray(classes, np.uint8)[order])
    las.return_number = las.number_of_returns = np.ones(len(xyz), np.uint8)
    plain = io.BytesIO()
    las.write(plain)
    raw = plain.getvalue()
    header_size, point_offset, n_vlrs = struct.unpack_from("<HII", raw, 94)
    record = struct.unpack_from("<H", raw, 105)[0]
    # the points compressed node by node: one variable-size LAZ chunk each
    laz_vlr = lazrs.LazVlr.new_for_compression(6, 0, use_variable_size_chunks=True)
    laszip = _vlr("laszip encoded", 22204, laz_vlr.record_data())
    data_start = point_offset + len(laszip)
    ends = np.cumsum([len(index) for index in nodes.values()]) * record + point_offset
    compressed = io.BytesIO()
    compressor = lazrs.ParLasZipCompressor(compressed, laz_vlr)
    compressor.compress_chunks([raw[a:b] for a, b in zip([point_offset, *ends[:-1]], ends)])
    compressor.done()
    compressed.seek(0)
    table = lazrs.read_chunk_table(compressed, laz_vlr)
    chunks = bytearray(compressed.getvalue())  # its chunk table's offset is the file's
    struct.pack_into("<q", chunks, 0, data_start + struct.unpack_from("<q", chunks)[0])
    # the hierarchy: every node's entry, its chunk's offset and size in the file
    assert [count for count, _ in table] == [len(index) for index in nodes.values()]
    starts = data_start + 8 + np.cumsum([0] + [size for _, size in table])
    page = b"".join(struct.pack("<iiiiQii", *key, int(start), size, count)
                    for key, start, (count, size) in zip(nodes, starts, table))
    evlr_start = data_start + len(chunks)
    info = struct.pack("<3dddQQdd", *(corner + side / 2), side / 2, side / GRID,
                       evlr_start + EVLR_HEADER, len(page), 0.0, 0.0) + bytes(88)
    head = bytearray(raw[:point_offset])
    head[header_size + VLR_HEADER:header_size + VLR_HEADER + 160] = info  # the first VLR
    struct.pack_into("<IIB", head, 96, data_start, n_vlrs + 1, raw[104] | 0x80)
    struct.pack_into("<QI", head, 235, evlr_start, 1)
    Path(path).write_bytes(bytes(head) + laszip + bytes(chunks)
                           + _vlr("copc", 1000, page, extended=True))
    return Path(path)
