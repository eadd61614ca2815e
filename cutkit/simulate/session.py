"""A cutting session: the tissue and the tasks of the paper's Fig. 1 as small objects.

:class:`Session` owns the one mesh store of a run (the tissue: cut mesh,
positions, rest positions, fixed flags, materials, on one node numbering)
and the tasks that work on it:

* :class:`ContactTask` (surface collision, section 4.1): the blade entering
  the tissue (the whole blade against the boundary hierarchy) and leaving it;
* the scalpel force model (section 6), in process or in the haptics service
  (:mod:`cutkit.simulate.blade`);
* :class:`CutTask` (volume collision and subdivision, sections 3 and 4.2):
  the blade at the proxy cuts the rest configuration, the topology change
  goes over to the tissue in one batch;
* :class:`RelaxTask` (section 5): the tissue relaxes to a given time.

Topology changes and relaxation steps exclude each other through
:attr:`Session.lock`: a relaxation thread holds it for one step, the cut
task for one ``apply_cut``, so a thread never sees half a cut.  Offline
(:func:`cutkit.simulate.simulate`) one thread calls the tasks in a fixed
order on the simulated clock; live (:mod:`cutkit.simulate.live`) the
relaxation runs in its own thread on the wall clock.
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from cutkit.cutting import surface_bvh
from cutkit.scalpel import CUTTING, FREE, O_CUT, O_N, STATE_NAMES

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
    tissue : TissueBase
    model : TetModel
        For the materials of the entry face's tissue.
    blade_length : float
        mm.
    """

    def __init__(self, tissue, model, blade_length: float):
        self.tis = tissue
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
        x = self.tis.positions[fv]
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
        """True once the hand's tip is more than :data:`LEAVE_MARGIN_MM` outside the entry face's plane."""
        return bool(np.dot(np.asarray(tip) - self.contact.entry, self.contact.inward) < -LEAVE_MARGIN_MM)

    def refit(self) -> None:
        """Refit the hierarchy to the relaxed surface (it serves the entry test)."""
        self.bvh.update(self.tis.positions[:self.n0])

    def rebase(self) -> None:
        """(Re)build the boundary and its hierarchy from the original tets of the cut mesh.

        Called at the start and after every :meth:`Session.rebase`: then the
        original tets are the live ones, so the cut surface of the earlier
        strokes is tissue surface too (the blade may enter through it), and
        every node (``n0``) is an original node.
        """
        from cutkit.collision import SurfaceBVH
        from cutkit.mesh.topology import boundary_faces

        cm = self.tis.cm
        self.n0 = cm.n_orig_points
        self.faces, self.face_tet = boundary_faces(cm.orig_tets)
        self.bvh = SurfaceBVH.build(self.tis.positions[:self.n0].copy(), self.faces)
        self.row_of_tet = self.materials.row_of(cm.labels)


def _segment_meets_tets(points, tets, p, q) -> bool:
    """Whether segment p-q meets one of the tets (k, 4) over ``points`` (either orientation)."""
    from cutkit.cutting._geometry import segment_hits_tet

    for t in tets:
        x = points[t]
        if np.dot(np.cross(x[1] - x[0], x[2] - x[0]), x[3] - x[0]) < 0.0:
            x = x[[0, 2, 1, 3]]
        if segment_hits_tet(p, q, x):
            return True
    return False


