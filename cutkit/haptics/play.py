"""A reference device client: stream a trajectory file's poses to the haptics service.

``cutkit haptics play`` stands in for a force-feedback device in tests and
demonstrations.  It connects in the *device* role and sends one POSE frame
per period (1 kHz by default) on absolute deadlines, as a device's servo
loop does; pose k is the trajectory's pose at ``k / rate`` s
(``Trajectory.pose_at``).  It reads (and counts) the FORCE frames the
service sends back, so the service never drops it as a client that does
not read.

Frames: a trajectory row has ``a`` along the blade (handle to tip) and
``n`` towards the sharp edge; a POSE frame has the force model's frame,
forward cutting direction first.  So a POSE carries ``(tip, n_traj,
a_traj)`` (docs/haptics-protocol.md).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from cutkit.errors import InputError
from cutkit.haptics import protocol as P
from cutkit.haptics.client import HapticsClient

#: The loop sleeps until this long before a deadline, then busy-waits (s).
SPIN_S = 0.0002
#: Send times kept for the period statistics (the newest ones, about 17 min at 1 kHz).
SEND_HISTORY = 1 << 20


def pose_frame_payload(tip, a_traj, n_traj, buttons: int = 0) -> bytes:
    """The POSE payload for a trajectory pose (tip, a, n in the trajectory's convention).

    Parameters
    ----------
    tip : (3,) float
        Blade tip, mm.
    a_traj : (3,) float
        Along the blade, handle to tip.
    n_traj : (3,) float
        Towards the sharp edge.
    buttons : int

    Returns
    -------
    bytes
        80 bytes: tip, the forward direction (``n_traj``), the along-blade
        direction (``a_traj``), buttons.
    """
    return P.POSE_PAYLOAD.pack(*map(float, tip), *map(float, n_traj), *map(float, a_traj), int(buttons))


def play_trajectory(traj, host: str, port: int, rate_hz: float = 1000.0, loop: bool = False,
                    stop: threading.Event | None = None, max_seconds: float | None = None) -> dict:
    """Stream ``traj`` to a haptics server as a device, paced to the wall clock.

    Parameters
    ----------
    traj : cutkit.cutting.trajectory.Trajectory
    host, port : address of ``cutkit haptics serve``
    rate_hz : float
        Poses per second.
    loop : bool
        Start again from the first row after the last (until ``stop``).
    stop : threading.Event, optional
        Set it to end the stream after the current period.
    max_seconds : float, optional
        End after this long whatever ``loop`` says.

    Returns
    -------
    dict
        ``poses_sent``, ``seconds``, ``rate_hz`` (poses per wall second),
        ``period_p50_ms`` / ``period_p99_ms`` / ``period_max_ms`` (between
        sends), ``resyncs`` (periods skipped after a stall), ``forces_received``,
        ``max_force_n``, ``loops``, ``ended`` (``"trajectory"``, ``"stopped"``
        or ``"server closed"``).
    """
    if not rate_hz > 0:
        raise InputError(f"rate must be positive, got {rate_hz}")
    stop = stop or threading.Event()
    client = HapticsClient(host, port, "device")
    try:
        result = _stream(client, traj, float(rate_hz), loop, stop, max_seconds)
    finally:
        client.close()
    return result


def _stream(client, traj, rate_hz, loop, stop, max_seconds) -> dict:
    period = int(round(1e9 / rate_hz))
    spin = int(SPIN_S * 1e9)
    clock = time.perf_counter_ns
    t_first = float(traj.t[0])
    n_per_pass = int(np.floor(traj.duration * rate_hz + 1e-9)) + 1  # k = 0 .. last row
    sends = np.zeros(SEND_HISTORY, np.int64)
    count = 0
    forces, max_force, loops, resyncs, k = 0, 0.0, 0, 0, 0
    ended = "trajectory"
    start = clock()
    end = None if max_seconds is None else start + int(max_seconds * 1e9)
    deadline = start
    while True:
        if stop.is_set():
            ended = "stopped"
            break
        if end is not None and deadline > end:
            ended = "stopped"
            break
        rest = deadline - clock()
        if rest > spin:
            time.sleep((rest - spin) * 1e-9)
        while clock() < deadline:
            pass
        # the last pose of a pass is exactly the last row, whatever the rate
        t = traj.t[-1] if k == n_per_pass - 1 else t_first + k / rate_hz
        tip, a, n = traj.pose_at(t)
        client.seq += 1
        client.send_raw(P.frame(P.POSE, pose_frame_payload(tip, a, n), client.seq, clock()))
        sends[count % SEND_HISTORY] = clock()
        count += 1
        for ftype, _, _, payload in client.drain():
            if ftype == P.FORCE:
                forces += 1
                f = P.FORCE_PAYLOAD.unpack(payload)[:3]
                max_force = max(max_force, float(np.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2)))
            elif ftype == P.BYE:
                ended = "server closed"
        if ended == "server closed":
            break
        k += 1
        if k == n_per_pass:
            loops += 1
            if not loop:
                break
            k = 0
        deadline += period
        late = clock() - deadline
        if late > period:  # a stall: start afresh from now, skipping the missed poses
            skipped = late // period
            resyncs += 1
            deadline += skipped * period
            k = min(k + int(skipped), n_per_pass - 1)  # the last row is always sent
    if count > SEND_HISTORY:  # oldest first
        sends = np.roll(sends, -(count % SEND_HISTORY))
    return _stats(sends[:min(count, SEND_HISTORY)], count, forces, max_force, loops, resyncs, ended)


def _stats(ts, count, forces, max_force, loops, resyncs, ended) -> dict:
    periods = np.diff(ts) * 1e-6
    seconds = (ts[-1] - ts[0]) * 1e-9 if ts.size > 1 else 0.0

    def q(p):
        return float(np.percentile(periods, p)) if periods.size else float("nan")

    return {
        "poses_sent": int(count),
        "seconds": float(seconds),
        "rate_hz": (ts.size - 1) / seconds if seconds > 0 else 0.0,
        "period_p50_ms": q(50),
        "period_p99_ms": q(99),
        "period_max_ms": float(periods.max()) if periods.size else float("nan"),
        "resyncs": int(resyncs),
        "forces_received": int(forces),
        "max_force_n": float(max_force),
        "loops": int(loops),
        "ended": ended,
    }
