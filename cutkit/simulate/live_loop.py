"""The main loop of a live session (:func:`cutkit.simulate.live.run_live`)."""

from __future__ import annotations

import collections
import threading
import time
from pathlib import Path

import numpy as np

from cutkit.errors import InputError
from cutkit.interrupts import check_stop, safe_points
from cutkit.scalpel import FREE
from cutkit.simulate.clock import as_clock
from cutkit.simulate.live_parts import MAX_CATCH_UP_TICKS, MirroredForceModel, RelaxThread, TickMeter
from cutkit.simulate.live_rebase import CATCH_UP_BUDGET_S, BackgroundRebase, StillPicture
from cutkit.simulate.run import HAPTIC_DT, RATE_WARN_FRACTION, SimulateOptions

#: The loop's pause when it has nothing to do, s: poses come at 1 kHz and each pass takes
#: all that arrived, so a pose waits at most this long before its tick.
LOOP_IDLE_S = 0.0005
#: A stroke's rebase waits, on the wall clock, until the tissue comes to rest (``at_rest``: the
#: hybrid's resting step ended within its tolerance), the blade touches the tissue again, or this
#: many seconds have passed: the rebase holds the relaxation for about a second on the knee, so
#: started at once it kept the wound from its equilibrium that long (docs/live.md, "Between strokes").
#: The rebase stops the step in flight, so a bound shorter than the first resting step's solve (up to
#: 2 s on the demo knee with the session's drawing beside it) threw that solve away and made the
#: knee's coming to balance 4.4-4.8 s instead of about 2-3 s.
REBASE_WAIT_MAX_S = 4.0
#: Behind the poses (a backlog after a rebase, or slow cut steps), a due pose gets its own cut only
#: once the blade has moved this far since the last cut, mm: the cut of the newest then sweeps at most
#: about this far (one sweep from a held stroke's first pose to one 8 mm deep went through uncut).
MAX_SKIPPED_SWEEP_MM = 1.0
#: A cut is preceded by a frame when the newest frame is older than this many frame periods.
PRE_CUT_FRAME_AGE = 0.5
#: While device poses wait for their ticks, a frame waits until they are ticked, unless the newest
#: frame is this old, s.  A frame costs this thread what drawing costs (20-30 ms for the demo knee
#: at 1024 x 768 on a software OpenGL, 2-core machine); frames drawn between chunks of a backlog made
#: it grow through a whole stroke there (pose to picture p50 1.2 s).  The poses first keeps the
#: backlog at a pass; this bound keeps frames coming at least about 12 times a second.
MAX_FRAME_AGE_S = 0.08
#: While nothing a frame shows has moved since the last one (the tissue's nodes, the blade, the
#: force, the cut), the frame clock's frames are left out, but for one every this many seconds
#: (the status lines' rates and time); views still process their window's events.  After the hand
#: stops, the resting step's Newton iterations leave the nodes where they are for 0.3-1 s at a time,
#: and frames drawn meanwhile took the processor from it (a frame of the knee costs 20-30 ms of
#: drawing on a software OpenGL).
IDLE_FRAME_S = 0.25
#: Relaxation steps a live session makes before its clock starts: the settled tissue's resting steps
#: go on in stages to the rest tolerance (docs/relaxation.md, "Resting steps"), and a stage that
#: needs a Newton solve made after the clock started held the relaxation until the first cut
#: stopped it (on the demo knee 1.4 s, so the tissue ran that far behind the blade all through the
#: first stroke).  Three steps: the first (it has no last load to compare with, so it does not rest),
#: the first resting stage, and the last.
PRE_CLOCK_STEPS = 3


