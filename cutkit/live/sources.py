"""Pose sources: where the blade of a live session comes from.

Every source has one interface, :class:`PoseSource`: ``poll()`` returns the
newest blade pose since the previous call, or None when there is none, and
never blocks; ``close()`` lets go of what the source holds (sockets,
threads); ``finished`` says that no pose will come any more (a trajectory
played to its end, a service that said goodbye).

A :class:`Pose` uses the trajectory files' convention
(docs/trajectory-format.md): ``tip`` in model coordinates (mm), ``a`` the
unit vector along the blade from the handle to the tip, ``n`` the unit
vector in the blade plane towards the sharp edge.

Sources here: :class:`TrajectoryPoseSource` (a trajectory file on the wall
clock), :class:`MouseKeyboardPoseSource` (fed by the live window) and
:class:`HapticsPoseSource` (a device through ``cutkit haptics serve``).
``cutkit.live.igtl.IGTLPoseSource`` takes a tracked tool from OpenIGTLink.
"""

from __future__ import annotations

import collections
import math
import time
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from cutkit.errors import InputError, ProtocolError

__all__ = ["Pose", "PoseSource", "TrajectoryPoseSource", "MouseKeyboardPoseSource", "HapticsPoseSource",
           "make_pose", "orthonormal_blade"]


class Pose(NamedTuple):
    """One blade pose.

    Attributes
    ----------
    t : float
        Wall-clock time the pose was taken, s (``time.time()`` scale).
    tip : (3,) float64
        Blade tip, mm, model coordinates.
    a : (3,) float64
        Unit vector along the blade, handle to tip.
    n : (3,) float64
        Unit vector in the blade plane, perpendicular to ``a``, towards the sharp edge.
    buttons : int
        Button bit mask of the device (0 where there are none).
    """

    t: float
    tip: np.ndarray
    a: np.ndarray
    n: np.ndarray
    buttons: int = 0


@runtime_checkable
class PoseSource(Protocol):
    """The interface every pose source has."""

    #: True once the source will produce no more poses.
    finished: bool

    def poll(self) -> Pose | None:
        """The newest pose since the previous call, or None; never blocks."""

    def close(self) -> None:
        """Release sockets and threads; the source gives no poses after it."""


def orthonormal_blade(a, n) -> tuple[np.ndarray, np.ndarray]:
    """Normalise ``a`` and make ``n`` a unit vector perpendicular to it (Gram-Schmidt).

    Parameters
    ----------
    a, n : (3,) float
        Along the blade and towards the edge; any length, not parallel.

    Returns
    -------
    a, n : (3,) float64

    Raises
    ------
    InputError
        ``a`` is zero or ``n`` is parallel to it.
    """
    a = np.array(a, dtype=np.float64).reshape(3)
    n = np.array(n, dtype=np.float64).reshape(3)
    la = float(np.linalg.norm(a))
    if not la > 1e-12 or not np.all(np.isfinite(a)):
        raise InputError(f"blade axis must be a finite non-zero vector, got {a}")
    a /= la
    n -= np.dot(n, a) * a
    ln = float(np.linalg.norm(n))
    if not ln > 1e-9 or not np.all(np.isfinite(n)):
        raise InputError("the blade's edge direction is parallel to its axis")
    return a, n / ln


def make_pose(t, tip, a, n, buttons: int = 0) -> Pose:
    """A :class:`Pose` with float64 arrays, ``a`` and ``n`` made orthonormal."""
    a, n = orthonormal_blade(a, n)
    return Pose(float(t), np.array(tip, dtype=np.float64).reshape(3), a, n, int(buttons))


