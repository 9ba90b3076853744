"""The VTU file format of a run's snapshots, written and read here without meshio.

The files have the layout meshio 5 writes by default (and which the snapshots of earlier versions
of this package were written with): an XML ``UnstructuredGrid`` whose ``DataArray`` elements are
"binary", in native byte order, zlib-compressed in blocks of 32768 bytes behind a UInt32 block
header, header and blocks base64-encoded separately. Only the comment naming the writer differs.

Importing meshio cost ~0.06-0.09 s at every start (its command-line tools import rich), and its
writer walked an element tree for every array; this module formats the text directly. The work
is split in two: :func:`vtu_layout` (checks and copies, in the caller's thread) and
:func:`encode_vtu` (compression, which releases the GIL, so it can run on another thread).
:func:`read_vtu_arrays` reads this layout back and says so when a file has another one.
"""

from __future__ import annotations

import base64
import sys
import xml.etree.ElementTree as ET
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

#: Bytes of uncompressed data per zlib block (VTK's default, and meshio's).
BLOCK_SIZE = 32768
#: VTK's cell type of the 4-node quadrilateral.
VTK_QUAD = 9
_BYTE_ORDER = "LittleEndian" if sys.byteorder == "little" else "BigEndian"
_HEADER = np.dtype(np.uint32).newbyteorder("=")
_TYPE_NAMES = {np.dtype(t).newbyteorder("="): name for t, name in (
    (np.float32, "Float32"), (np.float64, "Float64"), (np.int8, "Int8"), (np.int16, "Int16"),
    (np.int32, "Int32"), (np.int64, "Int64"), (np.uint8, "UInt8"), (np.uint16, "UInt16"),
    (np.uint32, "UInt32"), (np.uint64, "UInt64"))}
_DTYPES = {name: dtype for dtype, name in _TYPE_NAMES.items()}
_OPENING = ('<?xml version="1.0"?>\n'
            f'<VTKFile type="UnstructuredGrid" version="0.1" byte_order="{_BYTE_ORDER}" '
            'compressor="vtkZLibDataCompressor">\n'
            "<!--This file was created by ntncontact-->\n<UnstructuredGrid>\n")


class UnsupportedVtu(ValueError):
    """A VTU file that is valid XML but not of the layout :func:`read_vtu_arrays` reads."""


#: A VTU file in order: XML text, and arrays that :func:`encode_vtu` compresses and encodes.
VtuLayout = list[str | NDArray]


def vtu_layout(points: NDArray, quads: NDArray, point_data: Mapping[str, NDArray],
               cell_data: Mapping[str, NDArray]) -> VtuLayout:
    """The file of one snapshot: ``points`` (n, 3), ``quads`` (m, 4) node indices, data with one
    row per point or cell. The arrays are copied, so the caller may reuse its own."""
    quads = np.asarray(quads)
    m = len(quads)
    connectivity = quads.reshape(-1)
    layout: VtuLayout = [f'<Piece NumberOfPoints="{len(points)}" NumberOfCells="{m}">\n'
                         "<Points>\n"]
    _add_array(layout, "Points", points)
    layout.append("</Points>\n<Cells>\n")
    _add_array(layout, "connectivity", connectivity)
    _add_array(layout, "offsets", 4 * np.arange(1, m + 1, dtype=connectivity.dtype))
    _add_array(layout, "types", np.full(m, VTK_QUAD))
    layout.append("</Cells>\n")
    for tag, data in (("PointData", point_data), ("CellData", cell_data)):
        if data:
            layout.append(f"<{tag}>\n")
            for name, values in data.items():
                _add_array(layout, name, values)
            layout.append(f"</{tag}>\n")
    layout.append("</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")
    return layout


def _add_array(layout: VtuLayout, name: str, values: NDArray) -> None:
    array = np.asarray(values)
    dtype = array.dtype.newbyteorder("=")
    if dtype not in _TYPE_NAMES:
        raise ValueError(f"VTU data '{name}' has type {array.dtype}, which VTU cannot hold")
    components = f' NumberOfComponents="{array.shape[1]}"' if array.ndim == 2 else ""
    layout.append(f'<DataArray type="{_TYPE_NAMES[dtype]}" Name="{name}"{components} '
                  'format="binary">\n')
    layout.append(np.array(array, dtype=dtype, order="C"))  # a copy: written later, maybe
    layout.append("\n</DataArray>\n")


