"""Cloud Optimized Point Cloud (COPC 1.0, https://copc.io) files written for the tests, since
no COPC writer is installed (laspy reads COPC but cannot write it; there is no PDAL): a LAS 1.4
file of point format 6, LAZ-compressed in variable-size chunks, one chunk per octree node, with
the COPC info VLR first and the hierarchy in an EVLR. Checked by laspy's own COPC reader
(``laspy.CopcReader``: whole, and by spatial query) and by laspy reading it as plain LAZ."""
import io
import struct
from pathlib import Path

import numpy as np

VLR_HEADER, EVLR_HEADER = 54, 60  # bytes of a VLR's and an EVLR's header (LAS 1.4)


def _octree(xyz, centre, half, max_node_points):
    """{(level, i, j, k): point indices} of the nodes holding points: a node splits into its
    eight children while it holds more than ``max_node_points``; points sit in the leaves."""
    nodes, stack = {}, [((0, 0, 0, 0), np.arange(len(xyz)))]
    while stack:
        key, index = stack.pop()
        if len(index) <= max_node_points:
            nodes[key] = index
            continue
        level, i, j, k = key
        side = 2 * half / 2 ** (level + 1)
        cell = np.floor((xyz[index] - (centre - half)) / side).astype(np.int64)
        cell = np.clip(cell, [2 * i, 2 * j, 2 * k], [2 * i + 1, 2 * j + 1, 2 * k + 1])
        nodes[key] = index[:0]  # an entry with no points, for the readers to walk down
        for child in {tuple(c) for c in cell}:
            stack.append(((level + 1, *child), index[(cell == child).all(axis=1)]))
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
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    centre, half = (lo + hi) / 2, float((hi - lo).max()) / 2 + 1.0
    nodes = _octree(xyz, centre, half, max_node_points)
    order = np.concatenate([index for index in nodes.values()])
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets, header.scales = np.floor(lo), np.array([0.001, 0.001, 0.001])
    header.vlrs.append(laspy.VLR("copc", 1, "COPC info", bytes(160)))  # filled below
    header.add_crs(CRS.from_wkt(crs_wkt))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[order, 0], xyz[order, 1], xyz[order, 2]
    las.classification = (np.full(len(xyz), 2, np.uint8) if classes is None
                          else np.asarray(classes, np.uint8)[order])
    plain = io.BytesIO()
    las.write(plain)
    raw = plain.getvalue()
    header_size, point_offset, n_vlrs = struct.unpack_from("<HII", raw, 94)
    record = struct.unpack_from("<H", raw, 105)[0]
    records = raw[point_offset:point_offset + len(xyz) * record]
    # the points compressed node by node: one variable-size LAZ chunk each
    laz_vlr = lazrs.LazVlr.new_for_compression(6, 0, use_variable_size_chunks=True)
    laszip = _vlr("laszip encoded", 22204, laz_vlr.record_data())
    data_start = point_offset + len(laszip)
    compressed = io.BytesIO()
    compressor = lazrs.LasZipCompressor(compressed, laz_vlr)
    filled = [key for key, index in nodes.items() if len(index)]
    start = 0
    for i, key in enumerate(filled):
        if i:
            compressor.finish_current_chunk()
        n = len(nodes[key])
        compressor.compress_many(records[start * record:(start + n) * record])
        start += n
    compressor.done()
    compressed.seek(0)
    table = lazrs.read_chunk_table(compressed, laz_vlr)
    chunks = bytearray(compressed.getvalue())  # its chunk table's offset is the file's
    struct.pack_into("<q", chunks, 0, data_start + struct.unpack_from("<q", chunks)[0])
    # the hierarchy: every node's entry, its chunk's offset and size in the file
    offset, places = data_start + 8, {}
    assert [count for count, _ in table] == [len(nodes[key]) for key in filled]
    for key, (count, size) in zip(filled, table):
        places[key] = (offset, size, count)
        offset += size
    page = b"".join(struct.pack("<iiiiQii", *key, *places.get(key, (0, 0, 0)))
                    for key in nodes)
    evlr_start = data_start + len(chunks)
    info = struct.pack("<3dddQQdd", *centre, half, 2 * half / 128, evlr_start + EVLR_HEADER,
                       len(page), 0.0, 0.0) + bytes(88)
    head = bytearray(raw[:point_offset])
    head[header_size + VLR_HEADER:header_size + VLR_HEADER + 160] = info  # the first VLR
    struct.pack_into("<IIB", head, 96, data_start, n_vlrs + 1, raw[104] | 0x80)
    struct.pack_into("<QI", head, 235, evlr_start, 1)
    Path(path).write_bytes(bytes(head) + laszip + bytes(chunks)
                           + _vlr("copc", 1000, page, extended=True))
    return Path(path)
