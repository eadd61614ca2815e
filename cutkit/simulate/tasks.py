"""The tasks of the paper's Fig. 1 that a :class:`~cutkit.simulate.session.Session` runs.

* :class:`ContactTask` (surface collision, section 4.1): the blade entering
  the tissue (the whole blade against the boundary hierarchy) and leaving it;
* :class:`CutTask` (volume collision and subdivision, sections 3 and 4.2):
  the blade at the proxy cuts the rest configuration, the topology change
  goes over to the tissue in one batch;
* :class:`RelaxTask` (section 5): the tissue relaxes to a given time;

and :class:`HandoverLock`, through which topology changes and relaxation
steps exclude each other.
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from cutkit.scalpel import CUTTING, FREE, O_CUT, O_N

#: The blade has left the tissue once the hand's tip is this far outside the
#: entry face's plane, mm (a small margin so surface noise does not flicker).
LEAVE_MARGIN_MM = 0.5
#: A stroke's first cut sweeps from this far behind the entry pose, against the blade's motion (mm).
ENTRY_SWEEP_MARGIN_MM = 0.5


class HandoverLock:
    """A lock a waiting topology change gets before the next relaxation step.

    Plain locks are not fair: a relaxation thread that releases the lock and
    takes it again at once could keep a cut waiting for many steps.  ``with
    lock.urgent():`` (the cut task, a rebase) makes ordinary acquirers (``with
    lock:``, the relaxation) wait until it has had its turn, and raises
    :attr:`flag`, which the holder's kernels read between colour classes to
    end their step early.

    Attributes
    ----------
    flag : (1,) int64
        Topology changes waiting for the lock (non-zero: the holder should let go).
    """

    def __init__(self):
        self._lock = threading.Lock()
        self._cond = threading.Condition()
        self.flag = np.zeros(1, np.int64)

    def __enter__(self):
        with self._cond:
            self._cond.wait_for(lambda: self.flag[0] == 0, timeout=1.0)
        self._lock.acquire()
        return self

    def __exit__(self, *exc):
        self._lock.release()

    @contextmanager
    def urgent(self):
        with self._cond:
            self.flag[0] += 1
        try:
            with self._lock:
                yield self
        finally:
            with self._cond:
                self.flag[0] -= 1
                self._cond.notify_all()


@dataclass
class Contact:
    """Where the blade entered: the entry point, the face's inward normal and nodes, the blade plane."""

    entry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inward: np.ndarray = field(default_factory=lambda: np.zeros(3))
    face_nodes: np.ndarray = field(default_factory=lambda: np.zeros(3, np.int64))
    normal: np.ndarray = field(default_factory=lambda: np.zeros(3))


class ContactTask:
    """Surface collision: the blade's entry into the tissue and its leaving (section 4.1).

    Parameters
    ----------
    tissue : TissuePhysics
        Its positions place the surface.
    store : TissueStore
        Its boundary faces are the surface.
    model : TetModel
        For the materials of the entry face's tissue.
    blade_length : float
        mm.
    """

    def __init__(self, tissue, store, model, blade_length: float):
        self.tis = tissue
        self.store = store
        self.materials = model.materials
        self.rows = model.materials.rows()
        self.rebase()
        self.blade_length = float(blade_length)
        self.contact = Contact()
        self.first_plane = None
        self.prev = None  # previous (tip, a)

    def entry(self, tip, a, n):
        """Test the blade's motion since the previous pose; returns (Contact, material) on entry, else None.

        The whole blade against the current surface: the tip's path, the
        blade now (the surface may have moved past it), the quad it swept.
        """
        from cutkit.collision import blade_entry

        prev, self.prev = self.prev, (np.array(tip, np.float64), np.array(a, np.float64))
        if prev is None:
            return None
        prev_tip, prev_a = prev
        L = self.blade_length
        hit = blade_entry(self.bvh, self.tis.positions[:self.n0], prev_tip, prev_tip - L * prev_a, tip, tip - L * a)
        if hit is None:
            return None
        fv = self.bvh.faces[hit.face]
        # the face's rest orientation: the blade dimples the face it presses on (by 21 degrees on the
        # springs' slab of tests/test_simulate_strokes.py), and the plane of a dimpled face, drawn along
        # a stroke of 20 mm, never had the lifted hand outside it
        x = self.tis.rest_positions[fv]
        normal = np.cross(x[1] - x[0], x[2] - x[0])
        b = np.cross(n, a)
        c = self.contact
        c.entry = hit.point.copy()
        c.inward = -normal / np.linalg.norm(normal)
        c.face_nodes = np.asarray(fv, np.int64).copy()
        c.normal = b / np.linalg.norm(b)
        if self.first_plane is None:
            self.first_plane = {"entry": c.entry.copy(), "a": np.array(a), "b": c.normal.copy(), "n": np.array(n)}
        return c, self.rows[int(self.row_of_tet[self.face_tet[hit.face]])]

    def left(self, tip) -> bool:
        """True once the hand's tip is more than :data:`LEAVE_MARGIN_MM` outside the entry face's plane
        (through the entry point, with the face's rest orientation)."""
        return bool(np.dot(np.asarray(tip) - self.contact.entry, self.contact.inward) < -LEAVE_MARGIN_MM)

    def refit(self) -> None:
        """Refit the hierarchy to the relaxed surface (it serves the entry test)."""
        self.bvh.update(self.tis.positions[:self.n0])

    def rebase(self) -> None:
        """(Re)build the boundary and its hierarchy from the original tets of the store.

        Called at the start and after every :meth:`Session.rebase`: then the
        original tets are the live ones, so the cut surface of the earlier
        strokes is tissue surface too (the blade may enter through it), and
        every node (``n0``) is an original node.
        """
        from cutkit.collision import SurfaceBVH

        store = self.store
        self.n0 = store.n_orig_nodes
        self.faces, self.face_tet = store.boundary_faces, store.boundary_face_tet
        self.bvh = SurfaceBVH.build(self.tis.positions[:self.n0].copy(), self.faces)
        self.row_of_tet = self.materials.row_of(store.labels)


