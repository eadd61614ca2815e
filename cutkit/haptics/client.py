"""A small client of the haptics service, a server spawner and the 1 kHz bench."""

from __future__ import annotations

import contextlib
import os
import select
import socket
import subprocess
import sys
import time
from typing import NamedTuple

import numpy as np

from cutkit.errors import InputError, ProtocolError
from cutkit.haptics import protocol as P

#: How long a client waits for the server's WELCOME, s.
CONNECT_TIMEOUT_S = 5.0
#: The bench device sends its pose this long before the server's next tick, s.
BENCH_LEAD_S = 0.0003


class ForceFrame(NamedTuple):
    """A decoded FORCE (to a device) or STATE (to a simulation) frame."""

    type: int
    seq: int  # server tick (low 32 bits)
    server_ns: int  # server clock at the tick
    force: tuple  # N, watchdog gain applied
    proxy: tuple  # mm
    a: tuple
    n: tuple
    gain: float
    echo_ns: int  # timestamp of the client's newest frame the tick used
    tick: int
    echo_seq: int  # sequence number of that frame
    state: int  # FREE, STATIC, CUTTING, WITHDRAWING
    arrival_ns: int  # perf_counter_ns() when this client parsed the frame


class DevicePoseFrame(NamedTuple):
    """A decoded DEVICE_POSE frame: a device's pose as it sent it (device convention).

    ``a`` is the forward cutting direction and ``n`` the in-plane direction
    along the blade, handle to tip (docs/haptics-protocol.md, POSE).
    """

    tip: tuple  # mm
    a: tuple
    n: tuple
    buttons: int
    device_id: int  # client id of the device that sent the pose
    device_ns: int  # header timestamp of that POSE (the device's clock)
    device_seq: int  # header sequence of that POSE
    tick: int  # server tick that used it
    server_ns: int  # server clock at that tick
    arrival_ns: int  # perf_counter_ns() when this client parsed the frame


def decode_device_pose(ts: int, payload, arrival_ns: int) -> DevicePoseFrame:
    """Decode a DEVICE_POSE payload (``ts``: the frame header's timestamp)."""
    v = P.DEVICE_POSE_PAYLOAD.unpack(payload)
    return DevicePoseFrame(v[0:3], v[3:6], v[6:9], v[9], v[10], v[11], v[12], v[13], ts, arrival_ns)


