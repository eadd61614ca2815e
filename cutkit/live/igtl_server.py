"""The OpenIGTLink endpoint: a TCP server that several clients (3D Slicer, PLUS, scripts) share.

Each client has its own thread: it reads whole messages (58-byte header,
body), checks each body's CRC64, answers queries and sends that client what
:meth:`IGTLEndpoint.send` broadcasts, in the header version the client last
used (1: protocol v2, 2: protocol v3).

What each client gets:

- on connect, a STATUS (code OK) with device name :data:`STATUS_DEVICE`;
- every broadcast message (the tissue and cut POLYDATA, the blade
  TRANSFORM); a message not yet sent is replaced by a newer one of the same
  device name;
- a reply to GET_CAPABIL (CAPABILITY), GET_STATUS (STATUS), GET_TRANSFORM
  (type field ``GET_TRANS``) and GET_POLYDATA (the newest of that device name, all of them for an empty
  name, or STATUS "not found");
- a STATUS error for a message it sent that was dropped: bad CRC, a body
  that does not decode, a query cutkit does not answer; and once, STATUS
  "access denied", when it sends a tool that another client drives.

A header of an unknown version, a body over ``max_body`` bytes, or a message
that stalls for ``body_timeout_s`` gets a STATUS error and its connection is
closed; the endpoint and the other clients go on.  Message types cutkit
does not use are skipped whole (the stream stays in step), logged once per
type, then counted in :attr:`IGTLEndpoint.dropped`.

Who drives: for each device name, TRANSFORMs are taken from one client at a
time.  ``driver="first"``: the first client that sends that device name
holds it until it disconnects; ``driver="latest"``: the client that sent it
last takes it over.  Each change of driver is logged.
"""

from __future__ import annotations

import collections
import logging
import socket
import socketserver
import threading
import time

import numpy as np
import pyigtl

from cutkit.errors import InputError
from cutkit.live import igtl_protocol as wire

__all__ = ["IGTLEndpoint", "DEFAULT_PORT", "MAX_BODY", "BODY_TIMEOUT_S", "MAX_CLIENTS", "STATUS_DEVICE",
           "CAPABILITIES", "DRIVER_RULES"]

log = logging.getLogger("cutkit.live")

#: The OpenIGTLink port Slicer and PLUS use by default.
DEFAULT_PORT = 18944
#: The receive loop waits this long for data before it sends what is queued (s).
POLL_S = 0.01
#: A message body larger than this closes its connection (bytes): 16 MiB holds any TRANSFORM or query with
#: room to spare, and a client cannot make the endpoint buffer more than this.
MAX_BODY = 16 << 20
#: A message begun but not finished that gets no byte for this long closes its connection (s): far beyond
#: a body's transfer time on a local network, short enough that a stuck client is noticed.
BODY_TIMEOUT_S = 2.0
#: A send that makes no progress for this long closes the connection (s).
SEND_TIMEOUT_S = 5.0
#: Clients beyond this many are refused with STATUS BUSY: each costs a thread and a copy of every surface.
MAX_CLIENTS = 8
#: Replies queued for one client beyond this many drop the oldest (a client that asks and never reads).
MAX_REPLIES = 256
#: Device name of the STATUS messages that are not a reply to a named message.
STATUS_DEVICE = "Cutkit"
#: Message types the endpoint takes or sends (its CAPABILITY reply).
CAPABILITIES = ("TRANSFORM", "POLYDATA", "STATUS", "CAPABILITY", "GET_TRANS", "GET_POLYDATA", "GET_STATUS",
                "GET_CAPABIL")
#: Who drives a device name's TRANSFORMs when several clients send it.
DRIVER_RULES = ("first", "latest")
#: Queries answered with STATUS "unknown instruction" when their type is not one of CAPABILITIES.
_QUERY_PREFIXES = ("GET_", "STT_", "STP_", "RTS_")
#: What a query asks for, where its type name does not say it whole.
_QUERIED = {"GET_TRANS": "TRANSFORM", "GET_TRANSFOR": "TRANSFORM"}
#: How the log calls a dropped message of each reason.
_ADJECTIVE = {"crc": "corrupt", "malformed": "malformed", "unused": "unused"}
#: TRANSFORM content: 12 big-endian float32.
_TRANSFORM_SIZE = 48


class _PeerClosed(Exception):
    pass


class _Close(Exception):
    """End this connection after a STATUS error (code, error name, text)."""

    def __init__(self, code: int, name: str, text: str, subcode: int = 0):
        super().__init__(text)
        self.code, self.name, self.text, self.subcode = code, name, text, subcode


