"""The 1 kHz haptic scalpel service (paper sections 2 and 6).

One process, one thread: every millisecond the loop reads whatever the
clients sent (non-blocking sockets polled through :mod:`selectors`), steps
the scalpel model once with the fixed 1 ms time step, and sends each device
client its force.  Poses and simulation updates are "newest state wins": a
tick uses the last one received and drops older ones.

Pacing: each tick has an absolute deadline; the loop sleeps until
``SPIN_S`` before it and busy-waits the rest.  A loop late by up to
``MAX_CATCH_UP_PERIODS`` periods runs the missed ticks at once (each one a
step of the force model), so a short stall of the machine costs no ticks; a
loop later than that starts afresh from now instead of catching up in a burst.

A watchdog ramps the rendered force to zero, at ``1 / WATCHDOG_RAMP_S`` per
second, once no simulation update has arrived for ``WATCHDOG_TIMEOUT_S``;
it ramps back up the same way when updates return.

A simulation that asks for it in its HELLO (``HELLO_FORWARD_POSES``) gets
the device's pose as the device sent it, in a DEVICE_POSE frame, every tick
in which a new pose arrived: the hand's raw tip, not only the proxy.
"""

from __future__ import annotations

import gc
import logging
import math
import os
import selectors
import signal
import socket
import threading
import time

import numpy as np

from cutkit.errors import InputError
from cutkit.haptics import protocol as P
from cutkit.scalpel import (
    FREE, N_OUT, O_A, O_FORCE, O_N, Control, ScalpelParams, ScalpelState, enter, leave, step,
)

log = logging.getLogger("cutkit.haptics")

#: Haptic rate, Hz.
RATE_HZ = 1000
#: A stall of up to this many periods (the machine's scheduler, a page fault)
#: is caught up tick by tick, so the loop still runs 1000 force-model ticks a
#: second; after a longer one the loop resynchronises and those ticks are lost
#: (counted in ``resyncs``).  The periods the device sees show the stall.
MAX_CATCH_UP_PERIODS = 20
#: The loop sleeps until this long before a deadline, then busy-waits (s).
SPIN_S = 0.0002
#: Without a simulation update for this long the force ramps down (s).
WATCHDOG_TIMEOUT_S = 0.1
#: Time the watchdog takes to ramp the force from full to zero (s).
WATCHDOG_RAMP_S = 0.2
#: A frame left incomplete this long closes its connection (s).
PARTIAL_FRAME_TIMEOUT_S = 2.0
#: A device that has not read its force frames for this many ticks is closed.
MAX_DROPPED_TICKS = 2000
#: Receive buffer per connection (bytes); a read takes at most this much per tick.
RECV_CAPACITY = 16384
#: Ticks between housekeeping passes (timeouts).
HOUSEKEEPING_TICKS = 100
#: Below this length a plane normal from the simulation is "not given".
NORMAL_EPS = 1e-12


class _Conn:
    """One client connection and its preallocated receive buffer."""

    __slots__ = ("sock", "peer", "cid", "role", "buf", "view", "r", "w", "last_seq", "last_ts",
                 "pending", "dropped", "partial_since", "want_state", "out", "closed", "flags")

    def __init__(self, sock, peer, cid):
        self.sock = sock
        self.peer = peer
        self.cid = cid
        self.role = 0
        self.buf = bytearray(RECV_CAPACITY)
        self.view = memoryview(self.buf)
        self.r = 0
        self.w = 0
        self.last_seq = 0
        self.last_ts = 0
        self.pending = b""
        self.dropped = 0
        self.partial_since = 0
        self.want_state = False
        self.out = bytearray(P.HEADER_SIZE + P.FORCE_PAYLOAD.size)
        self.closed = False
        self.flags = 0  # HELLO flags granted