class CutTask:
    """Volume collision and subdivision (sections 3, 4.2) at the geometry rate.

    :meth:`step` cuts when the scalpel was cutting since the last step and
    returns the forces the blade puts on the tissue; the topology change is
    handed to the tissue under ``lock`` (``urgent``: a live session's
    relaxation ends its step after the sweep in flight and lets it in).
    """

    def __init__(self, tissue, lock, counts: dict):
        self.tis = tissue
        self.lock = lock
        self.counts = counts
        self.pending = False
        self.inside = False  # the blade has been in a tet since it entered (this stroke)
        self.through = False  # ... and the last cut step left it in none: out through the far side
        self.last_proxy = np.zeros(3)  # the proxy at the previous geometry update

    def _start_outside(self, blade_tip) -> None:
        """Begin the stroke's sweep :data:`ENTRY_SWEEP_MARGIN_MM` behind the entry pose, against the motion.

        The blade entered at the surface, and the edges of the faces it went in
        through lie in that surface: a sweep from the entry pose would meet
        them at its very start, where the cut refuses them (too close to the
        blade's previous pose), and the tissue would stay joined at the entry.
        """
        cm = self.tis.cm
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
        cm = self.tis.cm
        corners = cm.orig_tets[cm.active_tets]
        length = cm.blade_length
        return (_segment_meets_tets(cm._x, corners, blade_tip - length * axis, blade_tip),
                _segment_meets_tets(self.tis.positions, corners, proxy - length * axis, proxy))

    def _apply(self, result) -> None:
        """Hand a cut step's topology change over to the tissue."""
        with self.lock.urgent():
            added = self.tis.apply_cut(result)
        for key, value in added.items():
            self.counts[key] = self.counts.get(key, 0) + value
        self.counts["cut_steps"] += 1

    def note(self, code: int) -> None:
        """Record one haptic tick's scalpel state."""
        self.pending |= code == CUTTING

    def step(self, proxy, out, code: int, contact: Contact) -> np.ndarray:
        """One geometry update; returns the (n, 3) forces on the tissue's nodes, N."""
        from cutkit.cutting import cut_step

        cm = self.tis.cm
        axis = out[O_N:O_N + 3].copy()
        near = np.unique(cm.orig_tets[cm.active_tets]) if cm.active_tets.size else contact.face_nodes
        blade_tip = self.tis.blade_to_rest(proxy, near)
        if self.pending:
            if not self.inside and cm.prev_pose is not None:
                self._start_outside(blade_tip)
            before = cm.prev_pose
            self._apply(cut_step(cm, blade_tip, axis))
            self.pending = False
            in_rest, in_deformed = self._in_tissue(blade_tip, axis, proxy)
            # out through the far side only when out in both configurations, moving on: where
            # the blade drags the tissue along, its rest pose lags behind the hand's and can
            # fall back out through the entry face just after it went in
            onwards = before is not None and float(np.dot(blade_tip - before[0], proxy - self.last_proxy)) > 0.0
            self.through = self.inside and onwards and not (in_rest or in_deformed)
            self.inside |= in_rest
        elif code != FREE:
            # in tissue but not cutting: the blade rests or backs out, the sweep restarts here
            cm.prev_pose = (blade_tip, blade_tip - cm.blade_length * axis)
        self.last_proxy = np.array(proxy, np.float64)
        f_ext = np.zeros((self.tis.n_nodes, 3))
        if code == CUTTING and cm.active_tets.size:
            # the tissue along the blade feels the reaction of the cut force (eqs. 16-18);
            # before the blade enters the surface is not indented (docs/simulate.md)
            nodes = np.unique(cm.orig_tets[cm.active_tets])
            f_ext[nodes] -= out[O_CUT:O_CUT + 3] / len(nodes)
        return f_ext

    def leave(self) -> None:
        """The blade left the tissue: the cut's sweep restarts at the next entry."""
        cm = self.tis.cm
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


def settle(tis, material_model: str, opt, warnings: list) -> dict:
    """Settle the tissue under its prestress and boundary conditions; the settled state is the start."""
    from cutkit.simulate.run import SETTLE_MAX_SWEEPS

    sweeps = SETTLE_MAX_SWEEPS[material_model] if opt.settle_iterations is None else opt.settle_iterations
    if sweeps <= 0:
        return {"iterations": 0}
    if material_model == "springs":
        return tis.settle(sweeps, opt.settle_step_s)
    info = tis.settle(sweeps, opt.settle_rtol)
    if not info["converged"]:
        warnings.append(f"the settle stopped after {info['iterations']} sweeps at relative "
                        f"residual {info['relative_residual']:.1e} (asked: {opt.settle_rtol:.0e})")
    return info