class _Outgoing:
    """One message to send: its content packed once, the whole message once per header version."""

    def __init__(self, kind: str, device_name: str, content, timestamp: float | None = None, message_id: int = 0,
                 parent: "_Outgoing | None" = None):
        self.kind, self.device_name, self.message_id = kind, device_name, message_id
        self.timestamp = time.time() if timestamp is None else timestamp
        self._content = content  # bytes, or a callable that packs them (run on a client's thread)
        self._packed = {}
        self._lock = threading.Lock()
        self._parent = parent  # the broadcast this reply repeats: a v1 header has no message id, so the same bytes

    @classmethod
    def of(cls, message) -> "_Outgoing":
        """A pyigtl message, its body packed when a client first needs it: POLYDATA
        (:class:`~cutkit.live.igtl_protocol.PolyDataMessage`) and TRANSFORM here, any other type
        by pyigtl's own ``pack()`` (which also sums a CRC the server makes again)."""
        if isinstance(message, wire.PolyDataMessage):
            content = message.content
        elif isinstance(message, pyigtl.TransformMessage):
            matrix = np.array(message.matrix, np.float64)

            def content():
                return wire.transform_content(matrix)
        else:
            def content():
                packed = message.pack()
                head = wire.parse_header(packed[:wire.HEADER_SIZE])
                return wire.split_body(head.version, packed[wire.HEADER_SIZE:])[0]
        return cls(message.message_type, message.device_name, content, message.timestamp)

    def content(self) -> bytes:
        with self._lock:
            if callable(self._content):
                self._content = self._content()
            return self._content

    def reply(self, message_id: int) -> "_Outgoing":
        """The same message as a reply to the request ``message_id``."""
        if message_id == self.message_id:
            return self
        return _Outgoing(self.kind, self.device_name, self.content, self.timestamp, message_id, parent=self)

    def data(self, version: int) -> bytes:
        """The whole message with a header of ``version`` (1 or 2)."""
        if version == 1 and self._parent is not None:
            return self._parent.data(1)
        content = self.content()
        with self._lock:
            if version not in self._packed:
                self._packed[version] = wire.pack_message(self.kind, self.device_name, content, version,
                                                          self.timestamp, self.message_id)
            return self._packed[version]


class _Client:
    """One connection: its socket, the version it speaks, what is queued for it."""

    def __init__(self, sock, peer: str):
        self.sock, self.peer = sock, peer
        self.version = 1  # until the client sends a message: protocol v2 headers, which every peer reads
        self.replies = collections.deque(maxlen=MAX_REPLIES)
        self.stream = collections.OrderedDict()  # device name -> newest broadcast not yet sent
        self.lock = threading.Lock()
        self.buf = bytearray()
        self.progress = time.monotonic()  # last byte received

    def reply(self, item: _Outgoing) -> None:
        with self.lock:
            self.replies.append(item)

    def status(self, code: int, text: str, device_name: str = STATUS_DEVICE, error_name: str = "",
               subcode: int = 0, message_id: int = 0) -> None:
        self.reply(_Outgoing("STATUS", device_name[:wire.MAX_NAME],
                             wire.status_content(code, text, error_name, subcode), message_id=message_id))

    def queue(self, item: _Outgoing) -> None:
        with self.lock:
            self.stream.pop(item.device_name, None)
            self.stream[item.device_name] = item

    def flush(self) -> None:
        """Send the replies queued now, then the broadcasts queued now.

        What is queued meanwhile waits a turn, so that a slow client's thread
        still reads what the client sends between turns.
        """
        with self.lock:
            items = list(self.replies) + list(self.stream.values())
            self.replies.clear()
            self.stream.clear()
        for item in items:
            data = item.data(self.version)
            self.sock.settimeout(SEND_TIMEOUT_S)
            try:
                self.sock.sendall(data)
            finally:
                self.sock.settimeout(POLL_S)


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True

    def handle_error(self, request, client_address):
        # socketserver prints a traceback to stderr; the library logs instead
        log.exception("OpenIGTLink: unexpected error serving %s:%s", *client_address[:2])


class _Handler(socketserver.BaseRequestHandler):
    """One client's thread: whole messages in, replies and broadcasts out, until either side stops."""

    def handle(self):
        ep = self.server.cutkit_endpoint
        self.request.settimeout(POLL_S)
        client = ep._register(self.request, "%s:%s" % self.client_address[:2])
        if client is not None:
            ep._serve(client)


