"""OpenIGTLink: a tracked tool as a pose source, the cut tissue as POLYDATA (pyigtl).

3D Slicer (module *OpenIGTLinkIF*) or a PLUS server connects as a client to
the :class:`IGTLEndpoint` (a ``pyigtl.OpenIGTLinkServer``, port 18944 by
default).  It sends the tool's TRANSFORM; :class:`IGTLPoseSource` turns the
newest one of its device name into a blade pose.  :class:`IGTLPolyDataView`
sends the deformed boundary and the cut surface back over the same
connection as POLYDATA messages, at a capped rate, so Slicer shows the cut.

Frames: Slicer and PLUS speak RAS (x towards the patient's Right, y
Anterior, z Superior); cutkit models are LPS (x Left, y Posterior, z
Superior), the frame of DICOM and of the volumes cutkit reads.
``frame="RAS"`` (default) flips x and y both ways; an optional
``registration`` (4x4, model LPS <- tracker frame after the flip) maps a
tracker's space onto the model.  Units are mm on both sides.

pyigtl 0.3 can pack POLYDATA (without attributes) but not unpack it (its
``_unpack_content`` is unfinished) and does not register the type for
receiving; :class:`PolyDataMessage` here is the same message with a working
decoder, for clients and tests, and a vectorised encoder.
Its server thread also spins on a closed connection and prints tracebacks;
the endpoint replaces its connection handler with one that reads whole
messages, logs one line for a malformed one and ends on a closed socket.
"""

from __future__ import annotations

import logging
import socket
import socketserver
import struct
import threading
import time

import numpy as np
import pyigtl

from cutkit.errors import InputError
from cutkit.live.sources import Pose, make_pose
from cutkit.live.views import LiveFrame, compact_faces

__all__ = ["IGTLEndpoint", "IGTLPoseSource", "IGTLPolyDataView", "PolyDataMessage", "decode_polydata",
           "pose_from_matrix", "tracker_to_model", "DEFAULT_PORT", "DEFAULT_TOOL", "RAS_TO_LPS"]

log = logging.getLogger("cutkit.live")

#: The OpenIGTLink port Slicer and PLUS use by default.
DEFAULT_PORT = 18944
#: Default device name of the tracked blade's TRANSFORM (at most 20 bytes).
DEFAULT_TOOL = "ScalpelToReference"
#: RAS <-> LPS (its own inverse).
RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])
#: The receive loop polls the socket this often (s).
POLL_S = 0.01
#: A message body larger than this closes the connection (bytes).
MAX_BODY = 256 << 20
#: A send that makes no progress for this long closes the connection (s).
SEND_TIMEOUT_S = 5.0
#: Device names are at most this long on the wire (bytes).
MAX_NAME = 20
_AXES = {"x": 0, "y": 1, "z": 2}


class _PeerClosed(Exception):
    pass


class _BadStream(Exception):
    """A header that cannot start a valid message: the stream cannot be resynchronised."""