class HapticsClient:
    """Connect to a haptics server as a device or a simulation.

    Parameters
    ----------
    host, port : address of the server
    role : "device" or "simulation"
    timeout : float
        Seconds to wait for the connection and the WELCOME.
    forward_poses : bool
        Simulation role only: ask the server for DEVICE_POSE frames
        (:attr:`forwards_poses` says whether it agreed).
    """

    def __init__(self, host: str, port: int, role: str = "device", timeout: float = CONNECT_TIMEOUT_S,
                 forward_poses: bool = False):
        roles = {"device": P.ROLE_DEVICE, "simulation": P.ROLE_SIMULATION}
        if role not in roles:
            raise InputError(f"unknown haptics role {role!r} (device or simulation)")
        self.role = role
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as err:
            raise InputError(f"cannot connect to the haptics server at {host}:{port}: {err.strerror or err}") from None
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._buf = bytearray()
        self.seq = 0
        flags = P.HELLO_FORWARD_POSES if forward_poses else 0
        self.sock.sendall(P.frame(P.HELLO, P.HELLO_FLAGS_PAYLOAD.pack(roles[role], flags), ts=time.perf_counter_ns()))
        ftype, _, _, payload = self.read_frame(timeout)
        if ftype != P.WELCOME:
            raise ProtocolError(f"expected WELCOME from the haptics server, got {P.TYPE_NAMES.get(ftype, ftype)}")
        _, self.flags, self.client_id, self.rate_hz = P.WELCOME_FLAGS_PAYLOAD.unpack(payload)

    @property
    def forwards_poses(self) -> bool:
        """Whether the server agreed to send this client DEVICE_POSE frames."""
        return bool(self.flags & P.HELLO_FORWARD_POSES)

    # -- sending --------------------------------------------------------------
    def send_pose(self, tip, a, n, buttons: int = 0) -> tuple[int, int]:
        """Send the device pose; returns (sequence, timestamp_ns) of the frame."""
        self.seq += 1
        ts = time.perf_counter_ns()
        payload = P.POSE_PAYLOAD.pack(*map(float, tip), *map(float, a), *map(float, n), int(buttons))
        self.sock.sendall(P.frame(P.POSE, payload, self.seq, ts))
        return self.seq, ts

    def send_sim(self, entry, normal, f_ext=(0.0, 0.0, 0.0), material=None, contact: bool = True) -> int:
        """Send a simulation update.

        Parameters
        ----------
        entry : (3,) entry point P_e, mm
        normal : (3,) blade plane normal; zeros = the device's a x n
        f_ext : (3,) external force from the tissue, N
        material : 9 floats in ``cutkit.scalpel.CUT_FIELDS`` order, or None
            to keep the server's current material.
        contact : bool
            False tells the server the blade left the tissue.
        """
        self.seq += 1
        material = (0.0,) * 9 if material is None else tuple(map(float, material))
        payload = P.SIM_PAYLOAD.pack(*map(float, entry), *map(float, normal), *map(float, f_ext), *material,
                                     1 if contact else 0)
        self.sock.sendall(P.frame(P.SIM_UPDATE, payload, self.seq, time.perf_counter_ns()))
        return self.seq

    def send_raw(self, data: bytes) -> None:
        self.sock.sendall(data)

    # -- receiving --------------------------------------------------------------
    def read_frame(self, timeout: float | None = CONNECT_TIMEOUT_S):
        """Block for one whole frame: (type, seq, timestamp_ns, payload bytes).

        Raises ProtocolError if the server sends ERROR, closes, or nothing comes in time.
        """
        self.sock.settimeout(timeout)
        while True:
            if len(self._buf) >= P.HEADER_SIZE:
                ftype, length, seq, ts = P.check_header(self._buf)
                if len(self._buf) >= P.HEADER_SIZE + length:
                    payload = bytes(self._buf[P.HEADER_SIZE:P.HEADER_SIZE + length])
                    del self._buf[:P.HEADER_SIZE + length]
                    if ftype == P.ERROR:
                        (code,) = P.ERROR_HEAD.unpack_from(payload)
                        raise ProtocolError(f"haptics server error {code}: {payload[4:].decode('utf-8', 'replace')}")
                    return ftype, seq, ts, payload
            try:
                chunk = self.sock.recv(65536)
            except (socket.timeout, BlockingIOError):
                raise ProtocolError("no frame from the haptics server in time") from None
            if not chunk:
                raise ProtocolError("the haptics server closed the connection")
            self._buf += chunk

    def drain(self) -> list:
        """Every whole frame that has arrived, without blocking.

        Returns
        -------
        list of (type, seq, timestamp_ns, payload bytes)
            In arrival order; a BYE is returned like any other frame.

        Raises
        ------
        ProtocolError
            The server sent ERROR or a malformed frame, or closed the connection.
        """
        closed = False
        self.sock.settimeout(0.0)
        while True:
            try:
                chunk = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as err:
                raise ProtocolError(f"haptics connection failed: {err.strerror or err}") from None
            if not chunk:
                closed = True
                break
            self._buf += chunk
        frames = []
        while len(self._buf) >= P.HEADER_SIZE:
            ftype, length, seq, ts = P.check_header(self._buf)
            if len(self._buf) < P.HEADER_SIZE + length:
                break
            payload = bytes(self._buf[P.HEADER_SIZE:P.HEADER_SIZE + length])
            del self._buf[:P.HEADER_SIZE + length]
            if ftype == P.ERROR:
                (code,) = P.ERROR_HEAD.unpack_from(payload)
                raise ProtocolError(f"haptics server error {code}: {payload[4:].decode('utf-8', 'replace')}")
            frames.append((ftype, seq, ts, payload))
        if closed and not any(f[0] == P.BYE for f in frames):
            raise ProtocolError("the haptics server closed the connection")
        return frames

    def read_force(self, timeout: float | None = CONNECT_TIMEOUT_S) -> ForceFrame:
        """The next FORCE or STATE frame (other frames are skipped)."""
        while True:
            ftype, seq, ts, payload = self.read_frame(timeout)
            if ftype in (P.FORCE, P.STATE):
                return decode_force(ftype, seq, ts, payload, time.perf_counter_ns())
            if ftype == P.BYE:
                raise ProtocolError("the haptics server said BYE")

    def latest(self, timeout: float = CONNECT_TIMEOUT_S) -> ForceFrame:
        """Wait for one FORCE/STATE frame, then drain what else arrived; the newest wins."""
        frame = self.read_force(timeout)
        while True:
            try:
                frame = self.read_force(0.0)
            except ProtocolError:
                return frame

    def close(self) -> None:
        try:
            self.sock.sendall(P.frame(P.BYE))
        except OSError:
            pass
        self.sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def decode_force(ftype, seq, ts, payload, arrival) -> ForceFrame:
    """A force frame from the fields of a received message.

    Parameters
    ----------
    ftype, seq, ts : int
        Frame type, sequence number and server time stamp of the message.
    payload : bytes
        The message body, :data:`cutkit.haptics.protocol.FORCE_PAYLOAD`.
    arrival : int
        Arrival time, ``time.perf_counter_ns()``.

    Returns
    -------
    ForceFrame
    """
    v = P.FORCE_PAYLOAD.unpack(payload)
    return ForceFrame(ftype, seq, ts, v[0:3], v[3:6], v[6:9], v[9:12], v[12], v[13], v[14], v[15], v[16], arrival)


