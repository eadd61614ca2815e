"""The OpenIGTLink endpoint against a client written here from the protocol spec.

The client (:class:`SpecClient`) uses raw sockets and its own header, CRC64,
STATUS, CAPABILITY and POLYDATA code, none of cutkit's or pyigtl's: it
checks the CRC of every message it receives.  Waits are bounded on
conditions (a message arriving, a counter moving), never on the clock.
"""

import logging
import socket
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyigtl")

from click.testing import CliRunner  # noqa: E402

from cutkit.cli.main import cli  # noqa: E402
from cutkit.cutting.trajectory import read_trajectory  # noqa: E402
from cutkit.errors import InputError  # noqa: E402
from cutkit.live import LiveFrame  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
INCISION = ROOT / "sample_volumes" / "incision.csv"
#: Longest wait for a condition (s): generous for a loaded machine; the tests never wait it out when they pass.
WAIT_S = 30.0
TOOL = "ScalpelToReference"
FLIP = np.array([-1.0, -1.0, 1.0])  # LPS <-> RAS on points


# ---------------------------------------------------------------------------- the spec client
#: CRC-64/ECMA-182: the polynomial of the OpenIGTLink header's CRC field (MSB first, start 0, no final xor).
CRC_POLY = 0x42F0E1EBA9EA3693
MASK64 = (1 << 64) - 1


def _crc_table():
    table = []
    for i in range(256):
        c = i << 56
        for _ in range(8):
            c = ((c << 1) ^ CRC_POLY) if c & (1 << 63) else (c << 1)
        table.append(c & MASK64)
    return table


CRC_TABLE = _crc_table()


def crc64(data: bytes) -> int:
    c = 0
    for b in data:
        c = CRC_TABLE[((c >> 56) ^ b) & 0xFF] ^ ((c << 8) & MASK64)
    return c


@dataclass
class Msg:
    version: int
    kind: str
    name: str
    content: bytes
    message_id: int = 0
    metadata: dict = None


def _cstr(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode()


class SpecClient:
    """An OpenIGTLink client from the spec: 58-byte header, CRC64 of the body, v3 extended header and metadata."""

    def __init__(self, port, version=1):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=WAIT_S)
        self.version = version
        self.buf = b""
        self.crc_checked = 0
        self.seen = []

    def send(self, kind, name, content=b"", version=None, crc=None, message_id=0, metadata=None, body=None):
        v = self.version if version is None else version
        if body is None:
            body = content
            if v == 2:
                meta = metadata or {}
                index = b"".join(struct.pack(">HHI", len(k), 3, len(x)) for k, x in meta.items())
                mhead = struct.pack(">H", len(meta)) + index if meta else b""
                values = b"".join(k.encode() + x.encode() for k, x in meta.items())
                body = struct.pack(">HHII", 12, len(mhead), len(values), message_id) + content + mhead + values
        head = struct.pack(">H12s20sIIQQ", v, kind.encode(), name.encode(), int(time.time()), 0, len(body),
                           crc64(body) if crc is None else crc)
        self.sock.sendall(head + body)

    def _read(self, n):
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                return None
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def recv(self):
        """The next message (its CRC checked), or None at the end of the stream."""
        head = self._read(58)
        if head is None:
            return None
        v, kind, name, _, _, size, crc = struct.unpack(">H12s20sIIQQ", head)
        body = self._read(size)
        assert body is not None, "the stream ended inside a message"
        assert crc64(body) == crc, f"bad CRC on a {_cstr(kind)} message"
        self.crc_checked += 1
        msg = Msg(v, _cstr(kind), _cstr(name), body, 0, {})
        if v == 2:
            ext, mh, ms, msg.message_id = struct.unpack_from(">HHII", body)
            msg.content = body[ext:len(body) - mh - ms]
        self.seen.append(msg)
        return msg

    def until(self, pred):
        """Read until a message satisfies ``pred``; return it."""
        while True:
            msg = self.recv()
            assert msg is not None, "the stream ended first"
            if pred(msg):
                return msg

    def eof(self):
        """Read to the end of the stream; return what came."""
        out = []
        while (msg := self.recv()) is not None:
            out.append(msg)
        return out

    def close(self):
        self.sock.close()