class CutTask:
    """Volume collision and subdivision (sections 3, 4.2) at the geometry rate.

    :meth:`step` cuts when the scalpel was cutting since the last step and
    returns the forces the blade puts on the tissue; the topology change is
    handed to the tissue under ``lock`` (``urgent``: a live session's
    relaxation ends its step after the sweep in flight and lets it in).
    """

    def __init__(self, tissue, cut_mesh, lock, counts: dict):
        self.tis = tissue
        self.cm = cut_mesh
        self.lock = lock
        self.counts = counts
        self.pending = False
        self.inside = False  # the blade has been in a tet since it entered (this stroke)
        self.through = False  # ... and the last cut step left it in none: out through the far side
        self.last_proxy = np.zeros(3)  # the proxy at the previous geometry update
        self.step_s: list[float] = []  # wall time of each cut step with its hand-over, s
        self.handover_s: list[float] = []  # ... of its hand-over to the tissue alone

    def _start_outside(self, blade_tip) -> None:
        """Begin the stroke's sweep :data:`ENTRY_SWEEP_MARGIN_MM` behind the entry pose, against the motion.

        The blade entered at the surface, and the edges of the faces it went in
        through lie in that surface: a sweep from the entry pose meets them on
        its boundary, not strictly inside, so they stayed uncut and the tissue
        stayed joined at the entry (measured on a side entry, docs/simulate.md).
        """
        cm = self.cm
        p0, q0 = cm.prev_pose
        motion = blade_tip - p0
        length = float(np.linalg.norm(motion))
        if length > 0.0:
            back = ENTRY_SWEEP_MARGIN_MM / length * motion
            cm.prev_pose = (p0 - back, q0 - back)

    def _in_tissue(self, blade_tip, axis, proxy) -> tuple[bool, bool]:
        """Whether the blade at its new pose meets one of the step's active tets: in the rest
        configuration (where it cut) and, at the proxy, in the deformed one.

        The active tets are those the swept quad met, whose last edge is the
        blade at its new pose: a tet the blade is in now is among them.
        """
        from cutkit.mesh.geometry import segment_meets_any_tet

        cm = self.cm
        corners = np.ascontiguousarray(cm.orig_tets[cm.active_tets])
        length = cm.blade_length
        return (segment_meets_any_tet(blade_tip - length * axis, blade_tip, cm.points, corners),
                segment_meets_any_tet(proxy - length * axis, proxy, self.tis.positions, corners))

    def _apply(self, result, counted: str = "cut_steps") -> None:
        """Hand a cut step's topology change over to the tissue; ``counted``: the count it adds to."""
        with self.lock.urgent():
            added = self.tis.apply_delta(result.delta)
        for key, value in added.items():
            self.counts[key] = self.counts.get(key, 0) + value
        self.counts[counted] = self.counts.get(counted, 0) + 1

    def finish(self, every_cut_tet: bool = True) -> None:
        """The stroke ended (the blade left, or the trajectory ends with it inside): the slivers the blade
        held are looked at once more (:func:`cutkit.cutting.finish_stroke`; with ``every_cut_tet`` every
        cut-made tet too), their moves handed over."""
        from cutkit.cutting import finish_stroke

        result = finish_stroke(self.cm, every_cut_tet)
        if result is not None:
            self._apply(result, "strokes_finished")

    def note(self, code: int) -> None:
        """Record one haptic tick's scalpel state."""
        self.pending |= code == CUTTING

    def _cut(self, blade_tip, axis, proxy) -> None:
        """Cut with the blade at ``blade_tip`` (rest configuration), hand the change over, and tell
        whether the blade went out through the far side (:attr:`through`)."""
        from cutkit.cutting import cut_step

        cm = self.cm
        if not self.inside and cm.prev_pose is not None:
            self._start_outside(blade_tip)
        before = cm.prev_pose
        t0 = time.perf_counter()
        result = cut_step(cm, blade_tip, axis)
        t1 = time.perf_counter()
        self._apply(result)
        self.step_s.append(time.perf_counter() - t0)
        self.handover_s.append(time.perf_counter() - t1)
        self.pending = False
        in_rest, in_deformed = self._in_tissue(blade_tip, axis, proxy)
        # out through the far side only when out in both configurations, moving on: where the
        # blade drags the tissue along, its rest pose lags behind the hand's and can fall back
        # out through the entry face just after it went in
        onwards = before is not None and float(np.dot(blade_tip - before[0], proxy - self.last_proxy)) > 0.0
        self.through = self.inside and onwards and not (in_rest or in_deformed)
        self.inside |= in_rest

    def step(self, proxy, out, code: int, contact: Contact) -> np.ndarray:
        """One geometry update; returns the (n, 3) forces on the tissue's nodes, N."""
        cm = self.cm
        axis = out[O_N:O_N + 3].copy()
        blade_tip = self.tis.blade_to_rest(proxy, axis, cm.blade_length, cm.active_tets, contact.face_nodes)
        if self.pending:
            self._cut(blade_tip, axis, proxy)
        elif code != FREE:
            # in tissue but not cutting: the blade rests or backs out, the sweep restarts here
            cm.prev_pose = (blade_tip, blade_tip - cm.blade_length * axis)
        self.last_proxy = np.array(proxy, np.float64)
        f_ext = np.zeros((self.tis.n_nodes, 3))
        if code == CUTTING and cm.active_tets.size:
            # the tissue around the blade carries the reaction of the cut force (eqs. 16-18), each
            # node by its mass (cutkit.tissue.BLADE_LOAD_RINGS); before the blade enters the surface
            # is not indented (docs/simulate.md)
            nodes, shares = self.tis.load_shares(cm.orig_tets[cm.active_tets])
            f_ext[nodes] -= shares[:, None] * out[O_CUT:O_CUT + 3]
        return f_ext

    def leave(self) -> None:
        """The blade left the tissue: the cut's sweep restarts at the next entry."""
        cm = self.cm
        cm.prev_pose = None
        cm.tip_tet = -1
        cm.active_tets = np.zeros(0, np.int64)
        self.inside = self.through = False


class RelaxTask:
    """Relaxation (section 5): bring the whole tissue to a time, one step at a time under the lock."""

    def __init__(self, tissue, lock, counts: dict):
        self.tis = tissue
        self.lock = lock
        self.counts = counts
        self.wall_s = 0.0

    def advance(self, f_ext, until: float, yield_to_cut: bool = False) -> int:
        """Relax to ``until`` s under the lock; with ``yield_to_cut`` (live) a topology change
        waiting for the lock ends the step in flight at its next colour class."""
        t0 = time.perf_counter()
        with self.lock:
            if f_ext.shape[0] != self.tis.n_nodes:  # a cut added nodes since the forces were made
                f_ext = np.concatenate([f_ext, np.zeros((self.tis.n_nodes - f_ext.shape[0], 3))])
            passes = self.tis.advance(f_ext, until, self.lock.flag if yield_to_cut else None)
        self.counts["relax_passes"] += passes
        self.wall_s += time.perf_counter() - t0
        return passes


__all__ = ["HandoverLock", "Contact", "ContactTask", "CutTask", "RelaxTask", "LEAVE_MARGIN_MM",
           "ENTRY_SWEEP_MARGIN_MM"]
