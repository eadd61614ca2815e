"""A cutting session: the tissue and the tasks of the paper's Fig. 1 as small objects.

:class:`Session` owns the one tissue store of a run
(:class:`~cutkit.tissue.store.TissueStore`: nodes and tets on one
numbering), the cut state that writes it (:class:`~cutkit.cutting.CutMesh`),
the physics that reads it (a :class:`~cutkit.tissue.TissuePhysics`) and the
tasks that work on them:

* :class:`~cutkit.simulate.tasks.ContactTask` (surface collision, section 4.1): the blade entering
  the tissue (the whole blade against the boundary hierarchy) and leaving it;
* the scalpel force model (section 6), in process or in the haptics service
  (:mod:`cutkit.simulate.blade`);
* :class:`~cutkit.simulate.tasks.CutTask` (volume collision and subdivision, sections 3 and 4.2):
  the blade at the proxy cuts the rest configuration, the topology change
  goes over to the tissue in one batch;
* :class:`~cutkit.simulate.tasks.RelaxTask` (section 5): the tissue relaxes to a given time.

Topology changes and relaxation steps exclude each other through
:attr:`Session.lock`: a relaxation thread holds it for one step, the cut
task for one ``apply_cut``, so a thread never sees half a cut.  Offline
(:func:`cutkit.simulate.simulate`) one thread calls the tasks in a fixed
order on the simulated clock; live (:mod:`cutkit.simulate.live`) the
relaxation runs in its own thread on the wall clock.
"""

from __future__ import annotations

import time

import numpy as np

from cutkit.cutting import surface_bvh
from cutkit.scalpel import FREE, STATE_NAMES
from cutkit.simulate.tasks import ContactTask, CutTask, HandoverLock, RelaxTask

