"""A live session: a :class:`~cutkit.simulate.session.Session` on the wall clock (or a stepped one).

Three activities, as in the paper's Fig. 1 (section 2):

* the **force model** at 1 kHz: in ``cutkit haptics serve`` for a
  :class:`~cutkit.live.HapticsPoseSource` (the session sends a SIM_UPDATE
  every loop; a copy of the model, :class:`MirroredForceModel`, ticked with
  every forwarded device pose, gives the cut its proxy), in this process
  for the other sources (every elapsed millisecond is one tick with the
  newest pose);
* **relaxation** in its own thread (:class:`RelaxThread`), continuously:
  the element kernels release the GIL, so it runs beside the main loop;
  it holds the session's lock for one step at a time;
* the **main loop**: poses, the entry and leave tests, the cut at the
  geometry rate (the topology goes over under the lock), frames to the
  views, recording.

Every session records the poses it acted on (``trajectory.csv``),
``forces.csv``, ``summary.json`` and the cut ``model.h5``; ``cutkit
simulate model.h5 --trajectory OUT/trajectory.csv`` replays it.

On a :class:`~cutkit.simulate.clock.SteppedClock` (``clock=``) the loop
does each tick whole before the clock moves, the relaxation in its own
thread and a stroke's rebase waited for: the session then cuts what that
replay cuts, to the bit (docs/live.md, "The stepped clock").
"""

from __future__ import annotations

import threading
from pathlib import Path

from cutkit.simulate.live_loop import LiveLoop
from cutkit.simulate.live_parts import KEEP_ALIVE_S, MAX_CATCH_UP_TICKS, MirroredForceModel, RelaxThread, TickMeter
from cutkit.threads import one_blas_thread

__all__ = ["KEEP_ALIVE_S", "MAX_CATCH_UP_TICKS", "MirroredForceModel", "RelaxThread", "TickMeter", "run_live"]


def run_live(model, source, views, out_dir, opt=None, *, max_seconds: float | None = None, fps: float = 30.0,
             idle_end_s: float = 0.5, stop: threading.Event | None = None, model_path: str | None = None,
             on_frame=None, until_idle_s: float | None = None, on_start=None, clock=None) -> dict:
    """Cut ``model`` live with the poses of ``source``; show it in ``views``; record into ``out_dir``.

    Parameters
    ----------
    model : TetModel
    source : PoseSource
    views : list of View
    out_dir : path-like
        ``trajectory.csv``, ``forces.csv``, ``summary.json``, ``model.h5``.
    opt : SimulateOptions
        Material model, geometry rate, blade length ... (``fps``, ``hold_s`` unused).
    max_seconds : float, optional
        End after this many seconds.
    fps : float
        Frames per second to the views.
    idle_end_s : float
        Once the source is finished the tissue goes on relaxing for this long.
    until_idle_s : float, optional
        The source counts as finished once the tissue has relaxed this long (its own,
        simulated time, which lags the wall clock on a slow machine) past the last pose.
    stop : threading.Event, optional
        Set it to end the session.
    on_frame : callable(LiveFrame), optional
        Called after each frame went to the views.
    on_start : callable(), optional
        Called once the model has settled and the loop starts.
    clock : WallClock or SteppedClock, optional
        The time the session reads (:mod:`cutkit.simulate.clock`); the wall clock by default.
        On a :class:`~cutkit.simulate.clock.SteppedClock` (given to the source too) every loop
        pass is one haptic tick done whole: ``max_seconds``, ``idle_end_s`` and the rates are
        in its seconds, and the session cuts what ``cutkit simulate`` replaying its recording cuts.

    Returns
    -------
    summary : dict
        What ``summary.json`` holds: the simulate keys and ``live`` (rates, latency).
    """
    from cutkit.threads import threads_in_this_thread, worker_threads

    # a core stays for drawing (cutkit.threads.worker_threads); the same sums on every machine (BLAS)
    with threads_in_this_thread(worker_threads()), one_blas_thread():
        return _run_live(model, source, views, out_dir, opt, max_seconds=max_seconds, fps=fps,
                         idle_end_s=idle_end_s, stop=stop, model_path=model_path, on_frame=on_frame,
                         until_idle_s=until_idle_s, on_start=on_start, clock=clock)


def _run_live(model, source, views, out_dir, opt, *, max_seconds, fps, idle_end_s, stop, model_path, on_frame,
              until_idle_s, on_start, clock) -> dict:
    """:func:`run_live` with BLAS on one thread."""
    loop = LiveLoop(model, source, views, Path(out_dir), opt, fps=fps, model_path=model_path, clock=clock)
    return loop.run(max_seconds=max_seconds, idle_end_s=idle_end_s, stop=stop, on_frame=on_frame,
                    until_idle_s=until_idle_s, on_start=on_start)