class IGTLEndpoint:
    """An OpenIGTLink server that the pose source and the POLYDATA view share.

    Parameters
    ----------
    port : int
        TCP port; 0 picks a free one (:attr:`port` tells which).
    local_only : bool
        Bind 127.0.0.1 (default); False binds ``iface`` (default every interface).
    iface : str, optional
        Address to bind with ``local_only=False``.
    driver : "first" or "latest"
        Which client's TRANSFORMs of a device name are used (module notes).
    max_clients : int
    max_body : int
        Largest message body taken, bytes.
    body_timeout_s : float
        A message begun that gets no byte for this long ends its connection.

    Attributes
    ----------
    errors : int
        Messages dropped and connections ended for a protocol error.
    dropped : dict
        ``(reason, message type) -> count``; reasons ``"crc"``, ``"malformed"``,
        ``"unused"``, ``"not driver"``, ``"oversize"``, ``"timeout"``, ``"version"``.
    received : dict
        Device name -> TRANSFORMs taken.
    drivers : dict
        Device name -> the client (``host:port``) that drives it now.
    """

    def __init__(self, port: int = DEFAULT_PORT, local_only: bool = True, iface: str | None = None,
                 driver: str = "first", max_clients: int = MAX_CLIENTS, max_body: int = MAX_BODY,
                 body_timeout_s: float = BODY_TIMEOUT_S):
        if driver not in DRIVER_RULES:
            raise InputError(f"OpenIGTLink driver rule must be one of {', '.join(DRIVER_RULES)}, got {driver!r}")
        host = "127.0.0.1" if local_only else (iface or "0.0.0.0")
        try:
            srv = _Server((host, port), _Handler)
        except OSError as err:
            raise InputError(f"cannot listen for OpenIGTLink on port {port}: {err.strerror or err}") from None
        srv.cutkit_endpoint = self
        self.server = srv
        self.host, self.port = srv.server_address[:2]
        self.driver, self.max_clients = driver, int(max_clients)
        self.max_body, self.body_timeout_s = int(max_body), float(body_timeout_s)
        self.errors = 0
        self.dropped = {}
        self.received = {}
        self.drivers = {}
        self._holders = {}  # device name -> _Client
        self._warned = set()  # (client, device name) told once that another client drives
        self._clients = []
        self._threads = []
        self._latest = {}  # device name -> newest TRANSFORM not yet taken
        self._last_in = {}  # device name -> newest TRANSFORM taken (GET_TRANSFORM)
        self._sent = {}  # device name -> newest broadcast (GET_ replies)
        self._lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="cutkit-igtl", daemon=True)
        self._thread.start()
        log.info("OpenIGTLink: listening on %s:%d (driver rule: %s)", self.host, self.port, driver)

    # ------------------------------------------------------------------ public
    @property
    def connected(self) -> bool:
        """Whether a client is connected now."""
        return bool(self._clients)

    @property
    def clients(self) -> list[str]:
        """``host:port`` of each connected client."""
        with self._lock:
            return [c.peer for c in self._clients]

    def take(self, device_name: str):
        """The newest TRANSFORM of ``device_name`` from its driver since the last call, or None."""
        with self._lock:
            return self._latest.pop(device_name, None)

    def send(self, message) -> None:
        """Send a pyigtl message to every client (a queued older one of its device name is dropped)."""
        item = _Outgoing.of(message)
        with self._lock:
            self._sent[message.device_name] = item
            clients = list(self._clients)
        for c in clients:
            c.queue(item)

    def close(self) -> None:
        """Stop listening and end every connection (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=5.0)
        for t in list(self._threads):
            t.join(timeout=2.0)

    # ------------------------------------------------------------------ connections
    def _register(self, sock, peer: str) -> _Client | None:
        client = _Client(sock, peer)
        with self._lock:
            busy = len(self._clients) >= self.max_clients or self._closed
            if not busy:
                self._clients.append(client)
                self._threads.append(threading.current_thread())
        if busy:
            log.warning("OpenIGTLink client %s refused: %d clients are connected (at most %d)", peer,
                        len(self._clients), self.max_clients)
            client.status(wire.STATUS_BUSY, f"cutkit serves at most {self.max_clients} clients", error_name="Busy")
            try:
                client.flush()
            except OSError:
                pass
            return None
        log.info("OpenIGTLink client %s connected (%d connected)", peer, len(self._clients))
        client.status(wire.STATUS_OK, "cutkit live: connected")
        with self._lock:  # then the newest surfaces and blade, before any reply to what it asks
            for item in self._sent.values():
                client.reply(item)
        return client

    def _serve(self, client: _Client) -> None:
        try:
            while not self._closed:
                self._receive(client)
                client.flush()
        except _PeerClosed:
            log.info("OpenIGTLink client %s disconnected", client.peer)
        except _Close as err:
            log.warning("OpenIGTLink client %s: %s; closing the connection", client.peer, err.text)
            client.status(err.code, err.text, error_name=err.name, subcode=err.subcode)
            try:
                client.flush()
            except OSError:
                pass
        except OSError as err:
            log.info("OpenIGTLink client %s: connection lost (%s)", client.peer, err)
        finally:
            self._unregister(client)

    def _unregister(self, client: _Client) -> None:
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)
            if threading.current_thread() in self._threads:
                self._threads.remove(threading.current_thread())
            freed = [name for name, c in self._holders.items() if c is client]
            for name in freed:
                del self._holders[name]
                del self.drivers[name]
        for name in freed:
            log.info("OpenIGTLink: %s no longer drives %s; the next client to send it will", client.peer, name)

    def _receive(self, client: _Client) -> None:
        """Read what has arrived (waiting at most POLL_S) and handle every whole message."""
        try:
            chunk = client.sock.recv(1 << 20)
        except (socket.timeout, BlockingIOError):
            chunk = None
        if chunk == b"":
            raise _PeerClosed()
        now = time.monotonic()
        buf = client.buf
        if chunk:
            buf += chunk
            client.progress = now
        while len(buf) >= wire.HEADER_SIZE:
            head = wire.parse_header(bytes(buf[:wire.HEADER_SIZE]))
            self._check_header(head)
            end = wire.HEADER_SIZE + head.body_size
            if len(buf) < end:
                break
            body = bytes(buf[wire.HEADER_SIZE:end])
            del buf[:end]
            self._message(client, head, body)
        if buf and now - client.progress > self.body_timeout_s:
            self._count("timeout", "stream")
            raise _Close(wire.STATUS_TIME_OUT, "Timeout", f"a message stalled for over {self.body_timeout_s:g} s "
                         f"with {len(buf)} bytes received")

    def _check_header(self, head: wire.Header) -> None:
        if head.version not in wire.HEADER_VERSIONS:
            self._count("version", head.type)
            raise _Close(wire.STATUS_UNKNOWN_VERSION, "Version",
                         f"OpenIGTLink header version {head.version} (this peer speaks 1 and 2)")
        if head.body_size > self.max_body:
            self._count("oversize", head.type)
            raise _Close(wire.STATUS_OVERFLOW, "TooLarge", f"a {head.type} body of {head.body_size} bytes is "
                         f"over the limit of {self.max_body}", subcode=head.body_size)

    # ------------------------------------------------------------------ messages
    def _message(self, client: _Client, head: wire.Header, body: bytes) -> None:
        """Check one whole message and hand it to its type's handler."""
        if wire.crc64(body) != head.crc:
            self._drop(client, "crc", head, "its CRC64 does not match its body", wire.STATUS_CHECKSUM_ERROR, "CRC")
            return
        try:
            content, message_id, metadata = wire.split_body(head.version, body)
        except wire.ProtocolError as err:
            self._drop(client, "malformed", head, str(err), wire.STATUS_UNKNOWN_ERROR, "Malformed")
            return
        client.version = head.version
        handler = _HANDLERS.get(head.type)
        if handler is None:
            query = head.type.startswith(_QUERY_PREFIXES)
            self._drop(client, "unused", head, "cutkit does not use this message type",
                       wire.STATUS_UNKNOWN_INSTRUCTION if query else None, "Unknown", message_id)
            return
        handler(self, client, head, content, message_id, metadata)

    def _count(self, reason: str, kind: str, error: bool = True) -> int:
        with self._lock:
            key = (reason, kind)
            self.dropped[key] = n = self.dropped.get(key, 0) + 1
            self.errors += int(error)
        return n

    def _drop(self, client: _Client, reason: str, head: wire.Header, why: str, code: int | None,
              error_name: str = "", message_id: int = 0) -> None:
        """Count a dropped message, log the first of its reason and type, answer with a STATUS error."""
        if self._count(reason, head.type, error=reason != "unused") == 1:
            level = logging.INFO if reason == "unused" else logging.WARNING
            log.log(level, "OpenIGTLink client %s: dropped a %s %s message %r: %s (logged once per type, then "
                    "counted)", client.peer, _ADJECTIVE.get(reason, reason), head.type, head.device_name, why)
        if code is not None:
            client.status(code, f"{head.type} {head.device_name!r} dropped: {why}", head.device_name or STATUS_DEVICE,
                          error_name, message_id=message_id)

    def _on_transform(self, client, head, content, message_id, metadata) -> None:
        if len(content) != _TRANSFORM_SIZE:
            self._drop(client, "malformed", head, f"a TRANSFORM body is {_TRANSFORM_SIZE} bytes, not {len(content)}",
                       wire.STATUS_UNKNOWN_ERROR, "Malformed", message_id)
            return
        msg = pyigtl.TransformMessage(wire.parse_transform(content), device_name=head.device_name,
                                      timestamp=head.timestamp)
        msg.header_version, msg.message_id, msg.metadata = head.version, message_id, metadata
        name = head.device_name
        with self._lock:
            holder = self._holders.get(name)
            if holder is not None and holder is not client and self.driver == "first":
                first = (client, name) not in self._warned
                self._warned.add((client, name))
            else:
                first = None
                if holder is not client:
                    self._holders[name], self.drivers[name] = client, client.peer
                self._latest[name] = self._last_in[name] = msg
                self.received[name] = self.received.get(name, 0) + 1
        if first is not None:
            n = self._count("not driver", "TRANSFORM", error=False)
            if first:
                log.warning("OpenIGTLink client %s sends %s, which %s drives (driver rule: first); its TRANSFORMs "
                            "are ignored until %s disconnects (%d ignored so far)", client.peer, name, holder.peer,
                            holder.peer, n)
                client.status(wire.STATUS_ACCESS_DENIED, f"{name} is driven by another client (driver rule: first); "
                              "this client's TRANSFORMs of it are ignored", name, "NotDriver", message_id=message_id)
        elif holder is not client:
            log.info("OpenIGTLink client %s drives %s (driver rule: %s)", client.peer, name, self.driver)

    def _on_get_transform(self, client, head, content, message_id, metadata) -> None:
        with self._lock:
            items = [i for i in self._sent.values() if i.kind == "TRANSFORM"
                     and head.device_name in ("", i.device_name)]
            if not items and head.device_name in self._last_in:
                items = [_Outgoing.of(self._last_in[head.device_name])]
        self._answer(client, head, items, message_id)

    def _on_get_polydata(self, client, head, content, message_id, metadata) -> None:
        with self._lock:
            items = [i for i in self._sent.values() if i.kind == "POLYDATA"
                     and head.device_name in ("", i.device_name)]
        self._answer(client, head, items, message_id)

    def _answer(self, client, head, items, message_id) -> None:
        if not items:
            what = repr(head.device_name) if head.device_name else "yet"
            client.status(wire.STATUS_NOT_FOUND, f"{head.type}: no {_QUERIED.get(head.type, head.type[4:])} {what}",
                          head.device_name or STATUS_DEVICE, "NotFound", message_id=message_id)
        for item in items:
            client.reply(item.reply(message_id))

    def _on_get_status(self, client, head, content, message_id, metadata) -> None:
        with self._lock:
            n, drivers = len(self._clients), dict(self.drivers)
        driven = ", ".join(f"{k} by {v}" for k, v in drivers.items()) or "nothing driven yet"
        client.status(wire.STATUS_OK, f"cutkit live: {n} client(s); {driven}", head.device_name or STATUS_DEVICE,
                      message_id=message_id)

    def _on_get_capabil(self, client, head, content, message_id, metadata) -> None:
        client.reply(_Outgoing("CAPABILITY", head.device_name or STATUS_DEVICE, wire.capability_content(CAPABILITIES),
                               message_id=message_id))

    def _on_status(self, client, head, content, message_id, metadata) -> None:
        try:
            code, _, name, text = wire.parse_status(content)
        except wire.ProtocolError as err:
            self._drop(client, "malformed", head, str(err), None)
            return
        log.debug("OpenIGTLink client %s: STATUS %d %s %s", client.peer, code, name, text)

    def _on_capability(self, client, head, content, message_id, metadata) -> None:
        try:
            types = wire.parse_capability(content)
        except wire.ProtocolError as err:
            self._drop(client, "malformed", head, str(err), None)
            return
        log.debug("OpenIGTLink client %s: CAPABILITY %s", client.peer, " ".join(types))


#: What each message type does (a type not here is skipped, logged once and counted).
#: GET_TRANSFORM travels as "GET_TRANS" (the reference library's name; the type field holds 12 bytes), or
#: cut to "GET_TRANSFOR" by some clients.
_HANDLERS = {"TRANSFORM": IGTLEndpoint._on_transform, "GET_TRANS": IGTLEndpoint._on_get_transform,
             "GET_TRANSFOR": IGTLEndpoint._on_get_transform,
             "GET_POLYDATA": IGTLEndpoint._on_get_polydata, "GET_STATUS": IGTLEndpoint._on_get_status,
             "GET_CAPABIL": IGTLEndpoint._on_get_capabil, "STATUS": IGTLEndpoint._on_status,
             "CAPABILITY": IGTLEndpoint._on_capability}