def transform_content(m) -> bytes:
    m = np.asarray(m, np.float64)
    return struct.pack(">12f", *m[:3, :3].T.ravel(), *m[:3, 3])


def parse_transform(content) -> np.ndarray:
    v = struct.unpack(">12f", content)
    m = np.eye(4)
    m[:3, :3] = np.reshape(v[:9], (3, 3)).T
    m[:3, 3] = v[9:]
    return m


def parse_status(content):
    code, sub, name = struct.unpack_from(">Hq20s", content)
    return code, sub, _cstr(name), _cstr(content[30:])


def parse_polydata(content):
    """Points, triangles and attributes of a POLYDATA body, from the spec."""
    h = struct.unpack_from(">10I", content)
    off = 40
    pts = np.frombuffer(content, ">f4", h[0] * 3, off).reshape(-1, 3)
    off += h[0] * 12
    cells = []
    for size in (h[2], h[4], h[6], h[8]):
        cells.append(np.frombuffer(content, ">u4", size // 4, off))
        off += size
    heads = [struct.unpack_from(">BBI", content, off + 6 * i) for i in range(h[9])]
    off += 6 * h[9]
    start, names = off, []
    for _ in heads:
        end = content.index(b"\0", off)
        names.append(content[off:end].decode())
        off = end + 1
    off += (off - start) % 2
    attrs = {}
    for (kind, ncomp, n), name in zip(heads, names):
        comps = {1: 3, 2: 3, 3: 9, 4: 4}.get(kind & 0x0F, ncomp)
        attrs[name] = (kind, np.frombuffer(content, ">f4", n * comps, off).reshape(n, comps))
        off += n * comps * 4
    assert off == len(content)
    polys = cells[2].reshape(-1, 4)
    assert np.all(polys[:, 0] == 3)
    return pts.astype(np.float64), polys[:, 1:].astype(np.int64), attrs


def tool_matrix_ras(tip, a, n):
    """The tool matrix in RAS whose -z column is the blade and x column the edge (an LPS pose in)."""
    m = np.eye(4)
    m[:3, 0], m[:3, 2] = n * FLIP, -a * FLIP
    m[:3, 1] = np.cross(m[:3, 2], m[:3, 0])
    m[:3, 3] = tip * FLIP
    return m


def wait_for(cond):
    t_end = time.monotonic() + WAIT_S
    while time.monotonic() < t_end:
        value = cond()
        if value:
            return value
        time.sleep(0.005)
    return cond()


def box_frame(lo, hi):
    """A closed box surface (outward triangles) around [lo, hi]."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    pts = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                    [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float64)
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                      [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [3, 0, 4], [3, 4, 7]], np.int64)
    return pts, faces


# ---------------------------------------------------------------------------- fixtures
@pytest.fixture
def endpoint():
    from cutkit.live.igtl import IGTLEndpoint

    ep = IGTLEndpoint(0, body_timeout_s=0.5)
    yield ep
    ep.close()


@pytest.fixture
def client_factory(endpoint):
    made = []

    def make(version=1, expect_ok=True):
        c = SpecClient(endpoint.port, version)
        made.append(c)
        if expect_ok:
            first = c.recv()
            assert first.kind == "STATUS" and parse_status(first.content)[0] == 1, "no STATUS OK on connect"
        return c

    yield make
    for c in made:
        c.close()


def test_the_spec_client_crc_is_crc64_ecma182():
    assert crc64(b"123456789") == 0x6C40DF5F0B497347  # the catalogued check value


# ---------------------------------------------------------------------------- a whole incision
def test_transforms_along_an_incision_surfaces_and_every_query(endpoint, client_factory):
    from cutkit.live.igtl import CUT_RGBA, IGTLPolyDataView, IGTLPoseSource, pose_from_matrix

    source = IGTLPoseSource(endpoint=endpoint)
    view = IGTLPolyDataView(endpoint=endpoint, max_rate_hz=1000.0)
    view.min_period = 0.0  # every frame is sent, however close together
    c = client_factory()
    traj = read_trajectory(INCISION)
    box, box_faces = box_frame(traj.tip.min(axis=0) - 10.0, traj.tip.max(axis=0) + 10.0)
    rgb = np.random.default_rng(1).integers(0, 256, (8, 3)).astype(np.uint8)
    edge, cut, tips = [], [], []
    rows = list(range(0, len(traj), 10))
    for i in rows:
        c.send("TRANSFORM", TOOL, transform_content(tool_matrix_ras(traj.tip[i], traj.a[i], traj.n[i])))
        pose = wait_for(source.poll)
        assert pose is not None, f"row {i} gave no pose"
        np.testing.assert_allclose(pose.tip, traj.tip[i], atol=1e-4)
        tips.append(pose.tip)
        edge += [pose.tip, pose.tip - 4.0 * pose.a]
        k = len(edge)
        if k >= 4:
            cut += [[k - 4, k - 3, k - 1], [k - 4, k - 1, k - 2]]
        points = np.vstack([box, edge])
        frame = LiveFrame(points=points, boundary_faces=box_faces, cut_faces=np.array(cut, np.int64).reshape(-1, 3) + 8,
                          rgb=np.vstack([rgb, np.zeros((len(edge), 3), np.uint8)]), tip=pose.tip, a=pose.a, n=pose.n)
        view.show(frame)
    view.min_period = 3600.0  # nothing more is broadcast: what comes next is a reply
    got = {}

    def last_frame_arrived(m):
        got[m.name] = m
        return ("CutkitBlade" in got and np.allclose(pose_from_matrix(parse_transform(got["CutkitBlade"].content))[0],
                                                     tips[-1], atol=1e-4)
                and "CutkitCutSurface" in got and len(parse_polydata(got["CutkitCutSurface"].content)[1]) == len(cut)
                and "CutkitTissue" in got)

    c.until(last_frame_arrived)
    # the tissue: the box in RAS, outward unit normals, the frame's colours
    pts, tris, attrs = parse_polydata(got["CutkitTissue"].content)
    np.testing.assert_allclose(pts, box * FLIP, atol=1e-4)
    np.testing.assert_array_equal(np.sort(tris, axis=1), np.sort(box_faces, axis=1))
    kind, normals = attrs["Normals"]
    assert kind == 0x02 and normals.shape == (8, 3)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    assert np.all(np.einsum("ij,ij->i", normals, pts - pts.mean(axis=0)) > 0), "tissue normals point inwards"
    kind, colours = attrs["Colors"]
    assert kind == 0x04 and colours.shape == (8, 4)
    np.testing.assert_allclose(colours[:, :3], rgb / 255.0, atol=1e-6)
    # the cut surface: through every tip, in the cut colour
    pts, tris, attrs = parse_polydata(got["CutkitCutSurface"].content)
    d = np.linalg.norm((pts * FLIP)[:, None, :] - np.array(tips)[None], axis=2).min(axis=0)
    assert d.max() < 1e-4
    np.testing.assert_allclose(attrs["Colors"][1], np.tile(CUT_RGBA, (len(pts), 1)), atol=1e-6)
    length = np.linalg.norm(attrs["Normals"][1], axis=1)
    # unit, or zero where a point is only in triangles of no area (the blade pressing in along its axis)
    assert np.all((np.abs(length - 1.0) < 1e-5) | (length == 0.0)) and np.mean(length > 0) > 0.5
    _every_query(c, traj, tips, rows[-1])
    assert c.crc_checked == len(c.seen) > len(rows)  # every message's CRC, the first STATUS's included
    source.close()
    view.close()


def _every_query(c, traj, tips, last_row):
    from cutkit.live.igtl import pose_from_matrix

    c.send("GET_CAPABIL", "")
    msg = c.until(lambda m: m.kind == "CAPABILITY")
    types = [_cstr(msg.content[i:i + 12]) for i in range(0, len(msg.content), 12)]
    assert len(msg.content) % 12 == 0
    assert {"TRANSFORM", "POLYDATA", "STATUS", "GET_TRANS", "GET_POLYDATA", "GET_STATUS",
            "GET_CAPABIL"} <= set(types)
    c.send("GET_STATUS", "")
    code, _, _, text = parse_status(c.until(lambda m: True).content)
    assert code == 1 and TOOL in text
    c.send("GET_TRANS", "")  # GET_TRANSFORM's type field (12 bytes at most)
    msg = c.until(lambda m: True)
    assert (msg.kind, msg.name) == ("TRANSFORM", "CutkitBlade")
    np.testing.assert_allclose(pose_from_matrix(parse_transform(msg.content))[0], tips[-1], atol=1e-4)
    c.send("GET_TRANSFOR", TOOL)  # the tool's newest pose, as it came; the name cut at 12 bytes works too
    msg = c.until(lambda m: True)
    last = tool_matrix_ras(traj.tip[last_row], traj.a[last_row], traj.n[last_row])
    assert msg.kind == "TRANSFORM" and msg.name == TOOL
    np.testing.assert_allclose(parse_transform(msg.content), last, atol=1e-4)
    c.send("GET_TRANS", "NoSuchTool")
    msg = c.until(lambda m: True)
    assert msg.kind == "STATUS" and parse_status(msg.content)[0] == 4  # not found
    c.send("GET_POLYDATA", "")
    names = {c.until(lambda m: True).name for _ in range(2)}
    assert names == {"CutkitTissue", "CutkitCutSurface"}
    c.send("GET_POLYDATA", "CutkitCutSurface")
    msg = c.until(lambda m: True)
    assert (msg.kind, msg.name) == ("POLYDATA", "CutkitCutSurface")
    c.send("GET_POLYDATA", "Liver")
    assert parse_status(c.until(lambda m: True).content)[0] == 4


# ---------------------------------------------------------------------------- protocol v3
def test_a_v3_client_is_read_and_answered_in_v3(endpoint, client_factory):
    c = client_factory(version=2)
    m = np.eye(4)
    m[:3, 3] = (1.0, 2.0, 3.0)
    c.send("TRANSFORM", TOOL, transform_content(m), message_id=5, metadata={"Status": "OK", "Tool": "scalpel"})
    msg = wait_for(lambda: endpoint.take(TOOL))
    np.testing.assert_allclose(msg.matrix[:3, 3], (1.0, 2.0, 3.0))
    assert msg.metadata == {"Status": "OK", "Tool": "scalpel"} and msg.header_version == 2
    c.send("GET_STATUS", "", message_id=77)
    reply = c.until(lambda x: True)
    assert (reply.version, reply.kind, reply.message_id) == (2, "STATUS", 77)
    assert parse_status(reply.content)[0] == 1
    c.send("GET_CAPABIL", "", message_id=78)
    reply = c.until(lambda x: True)
    assert (reply.version, reply.kind, reply.message_id) == (2, "CAPABILITY", 78)
    # an extended header that does not fit its body: dropped, answered, the stream goes on
    c.send("TRANSFORM", TOOL, body=struct.pack(">HHII", 12, 0, 999, 1) + transform_content(m))
    reply = c.until(lambda x: True)
    assert reply.kind == "STATUS" and parse_status(reply.content)[0] == 2
    c.send("TRANSFORM", TOOL, transform_content(m), version=1)  # a v1 message on the same stream is read too
    assert wait_for(lambda: endpoint.take(TOOL)) is not None


# ---------------------------------------------------------------------------- what goes wrong
def test_a_bad_crc_is_dropped_logged_once_and_answered(endpoint, client_factory, caplog):
    c = client_factory()
    m = transform_content(np.eye(4))
    with caplog.at_level(logging.INFO, logger="cutkit.live"):
        c.send("TRANSFORM", TOOL, m, crc=crc64(m) ^ 1)
        c.send("TRANSFORM", TOOL, m, crc=12345)
        for _ in range(2):
            reply = c.until(lambda x: True)
            code, _, name, _ = parse_status(reply.content)
            assert (reply.kind, reply.name, code, name) == ("STATUS", TOOL, 9, "CRC")
        c.send("TRANSFORM", TOOL, m)
        assert wait_for(lambda: endpoint.take(TOOL)) is not None, "a good message after bad ones was lost"
    assert endpoint.dropped[("crc", "TRANSFORM")] == 2 and endpoint.received[TOOL] == 1
    lines = [r.getMessage() for r in caplog.records if "CRC" in r.getMessage()]
    assert len(lines) == 1 and "\n" not in lines[0] and "TRANSFORM" in lines[0]


def test_an_oversize_body_closes_only_its_connection(endpoint, client_factory, caplog):
    from cutkit.live.igtl_server import MAX_BODY

    good = client_factory()
    bad = client_factory()
    with caplog.at_level(logging.WARNING, logger="cutkit.live"):
        header = struct.pack(">H12s20sIIQQ", 1, b"TRANSFORM", TOOL.encode(), 0, 0, 100 << 20, 0)
        bad.sock.sendall(header + bytes(1000))
        rest = bad.eof()
    assert [m.kind for m in rest] == ["STATUS"]
    code, sub, name, text = parse_status(rest[0].content)
    assert (code, sub, name) == (8, 100 << 20, "TooLarge") and str(MAX_BODY) in text
    assert endpoint.dropped[("oversize", "TRANSFORM")] == 1
    assert sum("over the limit" in r.getMessage() for r in caplog.records) == 1
    good.send("TRANSFORM", TOOL, transform_content(np.eye(4)))
    assert wait_for(lambda: endpoint.take(TOOL)) is not None, "the other client is no longer served"
    again = client_factory()  # and new clients are taken
    again.send("GET_STATUS", "")
    assert parse_status(again.until(lambda m: True).content)[0] == 1


def test_a_stuck_body_times_out_and_the_others_are_served(endpoint, client_factory, caplog):
    good = client_factory()
    stuck = client_factory()
    body = transform_content(np.eye(4))
    header = struct.pack(">H12s20sIIQQ", 1, b"TRANSFORM", TOOL.encode(), 0, 0, len(body), crc64(body))
    with caplog.at_level(logging.WARNING, logger="cutkit.live"):
        stuck.sock.sendall(header + body[:10])  # and nothing more
        good.send("TRANSFORM", "Other", body)
        assert wait_for(lambda: endpoint.take("Other")) is not None
        rest = stuck.eof()
    assert [m.kind for m in rest] == ["STATUS"] and parse_status(rest[0].content)[:3:2] == (7, "Timeout")
    assert sum("stalled" in r.getMessage() for r in caplog.records) == 1
    assert endpoint.dropped[("timeout", "stream")] == 1
    good.send("TRANSFORM", TOOL, body)
    assert wait_for(lambda: endpoint.take(TOOL)) is not None


def test_unknown_types_are_skipped_logged_once_and_counted(endpoint, client_factory, caplog):
    c = client_factory()
    m = np.eye(4)
    m[0, 3] = 7.0
    with caplog.at_level(logging.INFO, logger="cutkit.live"):
        for _ in range(3):
            c.send("FOOBAR", "Thing", bytes(range(100)))
        c.send("TRANSFORM", TOOL, transform_content(m))  # right behind them: the stream stays in step
        msg = wait_for(lambda: endpoint.take(TOOL))
        c.send("GET_IMAGE", "CT")  # a query cutkit cannot answer gets a STATUS
        reply = c.until(lambda x: True)
    assert msg is not None and msg.matrix[0, 3] == 7.0
    assert endpoint.dropped[("unused", "FOOBAR")] == 3 and endpoint.dropped[("unused", "GET_IMAGE")] == 1
    assert reply.kind == "STATUS" and parse_status(reply.content)[0] == 12
    lines = [r.getMessage() for r in caplog.records if "FOOBAR" in r.getMessage()]
    assert len(lines) == 1 and "\n" not in lines[0]
    assert endpoint.errors == 0  # unused types are not errors


# ---------------------------------------------------------------------------- several clients
def _sync(c):
    """Wait until the endpoint has handled everything ``c`` sent (its messages are handled in order)."""
    c.send("GET_STATUS", "Sync")
    c.until(lambda m: m.kind == "STATUS" and m.name == "Sync")


def _tool(x):
    m = np.eye(4)
    m[0, 3] = x
    return transform_content(m)


def test_two_clients_both_get_surfaces_and_the_first_drives(endpoint, client_factory, caplog):
    from cutkit.live.igtl import IGTLPolyDataView

    view = IGTLPolyDataView(endpoint=endpoint, max_rate_hz=1000.0)
    a, b = client_factory(), client_factory()
    assert wait_for(lambda: len(endpoint.clients) == 2)
    pts, faces = box_frame((0, 0, 0), (1, 1, 1))
    view.show(LiveFrame(points=pts, boundary_faces=faces))
    for c in (a, b):
        msg = c.until(lambda m: m.kind == "POLYDATA" and m.name == "CutkitTissue")
        assert len(parse_polydata(msg.content)[1]) == 12
    with caplog.at_level(logging.INFO, logger="cutkit.live"):
        a.send("TRANSFORM", TOOL, _tool(1.0))
        _sync(a)
        assert endpoint.take(TOOL).matrix[0, 3] == 1.0
        for x in (2.0, 3.0):
            b.send("TRANSFORM", TOOL, _tool(x))
        _sync(b)
        assert endpoint.take(TOOL) is None, "a second client took the blade from the first"
        assert endpoint.dropped[("not driver", "TRANSFORM")] == 2
        told = [parse_status(m.content) for m in b.seen if m.kind == "STATUS" and m.name == TOOL]
        assert [x[:3:2] for x in told] == [(5, "NotDriver")]  # access denied, once
        a.close()
        assert wait_for(lambda: len(endpoint.clients) == 1)
        b.send("TRANSFORM", TOOL, _tool(4.0))
        _sync(b)
        assert endpoint.take(TOOL).matrix[0, 3] == 4.0
    text = [r.getMessage() for r in caplog.records]
    assert sum("which" in t and "drives" in t for t in text) == 1  # the ignored client is told once
    assert sum(" drives ScalpelToReference (driver rule: first)" in t for t in text) == 2
    view.close()


def test_the_latest_client_drives_with_driver_latest():
    from cutkit.live.igtl import IGTLEndpoint

    ep = IGTLEndpoint(0, driver="latest")
    try:
        a, b = SpecClient(ep.port), SpecClient(ep.port)
        for c in (a, b):
            c.recv()
        a.send("TRANSFORM", TOOL, _tool(1.0))
        _sync(a)
        b.send("TRANSFORM", TOOL, _tool(2.0))
        _sync(b)
        assert ep.take(TOOL).matrix[0, 3] == 2.0 and ep.drivers[TOOL] == b.sock.getsockname()[0] + ":" + str(
            b.sock.getsockname()[1])
        a.send("TRANSFORM", TOOL, _tool(3.0))
        _sync(a)
        assert ep.take(TOOL).matrix[0, 3] == 3.0
        a.close()
        b.close()
    finally:
        ep.close()
    with pytest.raises(InputError, match="first, latest"):
        IGTLEndpoint(0, driver="loudest")


def test_a_client_beyond_the_limit_is_refused_with_a_status():
    from cutkit.live.igtl import IGTLEndpoint

    ep = IGTLEndpoint(0, max_clients=1)
    try:
        a = SpecClient(ep.port)
        assert parse_status(a.recv().content)[0] == 1
        b = SpecClient(ep.port)
        rest = b.eof()
        assert [m.kind for m in rest] == ["STATUS"] and parse_status(rest[0].content)[0] == 6  # busy
        a.send("GET_STATUS", "")
        assert parse_status(a.until(lambda m: True).content)[0] == 1
        a.close()
        b.close()
    finally:
        ep.close()


# ---------------------------------------------------------------------------- POLYDATA, registration, CLI
def test_polydata_attributes_round_trip_through_the_python_decoder():
    import pyigtl

    from cutkit.live.igtl import PolyDataMessage, decode_polydata, polydata_attributes
    from cutkit.live.igtl_protocol import POINT_NORMAL, POINT_RGBA, POINT_SCALAR, PolyDataAttribute

    pts, faces = box_frame((0, 0, 0), (2, 3, 4))
    cells = np.hstack([np.full((12, 1), 3), faces]).ravel()
    rng = np.random.default_rng(0)
    attrs = [PolyDataAttribute("Normals", POINT_NORMAL, rng.random((8, 3))),
             PolyDataAttribute("Colors", POINT_RGBA, rng.random((8, 4))),
             PolyDataAttribute("Depth", POINT_SCALAR, rng.random(8))]
    data = PolyDataMessage(points=pts, polygons=cells, attributes=attrs, device_name="Box").pack()
    fields = pyigtl.MessageBase.parse_header(data[:58])
    msg = PolyDataMessage()
    msg.unpack(fields, data[58:])
    p, t = decode_polydata(msg)
    np.testing.assert_allclose(p, pts)
    np.testing.assert_array_equal(t, faces)
    got = polydata_attributes(msg)
    assert list(got) == ["Normals", "Colors", "Depth"]
    for a in attrs:
        np.testing.assert_allclose(got[a.name].data, np.asarray(a.data, np.float32).reshape(8, -1))
    # and the spec client reads the same bytes
    assert crc64(data[58:]) == struct.unpack_from(">Q", data, 50)[0]
    _, _, spec = parse_polydata(data[58:])
    np.testing.assert_allclose(spec["Depth"][1][:, 0], attrs[2].data.astype(np.float32))


def test_registration_files(tmp_path):
    from cutkit.live.igtl import load_registration, pose_from_matrix, tracker_to_model

    m = np.eye(4)
    m[:3, 3] = (10.0, -5.0, 2.0)
    np.save(tmp_path / "r.npy", m)
    (tmp_path / "r.txt").write_text("# model <- tracker\n1 0 0 10\n0 1 0 -5\n0 0 1 2\n0 0 0 1\n")
    (tmp_path / "r12.csv").write_text("1,0,0,10\n0,1,0,-5\n0,0,1,2\n")
    for name in ("r.npy", "r.txt", "r12.csv"):
        np.testing.assert_array_equal(load_registration(tmp_path / name), m)
    tip, _, _ = pose_from_matrix(np.eye(4), to_model=tracker_to_model("LPS", load_registration(tmp_path / "r.txt")))
    np.testing.assert_array_equal(tip, (10.0, -5.0, 2.0))
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    (tmp_path / "flat.txt").write_text("0 0 0 0\n" * 4)
    (tmp_path / "words.txt").write_text("identity\n")
    for name, what in (("bad.txt", "16 numbers"), ("flat.txt", "invertible"), ("words.txt", "cannot read"),
                       ("missing.txt", "cannot read")):
        with pytest.raises(InputError, match=what) as err:
            load_registration(tmp_path / name)
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("args, what", [
    (["--igtl-axis", "w"], "--igtl-axis must be one of"),
    (["--igtl-edge", "-z"], "must be different axes"),
    (["--igtl-frame", "XYZ"], "--igtl-frame must be RAS or LPS"),
    (["--igtl-surface-rate", "0"], "--igtl-surface-rate must be a positive"),
    (["--igtl-surface-rate", "nan"], "--igtl-surface-rate must be a positive"),
    (["--igtl-driver", "loudest"], "--igtl-driver must be first or latest"),
    (["--igtl-registration", "no/such/file.txt"], "cannot read the registration"),
])
def test_bad_igtl_options_are_one_line_and_exit_2(tmp_path, args, what):
    r = CliRunner().invoke(cli, ["live", str(tmp_path / "m.h5"), "-o", str(tmp_path / "out"), "--igtl", "18944",
                                 "--no-window", *args])
    assert r.exit_code == 2, r.output
    lines = [line for line in r.output.splitlines() if line.strip()]
    assert len(lines) == 1 and what in lines[0], r.output


def test_igtl_options_need_igtl_and_reach_the_source_and_view(tmp_path):
    from cutkit.cli.live import _igtl_options, _open

    r = CliRunner().invoke(cli, ["live", str(tmp_path / "m.h5"), "-o", str(tmp_path / "out"), "--igtl-frame", "LPS"])
    assert r.exit_code == 2 and "only work with --igtl" in r.output
    reg = tmp_path / "r.txt"
    reg.write_text("1 0 0 5\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    opts = _igtl_options(0, "x", "y", "lps", str(reg), 7.5, "latest")
    log = logging.getLogger("cutkit.live")
    handlers, level = list(log.handlers), log.level
    source, views, closers = _open(None, None, 1.0, 0, TOOL, True, opts)
    try:
        assert len(log.handlers) == len(handlers) + (not handlers)  # the endpoint's lines go to stderr
        assert (source.axis, source.edge) == ("x", "y") and closers[0].driver == "latest"
        np.testing.assert_array_equal(source.to_model[:3, 3], (5.0, 0.0, 0.0))  # LPS: no flip
        assert views[0].min_period == pytest.approx(1 / 7.5)
    finally:
        source.close()
        for x in views + closers:
            x.close()
        log.handlers[:], log.level = handlers, level


class _CountingEndpoint:
    """Stands in for an endpoint with a client: counts the messages a view hands it."""

    connected = True

    def __init__(self):
        self.sent = 0

    def send(self, message) -> None:
        self.sent += 1


def test_the_surface_rate_cap_keeps_frames_with_jitter_and_caps_faster_ones():
    from cutkit.live.igtl import IGTLPolyDataView

    t = [0.0]
    view = IGTLPolyDataView(endpoint=_CountingEndpoint(), max_rate_hz=30.0, clock=lambda: t[0])
    box, faces = box_frame((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    frame = LiveFrame(points=box, boundary_faces=faces)
    jitter = np.random.default_rng(5).uniform(-0.004, 0.004, 300)
    # the session's frames at the cap's own rate, each up to 4 ms early or late: every one is sent
    for k in range(300):
        t[0] = k / 30.0 + jitter[k]
        view.show(frame)
    assert view.frames_sent == 300
    # frames at 120 a second for 10 s: the cap's rate, not more
    start, sent = t[0] + 1.0, view.frames_sent
    for k in range(1200):
        t[0] = start + k / 120.0
        view.show(frame)
    assert 299 <= view.frames_sent - sent <= 301


def test_a_transform_body_is_the_protocols_layout_and_pyigtls_bytes():
    """TRANSFORM bodies are packed and parsed here (not through pyigtl's private methods): 12
    big-endian float32, the rotation column by column then the translation (the OpenIGTLink spec),
    the same bytes as pyigtl's own pack() after its 58-byte header, and parsed back exactly."""
    import struct

    import pyigtl

    from cutkit.live.igtl_protocol import parse_transform, transform_content

    m = np.eye(4)
    m[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    m[:3, 3] = [1.5, -2.25, 3.0]
    body = transform_content(m)
    assert struct.unpack(">12f", body) == (0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.5, -2.25, 3.0)
    assert body == pyigtl.TransformMessage(m, device_name="T").pack()[58:]
    np.testing.assert_array_equal(parse_transform(body), m)


def test_any_other_pyigtl_message_is_sent_with_the_body_pyigtl_packs():
    """The server packs POLYDATA and TRANSFORM bodies itself; any other pyigtl message type a caller
    sends goes out with the body of pyigtl's public pack() (its 58-byte v1 header cut off)."""
    import pyigtl

    from cutkit.live.igtl_server import _Outgoing

    m = pyigtl.StringMessage("cutkit", device_name="S")
    out = _Outgoing.of(m)
    assert out.kind == "STRING" and out.content() == m.pack()[58:]