# ------------------------------------------------------------------ spawning
@contextlib.contextmanager
def spawned_server(*args: str, host: str = "127.0.0.1", timeout: float = 60.0):
    """Run ``cutkit haptics serve`` on a free port in a subprocess.

    Yields ``(host, port, process)``; the server gets SIGTERM on exit.
    ``args`` are further ``serve`` options (e.g. ``"--model", "m.h5"``).
    """
    cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "serve", "--host", host, "--port", "0", *args]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        port = None
        t_end = time.monotonic() + timeout
        while port is None and time.monotonic() < t_end:
            # wait for output with a deadline: a server that never starts must not hang us
            ready, _, _ = select.select([proc.stdout], [], [], max(0.0, t_end - time.monotonic()))
            if not ready:
                break
            line = proc.stdout.readline()
            if not line:
                break
            if "listening on" in line:
                port = int(line.rsplit(":", 1)[1])
        if port is None:
            proc.kill()
            err = proc.stderr.read().strip().splitlines()
            raise InputError(f"the haptics server did not start: {err[-1] if err else 'no output'}")
        yield host, port, proc
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


# ------------------------------------------------------------------ bench
def run_bench(host: str, port: int, seconds: float = 3.0, lead_s: float = BENCH_LEAD_S) -> dict:
    """Drive a 1 kHz device against a running server and measure it.

    The device loop locks onto the server's ticks: after each FORCE frame
    it sleeps until ``lead_s`` before the next expected tick, then sends
    its pose, as a device servo loop synchronised to the service would.

    Returns
    -------
    dict
        rate_hz (FORCE frames per second received), period_p50_ms /
        period_p99_ms / period_max_ms / fraction_periods_over_2ms (intervals
        between FORCE arrivals at the client), rtt_p50_ms / rtt_p99_ms /
        rtt_max_ms (pose sent -> first FORCE computed from it received),
        server_period_p50_ms / server_period_p99_ms (intervals between the
        server's tick timestamps), and counts.
    """
    client = HapticsClient(host, port, "device")
    period_ns = 1_000_000_000 // client.rate_hz
    sent: dict[int, int] = {}
    arrivals, server_ts, rtts = [], [], []
    tip = [0.0, 0.0, 0.0]
    a, n = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    clock = time.perf_counter_ns
    try:
        first = client.read_force(5.0)
        start = clock()
        stop = start + int(seconds * 1e9)
        last = first.arrival_ns
        while clock() < stop:
            wait = last + period_ns - int(lead_s * 1e9) - clock()
            if wait > 0:
                time.sleep(wait * 1e-9)
            tip[0] = 2.0 * np.sin(2e-9 * np.pi * clock())  # a slow 1 Hz stroke
            seq, ts = client.send_pose(tip, a, n)
            sent[seq] = ts
            frame = client.read_force(1.0)
            while True:  # take every frame that is already here
                arrivals.append(frame.arrival_ns)
                server_ts.append(frame.server_ns)
                if frame.echo_seq in sent:
                    rtts.append(frame.arrival_ns - sent.pop(frame.echo_seq))
                    sent.clear()  # older poses were superseded: newest state wins
                last = frame.arrival_ns
                if len(client._buf) < P.HEADER_SIZE + P.FORCE_PAYLOAD.size:
                    break
                frame = client.read_force(0.0)
        elapsed = (arrivals[-1] - arrivals[0]) * 1e-9 if len(arrivals) > 1 else 0.0
    finally:
        client.close()
    periods = np.diff(np.array(arrivals, np.int64)) * 1e-6
    speriods = np.diff(np.array(server_ts, np.int64)) * 1e-6
    rtt = np.array(rtts, np.float64) * 1e-6

    def q(x, p):
        return float(np.percentile(x, p)) if x.size else float("nan")

    return {
        "seconds": float(seconds),
        "frames": len(arrivals),
        "rate_hz": (len(arrivals) - 1) / elapsed if elapsed > 0 else 0.0,
        "period_p50_ms": q(periods, 50),
        "period_p99_ms": q(periods, 99),
        "period_max_ms": float(periods.max()) if periods.size else float("nan"),
        "fraction_periods_over_2ms": float(np.mean(periods > 2.0)) if periods.size else float("nan"),
        "rtt_p50_ms": q(rtt, 50),
        "rtt_p99_ms": q(rtt, 99),
        "rtt_max_ms": float(rtt.max()) if rtt.size else float("nan"),
        "rtt_samples": int(rtt.size),
        "server_period_p50_ms": q(speriods, 50),
        "server_period_p99_ms": q(speriods, 99),
        "server_period_max_ms": float(speriods.max()) if speriods.size else float("nan"),
    }
