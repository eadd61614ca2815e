"""OpenIGTLink on the wire: headers (protocol v2 and v3), CRC64, STATUS, CAPABILITY, POLYDATA.

The 58-byte header (all fields big-endian)::

    uint16 header_version   1 = protocol v1/v2, 2 = protocol v3
    char[12] type           TRANSFORM, POLYDATA, GET_STATUS, ...
    char[20] device_name
    uint64 timestamp        seconds (32 bits) and fraction (32 bits)
    uint64 body_size
    uint64 crc              CRC64 (ECMA-182) of the body

A v3 body (header_version 2) is an extended header (uint16 its size, uint16
metadata header size, uint32 metadata size, uint32 message id), the content,
then the metadata header (uint16 count, then per entry uint16 key size,
uint16 value encoding, uint32 value size) and the keys and values.  The CRC
covers the whole body.

POLYDATA carries points, vertices, lines, polygons, triangle strips and
attributes (per point or per cell: SCALAR, VECTOR, NORMAL, TENSOR, RGBA, as
float32).  pyigtl 0.3 packs none of its attributes and cannot unpack the
message; :class:`PolyDataMessage` here does both.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass, field

import numpy as np
import pyigtl
from pyigtl.messages import CRC64  # crcmod with its C extension: about 80 MB/s

from cutkit.errors import InputError

__all__ = ["Header", "ProtocolError", "PolyDataMessage", "decode_polydata", "polydata_attributes", "crc64",
           "parse_header", "pack_message", "split_body", "status_content", "parse_status",
           "capability_content", "parse_capability", "transform_content", "parse_transform", "HEADER_SIZE", "STATUS_OK", "STATUS_NOT_FOUND",
           "STATUS_ACCESS_DENIED", "STATUS_BUSY", "STATUS_TIME_OUT", "STATUS_OVERFLOW", "STATUS_CHECKSUM_ERROR",
           "STATUS_UNKNOWN_INSTRUCTION", "STATUS_UNKNOWN_VERSION", "STATUS_CONFIGURATION_ERROR",
           "POINT_SCALAR", "POINT_NORMAL", "POINT_RGBA"]

#: Every OpenIGTLink message starts with this many header bytes.
HEADER_SIZE = 58
#: Device names are at most this long on the wire (bytes).
MAX_NAME = 20
#: struct of the header: version, type, device name, timestamp (s, fraction), body size, CRC.
_HEADER = struct.Struct(">H12s20sIIQQ")
#: The v3 extended header: its size, metadata header size, metadata size, message id.
_EXT_HEADER = struct.Struct(">HHII")
#: Header versions this peer reads and writes (1: protocol v1/v2; 2: protocol v3).
HEADER_VERSIONS = (1, 2)
#: IANA character set numbers of metadata values (the v3 spec's encodings).
_ASCII, _UTF8 = 3, 106

#: STATUS codes (OpenIGTLink STATUS spec; the reference library's igtlStatusMessage.h).
STATUS_OK = 1
STATUS_UNKNOWN_ERROR = 2
STATUS_NOT_FOUND = 4
STATUS_ACCESS_DENIED = 5
STATUS_BUSY = 6
STATUS_TIME_OUT = 7
STATUS_OVERFLOW = 8
STATUS_CHECKSUM_ERROR = 9
STATUS_CONFIGURATION_ERROR = 10
STATUS_UNKNOWN_INSTRUCTION = 12
STATUS_UNKNOWN_VERSION = 17
#: STATUS body before its string: code uint16, subcode int64, error name char[20].
_STATUS = struct.Struct(">Hq20s")
#: CAPABILITY lists type names of this many bytes each.
TYPE_NAME_SIZE = 12

#: POLYDATA attribute types (low nibble: kind; 0x10: per cell instead of per point).
POINT_SCALAR, POINT_VECTOR, POINT_NORMAL, POINT_TENSOR, POINT_RGBA = 0x00, 0x01, 0x02, 0x03, 0x04
#: Components of each attribute kind (SCALAR: its own count, 1 to 16).
_KIND_COMPONENTS = {POINT_VECTOR: 3, POINT_NORMAL: 3, POINT_TENSOR: 9, POINT_RGBA: 4}
#: POLYDATA's fixed header: npoints, then count and byte size of vertices, lines, polygons, strips, nattributes.
_POLY_HEAD = struct.Struct(">10I")
#: A TRANSFORM body: the rotation's columns, then the translation, big-endian float32.
_TRANSFORM = struct.Struct(">12f")
#: One attribute header: type uint8, components uint8, count uint32.
_ATTR_HEAD = struct.Struct(">BBI")


class ProtocolError(Exception):
    """A message that breaks the OpenIGTLink spec (its text says how)."""


def crc64(data: bytes) -> int:
    """CRC64 (ECMA-182 polynomial, no reflection, zero start) of ``data``, as OpenIGTLink uses it."""
    return CRC64(data)


@dataclass
class Header:
    """The fields of one 58-byte OpenIGTLink header."""

    version: int
    type: str
    device_name: str
    timestamp: float
    body_size: int
    crc: int


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace").rstrip(" \t\r\n")


def parse_header(data: bytes) -> Header:
    """The fields of a 58-byte header (version not checked here).

    Parameters
    ----------
    data : bytes
        Exactly :data:`HEADER_SIZE` bytes.

    Returns
    -------
    Header
    """
    version, kind, name, sec, frac, size, crc = _HEADER.unpack(data)
    return Header(version, _text(kind), _text(name), sec + frac / 2.0 ** 32, size, crc)


def _timestamp(t: float) -> tuple[int, int]:
    sec = int(t)
    return sec & 0xFFFFFFFF, min(int((t - sec) * 2.0 ** 32), 0xFFFFFFFF)


def pack_message(kind: str, device_name: str, content: bytes, version: int = 1, timestamp: float | None = None,
                 message_id: int = 0, metadata: dict | None = None) -> bytes:
    """A whole message: header (with the body's CRC64) and body.

    Parameters
    ----------
    kind : str
        Message type, at most 12 bytes.
    device_name : str
        At most 20 bytes.
    content : bytes
        The type's content.
    version : 1 or 2
        Header version: 2 wraps the content in a v3 extended header and metadata.
    timestamp : float, optional
        Seconds since 1970; default now.
    message_id : int
        v3 message id (a reply repeats its request's).
    metadata : dict of str, optional
        v3 metadata (ignored with version 1).

    Returns
    -------
    bytes
    """
    body = content if version == 1 else _v3_body(content, message_id, metadata or {})
    sec, frac = _timestamp(time.time() if timestamp is None else timestamp)
    head = _HEADER.pack(version, kind.encode("ascii"), device_name.encode("utf-8"), sec, frac, len(body),
                        crc64(body))
    return head + body


def _v3_body(content: bytes, message_id: int, metadata: dict) -> bytes:
    index, values = [], []
    for key, value in metadata.items():
        k, v = str(key).encode("utf-8"), str(value).encode("utf-8")
        index.append(struct.pack(">HHI", len(k), _UTF8, len(v)))
        values += [k, v]
    meta_head = struct.pack(">H", len(index)) + b"".join(index) if index else b""
    meta = b"".join(values)
    ext = _EXT_HEADER.pack(_EXT_HEADER.size, len(meta_head), len(meta), message_id & 0xFFFFFFFF)
    return ext + content + meta_head + meta


def split_body(version: int, body: bytes) -> tuple[bytes, int, dict]:
    """The content, message id and metadata of a body.

    Parameters
    ----------
    version : int
        The header's version (1: the body is all content).
    body : bytes

    Returns
    -------
    content : bytes
    message_id : int
    metadata : dict of str

    Raises
    ------
    ProtocolError
        An extended header or metadata that does not fit the body.
    """
    if version == 1:
        return body, 0, {}
    if len(body) < _EXT_HEADER.size:
        raise ProtocolError(f"a v3 body of {len(body)} bytes has no room for its extended header")
    ext, meta_head, meta, message_id = _EXT_HEADER.unpack_from(body, 0)
    if ext < _EXT_HEADER.size or ext + meta_head + meta > len(body):
        raise ProtocolError(f"v3 extended header ({ext}, {meta_head}, {meta}) does not fit a {len(body)}-byte body")
    end = len(body) - meta_head - meta
    return body[ext:end], message_id, _metadata(body[end:end + meta_head], body[end + meta_head:])


def _metadata(head: bytes, values: bytes) -> dict:
    if not head:
        return {}
    (count,) = struct.unpack_from(">H", head, 0)
    if len(head) != 2 + 8 * count:
        raise ProtocolError(f"v3 metadata header of {len(head)} bytes does not hold {count} entries")
    out, off = {}, 0
    for i in range(count):
        klen, encoding, vlen = struct.unpack_from(">HHI", head, 2 + 8 * i)
        if off + klen + vlen > len(values):
            raise ProtocolError("v3 metadata entry runs past the body")
        key = values[off:off + klen].decode("utf-8", "replace")
        raw = values[off + klen:off + klen + vlen]
        out[key] = raw.decode("ascii" if encoding == _ASCII else "utf-8", "replace")
        off += klen + vlen
    return out


# ---------------------------------------------------------------------------- STATUS, CAPABILITY
def status_content(code: int, message: str = "", error_name: str = "", subcode: int = 0) -> bytes:
    """A STATUS body: code uint16, subcode int64, error_name char[20], status string with its null."""
    name = error_name.encode("ascii", "replace")[:20]
    return _STATUS.pack(code, subcode, name) + message.encode("utf-8", "replace") + b"\0"


def parse_status(content: bytes) -> tuple[int, int, str, str]:
    """Code, subcode, error name and status string of a STATUS body.

    Raises
    ------
    ProtocolError
        A body shorter than the fixed part.
    """
    if len(content) < _STATUS.size:
        raise ProtocolError(f"a STATUS body of {len(content)} bytes is shorter than {_STATUS.size}")
    code, subcode, name = _STATUS.unpack_from(content, 0)
    return code, subcode, _text(name), _text(content[_STATUS.size:])


def capability_content(types) -> bytes:
    """A CAPABILITY body: each type name in 12 bytes, null-padded."""
    return b"".join(struct.pack("12s", t.encode("ascii")) for t in types)


def parse_capability(content: bytes) -> list[str]:
    """The type names of a CAPABILITY body.

    Raises
    ------
    ProtocolError
        A body that is not a whole number of 12-byte names.
    """
    if len(content) % TYPE_NAME_SIZE:
        raise ProtocolError(f"a CAPABILITY body of {len(content)} bytes is not a list of 12-byte names")
    return [_text(content[i:i + TYPE_NAME_SIZE]) for i in range(0, len(content), TYPE_NAME_SIZE)]


# ---------------------------------------------------------------------------- POLYDATA
def transform_content(matrix) -> bytes:
    """The 48-byte TRANSFORM body of a (4, 4) homogeneous ``matrix`` (its top three rows):
    R11 R21 R31 R12 R22 R32 R13 R23 R33 TX TY TZ, big-endian float32 (the protocol's layout)."""
    m = np.asarray(matrix, np.float64)
    return _TRANSFORM.pack(*m[:3, :3].T.ravel(), *m[:3, 3])


def parse_transform(content: bytes) -> np.ndarray:
    """(4, 4) float64 homogeneous matrix of a 48-byte TRANSFORM body (:func:`transform_content`)."""
    v = np.asarray(_TRANSFORM.unpack(content), np.float64)
    m = np.eye(4)
    m[:3, :3] = v[:9].reshape(3, 3).T
    m[:3, 3] = v[9:]
    return m


@dataclass
class PolyDataAttribute:
    """One POLYDATA attribute.

    Attributes
    ----------
    name : str
    type : int
        :data:`POINT_SCALAR`, :data:`POINT_NORMAL`, :data:`POINT_RGBA`, ... (``| 0x10``: per cell).
    data : (n, components) float32
    """

    name: str
    type: int
    data: np.ndarray = field(repr=False)


class PolyDataMessage(pyigtl.PolyDataMessage):
    """pyigtl's POLYDATA message with attributes and a working decoder.

    ``attributes`` is a list of :class:`PolyDataAttribute` (or None).  Register
    the class with ``pyigtl.messages.message_type_to_class_constructor["POLYDATA"]
    = PolyDataMessage`` for a pyigtl client to receive POLYDATA.
    """

    def _pack_content(self):  # pyigtl's hook (its pack())
        return self.content()

    def content(self) -> bytes:
        """The POLYDATA body: the points, the four cell lists and the attributes."""
        parts = [np.asarray(x if x is not None else (), np.int64).ravel()
                 for x in (self.vertices, self.lines, self.polygons, self.triangle_strips)]
        pts = np.zeros((0, 3)) if self.points is None else np.asarray(self.points).reshape(-1, 3)
        attrs = list(self.attributes or ())
        head = [pts.shape[0]]
        for cells in parts:
            head += [_count_cells(cells), 4 * cells.size]
        head.append(len(attrs))
        out = [_POLY_HEAD.pack(*head), np.ascontiguousarray(pts, ">f4").tobytes()]
        out += [np.ascontiguousarray(c, ">u4").tobytes() for c in parts]
        return b"".join(out) + _pack_attributes(attrs)

    def _unpack_content(self, content):
        try:
            self._unpack_checked(content)
        except (struct.error, ValueError) as err:
            raise ProtocolError(f"POLYDATA body does not hold what its header says ({err})") from None

    def _unpack_checked(self, content):
        v = _POLY_HEAD.unpack_from(content, 0)
        npts, sizes, nattr = v[0], (v[2], v[4], v[6], v[8]), v[9]
        off = _POLY_HEAD.size
        self.points = np.frombuffer(content, ">f4", npts * 3, off).reshape(npts, 3).astype(np.float64)
        off += npts * 12
        arrays = []
        for size in sizes:
            arrays.append(np.frombuffer(content, ">u4", size // 4, off).astype(np.int64))
            off += size
        self.vertices, self.lines, self.polygons, self.triangle_strips = arrays
        self.attributes = _unpack_attributes(content, off, nattr)


def _components(kind: int, ncomp: int) -> int:
    return _KIND_COMPONENTS.get(kind & 0x0F, ncomp)


def _pack_attributes(attrs) -> bytes:
    if not attrs:
        return b""
    heads, names, data = [], [], []
    for att in attrs:
        d = np.asarray(att.data, np.float32)
        d = d[:, None] if d.ndim == 1 else d
        if (att.type & 0x0F) > POINT_RGBA or d.shape[1] != _components(att.type, d.shape[1]):
            raise InputError(f"POLYDATA attribute {att.name!r}: type {att.type:#x} with {d.shape[1]} components")
        heads.append(_ATTR_HEAD.pack(att.type, d.shape[1], d.shape[0]))
        names.append(att.name.encode("ascii") + b"\0")
        data.append(np.ascontiguousarray(d, ">f4").tobytes())
    names_bytes = b"".join(names)
    if len(names_bytes) % 2:  # the names are padded to an even length
        names_bytes += b"\0"
    return b"".join(heads) + names_bytes + b"".join(data)


def _unpack_attributes(content: bytes, off: int, nattr: int) -> list:
    heads = []
    for _ in range(nattr):
        heads.append(_ATTR_HEAD.unpack_from(content, off))
        off += _ATTR_HEAD.size
    names, start = [], off
    for _ in range(nattr):
        end = content.index(b"\0", off)
        names.append(content[off:end].decode("ascii", "replace"))
        off = end + 1
    if (off - start) % 2:
        off += 1
    out = []
    for (kind, ncomp, n), name in zip(heads, names):
        comps = _components(kind, ncomp)
        values = np.frombuffer(content, ">f4", n * comps, off).astype(np.float32).reshape(n, comps)
        off += n * comps * 4
        out.append(PolyDataAttribute(name, kind, values))
    if off != len(content):
        raise ValueError(f"{len(content) - off} bytes left after the attributes")
    return out


def _count_cells(cells: np.ndarray) -> int:
    """Number of cells in a VTK cell array (n, i0 .. in-1, n, ...)."""
    if cells.size == 0:
        return 0
    if cells.size % 4 == 0 and np.all(cells[::4] == 3):  # all triangles: no walk needed
        return cells.size // 4
    count, i = 0, 0
    while i < cells.size:
        count += 1
        i += int(cells[i]) + 1
    return count


def decode_polydata(message) -> tuple[np.ndarray, np.ndarray]:
    """Points and triangles of a POLYDATA message whose polygons are all triangles.

    Returns
    -------
    points : (m, 3) float64
    triangles : (k, 3) int64

    Raises
    ------
    InputError
        A polygon that is not a triangle.
    """
    cells = np.asarray(message.polygons, np.int64)
    if cells.size % 4 or (cells.size and np.any(cells[::4] != 3)):
        raise InputError("POLYDATA polygons are not all triangles")
    return np.asarray(message.points, np.float64).reshape(-1, 3), cells.reshape(-1, 4)[:, 1:].copy()


def polydata_attributes(message) -> dict:
    """A decoded POLYDATA message's attributes by name.

    Returns
    -------
    dict of str to PolyDataAttribute
        Empty where the message has none.
    """
    return {a.name: a for a in (message.attributes or ())}
