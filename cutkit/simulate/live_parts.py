"""What a live session (:mod:`cutkit.simulate.live`) runs beside its main loop.

The force model mirrored in process (:class:`MirroredForceModel`), the
relaxation thread (:class:`RelaxThread`) and the rate meter of each
activity (:class:`TickMeter`); :class:`cutkit.simulate.live_loop.LiveLoop`
puts them together.
"""

from __future__ import annotations

import collections
import threading
import time

import numpy as np

from cutkit.simulate.blade import InProcessScalpel

#: Most in-process force-model ticks run back to back when the loop falls behind.
MAX_CATCH_UP_TICKS = 50

#: Seconds between the SIM_UPDATEs that only keep the service's force on: a tenth of its
#: watchdog (``cutkit.haptics.server.WATCHDOG_TIMEOUT_S``, 0.1 s).  Every loop pass sent one
#: before, about 2,000 a second, which cost the main loop about a tenth of its time.
KEEP_ALIVE_S = 0.01


class MirroredForceModel(InProcessScalpel):
    """The force model in process, fed with every pose the service's model got, tick by tick.

    The service renders the device's force at 1 kHz; this copy of the same
    model (same poses in the same order, same entry, leave and material)
    gives the session the proxy at every tick, so the cut is sampled on
    the device's tick clock, as ``cutkit simulate`` replays the recorded
    poses.  Entry and leave go to the service too (SIM_UPDATE).
    """

    def __init__(self, source, blade_breadth: float):
        super().__init__(blade_breadth=blade_breadth)
        self.source = source
        self.contact = False
        self.entry = np.zeros(3)
        self.normal = np.zeros(3)
        self.sent = -np.inf  # perf_counter of the last SIM_UPDATE

    def enter(self, entry, normal, tip, material: dict) -> None:
        from cutkit.scalpel import CUT_FIELDS

        super().enter(entry, normal, tip, material)
        self.entry[:], self.normal[:] = entry, normal
        self.contact = True
        self.source.update(self.entry, self.normal, material=[material[k] for k in CUT_FIELDS], contact=True)
        self.sent = time.perf_counter()

    def leave(self) -> None:
        super().leave()
        self.contact = False
        self.source.update(self.entry, self.normal, contact=False)
        self.sent = time.perf_counter()

    def keep_alive(self) -> None:
        """A SIM_UPDATE when none went for :data:`KEEP_ALIVE_S` (the service ramps the force to zero
        ``WATCHDOG_TIMEOUT_S`` after the last one); entry and leave send theirs at once."""
        now = time.perf_counter()
        if now - self.sent >= KEEP_ALIVE_S:
            self.source.update(self.entry, self.normal, contact=self.contact)
            self.sent = now


class TickMeter:
    """The service's haptic loop as the forwarded device poses report it: rate and periods.

    Wraps the source's ``client.drain`` to see every DEVICE_POSE frame, not
    only the newest, and hands each pose to ``poses`` (a
    :class:`~cutkit.simulate.record.PoseRecorder`).  Each names the server tick that used it and the
    server's clock at that tick, so the loop's rate is ticks over server
    time, whatever frames this process missed; consecutive ticks give the
    periods.  ``clock`` (seconds, the session clock's scale) stamps each pose's arrival.
    """

    def __init__(self, source, capacity: int = 1 << 20, poses=None, clock=time.perf_counter):
        from cutkit.haptics import protocol as P
        from cutkit.haptics.client import decode_device_pose

        self.ticks = np.zeros((capacity, 2), np.int64)  # tick, server ns
        self.queue: collections.deque = collections.deque()  # (t, tip, a, n, arrival) not yet ticked
        self.n = 0
        drain = source.client.drain
        kind = P.DEVICE_POSE

        def counting_drain():
            frames = drain()
            for ftype, _seq, ts, payload in frames:
                if ftype == kind and self.n < capacity:
                    d = decode_device_pose(ts, payload, 0)
                    self.ticks[self.n] = d.tick, ts
                    self.n += 1
                    if any(d.n) and any(d.a):
                        # every pose the service's force model acted on, at its tick's time;
                        # the device frame's a is the trajectory's n and the other way round
                        tip, a, n = np.array(d.tip), np.array(d.n), np.array(d.a)
                        self.queue.append((ts / 1e9, tip, a, n, clock()))
                        if poses is not None:
                            poses.add(ts / 1e9, tip, a, n)
            return frames

        source.client.drain = counting_drain

    def rate(self) -> float:
        """Ticks per second of server time over the poses seen so far (for the screen: O(1))."""
        if self.n < 2 or self.ticks[self.n - 1, 1] <= self.ticks[0, 1]:
            return 0.0
        first, last = self.ticks[0], self.ticks[self.n - 1]
        return float((last[0] - first[0]) / ((last[1] - first[1]) / 1e9))

    def stats(self) -> dict:
        t = self.ticks[:self.n]
        if self.n < 3 or t[-1, 1] <= t[0, 1]:
            return {"haptic_hz": 0.0, "period_p99_ms": None, "periods_over_2ms": None, "haptic_ticks_seen": self.n}
        dtick, dns = np.diff(t[:, 0]), np.diff(t[:, 1]) / 1e6
        single = dns[dtick == 1]
        return {"haptic_hz": float((t[-1, 0] - t[0, 0]) / ((t[-1, 1] - t[0, 1]) / 1e9)),
                "period_p50_ms": float(np.percentile(single, 50)) if single.size else None,
                "period_p99_ms": float(np.percentile(single, 99)) if single.size else None,
                "periods_over_2ms": float(np.mean(single > 2.0)) if single.size else None,
                "haptic_ticks_seen": int(self.n)}


class RelaxThread(threading.Thread):
    """Relaxation on the wall clock in its own thread, one step per hold of the session's lock.

    On a stepped clock the thread is not started: the session's loop calls
    :meth:`relax_here` at each geometry update instead (docs/live.md, "The
    stepped clock").

    Parameters
    ----------
    session : Session
    clock : callable
        Session seconds now.
    chunk_s : float
        Most tissue time one hold of the lock advances.
    """

    def __init__(self, session, clock, chunk_s: float):
        super().__init__(name="cutkit-relaxation", daemon=True)
        self.session, self.clock, self.chunk_s = session, clock, float(chunk_s)
        self.f_ext = np.zeros((session.tis.n_nodes, 3))
        self.stop = threading.Event()
        self.steps = 0
        self.step_s: list[float] = []
        self.error: BaseException | None = None

    def run(self) -> None:
        from cutkit.threads import become_live_worker

        become_live_worker()  # its own thread count, and drawing, sending and feeling first
        s = self.session
        try:
            while not self.stop.is_set():
                before = s.tis.time
                until = min(self.clock(), before + self.chunk_s)
                t1 = time.perf_counter()
                s.relax.advance(self.f_ext, until, yield_to_cut=True)
                if s.tis.time == before:
                    self.stop.wait(0.001)
                    continue
                self.steps += 1
                self.step_s.append(time.perf_counter() - t1)
        except BaseException as err:  # handed to the main loop, which raises it
            self.error = err

    def relax_here(self, until: float) -> None:
        """Relax to ``until`` (session seconds) in the caller's thread, with :attr:`f_ext`, and refit
        the surface hierarchy while the blade is out: ``cutkit simulate``'s step after each cut."""
        t1 = time.perf_counter()
        self.session.relax_to(self.f_ext, until)
        self.steps += 1
        self.step_s.append(time.perf_counter() - t1)

    def halt(self) -> None:
        self.stop.set()
        if self.ident is not None:  # started (never on a stepped clock)
            self.join(timeout=30.0)