# ---------------------------------------------------------------------------- POLYDATA
class PolyDataMessage(pyigtl.PolyDataMessage):
    """pyigtl's POLYDATA message with a working decoder (points, vertices, lines, polygons, strips).

    Register it with ``pyigtl.messages.message_type_to_class_constructor["POLYDATA"] =
    PolyDataMessage`` for a pyigtl client to receive POLYDATA.
    """

    def _pack_content(self):
        parts = [np.asarray(x if x is not None else (), np.int64).ravel()
                 for x in (self.vertices, self.lines, self.polygons, self.triangle_strips)]
        pts = np.zeros((0, 3)) if self.points is None else np.asarray(self.points).reshape(-1, 3)
        head = [pts.shape[0]]
        for cells in parts:
            head += [_count_cells(cells), 4 * cells.size]
        head.append(0)  # no attributes
        return b"".join([struct.pack(">10I", *head), np.ascontiguousarray(pts, ">f4").tobytes()]
                        + [np.ascontiguousarray(c, ">u4").tobytes() for c in parts])

    def _unpack_content(self, content):
        head = struct.Struct(">10I")
        v = head.unpack_from(content, 0)
        npts, sizes = v[0], (v[2], v[4], v[6], v[8])
        off = head.size
        self.points = np.frombuffer(content, ">f4", npts * 3, off).reshape(npts, 3).astype(np.float64)
        off += npts * 12
        arrays = []
        for size in sizes:
            arrays.append(np.frombuffer(content, ">u4", size // 4, off).astype(np.int64))
            off += size
        self.vertices, self.lines, self.polygons, self.triangle_strips = arrays
        self.attributes = None


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


# ---------------------------------------------------------------------------- the endpoint
class _Handler(socketserver.BaseRequestHandler):
    """One client connection: whole messages in, queued messages out, until either side stops."""

    def handle(self):
        srv = self.server
        ep = srv.cutkit_endpoint
        sock = self.request
        sock.settimeout(POLL_S)
        peer = "%s:%s" % self.client_address[:2]
        srv._connected = True
        log.info("OpenIGTLink client %s connected", peer)
        buf = bytearray()
        try:
            while not srv.communication_thread_stop_requested:
                _receive(sock, buf, ep, peer)
                ep._send_queued(sock)
        except _PeerClosed:
            log.info("OpenIGTLink client %s disconnected", peer)
        except _BadStream as err:
            log.warning("OpenIGTLink client %s: %s; closing the connection", peer, err)
            ep.errors += 1
        except OSError as err:
            log.info("OpenIGTLink client %s: connection lost (%s)", peer, err)
        finally:
            srv._connected = False


def _receive(sock, buf: bytearray, ep, peer: str) -> None:
    """Read what has arrived (waiting at most POLL_S) and hand every whole message to ``ep``."""
    try:
        chunk = sock.recv(1 << 20)
    except (socket.timeout, BlockingIOError):
        return
    if not chunk:
        raise _PeerClosed()
    buf += chunk
    size = pyigtl.MessageBase.IGTL_HEADER_SIZE
    while len(buf) >= size:
        try:
            fields = pyigtl.MessageBase.parse_header(bytes(buf[:size]))
        except (UnicodeDecodeError, struct.error) as err:
            raise _BadStream(f"unreadable message header ({err})") from None
        if fields["header_version"] not in (1, 2):
            raise _BadStream(f"bad OpenIGTLink header version {fields['header_version']}")
        body = fields["body_size"]
        if body > MAX_BODY:
            raise _BadStream(f"message body of {body} bytes is larger than {MAX_BODY}")
        if len(buf) < size + body:
            return
        data = bytes(buf[size:size + body])
        del buf[:size + body]
        ep._incoming(fields, data, peer)


class IGTLEndpoint:
    """An OpenIGTLink server (``pyigtl.OpenIGTLinkServer``) that sources and views share.

    Parameters
    ----------
    port : int
        TCP port; 0 picks a free one (:attr:`port` tells which).
    local_only : bool
        Bind 127.0.0.1 (default).  False lets pyigtl bind the address of the
        network interface ``iface`` (Linux: an interface name such as eth0).
    iface : str, optional

    Notes
    -----
    pyigtl serves one client at a time and installs SIGINT/SIGTERM handlers
    when its server is made; the endpoint puts the previous handlers back at
    once, so it must be opened from the main thread.
    """

    def __init__(self, port: int = DEFAULT_PORT, local_only: bool = True, iface: str | None = None):
        if threading.current_thread() is not threading.main_thread():
            raise InputError("an OpenIGTLink endpoint must be opened from the main thread")
        try:
            srv = pyigtl.OpenIGTLinkServer(port=port, local_server=local_only, iface=iface, start_now=False)
        except OSError as err:
            raise InputError(f"cannot listen for OpenIGTLink on port {port}: {err.strerror or err}") from None
        import signal

        for sig, handler in getattr(srv, "_previous_signal_handlers", {}).items():
            signal.signal(sig, handler)
        srv.RequestHandlerClass = _Handler
        srv.cutkit_endpoint = self
        self.server = srv
        self.host, self.port = srv.server_address[:2]
        self.errors = 0  # malformed messages and streams
        self.received = {}  # device name -> messages received
        self._latest = {}  # device name -> newest message
        self._lock = threading.Lock()
        self._closed = False
        srv.start()

    @property
    def connected(self) -> bool:
        """Whether a client is connected now."""
        return bool(self.server.is_connected())

    def _incoming(self, fields, body: bytes, peer: str) -> None:
        msg = pyigtl.MessageBase.create_message(fields["message_type"])
        if msg is None:
            log.debug("OpenIGTLink client %s: ignored a %s message", peer, fields["message_type"])
            return
        try:
            msg.unpack(fields, body)
        except Exception as err:  # pyigtl's decoders raise anything on a bad body
            self.errors += 1
            log.warning("OpenIGTLink client %s: dropped a malformed %s message %r (%s: %s)", peer,
                        fields["message_type"], fields["device_name"], type(err).__name__, err)
            return
        with self._lock:
            self._latest[msg.device_name] = msg
            self.received[msg.device_name] = self.received.get(msg.device_name, 0) + 1

    def take(self, device_name: str):
        """The newest message of ``device_name`` since the last call, or None."""
        with self._lock:
            return self._latest.pop(device_name, None)

    def send(self, message) -> None:
        """Queue ``message``; a queued older message of the same device name is dropped (newest wins)."""
        srv = self.server
        with srv.lock_outgoing_messages:
            queue = srv.outgoing_messages
            for old in [m for m in queue if m.device_name == message.device_name]:
                queue.remove(old)
            queue.append(message)

    def _send_queued(self, sock) -> None:
        srv = self.server
        while True:
            with srv.lock_outgoing_messages:
                if not srv.outgoing_messages:
                    return
                data = srv.outgoing_messages.popleft().pack()
            sock.settimeout(SEND_TIMEOUT_S)
            try:
                sock.sendall(data)
            finally:
                sock.settimeout(POLL_S)

    def close(self) -> None:
        """Stop the server and its connection (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.server.stop()


def _check_name(name: str, what: str) -> str:
    if not name or len(name.encode("utf-8")) > MAX_NAME:
        raise InputError(f"{what} {name!r} must be 1 to {MAX_NAME} bytes long")
    return name


def tracker_to_model(frame: str = "RAS", registration=None) -> np.ndarray:
    """The 4x4 map from the tracker's coordinates to the model's (LPS, mm).

    Parameters
    ----------
    frame : "RAS" or "LPS"
        Frame of the tracker's (or Slicer's) coordinates.
    registration : (4, 4) array-like, optional
        Model <- tracker registration applied after the frame change.

    Returns
    -------
    (4, 4) float64
    """
    if frame not in ("RAS", "LPS"):
        raise InputError(f"coordinate frame must be RAS or LPS, got {frame!r}")
    m = RAS_TO_LPS.copy() if frame == "RAS" else np.eye(4)
    if registration is not None:
        r = np.asarray(registration, np.float64)
        if r.shape != (4, 4) or not np.all(np.isfinite(r)) or abs(np.linalg.det(r[:3, :3])) < 1e-12:
            raise InputError("registration must be a finite, invertible 4x4 matrix")
        m = r @ m
    return m


def _axis(spec: str) -> tuple[int, float]:
    s = spec.strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    col = _AXES.get(s.lstrip("+-"))
    if col is None:
        raise InputError(f"tool axis must be one of x, y, z, -x, -y, -z, got {spec!r}")
    return col, sign


def pose_from_matrix(matrix, axis: str = "-z", edge: str = "x", to_model=None):
    """Blade tip and directions from a tool's 4x4 pose matrix.

    Parameters
    ----------
    matrix : (4, 4) array-like
        Tool -> tracker transform (the TRANSFORM message's matrix), mm.
    axis : str
        Tool axis along the blade, handle to tip: ``"-z"`` (default), ``"z"``, ``"x"``, ...
    edge : str
        Tool axis the sharp edge faces (default ``"x"``); made perpendicular to ``axis``.
    to_model : (4, 4) array-like, optional
        Tracker -> model map (:func:`tracker_to_model`); default RAS -> LPS.

    Returns
    -------
    tip, a, n : (3,) float64
    """
    m = np.asarray(matrix, np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError("tool pose must be a finite 4x4 matrix")
    m = (RAS_TO_LPS if to_model is None else np.asarray(to_model, np.float64)) @ m
    ca, sa = _axis(axis)
    ce, se = _axis(edge)
    if ca == ce:
        raise InputError(f"tool axis {axis!r} and edge {edge!r} must be different axes")
    pose = make_pose(0.0, m[:3, 3], sa * m[:3, ca], se * m[:3, ce])
    return pose.tip, pose.a, pose.n


class _Owner:
    """Opens its own endpoint on ``port`` or shares ``endpoint``; closes only its own."""

    def _attach(self, port, endpoint, local_only):
        self._own = endpoint is None
        self.endpoint = IGTLEndpoint(port, local_only) if endpoint is None else endpoint

    def close(self) -> None:
        if self._own:
            self.endpoint.close()


class IGTLPoseSource(_Owner):
    """The blade pose from a tracked tool's OpenIGTLink TRANSFORM messages.

    Parameters
    ----------
    port : int
        Port of a new endpoint (ignored with ``endpoint``).
    device_name : str
        Device name of the tool's TRANSFORM (Slicer: the transform node's name).
    axis, edge : str
        Tool axes of the blade (handle to tip) and of the sharp edge; see
        :func:`pose_from_matrix`.
    frame : "RAS" or "LPS"
        Coordinates the tool's matrix is in (Slicer, PLUS: RAS).
    registration : (4, 4), optional
        Model <- tracker registration (:func:`tracker_to_model`).
    endpoint : IGTLEndpoint, optional
        Share an endpoint (with an :class:`IGTLPolyDataView`).
    local_only : bool
    clock : callable
        Wall clock stamped on each pose.
    """

    def __init__(self, port: int = DEFAULT_PORT, device_name: str = DEFAULT_TOOL, axis: str = "-z",
                 edge: str = "x", frame: str = "RAS", registration=None, endpoint: IGTLEndpoint | None = None,
                 local_only: bool = True, clock=time.time):
        self.device_name = _check_name(device_name, "tool device name")
        self.axis, self.edge = axis, edge
        if _axis(axis)[0] == _axis(edge)[0]:  # also checks both names
            raise InputError(f"tool axis {axis!r} and edge {edge!r} must be different axes")
        self.to_model = tracker_to_model(frame, registration)
        self.clock = clock
        self.finished = False
        self.rejected = 0  # TRANSFORMs that gave no pose
        self._attach(port, endpoint, local_only)

    def poll(self) -> Pose | None:
        msg = self.endpoint.take(self.device_name)
        if msg is None or self.finished:
            return None
        if msg.message_type != "TRANSFORM":
            self.rejected += 1
            log.warning("OpenIGTLink: %s is a %s message, not a TRANSFORM; ignored", self.device_name,
                        msg.message_type)
            return None
        try:
            tip, a, n = pose_from_matrix(msg.matrix, self.axis, self.edge, self.to_model)
        except InputError as err:
            self.rejected += 1
            log.warning("OpenIGTLink: ignored a TRANSFORM of %s: %s", self.device_name, err)
            return None
        return Pose(float(self.clock()), tip, a, n, 0)

    def close(self) -> None:
        self.finished = True
        super().close()


class IGTLPolyDataView(_Owner):
    """Send the deformed boundary and the cut surface to an OpenIGTLink client (3D Slicer).

    Each shown frame (at most ``max_rate_hz`` a second, and only while a
    client is connected) becomes two POLYDATA messages, ``tissue_name`` (the
    outer boundary) and ``cut_name`` (the cut surface), triangles over the
    points they use, in the client's frame; plus a TRANSFORM ``blade_name``
    whose columns are the edge (x), ``n x a`` (y) and the blade's
    tip-to-handle direction (z), translation the tip, so that the same
    convention read back by :class:`IGTLPoseSource` (axis -z, edge x) gives
    the blade.  Messages not yet sent are replaced by newer ones.

    Parameters
    ----------
    port, endpoint, local_only : as for :class:`IGTLPoseSource`
    max_rate_hz : float
    tissue_name, cut_name, blade_name : str
        Device names (at most 20 bytes each).
    frame, registration : as for :class:`IGTLPoseSource` (the view sends the inverse map)
    clock : callable
        Monotonic clock for the rate cap.
    """

    def __init__(self, port: int = DEFAULT_PORT, endpoint: IGTLEndpoint | None = None, max_rate_hz: float = 10.0,
                 tissue_name: str = "CutkitTissue", cut_name: str = "CutkitCutSurface",
                 blade_name: str = "CutkitBlade", frame: str = "RAS", registration=None,
                 local_only: bool = True, clock=time.monotonic):
        if not max_rate_hz > 0:
            raise InputError(f"POLYDATA rate must be positive, got {max_rate_hz}")
        self.names = tuple(_check_name(x, "device name") for x in (tissue_name, cut_name, blade_name))
        self.min_period = 1.0 / float(max_rate_hz)
        self.to_client = np.linalg.inv(tracker_to_model(frame, registration))
        self.clock = clock
        self.frames_sent = 0
        self._last = -np.inf
        self._attach(port, endpoint, local_only)

    def show(self, frame: LiveFrame) -> None:
        now = self.clock()
        if now - self._last < self.min_period or not self.endpoint.connected:
            return
        frame.check()
        self._last = now
        r, t = self.to_client[:3, :3], self.to_client[:3, 3]
        for name, faces in zip(self.names[:2], (frame.boundary_faces, frame.cut_faces)):
            pts, tris = compact_faces(frame.points, faces)
            cells = np.empty((tris.shape[0], 4), np.uint32)
            cells[:, 0] = 3
            cells[:, 1:] = tris
            msg = PolyDataMessage(points=(pts @ r.T + t).astype(np.float32), polygons=cells.ravel(),
                                  device_name=name)
            self.endpoint.send(msg)
        if frame.tip is not None:
            m = np.eye(4)
            m[:3, 0], m[:3, 1], m[:3, 2] = frame.n, np.cross(frame.n, frame.a), -np.asarray(frame.a)
            m[:3, 3] = frame.tip
            self.endpoint.send(pyigtl.TransformMessage(self.to_client @ m, device_name=self.names[2]))
        self.frames_sent += 1