class OuterBoundary:
    """The tissue's outer boundary triangles (without the cut surface), recomputed only after a cut.

    Uncut original tets keep their boundary faces; among the sub-tets of cut
    tets a boundary face is outer when it has an original and a cut node (a
    piece of a subdivided face) or is an intact original boundary face.
    After a rebase (:meth:`rebase`) the original tets' boundary holds the
    earlier strokes' cut surface too: it is left out, and so are pieces of it.
    """

    def __init__(self, cm, faces, face_tet):
        self.cm, self.faces, self.face_tet = cm, faces, face_tet
        self.n0 = cm.n_orig_points
        self.keys = np.sort(self._key(faces))
        self.version = -1
        self.value = faces

    def _key(self, f):
        s = np.sort(f, axis=1)
        n = np.int64(self.n0)
        return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]

    def get(self, version: int):
        if version == self.version:
            return self.value
        from cutkit.cutting.rebase import cut_surface_mask
        from cutkit.mesh.topology import boundary_faces

        cm = self.cm
        cut = np.fromiter(cm.subtets.keys(), np.int64, len(cm.subtets))
        keep = ~np.isin(self.face_tet, cut)
        m0, total = cm.orig_tets.shape[0], cm.n_tets_total
        sub = cm.tet_corners[m0:total][cm.tet_alive[m0:total]]
        parts = [self.faces[keep]]
        if sub.shape[0]:
            f, _ = boundary_faces(sub)
            is_orig = f < self.n0
            mixed = is_orig.any(axis=1) & ~is_orig.all(axis=1)
            mixed[mixed] = ~cut_surface_mask(cm, f[mixed])  # not a piece of an earlier stroke's cut surface
            whole = is_orig.all(axis=1)
            whole_outer = whole.copy()
            whole_outer[whole] = np.isin(self._key(f[whole]), self.keys)
            parts.append(f[mixed | whole_outer])
        self.value = np.ascontiguousarray(np.concatenate(parts), np.int64)
        self.version = version
        return self.value

    def rebase(self, old_of_new=None) -> None:
        """Follow a :meth:`Session.rebase <cutkit.simulate.session.Session.rebase>`: the outer faces on the new original tets.

        The boundary of the new original tets (the contact's) without the
        earlier strokes' cut surface; every node is an original node now.
        """
        from cutkit.cutting.rebase import cut_surface_mask

        cm = self.cm
        faces, face_tet = cm.orig_boundary_faces, cm.orig_boundary_face_tet
        outer = ~cut_surface_mask(cm, faces)
        self.faces, self.face_tet = faces[outer], face_tet[outer]
        self.n0 = cm.n_orig_points
        self.keys = np.sort(self._key(self.faces))
        self.version = None
        self.value = self.faces