class Session:
    """The tissue and the Fig. 1 tasks of one cutting session.

    Parameters
    ----------
    model : TetModel
    opt : SimulateOptions
    blade_length, blade_breadth : float
        mm.
    scalpel : InProcessScalpel or ServiceScalpel or None
        The force model; None: one in process.

    Attributes
    ----------
    tis : TissueBase
        The one mesh store.
    lock : HandoverLock
        Held for each relaxation step and each topology change.
    counts, task_s : dict
        Counters and seconds per task (``setup``, ``settle``, ``haptics``,
        ``collision_and_cut``, ``relaxation``, ``output``).
    """

    def __init__(self, model, opt, blade_length: float, blade_breadth: float, scalpel=None):
        from cutkit.simulate.blade import InProcessScalpel
        from cutkit.simulate.run import make_tissue

        wall0 = time.perf_counter()
        self.model, self.opt = model, opt
        self.blade_length, self.blade_breadth = float(blade_length), float(blade_breadth)
        self.warnings: list[str] = []
        self.task_s = dict.fromkeys(("setup", "settle", "haptics", "collision_and_cut", "relaxation", "output"), 0.0)
        self.counts = {"cut_steps": 0, "geometry_updates": 0, "haptic_ticks": 0, "relax_passes": 0,
                       "nodes_added": 0, "entries": 0}
        # strokes: what the strokes before the last rebase cut, and who follows a rebase
        self.rebase_due = False
        self.cut_before = {"cut_tets": 0, "new_tets": 0, "rebases": 0}
        self.pairs_before = np.zeros((0, 2), np.int64)
        self.on_rebase: list = []
        self.material_model = opt.material_model or model.materials.material_model
        self.tis = make_tissue(model, self.material_model, opt, blade_length)
        if not self.tis.fixed.any():
            self.warnings.append("the model has no fixed node: nothing holds it, it may drift (add [boundary] "
                                 "fixed_labels or fixed_regions to its recipe and run `cutkit assign`)")
        self.lock = HandoverLock()
        self.contact = ContactTask(self.tis, model, blade_length)
        self.cut = CutTask(self.tis, self.lock, self.counts)
        self.relax = RelaxTask(self.tis, self.lock, self.counts)
        self.scalpel = scalpel if scalpel is not None else InProcessScalpel(blade_breadth=self.blade_breadth)
        self.states_seen: list[str] = []
        self.out = self.scalpel.out
        self.task_s["setup"] = time.perf_counter() - wall0
        t1 = time.perf_counter()
        self.settle_info = settle(self.tis, self.material_model, opt, self.warnings)
        self.contact.refit()
        surface_bvh(self.tis.cm)  # built now, not in the first cut step
        self.task_s["settle"] = time.perf_counter() - t1

    @property
    def code(self) -> int:
        return self.scalpel.code

    def haptic_tick(self, tip, a, n) -> np.ndarray:
        """One 1 kHz tick for the hand's pose: entry test, force model, leave test; returns ``out``."""
        th = time.perf_counter()
        sc = self.scalpel
        if sc.code == FREE:
            hit = self.contact.entry(tip, a, n)
            if hit is not None:
                sc.enter(hit[0].entry, hit[0].normal, tip, hit[1])
                self.counts["entries"] += 1
        else:
            self.contact.prev = (np.array(tip, np.float64), np.array(a, np.float64))
        self.out = sc.tick(tip, a, n)
        if sc.code != FREE and self.contact.left(tip):
            self.leave()
        self.note_state(sc.code)
        self.cut.note(sc.code)
        self.counts["haptic_ticks"] += 1
        self.task_s["haptics"] += time.perf_counter() - th
        return self.out

    def leave(self) -> None:
        """The blade left the tissue: the force model goes free, the cut's sweep ends, a rebase is due."""
        self.scalpel.leave()
        self.cut.leave()
        self.rebase_due = True  # at the next geometry update (see rebase_if_left)

    def note_state(self, code: int) -> None:
        name = STATE_NAMES[code]
        if not self.states_seen or self.states_seen[-1] != name:
            self.states_seen.append(name)

    def geometry_update(self) -> np.ndarray:
        """Collision and cut at the proxy; returns the forces on the tissue for the relaxation."""
        tg = time.perf_counter()
        f_ext = self.cut.step(self.scalpel.proxy, self.out, self.scalpel.code, self.contact.contact)
        if self.scalpel.code != FREE and self.cut.through:
            self.leave()  # out through the far side: the entry plane's test would never see it
            f_ext[:] = 0.0
        self.rebase_if_left()
        self.counts["geometry_updates"] += 1
        self.task_s["collision_and_cut"] += time.perf_counter() - tg
        return f_ext

    def relax_to(self, f_ext, until: float) -> int:
        """Relax to ``until`` (tissue time, s), then refit the surface hierarchy while the blade is out."""
        tr = time.perf_counter()
        passes = self.relax.advance(f_ext, until)
        self.task_s["relaxation"] += time.perf_counter() - tr
        if self.scalpel.code == FREE:
            self.refit()
        return passes

    def refit(self) -> None:
        tg = time.perf_counter()
        # no lock: the hierarchy belongs to the thread that changes topology; a relaxation
        # step in flight only moves positions, which the tolerance boxes absorb
        self.contact.refit()
        self.task_s["collision_and_cut"] += time.perf_counter() - tg

    def rebase_if_left(self) -> bool:
        """Rebase once the blade has left the tissue after a stroke that cut; True when done.

        A blade back in the tissue before the next geometry update keeps the
        stroke going (the rebase comes at the next leaving).
        """
        if not self.rebase_due or self.scalpel.code != FREE:
            return False
        cm = self.tis.cm
        if not cm.subtets and cm.n_points == cm.n_orig_points:
            self.rebase_due = False  # the stroke cut nothing: nothing to rebase
            return False
        with self.lock.urgent():
            self.rebase()
        self.rebase_due = False
        return True

    def rebase(self) -> np.ndarray:
        """Make the live tets the original ones of a fresh cut state (:meth:`CutMesh.rebase`), between strokes.

        The one place where every holder of data keyed by CutMesh tet ids or
        built from the original tets follows: the tissue
        (``tis.rebase(old_of_new, old_orig)``), the surface collision
        (:meth:`ContactTask.rebase`), then each callable of
        :attr:`on_rebase` (``f(old_of_new)``, e.g. a live view's boundary).
        What the strokes so far cut is kept for the summary (:attr:`tets_cut`,
        :attr:`new_tets`, :meth:`opening`).  Node ids do not change.  Call it
        with the lock held and no cut in progress.

        Returns
        -------
        old_of_new : (m,) int64
            Old CutMesh tet id of each new (original) tet.
        """
        cm = self.tis.cm
        self.cut_before["cut_tets"] = self.tets_cut
        self.cut_before["new_tets"] = self.new_tets
        self.cut_before["rebases"] += 1
        self.pairs_before = cut_pairs(cm, self.pairs_before)
        old_orig = cm._tet_orig[:cm.n_tets_total].copy()
        old_of_new = cm.rebase()
        self.tis.rebase(old_of_new, old_orig[old_of_new])
        self.contact.rebase()
        surface_bvh(cm)
        for hook in self.on_rebase:
            hook(old_of_new)
        return old_of_new

    def opening(self) -> np.ndarray:
        """(p,) distances between the two copies of every duplicated cut node (all strokes), mm."""
        return cut_opening(self.tis.cm, self.tis.positions, self.pairs_before)

    @property
    def tets_cut(self) -> int:
        """Tets cut, summed over the strokes (each stroke counts the original tets of its cut state)."""
        return self.cut_before["cut_tets"] + len(self.tis.cm.subtets)

    @property
    def new_tets(self) -> int:
        """Sub-tets made, summed over the strokes."""
        return self.cut_before["new_tets"] + int(sum(len(v) for v in self.tis.cm.subtets.values()))


def cut_pairs(cm, before=None) -> np.ndarray:
    """(p, 2) int64 the two copies of every duplicated cut node of the current stroke, after ``before`` (q, 2)."""
    pairs = [cm.edge_node[np.all(cm.edge_node >= 0, axis=1)], cm.face_node[np.all(cm.face_node >= 0, axis=1)]]
    if before is not None:
        pairs.insert(0, before)
    return np.concatenate(pairs).astype(np.int64, copy=False)


def cut_opening(cm, positions, before=None) -> np.ndarray:
    """(p,) distances between the two copies of every duplicated cut node, mm.

    ``before`` (q, 2) int64: the pairs of the strokes before the last
    rebase (node ids do not change), measured first.
    """
    pairs = cut_pairs(cm, before)
    if pairs.size == 0:
        return np.zeros(0)
    return np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)


__all__ = ["Session", "HandoverLock", "ContactTask", "CutTask", "RelaxTask", "Contact", "cut_opening", "cut_pairs", "settle", "LEAVE_MARGIN_MM"]
