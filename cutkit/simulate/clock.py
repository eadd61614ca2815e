"""The clocks a live session (:func:`cutkit.simulate.live.run_live`) can run on.

A live session reads time to decide which pose it samples, how far the
relaxation goes between two cuts and when it ends.  On the wall clock
(:class:`WallClock`, the default) those depend on how fast the machine is
at that moment: what a person at the device sees, and what no test can pin.
On a :class:`SteppedClock` time moves only when the session's loop says so,
one haptic tick per pass, and the loop does each pass's work whole before
the clock moves (docs/live.md, "The stepped clock"): the session is then a
function of its inputs, and ``cutkit simulate`` replaying its recording
does the same ticks, cuts and relaxation in the same order.
"""

from __future__ import annotations

import time

from cutkit.errors import InputError
from cutkit.simulate.run import HAPTIC_DT

__all__ = ["SteppedClock", "WallClock", "as_clock"]


class WallClock:
    """The wall clock (``time.perf_counter``): a live session in real time.

    Attributes
    ----------
    stepped : bool
        False: the session's threads run beside its loop, and what each
        does between two poses depends on the machine's speed.
    """

    stepped = False

    def now(self) -> float:
        """Seconds on ``time.perf_counter``'s scale (its origin is arbitrary)."""
        return time.perf_counter()

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of wall time."""
        time.sleep(seconds)


class SteppedClock:
    """A clock that moves only when the session's loop has finished a pass: one ``step`` each.

    The time after ``k`` steps is ``k * step`` exactly (a product, not a sum
    of steps: the same float as ``cutkit simulate``'s tick ``k``), starting
    at 0.  Give the same clock to the pose source and the session::

        clock = SteppedClock()
        source = TrajectoryPoseSource(trajectory, clock=clock)
        run_live(model, source, [], out, clock=clock)

    Parameters
    ----------
    step : float
        Seconds per loop pass; the haptic period (1 ms) by default, so that
        each pass is one tick of the force model, as in ``cutkit simulate``.
        A pass is one force-model tick whatever the step: with another step
        the session is as deterministic, but the force model no longer runs
        at 1 kHz of this clock and the replay of the recording differs.

    Attributes
    ----------
    stepped : bool
        True: the session relaxes and rebases in step with its loop
        (no thread runs beside it on its own time).
    steps : int
        Steps taken so far.
    """

    stepped = True

    def __init__(self, step: float = HAPTIC_DT):
        step = float(step)
        if not step > 0.0 or step == float("inf"):
            raise InputError(f"a stepped clock's step must be positive and finite, got {step} s")
        self.step = step
        self.steps = 0

    def now(self) -> float:
        """Seconds since the start: ``steps * step``."""
        return self.steps * self.step

    def advance(self) -> None:
        """One step on (the session's loop calls it at the end of each pass)."""
        self.steps += 1

    def sleep(self, seconds: float) -> None:
        """Nothing to wait for: the clock moves only by :meth:`advance`."""


def as_clock(clock) -> WallClock | SteppedClock:
    """``clock`` as a clock object: None gives a :class:`WallClock`; an object with ``now()`` is kept.

    An object with a true ``stepped`` attribute needs ``advance()`` too;
    one without ``sleep()`` gets ``time.sleep``'s waits from the loop.

    Raises
    ------
    InputError
        ``clock`` has no ``now`` method.
    """
    if clock is None:
        return WallClock()
    if not callable(getattr(clock, "now", None)):
        raise InputError(f"a session clock needs a now() method (WallClock or SteppedClock), got {type(clock).__name__}")
    if getattr(clock, "stepped", False) and not callable(getattr(clock, "advance", None)):
        raise InputError(f"a stepped session clock needs an advance() method, {type(clock).__name__} has none")
    return clock