def settle(tis, material_model: str, opt, warnings: list) -> dict:
    """Settle the tissue under its prestress and boundary conditions; the settled state is the start."""
    from cutkit.simulate.tissues import SETTLE_MAX_SWEEPS

    sweeps = SETTLE_MAX_SWEEPS[material_model] if opt.settle_iterations is None else opt.settle_iterations
    if sweeps <= 0:
        return {"iterations": 0, "skipped": "settle-iterations 0"}
    if material_model == "springs":
        return tis.settle(sweeps, opt.settle_step_s)
    info = tis.settle(sweeps, opt.settle_rtol)
    if not info.get("converged", True):
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
    store : TissueStore
        The one tissue store.
    cut_mesh : CutMesh
        The cut state over it (the store's writer).
    tis : TissuePhysics
        The physics (reads the store).
    lock : HandoverLock
        Held for each relaxation step and each topology change.
    counts, task_s : dict
        Counters and seconds per task (``setup``, ``settle``, ``haptics``,
        ``collision_and_cut``, ``relaxation``, ``output``).
    rebase_runner : callable or None
        None (offline): :meth:`rebase_if_left` rebases at once.  A live
        loop sets a callable that starts :meth:`rebase` off its own thread
        (:class:`~cutkit.simulate.live_rebase.BackgroundRebase`).
    """

    def __init__(self, model, opt, blade_length: float, blade_breadth: float, scalpel=None):
        from cutkit.simulate.blade import InProcessScalpel, scalpel_blade
        from cutkit.cutting import CutMesh
        from cutkit.simulate.tissues import make_tissue
        from cutkit.tissue.store import TissueStore

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
        # None: a stroke's rebase runs in the geometry update that sees the blade out (offline);
        # a live loop sets a callable that starts it off its thread (cutkit.simulate.live_rebase)
        self.rebase_runner = None
        self.material_model = opt.material_model or model.materials.material_model
        self.store = TissueStore.from_model(model)
        # the paper's springs re-interpolate moved nodes from their defining nodes, which a mesh
        # vertex has none of: a vertex is smoothed around slivers for the element model only
        self.cut_mesh = CutMesh.over(self.store, blade_length=self.blade_length, centre_nodes=opt.centre_nodes,
                                     smooth_vertices=self.material_model != "springs")
        self.tis = make_tissue(model, self.store, self.material_model, opt)
        if not self.tis.fixed.any():
            self.warnings.append("the model has no fixed node: nothing holds it, it may drift (add [boundary] "
                                 "fixed_labels or fixed_regions to its recipe and run `cutkit assign`)")
        self.lock = HandoverLock()
        self.contact = ContactTask(self.tis, self.store, model, blade_length)
        self.cut = CutTask(self.tis, self.cut_mesh, self.lock, self.counts)
        self.relax = RelaxTask(self.tis, self.lock, self.counts)
        self.scalpel = scalpel if scalpel is not None else InProcessScalpel(blade_breadth=self.blade_breadth,
                                                                                 **scalpel_blade(opt.scalpel))
        self.states_seen: list[str] = []
        self.hand = (np.zeros(3), np.zeros(3))  # the hand's last pose (tip, axis), mm (haptic_tick)
        self.still_pose = None  # the hand's pose at the last geometry update (finish_if_still)
        self.looked_while_still = False  # that update was still too: every cut-made tet was looked at
        self.out = self.scalpel.out
        self.task_s["setup"] = time.perf_counter() - wall0
        t1 = time.perf_counter()
        self.settle_info = settle(self.tis, self.material_model, opt, self.warnings)
        self.contact.refit()
        surface_bvh(self.cut_mesh)  # built now, not in the first cut step
        self.task_s["settle"] = time.perf_counter() - t1

    @property
    def code(self) -> int:
        return self.scalpel.code

    def haptic_tick(self, tip, a, n) -> np.ndarray:
        """One 1 kHz tick for the hand's pose: entry test, force model, leave test; returns ``out``."""
        th = time.perf_counter()
        self.hand = (tip, a)
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
        self.finish_if_still()
        self.counts["geometry_updates"] += 1
        self.task_s["collision_and_cut"] += time.perf_counter() - tg
        return f_ext

    def finish_if_still(self) -> None:
        """Where the hand has not moved since the last geometry update, the slivers the blade holds are
        looked at now (:meth:`CutTask.finish <cutkit.simulate.tasks.CutTask.finish>`): no next pose
        moves what it placed (offline: from the trajectory's end on).  The blade's place in the rest
        configuration still drifts as the tissue settles around it, and a cut step it makes holds
        its own nodes again.  Every cut-made tet is looked at once, at the first still update (its
        slivers do not change while the hand holds still; on the demo knee a look costs about
        3 ms)."""
        tip, a = (np.array(v, np.float64) for v in self.hand)
        still = self.still_pose is not None and np.array_equal(tip, self.still_pose[0]) \
            and np.array_equal(a, self.still_pose[1])
        if still:
            self.cut.finish(every_cut_tet=not self.looked_while_still)
        self.looked_while_still = still
        self.still_pose = (tip, a)

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
        stroke going (the rebase comes at the next leaving).  With a
        :attr:`rebase_runner` the rebase is handed to it (started, not done).
        """
        if not self.rebase_due or self.scalpel.code != FREE:
            return False
        cm = self.cut_mesh
        if not cm.subtets and cm.n_points == cm.n_orig_points:
            self.rebase_due = False  # the stroke cut nothing: nothing to rebase
            return False
        self.cut.finish()  # what the blade held at the stroke's last steps, looked at once more
        if self.rebase_runner is not None:
            self.rebase_due = False
            self.rebase_runner()
            return True
        self.rebase_and_look()
        self.rebase_due = False
        return True

    def rebase_and_look(self) -> None:
        """:meth:`rebase` under the hand-over lock, then the look at every cut-made tet it opens (the
        cut's nodes are vertices of original tets now, which vertex smoothing may move;
        :func:`cutkit.cutting.step.rebase_if_left`), its moves handed over before the tissue's next
        step.  The look takes the lock itself (it is not re-entrant), so it comes after."""
        with self.lock.urgent():
            self.rebase()
        self.cut.finish()

    def rebase(self) -> np.ndarray:
        """Make the live tets the original ones of a fresh cut state (:meth:`CutMesh.rebase`), between strokes.

        The store renumbers its tets in place (:meth:`TissueStore.rebase
        <cutkit.tissue.store.TissueStore.rebase>`, inside the cut mesh's);
        this is the one place where every holder of data keyed by tet ids or
        built from the original tets follows: the tissue
        (``tis.rebase(old_of_new)``), the surface collision
        (:meth:`ContactTask.rebase`), then each callable of
        :attr:`on_rebase` (``f(old_of_new)``, e.g. a live view's boundary).
        What the strokes so far cut is kept for the summary (:attr:`tets_cut`,
        :attr:`new_tets`, :meth:`opening`).  Node ids do not change.  Call it
        with the lock held and no cut in progress.

        Returns
        -------
        old_of_new : (m,) int64
            Old tet id of each new (original) tet.
        """
        cm = self.cut_mesh
        self.cut_before["cut_tets"] = self.tets_cut
        self.cut_before["new_tets"] = self.new_tets
        self.cut_before["rebases"] += 1
        self.pairs_before = cut_pairs(cm, self.pairs_before)
        old_of_new = cm.rebase()
        self.tis.rebase(old_of_new)
        self.contact.rebase()
        surface_bvh(cm)
        if cm.cut_faces_before:  # and the earlier strokes' cut surface's, which the next cut's first step walks
            surface_bvh(cm, crack=True)
        for hook in self.on_rebase:
            hook(old_of_new)
        return old_of_new

    def opening(self) -> np.ndarray:
        """(p,) distances between the two copies of every duplicated cut node (all strokes), mm."""
        return cut_opening(self.cut_mesh, self.tis.positions, self.pairs_before)

    @property
    def tets_cut(self) -> int:
        """Tets cut, summed over the strokes (each stroke counts the original tets of its cut state)."""
        return self.cut_before["cut_tets"] + len(self.cut_mesh.subtets)

    @property
    def new_tets(self) -> int:
        """Sub-tets made, summed over the strokes."""
        return self.cut_before["new_tets"] + int(sum(len(v) for v in self.cut_mesh.subtets.values()))


def cut_pairs(cm, before=None) -> np.ndarray:
    """(p, 2) int64 the two copies of every duplicated cut node of the current stroke, after ``before`` (q, 2)."""
    # a face node's first two copies (a forked face's third is its third corner's)
    faces = cm.face_node[:, :2]
    pairs = [cm.edge_node[np.all(cm.edge_node >= 0, axis=1)], faces[np.all(faces >= 0, axis=1)]]
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


__all__ = ["Session", "cut_opening", "cut_pairs", "settle"]