def encode_vtu(layout: VtuLayout) -> bytes:
    """The bytes of the file ``layout`` describes."""
    return _OPENING.encode() + b"".join(
        part.encode() if isinstance(part, str) else _encode_array(part) for part in layout)


def _encode_array(array: NDArray) -> bytes:
    raw = array.tobytes()
    blocks = [zlib.compress(raw[k:k + BLOCK_SIZE]) for k in range(0, len(raw), BLOCK_SIZE)]
    last = len(raw) - (len(blocks) - 1) * BLOCK_SIZE  # VTK's header: BLOCK_SIZE if no block
    header = np.array([len(blocks), BLOCK_SIZE, last] + [len(b) for b in blocks], _HEADER)
    return base64.b64encode(header.tobytes()) + base64.b64encode(b"".join(blocks))


@dataclass(frozen=True)
class VtuArrays:
    """What a VTU file holds: points (n, 3), Q4 cells (m, 4) and the data arrays by name."""

    points: NDArray[np.float64]
    quads: NDArray[np.int64]
    point_data: dict[str, NDArray] = field(default_factory=dict)
    cell_data: dict[str, NDArray] = field(default_factory=dict)


def read_vtu_arrays(text: bytes) -> VtuArrays:
    """Decode a file of the layout :func:`encode_vtu` writes (whoever wrote it).

    Raises :class:`UnsupportedVtu` for another layout (other compression, ASCII or appended
    data, cells other than quadrilaterals) and ``ET.ParseError`` for text that is not XML.
    """
    root = ET.fromstring(text)
    if (root.get("type") != "UnstructuredGrid" or root.get("byte_order") != _BYTE_ORDER
            or root.get("compressor") != "vtkZLibDataCompressor"
            or root.get("header_type", "UInt32") != "UInt32"):
        raise UnsupportedVtu("not a zlib-compressed UnstructuredGrid with UInt32 headers")
    pieces = root.findall("UnstructuredGrid/Piece")
    if len(pieces) != 1:
        raise UnsupportedVtu(f"{len(pieces)} pieces instead of one")
    piece = pieces[0]
    cells = {a.get("Name"): _decode(a) for a in piece.findall("Cells/DataArray")}
    types, offsets = cells.get("types"), cells.get("offsets")
    if types is None or offsets is None or np.any(types != VTK_QUAD) \
            or not np.array_equal(offsets, 4 * np.arange(1, len(types) + 1)):
        raise UnsupportedVtu("cells other than 4-node quadrilaterals")
    return VtuArrays(
        _decode(piece.find("Points/DataArray")),
        cells["connectivity"].reshape(-1, 4).astype(np.int64),
        {a.get("Name"): _decode(a) for a in piece.findall("PointData/DataArray")},
        {a.get("Name"): _decode(a) for a in piece.findall("CellData/DataArray")})


def _decode(element: ET.Element | None) -> NDArray:
    if element is None or element.get("format") != "binary" or element.get("type") not in _DTYPES:
        raise UnsupportedVtu("an array that is missing, not binary or of an unknown type")
    data = (element.text or "").strip().encode()
    count = int(np.frombuffer(base64.b64decode(data[:8])[:4], _HEADER)[0])
    header_chars = 4 * -(-4 * (3 + count) // 3)  # base64 characters of the header
    sizes = np.frombuffer(base64.b64decode(data[:header_chars]), _HEADER)[3:]
    raw = base64.b64decode(data[header_chars:])
    ends = np.cumsum(sizes)
    if count != len(sizes) or (count and ends[-1] != len(raw)):
        raise UnsupportedVtu("block sizes that do not match the data")
    starts = ends - sizes
    values = np.frombuffer(b"".join(zlib.decompress(raw[s:e]) for s, e in zip(starts, ends,
                                                                              strict=True)),
                           _DTYPES[element.get("type")]).copy()  # writable, as meshio's
    components = int(element.get("NumberOfComponents", "0"))
    return values.reshape(-1, components) if components else values