# ---------------------------------------------------------------------------- trajectory
class TrajectoryPoseSource:
    """Replay a trajectory on the wall clock (or on a session's stepped clock).

    The clock starts at the first ``poll()`` (or at ``start``); each poll
    returns the trajectory's pose at the elapsed time (``Trajectory.pose_at``,
    interpolated).  After the last row has been returned once the source is
    ``finished`` (with ``loop``, it starts again instead).

    Parameters
    ----------
    trajectory : Trajectory or path-like
        A :class:`~cutkit.cutting.trajectory.Trajectory` or a trajectory file.
    speed : float
        Trajectory seconds per wall second.
    loop : bool
    clock : callable or clock object
        Seconds now (``time.time``); or a session clock with ``now()``
        (:class:`~cutkit.simulate.clock.SteppedClock`: give the session the same one).
    start : float, optional
        Wall time of the trajectory's first row; default: the first poll.
    """

    def __init__(self, trajectory, speed: float = 1.0, loop: bool = False, clock=time.time,
                 start: float | None = None):
        from cutkit.cutting.trajectory import Trajectory, read_trajectory

        self.trajectory = trajectory if isinstance(trajectory, Trajectory) else read_trajectory(trajectory)
        if not (speed > 0 and math.isfinite(speed)):
            raise InputError(f"replay speed must be positive, got {speed}")
        self.speed = float(speed)
        self.loop = bool(loop)
        self.clock = clock.now if callable(getattr(clock, "now", None)) else clock
        self.start = start
        self.finished = False
        self._last = None

    def poll(self) -> Pose | None:
        if self.finished:
            return None
        now = float(self.clock())
        if self.start is None:
            self.start = now
        traj = self.trajectory
        elapsed = (now - self.start) * self.speed
        if elapsed < 0.0 or elapsed == self._last:
            return None  # not started yet, or no time has passed: nothing new
        self._last = elapsed
        if elapsed >= traj.duration:
            if self.loop and traj.duration > 0:
                elapsed = math.fmod(elapsed, traj.duration)
            else:
                self.finished = True
                elapsed = traj.duration
        tip, a, n = traj.pose_at(traj.t[0] + elapsed)
        return Pose(now, tip, a, n, 0)

    def close(self) -> None:
        self.finished = True


