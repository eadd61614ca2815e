"""A live session's rebase between strokes, off the thread that draws, sends and feels.

When a stroke that cut ends, :meth:`Session.rebase <cutkit.simulate.session.Session.rebase>`
makes the live tets the original ones of a fresh cut state; it rebuilds the
cut mesh, the element model and the surface hierarchy, O(model): seconds on
the demo knee on a loaded machine.  Run in the main loop it stopped frames,
OpenIGTLink messages and the session's force ticks for that long, and the
poses that came meanwhile were met in one jump.

:class:`BackgroundRebase` runs it in its own thread under the session's
lock (the relaxation waits for it, as for a cut).  Meanwhile the main loop
touches neither the cut mesh nor the tissue: it draws the tissue as it was
when the stroke ended (:class:`StillPicture`) with the blade at the newest
pose, keeps the haptics service's force on, and holds every pose that
arrives.  Once the rebase is done the held poses are ticked and cut in the
order and on the clock they came, so the session does what a replay of its
recording (``cutkit simulate --trajectory``) does: the rebase first, then
the poses after it.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

__all__ = ["BackgroundRebase", "StillPicture", "CATCH_UP_BUDGET_S"]

#: Most seconds of held poses' ticks and cuts one pass of the main loop runs before it draws
#: again: a frame period at 30 fps, less what a frame costs.
CATCH_UP_BUDGET_S = 0.02


@dataclass
class StillPicture:
    """What the views show of the tissue while a rebase runs: the tissue when the stroke ended.

    Attributes
    ----------
    points : (n, 3) float64
    rgb : (n, 3) uint8 or None
    tets_cut : int
    """

    points: np.ndarray
    rgb: np.ndarray | None
    tets_cut: int


class BackgroundRebase:
    """:meth:`Session.rebase` in its own thread, one at a time.

    Parameters
    ----------
    session : Session
    clock : callable
        Seconds now, the session clock's scale (``time.perf_counter`` by default): the
        :attr:`windows`.

    Attributes
    ----------
    busy : bool
        A rebase started and not yet collected by :meth:`done`.
    wall_s : list of float
        Wall seconds of each rebase, waiting for the lock included.
    windows : list of (float, float)
        ``clock()`` at the start and the end of each rebase.
    error : BaseException or None
        What the last rebase raised (raised again by :meth:`done`).
    """

    def __init__(self, session, clock=time.perf_counter):
        self.session, self.clock = session, clock
        self.thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self.wall_s: list[float] = []
        self.windows: list[tuple[float, float]] = []

    @property
    def busy(self) -> bool:
        return self.thread is not None

    def start(self) -> None:
        """Start the rebase (the caller no longer touches the cut mesh or the tissue until :meth:`done`)."""
        if self.thread is not None:
            raise RuntimeError("a rebase is already running")
        self.thread = threading.Thread(target=self._run, name="cutkit-rebase", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        from cutkit.threads import become_live_worker

        become_live_worker()  # its own thread count, and drawing, sending and feeling first
        s = self.session
        t0, w0 = self.clock(), time.perf_counter()
        try:
            s.rebase_and_look()
        except BaseException as err:  # handed to the main loop by done()
            self.error = err
        self.wall_s.append(time.perf_counter() - w0)
        self.windows.append((t0, self.clock()))

    def done(self) -> bool:
        """True once a started rebase has finished (then no longer :attr:`busy`); raises its error."""
        if self.thread is None or self.thread.is_alive():
            return False
        self.wait()
        return True

    def wait(self) -> None:
        """Wait for a rebase in flight; raises its error."""
        if self.thread is None:
            return
        self.thread.join()
        self.thread = None
        if self.error is not None:
            err, self.error = self.error, None
            raise err