class LiveLoop:
    """One live session: the session, its threads, its views and its recording.

    ``clock`` (:mod:`cutkit.simulate.clock`) is the time the session reads:
    the wall clock by default; on a :class:`~cutkit.simulate.clock.SteppedClock`
    each pass of the loop is one haptic tick done whole (:meth:`_stepped_loop`).
    """

    def __init__(self, model, source, views, out_dir: Path, opt: SimulateOptions | None, fps: float = 30.0,
                 model_path: str | None = None, clock=None):
        from cutkit.cutting.trajectory import DEFAULT_BLADE_BREADTH, DEFAULT_BLADE_LENGTH
        from cutkit.live.sources import HapticsPoseSource
        from cutkit.simulate.record import ForceRecorder, NodeColours, PoseRecorder
        from cutkit.simulate.session import Session

        self.opt = opt or SimulateOptions(frames=False)
        self.opt.check()
        self.clock = as_clock(clock)
        self.stepped = bool(getattr(self.clock, "stepped", False))
        self.sleep = getattr(self.clock, "sleep", time.sleep)
        self.service = isinstance(source, HapticsPoseSource)
        _check_stepped_source(self.clock, self.stepped, source, self.service)
        self.out_dir, self.source, self.views, self.model_path = out_dir, source, list(views), model_path
        blade_length = self.opt.blade_length or DEFAULT_BLADE_LENGTH
        self.session = s = Session(model, self.opt, blade_length, DEFAULT_BLADE_BREADTH)
        out_dir.mkdir(parents=True, exist_ok=True)  # once the model is known to run
        self.poses = PoseRecorder(blade_length, DEFAULT_BLADE_BREADTH)
        self.meter = TickMeter(source, poses=self.poses, clock=self.clock.now) if self.service else None
        if self.service:
            # the cut follows an in-process copy of the service's model, ticked with every device pose
            s.scalpel = MirroredForceModel(source, DEFAULT_BLADE_BREADTH)
            s.out = s.scalpel.out
        self.geo_every = max(1, int(round(1.0 / (self.opt.geometry_rate_hz * HAPTIC_DT))))
        self.ticks = 0
        self.geometry_skipped = 0
        self.forces = ForceRecorder(1 << 14)
        self.colours = NodeColours(model, s.cut_mesh)
        self.boundary = OuterBoundary(s.cut_mesh, s.contact.faces, s.contact.face_tet)
        s.on_rebase.append(self.boundary.rebase)
        # a stroke's rebase runs off this thread; the poses meanwhile are held, then ticked and cut
        # (on a stepped clock it is waited for at once: _start_rebase)
        self.rebaser = BackgroundRebase(s, clock=self.clock.now)
        s.rebase_runner = self._start_rebase
        self.rebase_waiting_since: float | None = None  # a stroke ended: its rebase waits (_rebase_due)
        self.strokes_joined = 0  # strokes begun while the previous one's rebase waited (_rebase_due)
        self.still: StillPicture | None = None  # the tissue drawn while a rebase runs
        self.held: collections.deque = collections.deque()  # in-process ticks: poses not yet ticked
        self.cut_tip = None  # the blade's tip at the last geometry update
        self.newest = None  # the newest pose (tip, a, n): the drawn blade
        self.shown = None  # what the newest frame showed: (points, blade pose, force); its cut: faces_version
        self.frames_idle = 0  # frame clock ticks left out: nothing had moved (_scene_still)
        self.tets_at_rebases: list[int] = []  # tets cut when each stroke ended
        self.stroke_ends: list[float] = []  # session seconds when each stroke that cut ended
        self.frame_period = 1.0 / float(fps)
        self.geo_period = 1.0 / self.opt.geometry_rate_hz
        self.pose = None  # newest (tip, a, n, arrival)
        self.latency: list[float] = []
        self.latency_arrival: list[float] = []  # the pose's arrival of each latency, session s
        self.pending_cut: list[float] = []  # arrival times of poses whose cut is not drawn yet
        self.frames = 0
        self.frame_s: list[float] = []
        self.faces = np.zeros((0, 3), np.int64), self.boundary.get(0)
        self.faces_version = 0
        self.view_closed = False  # a window closed by its user ends the session (checked at frames)
        self.on_frame = None  # run()'s on_frame, for the frames drawn before a cut

    def run(self, max_seconds=None, idle_end_s: float = 0.5, stop=None, on_frame=None,
            until_idle_s: float | None = None, on_start=None) -> dict:
        from cutkit.simulate.warmup import warm_up

        s = self.session
        chunk = getattr(s.tis, "step_s", 4 * self.opt.dt0)
        # before the clock starts, kernels not yet loaded load (or compile) here, not in the
        # middle of the first cut: a tiny cut with this material model, one step of this tissue
        warm_up(outputs=False, material_model=s.material_model)
        if not self.stepped:  # a stepped session's tissue starts where cutkit simulate's does
            for _ in range(PRE_CLOCK_STEPS):
                s.relax.advance(np.zeros((s.tis.n_nodes, 3)), s.tis.time + chunk)
        s.tis.prepare_resting()  # the first stroke's wound then comes to rest without building it
        self.t0 = self.clock.now() - s.tis.time
        self._frame(None)  # views build their windows before the clock starts
        self.frame_s.clear()
        self.t0 = self.clock.now() - s.tis.time
        self.relax = RelaxThread(s, self.now, chunk)
        if not self.stepped:  # stepped: the loop relaxes in its own thread (RelaxThread.relax_here)
            self.relax.start()
        self.interrupted = False
        self.on_frame = on_frame
        # Ctrl-C and SIGTERM stop the loop between two passes; one that comes while the
        # recording is written waits until it is whole (cutkit.interrupts)
        with safe_points():
            return self._run_and_record(max_seconds, idle_end_s, stop or threading.Event(), on_frame,
                                        until_idle_s, on_start)

    def _run_and_record(self, max_seconds, idle_end_s, stop, on_frame, until_idle_s, on_start) -> dict:
        """The loop, then the recording whatever ended the loop; the loop's errors after it."""
        stopped_by = None
        try:
            if on_start is not None:
                on_start()
            self._loop(max_seconds, idle_end_s, stop, on_frame, until_idle_s)
        except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM as the command line raises it
            self.interrupted = True
            stopped_by = exc
        finally:
            rebase_error = self._finish_rebase()
            self.relax.halt()
            self.loop_wall = self.now()
            summary = self._record()
        if rebase_error is not None:
            raise rebase_error
        if self.relax.error is not None:
            raise self.relax.error
        if self.interrupted:
            raise stopped_by
        return summary

    def _finish_rebase(self):
        """Run a waiting rebase, wait for one in flight (the recording needs its cut mesh); returns its
        error or None."""
        try:
            if self.rebase_waiting_since is not None:
                self._begin_rebase()
            self.rebaser.wait()
        except BaseException as err:
            return err
        self.still = None
        return None

    def now(self) -> float:
        """Session seconds: the clock's time since the loop started, plus the tissue's time then."""
        return self.clock.now() - self.t0

    def _loop(self, max_seconds, idle_end_s, stop, on_frame, until_idle_s) -> None:
        if self.stepped:
            return self._stepped_loop(max_seconds, idle_end_s, stop, on_frame, until_idle_s)
        next_geo = next_frame = next_tick = 0.0
        finished_at = None
        while not stop.is_set():
            check_stop()  # the safe point: no tick, cut or frame is half done here
            now = self.now()
            if max_seconds is not None and now >= max_seconds:
                break
            if self.relax.error is not None or self.view_closed:
                break
            pose = self.source.poll()
            if pose is not None:
                self._on_pose(pose)
            if self.rebaser.busy and self.rebaser.done():
                self._rebased()
            if self._rebase_due(now):
                self._begin_rebase()
            if self.rebaser.busy:
                pass  # the session's state is the rebase's: poses wait (held, or in the service's queue)
            elif self.service:
                self._device_ticks()
            elif self.held:
                next_tick, next_geo = self._catch_up(now, next_tick, next_geo)
            elif self.pose is not None:
                next_tick = self._ticks(now, next_tick)
            if self.service:
                self.session.scalpel.keep_alive()
            elif not (self.rebaser.busy or self.held) and now >= next_geo:
                self._geometry()
                next_geo = max(next_geo + self.geo_period, now)
            # a cut is drawn at once (waiting for the frame clock would add up to a frame period to
            # the latency from the pose to the drawn cut), unless device poses wait (_frame_due)
            if self._frame_due(now, next_frame):
                due = now >= next_frame
                if self.pending_cut or not self._scene_still(now):
                    self._frame(on_frame)
                else:
                    self._idle_views()
                if due:  # a cut's extra frame leaves the frame clock as it is
                    next_frame = self._next_frame(next_frame)
            if self._finished(until_idle_s):
                finished_at = now if finished_at is None else finished_at
                if now - finished_at >= idle_end_s:
                    break
            self.sleep(LOOP_IDLE_S)

    def _frame_due(self, now: float, next_frame: float) -> bool:
        """Whether a frame is drawn now: the frame clock says so or a cut waits to be shown, and no
        device pose waits for its tick (:meth:`_behind_device`) or the newest frame is
        :data:`MAX_FRAME_AGE_S` old."""
        if now < next_frame and not self.pending_cut:
            return False
        return not self._behind_device() or not self.frame_s or now - self.frame_s[-1] >= MAX_FRAME_AGE_S

    def _scene_still(self, now: float) -> bool:
        """Whether a frame now would show what the newest one did, but for the status lines, and
        that frame is younger than :data:`IDLE_FRAME_S` (no rebase running: its still picture
        moves the blade alone)."""
        if self.shown is None or self.still is not None or not self.frame_s:
            return False
        if now - self.frame_s[-1] >= IDLE_FRAME_S:
            return False
        points, pose, force = self.shown
        cm, positions = self.session.cut_mesh, self.session.tis.positions
        if self.faces_version != (cm.n_rebases, cm.n_tets_total) or positions.shape != points.shape:
            return False
        if (pose is None) != (self.newest is None):
            return False
        if pose is not None and not all(np.array_equal(u, v) for u, v in zip(pose, self.newest)):
            return False
        return bool(np.array_equal(self._hand_force(), force) and np.array_equal(positions, points))

    def _idle_views(self) -> None:
        """A frame left out (:meth:`_scene_still`): each view that has a window processes its events."""
        for view in self.views:
            idle = getattr(view, "idle", None)
            if idle is not None:
                idle()
        self.frames_idle += 1
        self.view_closed = any(getattr(v, "closed", False) for v in self.views)

    def _behind_device(self) -> bool:
        """Whether poses the device sent wait for their ticks (a pass left a backlog)."""
        return self.meter is not None and bool(self.meter.queue)

    def _finished(self, until_idle_s) -> bool:
        """The source is finished, or idle: the tissue has relaxed ``until_idle_s`` of its own time past
        the last pose (on a slow machine the tissue lags the wall clock; the recording should not depend
        on it); and no pose waits for a rebase."""
        idle = (until_idle_s is not None and self.pose is not None
                and self.session.tis.time - self.pose[3] > until_idle_s
                and not (self.meter is not None and self.meter.queue))
        behind = self.rebaser.busy or self.held or self.rebase_waiting_since is not None
        return bool((self.source.finished or idle) and not behind)

    def _stepped_loop(self, max_seconds, idle_end_s, stop, on_frame, until_idle_s) -> None:
        """The loop on a stepped clock: each pass is one tick of the clock, done whole before it moves.

        Per pass, in ``cutkit simulate``'s order (``_Replay._ticks``): the
        source's pose at the pass's time, one force-model tick with it; every
        ``geo_every``-th pass the cut (a stroke's rebase waited for) and the
        relaxation to the pass's time in this thread; frames on the frame
        clock.  Nothing depends on how long any of it took.
        """
        s = self.session
        next_frame = 0.0
        finished_at = None
        k = 0
        while not stop.is_set():
            check_stop()  # the safe point: no tick, cut or frame is half done here
            now = self.now()
            if (max_seconds is not None and now >= max_seconds) or self.view_closed:
                break
            pose = self.source.poll()
            if pose is not None:
                self._on_pose(pose)
            if self.pose is not None:
                tip, a, n, _ = self.pose
                out = s.haptic_tick(tip, a, n)
                self.forces.add(now, s.code, out, tip, s.scalpel.proxy)
            if k % self.geo_every == 0:
                self._stepped_geometry(now)
            if now >= next_frame or self.pending_cut:
                self._frame(on_frame)
                next_frame = max(next_frame + self.frame_period, now) if now >= next_frame else next_frame
            if self._finished(until_idle_s):
                finished_at = now if finished_at is None else finished_at
                if now - finished_at >= idle_end_s:
                    break
            self.clock.advance()
            k += 1

    def _stepped_geometry(self, now: float) -> None:
        """The cut at the current pose, then the relaxation to ``now`` (session seconds) in this thread."""
        s = self.session
        before = s.tets_cut, s.tis.n_nodes
        if self.pose is not None:
            self.cut_tip = np.array(self.pose[0], np.float64)
        self.relax.f_ext = s.geometry_update()  # a stroke's rebase runs here, waited for (_start_rebase)
        if (s.tets_cut, s.tis.n_nodes) != before and self.pose is not None:
            self.pending_cut.append(self.pose[3])
        self.relax.relax_here(now)

    def _on_pose(self, pose) -> None:
        arrival = self.now()
        self.newest = (pose.tip, pose.a, pose.n)
        if not self.service:  # the service's poses are recorded and ticked as they come (TickMeter)
            self.poses.add(arrival, pose.tip, pose.a, pose.n)
            if self.rebaser.busy or self.held:
                self.held.append((pose.tip, pose.a, pose.n, arrival))
                return
        self.pose = (pose.tip, pose.a, pose.n, arrival)

    def _start_rebase(self) -> None:
        """The session's :attr:`~cutkit.simulate.session.Session.rebase_runner`.  On a stepped clock the
        rebase runs at once and is waited for (as offline); on the wall clock it waits
        (:meth:`_rebase_due`) while the relaxation brings the wound to rest."""
        self.tets_at_rebases.append(self.session.tets_cut)
        self.stroke_ends.append(self.now())
        if self.stepped:  # in step with the loop: the next pass sees the rebased tissue, as offline
            self._begin_rebase()
            self.rebaser.wait()
            self._rebased()
        else:
            self.rebase_waiting_since = self.now()

    def _rebase_due(self, now: float) -> bool:
        """Whether a waiting rebase starts now: the tissue is at rest since the stroke ended (the
        relaxation thread runs behind the clock: a step at rest from before the stroke's end does
        not count), or :data:`REBASE_WAIT_MAX_S` have passed.  A blade back in the tissue before
        then goes on in this cut state, as offline a blade back before the next geometry update
        does (:meth:`Session.rebase_if_left <cutkit.simulate.session.Session.rebase_if_left>`): the
        rebase no longer waits, and comes when that stroke ends; a rebase started holds the poses
        for its whole length (a second of the demo knee), a stroke going on holds none."""
        if self.rebase_waiting_since is None or self.rebaser.busy:
            return False
        s = self.session
        if s.scalpel.code != FREE:
            self.rebase_waiting_since = None
            self.strokes_joined += 1
            return False
        rested = s.tis.time > self.rebase_waiting_since and s.tis.at_rest()
        return rested or now - self.rebase_waiting_since >= REBASE_WAIT_MAX_S

    def _begin_rebase(self) -> None:
        """The picture stays as the tissue is now, and the rebase starts in its own thread."""
        s = self.session
        self.rebase_waiting_since = None
        points = np.array(s.tis.positions, np.float64)
        self.still = StillPicture(points, self.colours.get(points.shape[0]), s.tets_cut)
        self.rebaser.start()

    def _rebased(self) -> None:
        """The rebase is done: the poses that came meanwhile are ticked and cut next."""
        self.still = None

    def _due_cut(self, behind: bool, tip) -> bool:
        """Whether a due pose gets its own cut: always in step with the poses; behind them, once the
        blade has gone :data:`MAX_SKIPPED_SWEEP_MM` since the last cut (else counted skipped)."""
        if not behind or self.cut_tip is None:
            return True
        if float(np.linalg.norm(np.asarray(tip) - self.cut_tip)) >= MAX_SKIPPED_SWEEP_MM:
            return True
        self.geometry_skipped += 1
        return False

    def _catch_up(self, now: float, next_tick: float, next_geo: float) -> tuple[float, float]:
        """In-process ticks over the held poses, each tick with the newest pose that had come by then,
        and the cut every geometry period of tick time, as they would have run without the rebase
        (while behind, only as :meth:`_due_cut` says); for at most :data:`CATCH_UP_BUDGET_S`, then a frame."""
        s = self.session
        t_end = time.perf_counter() + CATCH_UP_BUDGET_S
        while next_tick <= now and not self.rebaser.busy and time.perf_counter() < t_end:
            while self.held and self.held[0][3] <= next_tick:
                self.pose = self.held.popleft()
            if self.pose is not None:
                tip = self.pose[0]
                out = s.haptic_tick(tip, self.pose[1], self.pose[2])
                self.forces.add(next_tick, s.code, out, tip, s.scalpel.proxy)
            next_tick += HAPTIC_DT
            if next_tick >= next_geo:
                next_geo += self.geo_period
                behind = bool(self.held) and self.held[-1][3] - next_tick > self.geo_period
                if self.pose is not None and self._due_cut(behind, self.pose[0]):
                    self._geometry()
        if next_tick > now and self.held and self.held[-1][3] <= now:
            self.pose = self.held[-1]  # every held pose came before the ticks so far
            self.held.clear()
        return next_tick, next_geo

    def _device_ticks(self) -> None:
        """Every device pose the service forwarded, in order: one tick each; the cut every ``geo_every``.

        Every pose gets its force tick (the 1 kHz loop never skips one), but a
        geometry update falls behind the device when a cut takes longer than
        ``geo_every`` ticks, and after a rebase (its poses queued meanwhile): a
        due pose with a newer due pose already queued behind it gets a geometry
        update of its own only once the blade has moved
        :data:`MAX_SKIPPED_SWEEP_MM` since the last cut (:meth:`_due_cut`), else
        a later one's sweeps the blade from the last pose cut to it (the paper's
        Fig. 1: geometry at the rate it can, on the current pose; counted in
        ``geometry_updates_skipped``).  A backlog is worked off
        :data:`~cutkit.simulate.live_rebase.CATCH_UP_BUDGET_S` at a time, frames
        in between.
        """
        s, queue = self.session, self.meter.queue
        t_end = time.perf_counter() + CATCH_UP_BUDGET_S
        while queue and not self.rebaser.busy:
            if time.perf_counter() > t_end:
                break  # a backlog (after a rebase): a frame now, the rest in the next passes
            t, tip, a, n, arrival = queue.popleft()
            out = s.haptic_tick(tip, a, n)
            self.forces.add(t, s.code, out, tip, s.scalpel.proxy)
            # a newer due pose already waiting behind this one: the cut may act on the newest
            if self.ticks % self.geo_every == 0 and self._due_cut(len(queue) >= self.geo_every, tip):
                self.pose = (tip, a, n, arrival - self.t0)
                self._geometry()
            self.ticks += 1

    def _ticks(self, now: float, next_tick: float) -> float:
        """In-process force model: one tick per elapsed millisecond with the newest pose."""
        s = self.session
        tip, a, n, _ = self.pose
        k = 0
        while next_tick <= now and k < MAX_CATCH_UP_TICKS:
            out = s.haptic_tick(tip, a, n)
            self.forces.add(next_tick, s.code, out, tip, s.scalpel.proxy)
            next_tick += HAPTIC_DT
            k += 1
        return max(next_tick, now - HAPTIC_DT) if k == MAX_CATCH_UP_TICKS else next_tick

    def _geometry(self) -> None:
        s = self.session
        if s.cut.pending and self.still is None and self._frame_stale() and not self._behind_device():
            # a cut holds this thread for tens of ms: draw first, so that the longest gap between
            # frames (and OpenIGTLink messages) is about one cut and one frame, not a frame period more
            self._frame(self.on_frame)
        before = s.tets_cut, s.tis.n_nodes
        if self.pose is not None:
            self.cut_tip = np.array(self.pose[0], np.float64)
        self.relax.f_ext = s.geometry_update()
        if self.rebaser.busy:
            return  # the stroke ended: the cut mesh is the rebase's now
        if (s.tets_cut, s.tis.n_nodes) != before and self.pose is not None:
            self.pending_cut.append(self.pose[3])
        if s.scalpel.code == FREE:  # the hierarchy serves the entry test: refit to the relaxed surface
            s.refit()

    def _next_frame(self, due: float) -> float:
        """When the frame after the one due at ``due`` is due: one frame period later, so that a frame
        drawn late is made up by the next one and the rate holds at ``fps``; more than a period behind
        (a long cut step), one period from now instead of a burst of frames."""
        now = self.now()
        following = due + self.frame_period
        return following if following >= now - self.frame_period else now + self.frame_period

    def _frame_stale(self) -> bool:
        """Whether the newest frame is older than :data:`PRE_CUT_FRAME_AGE` frame periods."""
        return bool(self.frame_s) and self.now() - self.frame_s[-1] > PRE_CUT_FRAME_AGE * self.frame_period

    def _frame(self, on_frame) -> None:
        from cutkit.cutting import cut_surface_faces
        from cutkit.live import LiveFrame

        s = self.session
        t1 = time.perf_counter()
        # topology changes only in this thread, and each cut reaches the tissue in the step that
        # makes it; the relaxation thread moves positions in place, and a frame may show them
        # half a sweep old
        if self.still is not None:  # a rebase runs: the tissue as the stroke left it, the blade moves on
            points, rgb, tets_cut = self.still.points, self.still.rgb, self.still.tets_cut
        else:
            cm = s.cut_mesh
            points = np.array(s.tis.positions, np.float64)
            version = (cm.n_rebases, cm.n_tets_total)
            if version != self.faces_version:
                self.faces = cut_surface_faces(cm), self.boundary.get(version)
                self.faces_version = version
            rgb, tets_cut = self.colours.get(points.shape[0]), s.tets_cut
        cut_faces, outer = self.faces
        tip, a, n = self.newest if self.newest is not None else (None, None, None)
        frame = LiveFrame(points=points, boundary_faces=outer, cut_faces=cut_faces, rgb=rgb, tip=tip, a=a, n=n,
                          blade_length=s.blade_length, blade_breadth=s.blade_breadth,
                          force=self._hand_force(), rates=self.rates(),
                          tets_cut=tets_cut, t=self.now())
        for view in self.views:
            view.show(frame)
        self.view_closed = any(getattr(v, "closed", False) for v in self.views)
        drawn = self.now()
        self.latency.extend(drawn - t for t in self.pending_cut)
        self.latency_arrival.extend(self.pending_cut)
        self.pending_cut.clear()
        self.frames += 1
        self.frame_s.append(drawn)
        self.shown = (points, None if self.newest is None else tuple(np.array(v) for v in self.newest), frame.force)
        s.task_s["output"] += time.perf_counter() - t1
        if on_frame is not None:
            on_frame(frame)

    def _hand_force(self) -> np.ndarray:
        from cutkit.scalpel import O_FORCE

        return -np.asarray(self.session.out[O_FORCE:O_FORCE + 3], np.float64)

    def rates(self) -> dict:
        wall = max(self.now(), 1e-9)
        recent = [t for t in self.frame_s[-31:]]
        fps = (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 1 and recent[-1] > recent[0] else 0.0
        haptic = (self.meter.rate() if self.meter is not None
                  else self.session.counts["haptic_ticks"] / wall)
        return {"haptic_hz": haptic, "relax_passes_per_s": self.session.counts["relax_passes"] / wall, "fps": fps}

    def _record(self) -> dict:
        from cutkit.simulate.record import closing_warnings, summary, write_cut_model, write_json

        s, out_dir = self.session, self.out_dir
        self.forces.write(out_dir / "forces.csv")
        recorded = self.poses.write(out_dir / "trajectory.csv")
        out = summary(s, model_path=self.model_path, loop_wall=self.loop_wall, t_traj_end=None,
                      opening_at_traj_end=None, frames=self.frames, forces=self.forces,
                      interrupted=self.interrupted, rates=True)
        out["live"] = self._live_stats(recorded)
        closing_warnings(s)
        if hasattr(s.tis, "relax_report"):
            from cutkit.simulate.run import relax_steps_warning

            out["relax_steps"] = s.tis.relax_report()
            line = relax_steps_warning(out["relax_steps"])
            if line:
                s.warnings.append(line)
        rate = out["live"]["haptic_hz"]
        if rate < RATE_WARN_FRACTION / HAPTIC_DT:
            s.warnings.append(f"the haptic loop reached {rate:.0f} Hz, below "
                              f"{RATE_WARN_FRACTION:.0%} of {1.0 / HAPTIC_DT:.0f} Hz")
        out["warnings"] = list(s.warnings)
        if self.opt.write_model:
            write_cut_model(s, out_dir, out)
        out["time_per_task_s"] = dict(s.task_s)
        if hasattr(s.tis, "counts"):
            out["counts"].update({f"relax_{k}": v for k, v in s.tis.counts.items()})
        write_json(out_dir / "summary.json", out)
        return out

    def _latency_outside_rebase(self) -> dict | None:
        """Pose-to-picture latency of the poses that did not come during a rebase (those wait for it; the
        ones just after it may still wait for its backlog), ms: p50, p95, n, and how many came during one."""
        arrival = np.array(self.latency_arrival)
        held = np.zeros(arrival.shape, bool)
        for a, b in self.rebaser.windows:
            held |= (arrival >= a - self.t0) & (arrival <= b - self.t0)
        lat = np.array(self.latency)[~held] * 1e3
        if not lat.size:
            return None
        return {"p50": float(np.percentile(lat, 50)), "p95": float(np.percentile(lat, 95)), "n": int(lat.size),
                "held": int(held.sum())}

    def _live_stats(self, recorded: bool) -> dict:
        wall = max(self.loop_wall, 1e-9)
        lat = np.array(self.latency) * 1e3
        f = np.diff(np.array(self.frame_s))
        rebase_s = self.rebaser.wall_s
        stats = {"source": type(self.source).__name__, "clock": type(self.clock).__name__,
                 "wall_s": self.loop_wall, "poses": len(self.poses.rows),
                 "trajectory_recorded": recorded, "frames": self.frames,
                 "geometry_updates_skipped": self.geometry_skipped,
                 "fps": float(1.0 / f.mean()) if f.size else 0.0,
                 "frames_left_out_still": self.frames_idle,
                 "fps_up_to_date": (float((self.frames + self.frames_idle - 1) / (self.frame_s[-1] - self.frame_s[0]))
                                    if f.size and self.frame_s[-1] > self.frame_s[0] else 0.0),
                 "frame_gap_max_ms": float(f.max() * 1e3) if f.size else None,
                 "rebases": len(rebase_s),
                 "rebase_s_max": float(max(rebase_s)) if rebase_s else None,
                 "rebase_windows_s": [[a - self.t0, b - self.t0] for a, b in self.rebaser.windows],
                 "tets_cut_at_rebases": list(self.tets_at_rebases),
                 "strokes_joined": self.strokes_joined,
                 "stroke_ends_s": list(self.stroke_ends),
                 "relax_passes_per_s": self.session.counts["relax_passes"] / wall,
                 "relax_steps_per_s": self.relax.steps / wall,
                 "relax_step_ms_p50_p95_max": ([float(np.percentile(self.relax.step_s, q)) * 1e3 for q in (50, 95, 100)]
                                               if self.relax.step_s else None),
                 "tissue_time_s": self.session.tis.time,
                 "latency_outside_rebase_ms": self._latency_outside_rebase(),
                 "latency_ms": ({"p50": float(np.percentile(lat, 50)), "p95": float(np.percentile(lat, 95)),
                                 "n": int(lat.size)} if lat.size else None)}
        if self.meter is not None:
            stats.update(self.meter.stats())
        else:
            stats["haptic_hz"] = self.session.counts["haptic_ticks"] / wall
        return stats


def _check_stepped_source(clock, stepped: bool, source, service: bool) -> None:
    """A stepped session needs a source on its clock: not the haptics service (its own 1 kHz clock),
    and a source with a ``clock`` (a TrajectoryPoseSource) given the session's."""
    if not stepped:
        return
    if service:
        raise InputError("a stepped clock cannot drive the haptics service, which ticks on its own clock: "
                         "use the wall clock with --haptics")
    own = getattr(source, "clock", None)
    if own is not None and own != clock.now:
        raise InputError(f"the pose source ({type(source).__name__}) reads another clock than the session's "
                         "stepped clock: give it the same clock (clock=...)")


__all__ = ["LiveLoop", "OuterBoundary"]