# ---------------------------------------------------------------------------- mouse and keyboard
def _rotate(v, axis, angle):
    """Rotate ``v`` about the unit ``axis`` by ``angle`` radians (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1.0 - c)


def _any_perpendicular(a):
    e = np.eye(3)[int(np.argmin(np.abs(a)))]
    v = e - np.dot(e, a) * a
    return v / np.linalg.norm(v)


class MouseKeyboardPoseSource:
    """A blade steered with the mouse over the tissue's surface and a few keys.

    The live window feeds it: :meth:`on_press` when a drag starts on the
    surface, :meth:`on_drag` for every surface point the drag passes (from a
    picker: the point and the outward surface normal there), :meth:`on_release`
    when the button is let go, :meth:`on_key` for key presses.  It needs no
    display and no window.

    The blade stands on the surface along the inward normal of the point
    where the drag started, tilted by the bevel angle about its edge
    direction; its tip is ``depth`` mm below the picked surface point along
    the blade; the sharp edge faces the direction of the drag.  A stroke
    starts with the tip ``approach`` mm outside the surface and ends with
    the tip pulled back out along the blade; those two poses are never
    skipped by ``poll`` (so a session always sees the blade go in and come
    out); between them the newest pose wins.

    Parameters
    ----------
    depth : float
        Initial cutting depth, mm.
    depth_step, max_depth : float
        mm per key press, and the deepest allowed.
    angle_step : float
        Bevel change per key press, degrees; the bevel stays within ±60°.
    approach : float
        Tip distance outside the surface at the start and end of a stroke, mm.
    clock : callable
        Wall clock, s.

    Keys (``KEYS``; VTK key symbols): Up / Down deepen / raise the blade,
    Left / Right bevel it, ``0`` resets depth and bevel.
    """

    KEYS = {"Up": ("depth", +1), "Down": ("depth", -1), "Right": ("bevel", +1), "Left": ("bevel", -1),
            "0": ("reset", 0)}
    MAX_BEVEL_DEG = 60.0
    #: Drags shorter than this (mm) keep the previous edge direction.
    MIN_DRAG_MM = 1e-3

    def __init__(self, depth: float = 5.0, depth_step: float = 0.5, max_depth: float = 20.0,
                 angle_step: float = 5.0, approach: float = 5.0, clock=time.time):
        if not (0 <= depth <= max_depth and depth_step > 0 and angle_step > 0 and approach >= 0):
            raise InputError("mouse blade: need 0 <= depth <= max_depth, positive steps and approach >= 0")
        self.depth0 = self.depth = float(depth)
        self.depth_step = float(depth_step)
        self.max_depth = float(max_depth)
        self.angle_step = float(angle_step)
        self.bevel = 0.0  # degrees
        self.approach = float(approach)
        self.clock = clock
        self.finished = False
        self._normal = None  # outward normal where the stroke started; None = no stroke
        self._stroke_normal = None  # that of the last stroke, after it ended
        self._point = None  # last surface point
        self._edge = None  # unit edge direction (perpendicular to the inward normal)
        self._must = collections.deque()  # poses poll never skips
        self._latest = None

    @property
    def dragging(self) -> bool:
        return self._normal is not None

    def _blade(self):
        inward = -(self._normal if self._normal is not None else self._stroke_normal)
        a = _rotate(inward, self._edge, math.radians(self.bevel))
        return a, self._edge

    def _emit(self, tip, must: bool) -> Pose:
        a, n = self._blade()
        pose = Pose(float(self.clock()), np.asarray(tip, np.float64).copy(), a, n.copy(), 1 if self.dragging else 0)
        if must:
            if self._latest is not None:
                self._must.append(self._latest)
            self._latest = None
            self._must.append(pose)
        else:
            self._latest = pose
        return pose

    def on_press(self, point, normal, edge=None) -> Pose:
        """A drag starts at surface ``point`` (3,) mm with outward ``normal`` (3,).

        ``edge`` (3,), optional: the first edge direction (e.g. the screen's
        right); by default any direction along the surface.
        """
        point = np.asarray(point, np.float64).reshape(3)
        normal = np.asarray(normal, np.float64).reshape(3)
        if not np.linalg.norm(normal) > 1e-12:
            raise InputError("surface normal must be non-zero")
        self._normal = normal / np.linalg.norm(normal)
        e = None if edge is None else np.asarray(edge, np.float64).reshape(3)
        if e is not None:
            e = e - np.dot(e, self._normal) * self._normal
        self._edge = e / np.linalg.norm(e) if e is not None and np.linalg.norm(e) > 1e-9 \
            else _any_perpendicular(self._normal)
        self._point = point
        return self._emit(point + self.approach * self._normal, must=True)

    def on_drag(self, point, normal=None) -> Pose | None:
        """The drag passes surface ``point`` (3,) mm; ``normal`` is ignored (the stroke keeps its start normal)."""
        if not self.dragging:
            if normal is None:
                return None
            return self.on_press(point, normal)
        point = np.asarray(point, np.float64).reshape(3)
        move = point - self._point
        move -= np.dot(move, self._normal) * self._normal
        if np.linalg.norm(move) > self.MIN_DRAG_MM:
            self._edge = move / np.linalg.norm(move)
        self._point = point
        return self._pose_now()

    def _pose_now(self) -> Pose:
        a, _ = self._blade()
        return self._emit(self._point + self.depth * a, must=False)

    def on_release(self) -> Pose | None:
        """The drag ends: the blade is pulled back out along its axis."""
        if not self.dragging:
            return None
        a, _ = self._blade()
        tip = self._point - self.approach * a
        self._stroke_normal, self._normal = self._normal, None  # buttons up from here
        return self._emit(tip, must=True)

    def on_key(self, key: str) -> bool:
        """Handle a key press (a VTK key symbol); returns whether the key was one of ``KEYS``."""
        action = self.KEYS.get(key)
        if action is None:
            return False
        what, sign = action
        if what == "depth":
            self.depth = min(self.max_depth, max(0.0, self.depth + sign * self.depth_step))
        elif what == "bevel":
            self.bevel = min(self.MAX_BEVEL_DEG, max(-self.MAX_BEVEL_DEG, self.bevel + sign * self.angle_step))
        else:
            self.depth, self.bevel = self.depth0, 0.0
        if self.dragging:
            self._pose_now()
        return True

    def poll(self) -> Pose | None:
        if self._must:
            return self._must.popleft()
        pose, self._latest = self._latest, None
        return pose

    def close(self) -> None:
        self.finished = True
        self._must.clear()
        self._latest = None


# ---------------------------------------------------------------------------- haptic device
class HapticsPoseSource:
    """The poses of a force-feedback device, through ``cutkit haptics serve``.

    Connects in the *simulation* role and asks the service to forward the
    device's poses (DEVICE_POSE frames, docs/haptics-protocol.md): the hand's
    own tip, as the device sent it, converted to the trajectory convention.
    The same connection carries the session's SIM_UPDATE frames
    (:meth:`update`) and brings back the service's STATE (:attr:`state`: the
    proxy P_s, the force, the scalpel's state).  The service ramps the force
    to zero 0.1 s after the last SIM_UPDATE, so a session sends one at least
    every few ms, in contact or not.

    Parameters
    ----------
    host, port : address of the service
    timeout : float
        Seconds to wait for the connection.
    clock : callable
        Wall clock stamped on each pose (``time.time``).
    """

    def __init__(self, host: str, port: int, timeout: float = 5.0, clock=time.time):
        from cutkit.haptics.client import HapticsClient

        self.client = HapticsClient(host, port, "simulation", timeout=timeout, forward_poses=True)
        if not self.client.forwards_poses:
            self.client.close()
            raise ProtocolError(f"the haptics server at {host}:{port} does not forward device poses "
                                f"(it predates DEVICE_POSE frames)")
        self.clock = clock
        self.finished = False
        #: newest STATE frame (:class:`cutkit.haptics.ForceFrame`), None before the first
        self.state = None
        #: newest DEVICE_POSE frame as received (:class:`cutkit.haptics.client.DevicePoseFrame`)
        self.device = None
        self.poses_received = 0

    def poll(self) -> Pose | None:
        """The newest device pose since the previous call (None if no new one).

        Raises
        ------
        ProtocolError
            The service sent a malformed frame or ERROR, or closed without BYE.
        """
        if self.finished:
            return None
        from cutkit.haptics import protocol as P
        from cutkit.haptics.client import decode_device_pose, decode_force

        newest = None
        arrival = time.perf_counter_ns()
        for ftype, seq, ts, payload in self.client.drain():
            if ftype == P.DEVICE_POSE:
                newest = decode_device_pose(ts, payload, arrival)
                self.poses_received += 1
            elif ftype == P.STATE:
                self.state = decode_force(ftype, seq, ts, payload, arrival)
            elif ftype == P.BYE:
                self.finished = True
        if newest is None:
            return None
        self.device = newest
        # the device frame: a = forward (the trajectory's n), n = along the blade (the trajectory's a)
        try:
            return make_pose(self.clock(), newest.tip, newest.n, newest.a, newest.buttons)
        except InputError:
            return None  # a degenerate device frame (zero vectors): no usable pose

    def update(self, entry, normal, f_ext=(0.0, 0.0, 0.0), material=None, contact: bool = True) -> int:
        """Send a SIM_UPDATE (see :meth:`cutkit.haptics.HapticsClient.send_sim`); returns its sequence number.

        Raises
        ------
        ProtocolError
            The connection to the service is gone.
        """
        try:
            return self.client.send_sim(entry, normal, f_ext, material, contact)
        except OSError as err:
            self.finished = True
            raise ProtocolError(f"the haptics server connection is gone ({err.strerror or err})") from None

    def close(self) -> None:
        self.finished = True
        self.client.close()