def material_from_model(path, name: str = "muscle") -> dict:
    """The material row called ``name`` (or with that label number) of a model file.

    Returns
    -------
    dict
        ``label``, ``name`` and every column of MATERIAL_FIELDS.
    """
    from cutkit.io.model_h5 import read_model

    rows = read_model(path).materials.rows()
    for row in rows:
        if row["name"] == name or (name.isdigit() and row["label"] == int(name)):
            return row
    names = ", ".join(r["name"] for r in rows) or "none"
    raise InputError(f"{path}: no material named {name!r} (materials: {names})")


class HapticsServer:
    """The haptic service.  Bind in the constructor, run with :meth:`serve`.

    Parameters
    ----------
    host : str
        Address to bind; loopback unless told otherwise.
    port : int
        0 picks a free port (see :attr:`address`).
    params : ScalpelParams, optional
        Scalpel and default material; the simulation may send another material.
    rate_hz : int
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, params: ScalpelParams | None = None,
                 rate_hz: int = RATE_HZ):
        self.params = params or ScalpelParams()
        self._params_array = self.params.array()
        self._material = self.params.material()
        self.rate_hz = int(rate_hz)
        self._stop = threading.Event()
        self._sel = selectors.DefaultSelector()
        try:
            lsock = socket.create_server((host, port), backlog=16)
        except OSError as err:
            reason = os.strerror(err.errno) if err.errno else str(err)
            raise InputError(f"cannot listen on {host}:{port}: {reason}") from None
        lsock.setblocking(False)
        self._lsock = lsock
        self._sel.register(lsock, selectors.EVENT_READ, None)
        self._conns: list[_Conn] = []
        self._next_cid = 1
        # scalpel model: state, control and buffers, allocated once
        self.state = ScalpelState()
        self.control = Control()
        self.f_sim = np.zeros(3)
        self.out = np.zeros(N_OUT)
        self._pose = None  # newest POSE payload of this tick
        self._pose_meta = (0, 0, 0)  # device client id, sequence, timestamp of that POSE
        self._forward = bytearray(P.HEADER_SIZE + P.DEVICE_POSE_PAYLOAD.size)  # DEVICE_POSE, packed per tick
        self._sim = None  # newest SIM_UPDATE payload of this tick
        self._last_sim_ns = None
        self.gain = 0.0
        self.tick = 0
        self.stats = {"ticks": 0, "resyncs": 0, "rejected": 0, "connections": 0}

    @property
    def address(self) -> tuple[str, int]:
        return self._lsock.getsockname()[:2]

    def request_stop(self, *_args) -> None:
        """Ask the loop to finish its tick and shut down (safe from a signal handler)."""
        self._stop.set()

    # ------------------------------------------------------------------ loop
    def serve(self, install_signals: bool = False, duration_s: float | None = None) -> dict:
        """Run the 1 kHz loop until :meth:`request_stop` (or SIGINT/SIGTERM).

        Returns the loop statistics (ticks, resyncs, rejected frames, connections).
        """
        old = {}
        if install_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, self.request_stop)
        # warm the kernel (numba dispatch, cache load) before the first deadline
        step(self._params_array, ScalpelState(), Control(), self.f_sim, self.out)
        period = 1_000_000_000 // self.rate_hz
        spin = int(SPIN_S * 1e9)
        clock = time.perf_counter_ns
        end = None if duration_s is None else clock() + int(duration_s * 1e9)
        gc.collect()
        gc.freeze()
        gc.disable()
        try:
            deadline = clock() + period
            while not self._stop.is_set():
                rest = deadline - clock()
                if rest > spin:
                    time.sleep((rest - spin) * 1e-9)
                while clock() < deadline:
                    pass
                now = clock()
                self._tick(now)
                deadline += period
                late = clock() - deadline
                if late > MAX_CATCH_UP_PERIODS * period:
                    deadline = clock()  # resynchronise: no long burst of catch-up ticks
                    self.stats["resyncs"] += 1
                if end is not None and now >= end:
                    break
        finally:
            gc.enable()
            gc.unfreeze()
            self._shutdown()
            for sig, handler in old.items():
                signal.signal(sig, handler)
        self.stats["ticks"] = self.tick
        return dict(self.stats)

    def _tick(self, now: int) -> None:
        for key, _ in self._sel.select(0):
            if key.data is None:
                self._accept()
            else:
                try:
                    self._read(key.data, now)
                except Exception:  # a bug must cost one connection, never the service
                    log.exception("client %d (%s): internal error; closing the connection", key.data.cid,
                                  key.data.peer)
                    self._close(key.data)
        new_pose = self._pose
        if new_pose is not None:
            v = new_pose
            self.control.set(v[0:3], v[3:6], v[6:9])
            self._pose = None
        if self._sim is not None:
            self._apply_sim(self._sim)
            self._sim = None
        # watchdog: ramp towards 1 while the simulation is fresh, else towards 0
        fresh = self._last_sim_ns is not None and now - self._last_sim_ns < WATCHDOG_TIMEOUT_S * 1e9
        ramp = 1.0 / (WATCHDOG_RAMP_S * self.rate_hz)
        self.gain = min(1.0, self.gain + ramp) if fresh else max(0.0, self.gain - ramp)
        step(self._params_array, self.state, self.control, self.f_sim, self.out)
        if not math.isfinite(self.out[O_FORCE] + self.out[O_FORCE + 1] + self.out[O_FORCE + 2]):
            # absurd (finite but huge) input overflowed: drop contact rather than render NaN
            log.error("non-finite scalpel force (pose %s); the blade leaves the tissue", self.control.tip)
            leave(self.state)
            self.state.proxy[:] = 0.0
            self.out[:] = 0.0
        self.tick += 1
        self._send_all(now)
        if new_pose is not None:
            self._forward_pose(new_pose, now)
        if self.tick % HOUSEKEEPING_TICKS == 0:
            self._housekeeping(now)

    # ------------------------------------------------------------------ connections
    def _accept(self) -> None:
        while True:
            try:
                sock, peer = self._lsock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as err:
                log.warning("accept failed: %s", err)
                return
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn = _Conn(sock, f"{peer[0]}:{peer[1]}", self._next_cid)
            self._next_cid += 1
            self._conns.append(conn)
            self._sel.register(sock, selectors.EVENT_READ, conn)
            self.stats["connections"] += 1
            log.info("client %d connected from %s", conn.cid, conn.peer)

    def _close(self, conn: _Conn, reason: str | None = None, farewell: bytes = b"") -> None:
        if conn.closed:
            return
        conn.closed = True
        try:
            if farewell:
                conn.sock.send(farewell)
            # FIN after the farewell; drain what the peer already sent so that
            # close() does not turn into a reset that could discard the farewell
            conn.sock.shutdown(socket.SHUT_WR)
            conn.sock.recv(65536)
        except OSError:
            pass
        try:
            self._sel.unregister(conn.sock)
        except (KeyError, ValueError):
            pass
        try:
            conn.sock.close()
        except OSError:
            pass
        self._conns.remove(conn)
        if reason:
            log.info("client %d (%s) closed: %s", conn.cid, conn.peer, reason)

    def _reject(self, conn: _Conn, err: P.FrameError) -> None:
        self.stats["rejected"] += 1
        log.warning("client %d (%s): rejected frame: %s; closing the connection", conn.cid, conn.peer, err)
        self._close(conn, None, P.error_frame(err.code, str(err)))

    def _read(self, conn: _Conn, now: int) -> None:
        try:
            n = conn.sock.recv_into(conn.view[conn.w:])
        except (BlockingIOError, InterruptedError):
            return
        except OSError as err:
            self._close(conn, f"connection error: {err}")
            return
        if n == 0:
            if conn.w > conn.r:
                self._reject(conn, P.FrameError(f"truncated frame: connection closed after {conn.w - conn.r} "
                                                f"bytes of a frame", P.E_TRUNCATED))
            else:
                self._close(conn, "disconnected")
            return
        conn.w += n
        try:
            self._parse(conn, now)
        except P.FrameError as err:
            self._reject(conn, err)

    def _parse(self, conn: _Conn, now: int) -> None:
        buf = conn.buf
        r, w = conn.r, conn.w
        while w - r >= P.HEADER_SIZE and not conn.closed:
            ftype, length, seq, ts = P.check_header(buf, r)
            end = r + P.HEADER_SIZE + length
            if end > w:
                break
            self._handle(conn, ftype, r + P.HEADER_SIZE, length, seq, ts, now)
            r = end
        if conn.closed:
            return
        if r == w:
            conn.r = conn.w = 0
            conn.partial_since = 0
        else:
            if r > 0:  # keep the incomplete frame at the front of the buffer
                buf[: w - r] = buf[r:w]
                conn.r, conn.w = 0, w - r
            if conn.partial_since == 0:
                conn.partial_since = now

    def _handle(self, conn: _Conn, ftype: int, off: int, length: int, seq: int, ts: int, now: int) -> None:
        buf = conn.buf
        if conn.role == 0:
            if ftype != P.HELLO:
                raise P.FrameError(f"expected HELLO first, got {P.TYPE_NAMES[ftype]}", P.E_UNEXPECTED)
            role, flags = P.HELLO_FLAGS_PAYLOAD.unpack_from(buf, off)
            if role not in P.ROLE_NAMES:
                raise P.FrameError(f"unknown role {role}", P.E_BAD_VALUE)
            conn.role = role
            # unknown flag bits are ignored; only what this server grants is echoed
            conn.flags = flags & P.HELLO_FORWARD_POSES if role == P.ROLE_SIMULATION else 0
            self._send(conn, P.frame(P.WELCOME, P.WELCOME_FLAGS_PAYLOAD.pack(role, conn.flags, conn.cid, self.rate_hz),
                                     seq=seq, ts=now))
            log.info("client %d (%s) is a %s", conn.cid, conn.peer, P.ROLE_NAMES[role])
            return
        if ftype == P.POSE and conn.role == P.ROLE_DEVICE:
            v = P.POSE_PAYLOAD.unpack_from(buf, off)
            if not all(map(math.isfinite, v[:9])):
                raise P.FrameError("POSE with a non-finite number", P.E_BAD_VALUE)
            self._pose = v  # newest state wins
            self._pose_meta = (conn.cid, seq, ts)
            conn.last_seq = seq
            conn.last_ts = ts
        elif ftype == P.SIM_UPDATE and conn.role == P.ROLE_SIMULATION:
            v = P.SIM_PAYLOAD.unpack_from(buf, off)
            if not all(map(math.isfinite, v[:18])):
                raise P.FrameError("SIM_UPDATE with a non-finite number", P.E_BAD_VALUE)
            if any(x < 0.0 for x in v[9:18]):
                raise P.FrameError("SIM_UPDATE with a negative material parameter", P.E_BAD_VALUE)
            self._sim = v  # newest state wins
            self._last_sim_ns = now
            conn.want_state = True
            conn.last_seq = seq
            conn.last_ts = ts
        elif ftype == P.BYE:
            self._close(conn, "said BYE")
        else:
            raise P.FrameError(f"{P.TYPE_NAMES[ftype]} is not allowed from a {P.ROLE_NAMES[conn.role]} client",
                               P.E_UNEXPECTED)

    def _apply_sim(self, v) -> None:
        self.f_sim[:] = v[6:9]
        material = tuple(v[9:18])
        if material[0] > 0.0 and material != self._material:  # eta = 0: keep the current material
            try:
                kw = dict(zip(("eta", "F_enter", "mu_static", "mu_dynamic", "rho_dynamic", "alpha_static",
                               "alpha_dynamic", "c_edge", "c_shape"), material))
                params = ScalpelParams(**{**self.params.__dict__, **kw})
            except InputError as err:
                log.warning("ignored a material from the simulation: %s", err)
            else:
                self.params = params
                self._params_array[:] = params.array()
                self._material = material
        if v[18]:
            normal = v[3:6]
            if math.sqrt(sum(x * x for x in normal)) < NORMAL_EPS:
                normal = np.cross(self.control.a, self.control.n)  # the device's blade plane
                if np.linalg.norm(normal) < NORMAL_EPS:
                    normal = (0.0, 0.0, 1.0)
            if self.state.code[0] == FREE:
                enter(self.state, v[0:3], normal, self.control.tip)
            else:  # the tissue moved: newest entry point and plane win
                self.state.entry[:] = v[0:3]
                self.state.normal[:] = normal
                self.state.normal /= np.linalg.norm(self.state.normal)
        elif self.state.code[0] != FREE:
            leave(self.state)

    # ------------------------------------------------------------------ output
    def _send_all(self, now: int) -> None:
        o = self.out
        g = self.gain
        s = self.state
        values = (o[O_FORCE] * g, o[O_FORCE + 1] * g, o[O_FORCE + 2] * g,
                  s.proxy[0], s.proxy[1], s.proxy[2],
                  o[O_A], o[O_A + 1], o[O_A + 2], o[O_N], o[O_N + 1], o[O_N + 2], g)
        code = int(s.code[0])
        for conn in tuple(self._conns):
            if conn.role == P.ROLE_DEVICE:
                ftype = P.FORCE
            elif conn.role == P.ROLE_SIMULATION and conn.want_state:
                ftype = P.STATE
                conn.want_state = False
            else:
                continue
            out = conn.out
            P.pack_header(out, ftype, P.FORCE_PAYLOAD.size, self.tick, now)
            P.FORCE_PAYLOAD.pack_into(out, P.HEADER_SIZE, *values, conn.last_ts, self.tick, conn.last_seq, code)
            self._send(conn, out)

    def _forward_pose(self, v, now: int) -> None:
        """Send this tick's device pose to every simulation that asked for it."""
        out = None
        for conn in tuple(self._conns):
            if conn.role != P.ROLE_SIMULATION or not conn.flags & P.HELLO_FORWARD_POSES:
                continue
            if out is None:
                out = self._forward
                cid, seq, ts = self._pose_meta
                P.pack_header(out, P.DEVICE_POSE, P.DEVICE_POSE_PAYLOAD.size, self.tick, now)
                P.DEVICE_POSE_PAYLOAD.pack_into(out, P.HEADER_SIZE, *v[:9], v[9], cid, ts, seq & 0xFFFFFFFF,
                                                self.tick)
            self._send(conn, out)

    def _send(self, conn: _Conn, data) -> None:
        try:
            if conn.pending:
                n = conn.sock.send(conn.pending)
                conn.pending = conn.pending[n:]
                if conn.pending:
                    conn.dropped += 1  # still backed up: this tick's frame is dropped
                    return
            n = conn.sock.send(data)
            if n < len(data):
                conn.pending = bytes(data[n:])
            conn.dropped = 0
        except (BlockingIOError, InterruptedError):
            conn.dropped += 1
        except OSError as err:
            self._close(conn, f"send failed: {err}")

    def _housekeeping(self, now: int) -> None:
        for conn in tuple(self._conns):
            if conn.partial_since and now - conn.partial_since > PARTIAL_FRAME_TIMEOUT_S * 1e9:
                self._reject(conn, P.FrameError(f"frame incomplete for over {PARTIAL_FRAME_TIMEOUT_S:g} s",
                                                P.E_TIMEOUT))
            elif conn.dropped > MAX_DROPPED_TICKS:
                log.warning("client %d (%s) has not read its frames for %d ticks; closing",
                            conn.cid, conn.peer, conn.dropped)
                self._close(conn)

    def _shutdown(self) -> None:
        bye = P.frame(P.BYE)
        for conn in tuple(self._conns):
            self._close(conn, "server shutting down", bye)
        try:
            self._sel.unregister(self._lsock)
        except (KeyError, ValueError):
            pass
        self._lsock.close()
        self._sel.close()
