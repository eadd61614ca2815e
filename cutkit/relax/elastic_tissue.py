"""The tissue being cut as stable neo-Hookean elements (the default material model).

Node ``k`` of the :class:`~cutkit.tissue.store.TissueStore` is node ``k`` of the
:class:`~cutkit.relax.elastic.ElementModel`, and element ``t`` is the
store's tetrahedron ``t``, so a cut step carries over without any search:

* a removed tetrahedron takes its energy and its mass share out;
* an added one (a sub-tetrahedron of a cut) gets its own rest shape from
  the store's rest positions, with the material, prestrain and fibre of
  the tetrahedron it was cut from;
* the tetrahedra of a node the blade moved (tip and crack-front nodes) get
  their rest shape again;
* new nodes take position and velocity interpolated from their defining
  nodes and a colour no node of their tetrahedra has.

The rest positions are the tissue store's (one truth); this module keeps only
the current positions and velocities.  Every step is local to the cut: no
work proportional to the model except the O(n) counting sort of the
colour classes.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from cutkit.relax.elastic import (
    ElementModel,
    ElementState,
    initial_element_state,
    node_damping,
)
from cutkit.mesh.geometry import signed_volumes_serial
from cutkit.relax.kernels import loaded_nodes, loose_nodes, node_rings, tets_around
from cutkit.relax.growable import append_rows
from cutkit.relax.hessian_pattern import HessianPattern
from cutkit.relax.vbd import DEFAULT_ATOL_N, kept_volume_ratios, local_step, refresh_forces
from cutkit.relax.materials import material_of_tets, prestress_of_tets
from cutkit.relax._handover_kernels import old_shape_corners, place_through_old_shape, step_tet_sets
from cutkit.relax.rest_map import rest_map_radius
from cutkit.relax.tissue_base import TissueBase, uncut_store
from cutkit.tissue.store import TissueStore

#: Each implicit step of a simulation is solved until its residual is below
#: this fraction of the model's force scale (the out-of-balance force of the
#: unsettled model, see :meth:`ElasticTissue.force_scale`): the same
#: accuracy as the settle's (docs/relaxation.md, "Accuracy of a step").
STEP_RTOL = 1e-2
#: An as-built out-of-balance force below this fraction of that of a 1 % strain of every tet is
#: rounding, not a load: the force scale is then the 1 % strain's (:meth:`ElasticTissue._force_scale`).
AS_BUILT_ROUNDING = 1e-9
#: Sweeps one step may take before it moves on (counted in the summary).
STEP_MAX_ITERATIONS = 50
#: Relative residual the settle before a cut reaches (docs/relaxation.md).
SETTLE_RTOL = 1e-3
#: How each relaxation step is solved: projected Newton (:mod:`cutkit.relax.newton`),
#: vertex block descent (:func:`cutkit.relax.vbd.local_step`), or vertex block descent with a
#: step it leaves out of balance finished by a local Newton polish (:mod:`cutkit.relax.hybrid`).
SOLVERS = ("newton", "vbd", "hybrid")
#: The solver of a run that names none (docs/relaxation.md, "Measured on the demo knee").
DEFAULT_SOLVER = "hybrid"
#: Newton iterations one step may take before it moves on (reported, as the sweep cap is).
NEWTON_STEP_MAX_ITERATIONS = 30
#: None: each Newton iteration solves the whole model; k: it solves where the model is out of balance,
#: grown by k rings, and the step still ends on the whole model's residual
#: (:class:`~cutkit.relax.newton.NewtonSolver`'s ``region_rings``; docs/relaxation.md, "Local Newton").
NEWTON_REGION_RINGS: int | None = None
#: A resting step of the hybrid (nothing cut since the last step and the last step's load, to within
#: this tolerance: the blade still or gone) is solved to this fraction of the force scale by a few
#: sweeps and projected Newton on the whole model (:meth:`ElasticTissue._rest_step`): the wound's
#: gaping is a soft mode whose force is within the cutting steps' tolerance almost at once, so only
#: a tighter solve brings it to its equilibrium; at 1e-3 the demo knee's wound ended 0.8 % short of
#: a static solve's opening, at 3e-4 0.17 %; on an MRI head 3e-4 left it 1.2 % short, 1e-4 0.07 %
#: (docs/relaxation.md, "Resting steps").
REST_RTOL = 1e-4
#: A resting step ends at this fraction of the force scale (or at the rest tolerance, where that is
#: looser) while the blade loads the tissue, and the first time after the tissue last moved on its
#: own (a cut, a step that did not rest); the resting steps of an unloaded tissue after it go on to
#: the rest tolerance.  Going on to 1e-4 while the blade pauses in the tissue cost a live session on
#: the demo knee its latency (pose to picture p95 47-59 ms against 40-42 ms, docs/live.md).
REST_FIRST_RTOL = 3e-4
#: The first resting step of a tissue the blade has left (no load) ends at this fraction of the
#: force scale (or at the rest tolerance, where looser), the resting steps after it go on to the rest
#: tolerance: the first one's Newton solve carries the wound's opening (one Newton iteration on the
#: demo knee whatever it is asked, then REST_SMOOTHING_SWEEPS sweeps), and asked 1e-3 instead of 3e-4
#: its conjugate gradients stop sooner (the first solve about 115 iterations instead of 195), so a
#: live wound is within 1e-3 sooner and a live session's rebase, which waits for a step at rest,
#: starts sooner (docs/live.md).
REST_UNLOADED_FIRST_RTOL = 1e-3
#: The relative tolerance of a resting step's conjugate gradients (inexact Newton; looser near the
#: end of a solve, :data:`~cutkit.relax.newton.NO_OVERSOLVE`).  On the demo knee's hold with the
#: blade drawn out (measured before the blade's load went by mass), 0.03 brought the first resting
#: step to 1e-3 of the force scale in 2 Newton iterations (219 CG iterations, 1.2 s on one core)
#: where 0.1 took 3 (210, 1.6 s); with the blade held in the two cost the same.
REST_CG_RTOL = 0.03
#: The no-oversolving factor of the hybrid's resting steps' and finishes' Newton iterations
#: (:class:`~cutkit.relax.newton.NewtonSolver`'s ``no_oversolve``): their conjugate gradients stop at
#: this fraction of the tolerance over the residual, where the other solves stop at
#: :data:`~cutkit.relax.newton.NO_OVERSOLVE` = 0.5.  On the demo knee's lifted incision
#: (``benchmarks/relax.py --knee-simulate knee.h5 --lift``) every resting step took as many Newton
#: iterations at 0.75 as at 0.5 and 9-14 % fewer CG iterations (the first step after the lift 191
#: against 223), each ending at 0.62-0.86 of its tolerance; at 1.0 one ended at 0.99 of it
#: (docs/relaxation.md, "Resting steps").
REST_NO_OVERSOLVE = 0.75
#: The preconditioner of the hybrid's resting steps' and finishes' conjugate gradients
#: (:data:`~cutkit.relax.newton.PRECONDITIONERS`).  ``"two_level"`` (block Jacobi plus the rigid
#: motions of aggregates a crack splits, :func:`~cutkit.relax.newton.coarse_space`) halves their CG
#: iterations on the demo knee and saved 6 % of the resting steps' time offline on one thread, but a
#: live session on two threads came to rest later with it (median 3.7 s against 2.0 s to 1e-3 over
#: eight runs each, alternated; docs/relaxation.md), so block Jacobi stays.
REST_PRECONDITIONER = "block_jacobi"
#: Whole-model vertex block descent sweeps a resting step makes before its Newton solve: a small
#: change (the blade pausing mid incision) settles in a few sweeps, 13 ms each on the knee on one
#: core, where a Newton iteration costs 0.5-0.7 s; the wound a blade has left needs Newton and pays
#: the sweeps for nothing (:func:`~cutkit.relax.newton.rest_step`).
REST_SWEEPS = 5
#: Whole-model sweeps a resting step makes after each Newton iteration that leaves it out of balance,
#: before another Newton iteration (:func:`~cutkit.relax.newton.rest_step`'s ``smoothing``).  After the
#: blade has left the demo knee, the first Newton iteration of the first resting step carries the
#: wound's opening but leaves a short-range rest its linear model missed (the residual 0.16 of 0.18 N);
#: a second Newton iteration removed it in 13 CG iterations but cost a matrix assembly, 0.3 s on one
#: core, where 4 sweeps (67 ms) brought the step within its tolerance (docs/relaxation.md, "Resting
#: steps").
REST_SMOOTHING_SWEEPS = 5
#: The Hessian of a resting step's Newton iterations (:data:`~cutkit.relax.newton.HESSIANS`): the exact
#: one, and the projected one only where conjugate gradients meet negative curvature.  The wound's
#: gaping bends the flaps, whose curvature the projection drops: on a live knee's first resting step
#: after the stroke (replayed on one idle core) the exact Hessian took 2 Newton iterations (210 CG
#: iterations, 0.72-0.93 s), the projected one 3 (249, 1.31-1.38 s) (docs/relaxation.md,
#: "Resting steps").
REST_HESSIAN = "auto"
#: The Hessian of a whole-model finish (:meth:`ElasticTissue._finish`).  Finishes are rare (none on the
#: demo knee, 10 of 176 steps of the MRI head of docs/relaxation.md), and there the exact Hessian first
#: changed nothing measurable (the head's relaxation 25.5 s against 26.0 s, one run each).
FINISH_HESSIAN = "projected"
#: ``relax_steps`` counts the steps that ended with a tet below this volume ratio J (the issue's
#: bound of a tet left crushed; the barrier acts below BARRIER_J = 0.1).
CRUSHED_J = 1e-3


#: A new or moved node within this (barycentric) distance outside the nearest tet of the
#: old shape is placed by that tet's affine map extended; farther, by its defining nodes.
PLACE_REACH = 0.5
#: The blade's load skips a piece with no held node (ElasticTissue.bearing_nodes) found whole by a search
#: of at most this many nodes (a larger loose piece is loaded: its mass takes the reaction).  The search
#: runs at every geometry update while cutting; where no held node is near it reads this many, about
#: 0.1 ms on the demo knee.
LOOSE_SEARCH_NODES = 1000
#: A tet born folded is opened to this volume ratio by moving one of its placed nodes ...
UNFOLD_J = 0.05
#: ... in at most this many exact steps per node (ElasticTissue._lift), ...
UNFOLD_STEPS = 4
#: ... moving it at most this fraction of the distance to the farthest corner of its tets: where the
#: faces opposite the node are near degenerate, the step that opens the worst tet exactly is far longer
#: than the tets (50 m in test_lift_moves_a_node_no_farther_than_its_tets_reach).  A tet left folded
#: shows in the relaxation's report (``min_J``).
UNFOLD_REACH = 0.5


#: Above this share of the nodes to sum again, the kept elastic forces are summed whole
#: (:class:`KeptForces`): one pass of the model's kernel beats gathering the tets around most of it.
KEPT_FORCES_WHOLE_SHARE = 0.25


def _farthest_corner(x: np.ndarray, tets: np.ndarray, point: np.ndarray) -> float:
    """Distance from ``point`` (3,) to the farthest corner of ``tets`` (k, 4) int64 at positions ``x`` (n, 3);
    0 for no tets."""
    return float(np.sqrt(((x[tets.ravel()] - point) ** 2).sum(axis=1).max())) if tets.size else 0.0


def _within(point: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """``point`` (3,) moved along the line to ``centre`` (3,) into the ball of ``radius`` around it."""
    d = point - centre
    size = float(np.linalg.norm(d))
    return point if size <= radius else centre + d * (radius / size)


class KeptForces:
    """The element model's elastic forces at the tissue's positions, kept between relaxation steps.

    Every step reports its true residual, which needs the elastic force on
    every node; summed over the whole knee after each 20 ms step it cost
    12 ms on one core, about what the step's own sweeps cost.  Kept, only
    the nodes a change can reach are summed again: those sharing a tet with
    a node that moved since the last call (found by comparing positions, so
    every writer of positions is seen) and the corners of the tets a cut
    removed or added (:meth:`changed`).  A node's force is the sum over its
    own adjacency row (:func:`~cutkit.relax.vbd.refresh_forces`), so the
    kept forces are the whole pass's, bit for bit.  The ANP element couples
    a node's patch: its forces are summed whole every time.
    """

    def __init__(self):
        self.forget()

    def forget(self) -> None:
        """Drop the kept forces (a new element model: the next call sums them whole)."""
        self.em, self.forces, self.at, self.stale, self.mark = None, None, None, [], None

    def changed(self, nodes) -> None:
        """Mark ``nodes`` (any shape, int) to be summed again: their tets changed."""
        if self.forces is not None:
            self.stale.append(np.asarray(nodes, np.int64).ravel())

    def get(self, em, x: np.ndarray) -> np.ndarray:
        """(n, 3) float64 N: the elastic forces at ``x`` (n, 3) float64; read only (kept)."""
        n = em.n_nodes
        if em is not self.em or em.element != "nh" or self.forces is None or self.forces.shape[0] > n:
            return self._whole(em, x)
        if self.forces.shape[0] < n:  # a cut's new nodes: no force kept, and no position (so: moved)
            grow = n - self.forces.shape[0]
            self.forces = np.concatenate([self.forces, np.zeros((grow, 3))])
            self.at = np.concatenate([self.at, np.full((grow, 3), np.nan)])
        if self.mark is None or self.mark.shape[0] != n:
            self.mark = np.zeros(n, bool)
        stale = np.concatenate(self.stale) if self.stale else np.empty(0, np.int64)
        self.stale = []
        if refresh_forces(em, x, self.at, stale, int(KEPT_FORCES_WHOLE_SHARE * n), self.mark, self.forces) < 0:
            return self._whole(em, x)
        return self.forces

    def _whole(self, em, x: np.ndarray) -> np.ndarray:
        from cutkit.relax.anp import element_forces

        forces = element_forces(em, x)
        self.forget()
        if em.element == "nh":
            self.em, self.forces, self.at = em, forces, np.array(x, np.float64)
        return forces


class KeptVolumeRatios:
    """Each element's volume ratio J at the tissue's positions, kept between relaxation steps for
    the per-step report of the smallest (:meth:`ElasticTissue.relax_report`'s ``min_J``).

    Computed whole after every step it cost 1.9 ms on the knee on one core, a tenth of a live
    step's budget; kept, only the elements around a node that moved since the last call (found
    by comparing positions, as :class:`KeptForces` does) and those a cut removed or added
    (:meth:`changed`) are computed again, and the report is the whole pass's, bit for bit.
    """

    def __init__(self):
        self.forget()

    def forget(self) -> None:
        """Drop the kept ratios (a new element model: the next call computes them all)."""
        self.em, self.at, self.mark, self.J, self.stale = None, None, None, None, []

    def changed(self, elements) -> None:
        """Compute ``elements`` (any shape, int) again: a cut removed or added them."""
        if self.J is not None:
            self.stale.append(np.asarray(elements, np.int64).ravel())

    def extremes(self, em, x: np.ndarray, below: float, stop=None) -> tuple[float, int]:
        """(lowest J, count below ``below``) at ``x`` (n, 3) float64; (NaN, 0) where ``stop`` ended
        the pass (the rest is computed at the next call)."""
        m, n = em.tets.shape[0], em.n_nodes
        if em is not self.em or self.at.shape[0] > n:
            self.forget()
            self.em, self.at = em, np.full((n, 3), np.nan)
            self.mark, self.J = np.ones(m, bool), np.ones(m)
        if self.at.shape[0] < n:  # a cut's new nodes: never seen (so: moved)
            self.at = np.concatenate([self.at, np.full((n - self.at.shape[0], 3), np.nan)])
        if self.J.shape[0] < m:  # the element rows grew
            self.mark = np.concatenate([self.mark, np.ones(m - self.J.shape[0], bool)])
            self.J = np.concatenate([self.J, np.ones(m - self.J.shape[0])])
        stale = np.concatenate(self.stale) if self.stale else np.empty(0, np.int64)
        self.stale = []
        return kept_volume_ratios(em, x, self.at, stale, self.mark, self.J, below, stop)


#: The true residual of a live step that a waiting cut ended early: not evaluated (a pass over every
#: element, 20-50 ms of the relaxation thread on the knee in a session, that the cut would wait for);
#: the next step starts from its own residual.
NOT_EVALUATED = float("nan")


def _stopped(stop) -> bool:
    """Whether a waiting cut raised the stop flag ((1,) int64, or None offline)."""
    return stop is not None and bool(stop[0])


class ElasticTissue(TissueBase):
    """Cut mesh + element model + state of one tissue model.

    Parameters
    ----------
    model : TetModel
        Needs a materials row (with a Poisson ratio) for every label.
    store : TissueStore, optional
        The nodes and tets it reads (default: the model's own, nothing cut).
    step_s : float
        Implicit step, s.
    poisson_ratio : float, optional
        Overrides the materials table for every label.
    step_rtol : float
        Each step ends when the residual norm over all free dofs is at most
        this fraction of :attr:`force_scale`.
    step_max_iterations : int
        Sweeps (vbd) one step may make; Newton steps take at most
        :data:`NEWTON_STEP_MAX_ITERATIONS` iterations.
    solver : str
        ``"newton"``, ``"vbd"`` or ``"hybrid"`` (:data:`SOLVERS`).
    element : str
        ``"nh"`` (stable neo-Hookean linear tets) or ``"anp"`` (average nodal
        pressure tetrahedron, :mod:`cutkit.relax.anp`; newton only).
    deviatoric_smoothing : float or None
        ANP's deviatoric share on the nodes; None:
        :data:`~cutkit.relax.anp.ANP_SMOOTHING`.
    rest_rtol : float or None
        ``"hybrid"`` only: the tolerance of a resting step (nothing cut since
        the last step, the last step's load to within this tolerance) as a fraction of :attr:`force_scale`,
        solved by Newton on the whole model once the blade has left; under the blade's load they
        end at ``max(rest_rtol, REST_FIRST_RTOL)``, and the first resting step once the blade has
        left (a step without load rests) at ``max(rest_rtol, REST_UNLOADED_FIRST_RTOL)``.
        None: resting steps are solved as the others.

    Attributes
    ----------
    step_log : dict
        Per relaxation step: ``iterations`` (Newton iterations or sweeps) and
        ``relative_residual`` (true final residual over the force scale);
        ``"hybrid"`` adds ``polish_iterations`` (the Newton iterations of
        each step's polish, 0 where the sweeps converged).
    """

    def __init__(self, model, store: TissueStore | None = None, *, step_s: float,
                 poisson_ratio: float | None = None, step_rtol: float = STEP_RTOL,
                 step_max_iterations: int = STEP_MAX_ITERATIONS, solver: str = DEFAULT_SOLVER,
                 element: str = "nh", deviatoric_smoothing: float | None = None,
                 rest_rtol: float | None = REST_RTOL):
        from cutkit.errors import InputError
        from cutkit.relax.anp import ANP_SMOOTHING, check_element

        if solver not in SOLVERS:
            raise InputError(f"solver must be one of {', '.join(SOLVERS)}, not {solver!r}")
        if check_element(element) == "anp" and solver != "newton":
            raise InputError("element anp is solved by the newton solver only")
        self.solver = solver
        self.model = model
        self.store = store = uncut_store(model, store)
        self.rest_map_radius = rest_map_radius(model.points, model.tets)
        self.step_s = float(step_s)
        self.step_rtol = float(step_rtol)
        self.step_max_iterations = int(step_max_iterations)
        if rest_rtol is not None and not (np.isfinite(rest_rtol) and rest_rtol > 0):
            raise InputError(f"rest_rtol must be a positive number or None, not {rest_rtol!r}")
        self.rest_rtol = None if rest_rtol is None else float(rest_rtol)
        n, m = store.n_orig_nodes, store.orig_tets.shape[0]
        self.n_orig_tets = m
        # material of each original tet (a sub-tet has its original's)
        self.poisson_ratio = poisson_ratio
        self._read_materials()
        self.em = em = ElementModel.empty(n, store.tet_capacity)
        em.add_elements(store.rest_points[:n], store.orig_tets, self.mu, self.lam, self.density, self.prestrain, self.fibre,
                        ids=np.arange(m))
        em.damping[:] = node_damping(n, store.orig_tets, self.damping)
        em.fixed[:] = store.held[:, None]
        em.element = element
        if element == "anp":  # ANP with the nodes' deviatoric share that meets the locking bound, unless told
            em.deviatoric_smoothing = ANP_SMOOTHING if deviatoric_smoothing is None else float(deviatoric_smoothing)
        em.recolour()
        em.lay_out_rows()
        self.state: ElementState = initial_element_state(model)
        self.counts = {"steps": 0, "sweeps": 0, "node_updates": 0, "steps_not_converged": 0}
        self.step_log: dict[str, list] = {"iterations": [], "relative_residual": [], "min_J": [], "crushed_tets": []}
        if solver in ("newton", "hybrid"):
            self.counts["newton_iterations"] = 0
            self.counts["resting_steps"] = 0
            self.step_log["resting"] = []
        #: seconds in each part of the hybrid's polishes (cutkit.relax.hybrid.TIMED)
        self.polish_timings: dict[str, float] = {}
        if solver == "hybrid":
            self.counts["polish_calls"] = 0
            self.counts["whole_model_finishes"] = 0
            self.step_log["polish_iterations"] = []
        #: the element model's matrix pattern, kept across cuts and shared by its Newton solvers
        self.hessian_pattern = HessianPattern(self.em)
        self._newton = self._newton_solver()
        self._whole_newton: dict = {}  # the hybrid's whole-model solvers by Hessian, built on first use
        self._last_load: np.ndarray | None = None
        self._cut_since_step = False  # tets or nodes added or removed since the last step
        self.resting_in_balance = False  # the last step rested within the rest tolerance (at_rest)
        self._rested_once = False  # a resting step ended within its first stage since the tissue last moved
        self.force_scale = self._force_scale()
        # last squared residual of every node and the nodes a cut or a load wakes (vbd.local_step)
        self.r2 = np.zeros(em.n_nodes)
        self._seeds: list[np.ndarray] = []
        self.kept_forces = KeptForces()  # the true residual of each step, at the cost of what it moved
        self.kept_ratios = KeptVolumeRatios()  # each step's smallest J, at the cost of what it moved

    def _newton_solver(self, always: bool = False):
        """A fresh :class:`~cutkit.relax.newton.NewtonSolver` of the element model, the ``newton``
        solver's steps' (None for vbd and the hybrid, whose polish keeps no pattern, unless
        ``always``: the settle's, which the hybrid shares)."""
        if self.solver != "newton" and not always:
            return None
        from cutkit.relax.newton import NewtonSolver

        return NewtonSolver(self.em, region_rings=NEWTON_REGION_RINGS, pattern=self.hessian_pattern)

    def _force_scale(self) -> float:
        """N: the out-of-balance force of the model as built (prestress, prescribed
        displacements), or, without either, that of a 1 % strain of every tet.

        "Without either" is an as-built force below :data:`AS_BUILT_ROUNDING` of the 1 % strain's:
        an unloaded model's forces are rounding (about 1e-16 N), not a scale."""
        from cutkit.relax.anp import element_forces as elastic_forces

        free = ~self.em.fixed
        r = float(np.linalg.norm(elastic_forces(self.em, self.state.positions)[free]))
        strained = float(np.linalg.norm(elastic_forces(self.em, self.rest_positions * 1.01)[free]))
        return r if r > AS_BUILT_ROUNDING * strained else strained

    # ------------------------------------------------------------ the shared interface
    @property
    def n_nodes(self) -> int:
        return self.em.n_nodes

    @property
    def positions(self) -> np.ndarray:
        return self.state.positions

    @property
    def rest_positions(self) -> np.ndarray:
        return self.store.rest_points[: self.em.n_nodes]

    @property
    def velocities(self) -> np.ndarray:
        return self.state.velocities

    @property
    def masses(self) -> np.ndarray:
        """(n,) float64 lumped masses (the element model's)."""
        return self.em.masses[:self.em.n_nodes]

    def node_rings(self, nodes: np.ndarray, rings: int) -> np.ndarray:
        """``nodes`` grown by ``rings`` rings of live tets, through the element model's adjacency."""
        em = self.em
        return node_rings(em.adjacency, np.ascontiguousarray(nodes, np.int64), int(rings), em.n_nodes)

    def bearing_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The nodes of ``nodes`` (k,) int64 not in a piece the cut has set loose (a component of the
        tets with no held node, of at most :data:`LOOSE_SEARCH_NODES` nodes; the springs'
        rule, :meth:`cutkit.relax.spring_tissue.Tissue.bearing_nodes`).

        A loose slice cannot resist the blade: the reaction of the cut force spread over its few
        milligrams threw one of 19 mm^3, cut off a wall by a retrace, 500 mm away within a stroke,
        where the next steps cut it again in the rest configuration.  It gets no share.
        """
        em = self.em
        loose = loose_nodes(em.adjacency, np.ascontiguousarray(nodes, np.int64), em.fixed, LOOSE_SEARCH_NODES,
                            em.n_nodes)
        return nodes[~loose]

    @property
    def fixed(self) -> np.ndarray:
        return self.em.fixed.all(axis=1)

    @property
    def time(self) -> float:
        return float(self.state.time)

    def settle(self, max_iterations: int, rtol: float = SETTLE_RTOL) -> dict:
        """Relax to static equilibrium under prestress and boundary conditions, then rest at time 0.

        Projected Newton (:func:`cutkit.relax.newton.newton_static`) with the ``"hybrid"`` and
        ``"newton"`` solvers (the same solve: it builds the matrix pattern the resting steps
        take up), modified Newton with the linear stiffness
        (:func:`cutkit.relax.settle.settle_static`) with ``"vbd"``: ``max_iterations``
        bounds its Newton steps.  On the demo knee, uncached, projected Newton takes 3
        iterations, about 2 s on one core, where modified Newton takes 4 and 8 s (most of
        it the multigrid setup; docs/relaxation.md).  The result is kept in the settle cache
        (:mod:`cutkit.relax.settle_cache`): a model and materials settled before are not
        solved again, and the positions are the very ones the solve gives.  The report says
        ``cached``.
        """
        from cutkit.relax.settle import settle_static
        from cutkit.relax import settle_cache

        params = {"rtol": float(rtol), "atol": float(DEFAULT_ATOL_N), "max_iterations": max(int(max_iterations), 1)}
        if self.solver in ("newton", "hybrid"):
            params["method"] = "newton"  # the vbd runs' cache keys stay as they were
        key = settle_cache.settle_key(self.em, self.state.positions, self.rest_positions, params)
        hit = settle_cache.load(key)
        if hit is not None and hit[0].shape == self.state.positions.shape:
            self.state.positions[:] = hit[0]
            report = dict(hit[1], cached=True)
        else:
            if self.solver in ("newton", "hybrid"):
                from cutkit.relax.newton import newton_static

                info = newton_static(self.em, self.state.positions, rtol=rtol, atol=DEFAULT_ATOL_N,
                                     max_iterations=params["max_iterations"],
                                     solver=self._newton or self._newton_solver(always=True))
            else:
                info = settle_static(self.em, self.state.positions, rtol=rtol, atol=DEFAULT_ATOL_N,
                                     max_iterations=params["max_iterations"])
            if info.iterations == 0 and info.converged:  # nothing to do: no relative residual to speak of
                report = {"iterations": 0, "skipped": f"already in balance (residual {info.initial_residual:.1e} N "
                          f"<= {DEFAULT_ATOL_N:.0e} N)", "residual_N": info.initial_residual, "rtol": rtol}
            else:
                report = {"iterations": info.iterations, "relative_residual": info.residual / info.initial_residual
                          if info.initial_residual > 0 else 0.0, "converged": bool(info.converged), "rtol": rtol}
            settle_cache.save(key, self.state.positions, report)
            report["cached"] = False
        self.state.velocities[:] = 0.0
        self.state.time = 0.0
        return report

    def advance(self, f_ext: np.ndarray, until: float, stop=None) -> int:
        """Implicit steps of :attr:`step_s` up to ``until`` s; returns the sweeps made.

        ``stop`` ((1,) int64, live sessions only, the
        :class:`~cutkit.simulate.tasks.HandoverLock`'s flag) is read between
        colour classes: non-zero ends the step in flight and the advance
        with it, so a waiting cut waits for one colour class of one sweep.
        Offline runs pass none, and every step ends on its residual.
        """
        n_steps = int(np.floor((until - self.state.time) / self.step_s + 1e-6))
        sweeps = 0
        loaded = loaded_nodes(np.ascontiguousarray(f_ext, np.float64))
        atol = max(self.step_rtol * self.force_scale, DEFAULT_ATOL_N)
        for _ in range(max(n_steps, 0)):
            if stop is not None and stop[0]:
                break
            if self.solver == "newton":
                info, true_residual = self._newton_step(f_ext, atol, stop)
            else:
                info, true_residual = self._sweep_step(f_ext, loaded, atol, stop)
            if not info.taken:
                break  # stopped before its first sweep was done: its seeds stay for the next
            self._seeds = []
            self._cut_since_step = False
            sweeps += info.iterations
            self._count(info, true_residual, stop)
        return sweeps

    def at_rest(self) -> bool:
        """Whether the last step was a resting step that ended within the rest tolerance (the hybrid;
        a live session starts a stroke's rebase then, cutkit.simulate.live_loop)."""
        return self.resting_in_balance

    def _resting(self, f_ext: np.ndarray) -> bool:
        """Whether the coming step rests: the hybrid or Newton, no tet or node added or removed since the last
        step (nodes that follow a still blade may have moved), and no load, or a load
        that differs from the last step's by at most the stage's tolerance (N, the norm of the
        difference: a change that small cannot move the equilibrium by more than the tolerance
        lets a step miss it; the blade's load on a still blade settles geometrically, it is not
        constant to the bit).  The step the blade's load is taken off in rests even when the blade cut
        on its way out: it is solved on the whole model either way, and as a sweep step its finish
        (:meth:`_finish`) took 2.4 s of a live knee's coming to rest where a resting step's Newton
        solve takes about 1 s (docs/live.md).  The load is kept for the next call."""
        if self.solver not in ("hybrid", "newton") or self.rest_rtol is None:
            return False
        last, self._last_load = self._last_load, f_ext.copy()
        if last is None:
            return False
        lifted = bool(last.any()) and not f_ext.any()
        if not lifted and (last.shape != f_ext.shape or self._cut_since_step):
            return False
        if not f_ext.any():
            # no load (the blade has left, or cuts no more): the step the load went to zero in is
            # solved by Newton too; by sweeps it took 26-32 of them to the step tolerance on the
            # demo knee (0.22-0.26 s live) before the resting steps began (docs/relaxation.md)
            self._rested_once &= not last.any()  # a load just taken off starts the first stage again
            return True
        return float(np.linalg.norm(f_ext - last)) <= self._rest_stage()[0]

    def _rest_stage(self) -> tuple[float, int]:
        """A resting step's tolerance (N) and its sweeps before Newton.  The tolerance over the force
        scale: :data:`REST_FIRST_RTOL` while the blade loads the tissue; once it has left,
        :data:`REST_UNLOADED_FIRST_RTOL` until a resting step has ended there, then the rest
        tolerance (each stage at least the rest tolerance).  The first stage after the blade left
        makes no sweeps: they leave the wound's opening as it was (0.19 N to 0.18 N on the demo
        knee) and a replay of that step was 0.06-0.1 s faster without them, with the same Newton and
        CG iterations (docs/relaxation.md, "Resting steps")."""
        unloaded = self._last_load is not None and not self._last_load.any()  # the blade has left
        if not unloaded:
            rtol, sweeps = self._first_rtol(), REST_SWEEPS
        elif self._rested_once:
            rtol, sweeps = self.rest_rtol, REST_SWEEPS
        else:
            rtol, sweeps = self._unloaded_first_rtol(), 0
        return max(rtol * self.force_scale, DEFAULT_ATOL_N), sweeps

    def prepare_resting(self, halt=None) -> None:
        """The Newton matrix's pattern built now (:class:`~cutkit.relax.hessian_pattern.HessianPattern`),
        so that the first resting step after a stroke only updates it: a live session calls this
        before its clock starts, and its idle resting steps call it after a rebase (on the demo knee
        a full build in that step cost 0.15-0.33 s of the wound's coming to rest; an update
        0.03-0.23 s).  ``halt`` ((1,) int64, optional): a waiting cut stops the build (what was
        built stays).  Nothing for vertex block descent alone or the ANP element (its Newton
        solver builds its own stencil)."""
        if self.solver in ("hybrid", "newton") and self.em.element != "anp":
            self.hessian_pattern.get(halt)

    def _first_rtol(self) -> float:
        """A resting step's first-stage tolerance over the force scale under the blade
        (:data:`REST_FIRST_RTOL`, or the rest tolerance where looser)."""
        return max(self.rest_rtol, REST_FIRST_RTOL)

    def _unloaded_first_rtol(self) -> float:
        """The first-stage tolerance once the blade has left (:data:`REST_UNLOADED_FIRST_RTOL`, or the
        rest tolerance where looser)."""
        return max(self.rest_rtol, REST_UNLOADED_FIRST_RTOL)

    def _rest_step(self, f_ext: np.ndarray, stop):
        """One resting step: a few sweeps (:meth:`_rest_stage`) and Newton on the whole model
        (:func:`~cutkit.relax.newton.rest_step`, its pattern kept until the mesh changes) to the
        stage's tolerance; a step already within it ends at once, at rest.  Returns (info, true
        residual N, Newton iterations)."""
        from cutkit.relax.newton import rest_step
        from cutkit.relax.vbd import SolveInfo

        atol, sweeps = self._rest_stage()
        x0, v0 = self.state.positions.copy(), self.state.velocities.copy()
        r = self._residual(x0, v0, f_ext)  # at x = x0: the kept forces, nothing summed again
        res = start = self._free_norm(r)
        if res <= atol:
            self.state.velocities[:] = 0.0
            self.state.time += self.step_s
            self.r2[:] = np.einsum("ij,ij->i", r, r)
            if stop is not None:  # live and idle: the pattern kept current while nothing else runs
                self.prepare_resting(stop)
            return SolveInfo(0, res, res, True, 0), res, 0
        info, swept = rest_step(self.em, self.state, self.step_s, f_ext, atol=atol, sweeps=sweeps,
                                max_iterations=NEWTON_STEP_MAX_ITERATIONS, solver=self._whole_model_newton(REST_HESSIAN),
                                stop=stop, smoothing=REST_SMOOTHING_SWEEPS)
        if not info.taken:
            return info, 0.0, 0
        if _stopped(stop):  # a cut waits: the step ended early, its residual not evaluated
            return SolveInfo(swept, start, NOT_EVALUATED, False, 0), NOT_EVALUATED, info.iterations
        r = self._residual(x0, v0, f_ext)
        self.r2[:] = np.einsum("ij,ij->i", r, r)
        res = self._free_norm(r)
        return SolveInfo(swept, start, res, res <= atol, 0), res, info.iterations

    def _newton_step(self, f_ext: np.ndarray, atol: float, stop):
        """One projected Newton step on the whole model (:func:`~cutkit.relax.newton.newton_step`) to
        ``atol`` (N), or, where the step rests (:meth:`_resting`), to the resting stage's tolerance
        (:meth:`_rest_stage`; no sweeps): the wound's gaping is a soft mode within the step
        tolerance, so a step asked that alone ends where the cut left the wound, closed
        (docs/relaxation.md, "Resting steps").  Returns (info, true residual N)."""
        from cutkit.relax.newton import newton_step

        resting = self._resting(f_ext)
        if resting:
            atol = min(atol, self._rest_stage()[0])
        info = newton_step(self.em, self.state, self.step_s, f_ext, atol=atol,
                           max_iterations=NEWTON_STEP_MAX_ITERATIONS, solver=self._newton, stop=stop)
        self._book_rest(resting, info)
        return info, info.residual

    def _sweep_step(self, f_ext: np.ndarray, loaded: np.ndarray, atol: float, stop):
        """One vertex block descent step (:func:`~cutkit.relax.vbd.local_step`); returns (info, true
        residual N).  With the ``"hybrid"`` solver, a step not stopped that the sweeps leave out of
        balance (their own test failed at the cap, or the true residual is above ``atol``) is
        finished by :meth:`_polish`."""
        if self._resting(f_ext):
            info, true_residual, newton = self._rest_step(f_ext, stop)
            self._book_rest(True, info)
            if info.taken:
                self.counts["newton_iterations"] += newton
                self.step_log["polish_iterations"].append(int(newton))
            return info, true_residual
        seeds = np.concatenate([loaded, *self._seeds]) if self._seeds else loaded
        x0, v0 = self.state.positions.copy(), self.state.velocities.copy()
        info = local_step(self.em, self.state, self.step_s, f_ext, self.r2, seeds, atol=atol,
                          max_iterations=self.step_max_iterations, stop=stop)
        self._book_rest(False, info)
        if not info.taken:
            return info, 0.0
        if _stopped(stop):  # a cut waits: the step ended early, its residual not evaluated
            return dataclasses.replace(info, residual=NOT_EVALUATED, converged=False), NOT_EVALUATED
        r = self._residual(x0, v0, f_ext)
        true_residual = self._free_norm(r)
        if self.solver != "hybrid":
            return info, true_residual
        polished = 0
        if not (stop is not None and stop[0]) and (true_residual > atol or not info.converged):
            info, true_residual, polished = self._polish(info, x0, v0, f_ext, r, atol)
        if not (stop is not None and stop[0]) and not info.converged:
            info, true_residual, finished = self._finish(info, x0, v0, f_ext, atol, stop)
            polished += finished
        self.counts["newton_iterations"] += polished
        self.step_log["polish_iterations"].append(int(polished))
        return info, true_residual

    def _book_rest(self, resting: bool, info) -> None:
        """Whether the step just made rested, for the next steps (:meth:`at_rest`, the rest stages) and
        the report (``resting_steps``, per step ``resting``, where the solver has resting steps): a
        step that did not rest starts the first stage again."""
        self.resting_in_balance = bool(resting and info.taken and info.converged)
        self._rested_once = (self._rested_once or self.resting_in_balance) if resting else False
        if info.taken and "resting" in self.step_log:
            self.counts["resting_steps"] += int(resting)
            self.step_log["resting"].append(resting)

    def _polish(self, info, x0, v0, f_ext, r, atol: float):
        """:func:`~cutkit.relax.hybrid.polish_step` of the step the sweeps left (residual r); the
        nodes' last residuals (what the next step's sweeps wake by) become the true ones.
        Returns (info, true residual N, Newton iterations)."""
        from cutkit.relax.hybrid import polish_step
        from cutkit.relax.vbd import SolveInfo

        t0 = time.perf_counter()
        p, r = polish_step(self.em, self.state, x0, v0, self.step_s, f_ext, atol=atol, residual=r,
                           timings=self.polish_timings)
        self.polish_timings["total"] = self.polish_timings.get("total", 0.0) + time.perf_counter() - t0
        self.counts["polish_calls"] += 1
        self.r2[:] = np.einsum("ij,ij->i", r, r)
        done = SolveInfo(info.iterations, info.initial_residual, p.residual, p.converged, info.node_updates)
        return done, p.residual, p.iterations

    def _finish(self, info, x0, v0, f_ext, atol: float, stop):
        """A step the sweeps and the polish left out of balance (the out-of-balance mode spans more of
        the model than a polish factorises, or the polish ran out of iterations) finished on the
        whole model (:func:`~cutkit.relax.newton.finish_step`, the resting steps' solver), so every
        step of the hybrid ends converged.  Returns (info, true residual N, Newton iterations)."""
        from cutkit.relax.newton import finish_step
        from cutkit.relax.vbd import SolveInfo

        p = finish_step(self.em, self.state, x0, v0, self.step_s, f_ext, atol=atol,
                        max_iterations=NEWTON_STEP_MAX_ITERATIONS, solver=self._whole_model_newton(FINISH_HESSIAN),
                        stop=stop)
        if not p.taken:
            return info, info.residual, 0
        self.counts["whole_model_finishes"] += 1
        r = self._residual(x0, v0, f_ext)
        self.r2[:] = np.einsum("ij,ij->i", r, r)
        res = self._free_norm(r)
        return SolveInfo(info.iterations, info.initial_residual, res, res <= atol, info.node_updates), res, p.iterations

    def _whole_model_newton(self, hessian: str):
        """The hybrid's whole-model Newton with ``hessian`` (resting steps: :data:`REST_HESSIAN`,
        finishes: :data:`FINISH_HESSIAN`), built on first use; both share the matrix pattern."""
        from cutkit.relax.newton import NewtonSolver

        solver = self._whole_newton.get(hessian)
        if solver is None:
            solver = self._whole_newton[hessian] = NewtonSolver(self.em, hessian=hessian, cg_rtol=REST_CG_RTOL,
                                                                pattern=self.hessian_pattern,
                                                                no_oversolve=REST_NO_OVERSOLVE,
                                                                preconditioner=REST_PRECONDITIONER)
        return solver

    def _true_residual(self, x0: np.ndarray, v0: np.ndarray, f_ext: np.ndarray) -> float:
        """N: the norm over all free dofs of the backward Euler residual of the step just made from
        (x0, v0) (vertex block descent's own residual keeps each sleeping node's last value)."""
        return self._free_norm(self._residual(x0, v0, f_ext))

    def _free_norm(self, r: np.ndarray) -> float:
        """N: the norm of r (n, 3) over the free dofs of nodes with tets."""
        em = self.em
        return float(np.linalg.norm(r[~em.fixed & (em.adj_degree > 0)[:, None]]))

    def _residual(self, x0: np.ndarray, v0: np.ndarray, f_ext: np.ndarray) -> np.ndarray:
        """(n, 3) float64 N: the backward Euler residual of the step just made from (x0, v0), 0 at
        held dofs and at nodes without tets."""
        em, x, h = self.em, self.state.positions, self.step_s
        m = em.masses[:, None]
        r = self.kept_forces.get(em, x) + f_ext - m / (h * h) * (x - x0 - h * v0) - em.damping[:, None] * m / h * (x - x0)
        r[em.fixed | (em.adj_degree == 0)[:, None]] = 0.0
        return r

    def _count(self, info, true_residual: float, stop=None) -> None:
        """Book one relaxation step: the counters and the per-step log (the true residual; the
        smallest volume ratio, not measured (NaN) where ``stop`` says a cut is waiting)."""
        self.counts["steps"] += 1
        if self.solver == "newton":
            self.counts["newton_iterations"] += info.iterations
        else:
            self.counts["sweeps"] += info.iterations
        self.counts["node_updates"] += info.node_updates
        self.counts["steps_not_converged"] += int(not info.converged)
        self.step_log["iterations"].append(int(info.iterations))
        self.step_log["relative_residual"].append(float(true_residual / self.force_scale)
                                                  if self.force_scale > 0 else 0.0)
        # how near the step's end state came to crushing a tet (J of the natural shape); one pass
        # like an energy's, 2-3 ms on the knee, that a waiting cut does not wait for
        lowest, crushed = self.kept_ratios.extremes(self.em, self.state.positions, CRUSHED_J, stop)
        self.step_log["min_J"].append(float(lowest))
        self.step_log["crushed_tets"].append(int(crushed))

    def relax_report(self) -> dict:
        """``summary.json``'s ``relax_steps``: how the relaxation steps ended (docs/simulate.md).

        Returns
        -------
        dict
            ``solver``, ``count``, ``not_converged``, ``worst_relative_residual``,
            ``iterations_total``, ``rtol``, ``min_J_worst`` (the smallest volume
            ratio any step ended with), ``steps_with_crushed_tets`` (steps that
            ended with a tet below ``crushed_J`` = :data:`CRUSHED_J`),
            ``steps_without_min_J`` (live steps whose report pass a waiting cut
            ended: :meth:`_count`), ``steps_without_residual`` (live steps a waiting cut
            ended early: not converged, their residual not evaluated, which the cut
            would wait for), and per step ``iterations``,
            ``relative_residual`` (true final residual over the force scale; None where
            not evaluated) and ``min_J`` (None where not measured);
            ``"newton"`` and ``"hybrid"`` add ``resting_steps``, ``rest_rtol``,
            ``rest_first_rtol``, ``rest_unloaded_first_rtol`` and per step ``resting``;
            ``"hybrid"`` adds ``polish_iterations_total``, ``polished_steps``
            (steps with a Newton iteration), ``polish_calls`` (steps that
            called the polish), ``whole_model_finishes`` (steps the polish left out
            of balance, finished by :meth:`_finish`), ``polish_s`` (wall seconds of the polishes:
            ``total`` and each part of :data:`cutkit.relax.hybrid.TIMED`), and per
            step ``polish_iterations`` (a resting step's Newton iterations
            included).
        """
        rel = self.step_log["relative_residual"]
        return {"solver": self.solver, "count": len(rel), "not_converged": int(self.counts["steps_not_converged"]),
                "worst_relative_residual": float(max((r for r in rel if not np.isnan(r)), default=0.0)),
                "steps_without_residual": int(sum(1 for r in rel if np.isnan(r))),
                "iterations_total": int(sum(self.step_log["iterations"])), "rtol": self.step_rtol,
                "force_scale_N": float(self.force_scale),
                "iterations": list(self.step_log["iterations"]),
                "relative_residual": [None if np.isnan(r) else r for r in rel],
                "min_J": [None if np.isnan(j) else j for j in self.step_log["min_J"]],
                "min_J_worst": float(min((j for j in self.step_log["min_J"] if not np.isnan(j)), default=1.0)),
                "steps_without_min_J": int(sum(1 for j in self.step_log["min_J"] if np.isnan(j))),
                "crushed_J": CRUSHED_J,
                "steps_with_crushed_tets": int(sum(1 for k in self.step_log["crushed_tets"] if k)),
                **self._solver_report()}

    def _solver_report(self) -> dict:
        """The resting steps (Newton and the hybrid) and the hybrid's polish in :meth:`relax_report`
        (nothing for vertex block descent alone)."""
        if self.solver not in ("hybrid", "newton"):
            return {}
        rest = {"resting_steps": int(self.counts["resting_steps"]), "rest_rtol": self.rest_rtol,
                "rest_first_rtol": None if self.rest_rtol is None else self._first_rtol(),
                "rest_unloaded_first_rtol": None if self.rest_rtol is None else self._unloaded_first_rtol(),
                "resting": list(self.step_log["resting"])}
        if self.solver == "newton":
            return rest
        its = self.step_log["polish_iterations"]
        return {"polish_iterations_total": int(sum(its)), "polished_steps": int(sum(1 for k in its if k)),
                "polish_calls": int(self.counts["polish_calls"]),
                "whole_model_finishes": int(self.counts["whole_model_finishes"]),
                **rest, "polish_s": {k: float(v) for k, v in self.polish_timings.items()},
                "polish_iterations": list(its)}

    # ------------------------------------------------------------ cut
    def apply_delta(self, delta) -> dict:
        """Carry a cut step's :class:`~cutkit.tissue.TopologyDelta` over to the elements.

        Returns
        -------
        counts : dict
            ``nodes_added``, ``elements_added``, ``elements_removed``.
        """
        store, em = self.store, self.em
        n_old, n_new = em.n_nodes, delta.n_nodes_after
        moved = delta.moved_nodes
        old_moved = moved[moved < n_old]
        # a tet made and unmade within the step is never simulated; the tets around moved nodes
        # that the step did not touch get their rest shape again
        added, removed, again, before = step_tet_sets(delta.added_tets, delta.removed_tets,
                                                      tets_around(em.adjacency, old_moved))
        # the tissue as it was before the step, piecewise affine over the removed tets and those
        # around moved nodes: new and moved nodes are placed in it (see _through_old_shape)
        old_shape = self._old_shape(before, old_moved, delta.moved_rest_from[moved < n_old])
        x_moved = self._through_old_shape(old_shape, old_moved)
        x_before = self.state.positions[old_moved].copy()
        if n_new > n_old:
            self._append_nodes(np.arange(n_old, n_new), old_shape)
        if old_moved.size:
            self.state.positions[old_moved] = x_moved
        em.remove_elements(np.concatenate([removed, again]))
        redo = np.concatenate([added, again])
        if redo.size:
            orig = store.tet_origins[redo]
            em.add_elements(store.rest_points, store.tet_corners[redo], self.mu[orig], self.lam[orig], self.density[orig],
                            self.prestrain[orig], self.fibre[orig], ids=redo)
            placed = np.concatenate([old_moved, np.arange(n_old, n_new)])
            self._unfold(redo, placed, np.concatenate([x_before, self.state.positions[n_old:n_new]]))
        # (a node listed twice is looked at twice, to the same effect: no sort for np.unique)
        self._hold_orphans(np.concatenate([store.tet_corners[np.concatenate([removed, redo])].ravel(),
                                           np.arange(n_old, n_new)]))
        self._recolour(added, n_old)
        if self.r2.shape[0] < em.n_nodes:
            self.r2 = append_rows(self.r2, np.zeros(em.n_nodes - self.r2.shape[0]))
        self.kept_forces.changed(store.tet_corners[np.concatenate([removed, redo])])  # their corners' sums changed
        self.kept_ratios.changed(np.concatenate([removed, again, redo]))
        touched = [np.arange(n_old, em.n_nodes), moved]
        if redo.size:
            touched.append(em.tets[redo].ravel())
        self._seeds.append(np.concatenate(touched))  # marked once each by step_seeds, repeats or not
        if self._newton is not None:
            self._newton.reset()  # nodes and elements changed: the matrix pattern is updated
        self.hessian_pattern.changed()
        self._whole_newton = {}
        # a step that only moved the nodes that follow the blade (a still blade re-places them
        # every step) cut nothing: the next step may rest
        self._cut_since_step |= bool(n_new > n_old or added.size or removed.size)
        self.resting_in_balance &= not self._cut_since_step
        self._rested_once &= not self._cut_since_step
        return {"nodes_added": int(n_new - n_old), "elements_added": int(added.size),
                "elements_removed": int(removed.size)}

    def _append_nodes(self, new: np.ndarray, old_shape) -> None:
        em, st = self.em, self.state
        par, w, valid = self._interpolation_weights(new)
        held = self.store.held[new]  # a node between held nodes only is held too (the store's rule)
        damping = (w * em.damping[par]).sum(axis=1)
        vel = np.einsum("pq,pqc->pc", w, st.velocities[par])
        x = self._through_old_shape(old_shape, new)
        em.add_nodes(new.size, damping=damping, fixed=held)
        st.positions = append_rows(st.positions, x)
        st.velocities = append_rows(st.velocities, np.where(held[:, None], 0.0, vel))

    def _unfold(self, tets: np.ndarray, placed: np.ndarray, before: np.ndarray) -> None:
        """Re-place the placed nodes of tets born folded, among a few candidate positions.

        A sub-tet spanning several old tets near the opened crack can be
        born folded however its nodes are placed by one map.  Each placed
        node of such a tet takes, of its position through the old shape, its
        interpolation over its defining nodes, its position before the step
        (moved nodes), the centroid of its tets' other corners and the
        midpoints, the one whose tets have the largest smallest volume ratio
        (deformed over rest volume, signed); if none opens them all,
        :meth:`_lift` moves it, and then any free corner of a tet still
        folded.

        Parameters
        ----------
        tets : (r,) int64
            Tets the step made or re-shaped.
        placed : (p,) int64
            Nodes the step placed (moved, then new).
        before : (p, 3) float64
            Their positions before the step (new nodes: as placed).
        """
        x, em = self.state.positions, self.em
        q = self.store.tet_corners[tets]
        folded = signed_volumes_serial(x, q) <= 0.0
        if not folded.any():
            return
        X = self.store.rest_points[: em.n_nodes]
        interp = self.interpolate_positions(placed)
        for k in np.flatnonzero(np.isin(placed, q[folded])):
            i = placed[k]
            around = em.tets[em.tets_of(i)]
            rest = signed_volumes_serial(X, around)
            now = x[i].copy()
            best, best_j = now, -np.inf
            ring = x[around[around != i]].mean(axis=0) if around.size else now  # the one-ring's centroid
            reach = _farthest_corner(x, around, now)
            for c in (now, interp[k], before[k], 0.5 * (now + interp[k]), 0.5 * (now + before[k]), ring,
                      0.5 * (now + ring)):
                if not np.linalg.norm(c - now) <= reach:
                    continue  # a far place opens every tet of a node on the surface, by moving it off the tissue
                x[i] = c
                j = float(np.min(signed_volumes_serial(x, around) / rest)) if around.size else 0.0
                if j > best_j:
                    best, best_j = c, j
            x[i] = best
            if best_j <= 0.0:
                self._lift(i, around, rest)
        # what one node could not open, the other corners of the tet may
        for i in np.unique(q[signed_volumes_serial(x, q) <= 0.0]):
            if not em.fixed[i].any():
                around = em.tets[em.tets_of(i)]
                self._lift(i, around, signed_volumes_serial(X, around))

    def _lift(self, i: int, around: np.ndarray, rest: np.ndarray) -> None:
        """Move node i so the most folded of its tets opens, keeping the others open.

        Each tet's volume ratio J is affine in x_i, J(x_i + d) = J + g . d, so
        the step d = (UNFOLD_J - J_min) g / |g|^2 opens the worst tet to
        UNFOLD_J exactly; it is shortened so that no tet of the node that is
        open falls below half its ratio.  Repeated for the next worst, at
        most :data:`UNFOLD_STEPS` times.

        Parameters
        ----------
        around : (k, 4) int64
            The node's tets.
        rest : (k,) float64
            Their rest volumes.
        """
        x = self.state.positions
        start = x[i].copy()
        reach = UNFOLD_REACH * _farthest_corner(x, around, start)
        for _ in range(UNFOLD_STEPS):
            J = signed_volumes_serial(x, around) / rest
            w = int(np.argmin(J))
            if J[w] > 0.0:
                return
            g = np.empty((J.shape[0], 3))  # dJ/dx_i of every tet: exact differences, J being affine
            xi = x[i].copy()
            for c in range(3):
                x[i, c] = xi[c] + 1.0
                g[:, c] = signed_volumes_serial(x, around) / rest - J
                x[i, c] = xi[c]
            gg = float(g[w] @ g[w])
            if gg == 0.0:
                return
            d = (UNFOLD_J - J[w]) / gg * g[w]
            slope = g @ d
            open_ = (J > 0.0) & (slope < 0.0)
            a = min(1.0, float(np.min(0.5 * J[open_] / -slope[open_]))) if open_.any() else 1.0
            x[i] = _within(xi + a * d, start, reach)

    def _old_shape(self, tets: np.ndarray, moved: np.ndarray, moved_from: np.ndarray):
        """Rest and current corners of tets as they were before a cut step moved some of their nodes.

        Parameters
        ----------
        tets : (r,) int64
            Cut-mesh tet ids alive before the step (removed ones included).
        moved : (b,) int64
            Nodes the step moved in the rest configuration.
        moved_from : (b, 3) float64
            Their rest positions before the step.

        Returns
        -------
        (X, x, Tinv) : (r, 4, 3), (r, 4, 3), (r, 3, 3) float64
            Rest and current corners and the inverse rest edge matrices; tets
            with no rest volume are left out.
        """
        order = np.argsort(moved)
        return old_shape_corners(self.store.tet_corners[tets], self.store.rest_points, self.state.positions, self.state.positions.shape[0],
                                 np.ascontiguousarray(moved[order]), np.ascontiguousarray(moved_from[order]))

    def _through_old_shape(self, old_shape, nodes: np.ndarray) -> np.ndarray:
        """Current positions of nodes at their (new) rest positions, through the old shape.

        The old shape is the deformation of the tets before the step: each is
        affine, so the new sub-tets of a tet, pieces of its rest shape, are
        pieces of its deformed shape and never folded over.  A node inside
        none of them takes the affine map of the
        nearest one (the largest smallest weight), extended, if it lies within
        :data:`PLACE_REACH` of it, else its interpolation over its defining
        nodes.

        Returns
        -------
        x : (p, 3) float64
        """
        x = self.interpolate_positions(nodes)
        X, xc, Tinv = old_shape
        if X.shape[0] and nodes.size:
            place_through_old_shape(np.ascontiguousarray(self.store.rest_points[nodes]), X, xc, Tinv, PLACE_REACH, x)
        return x

    def _hold_orphans(self, nodes: np.ndarray) -> None:
        """Of ``nodes`` (those whose tets a step changed), the ones no tet uses any more stay where
        they are; those with tets are free unless held by a condition."""
        em = self.em
        fixed = self.store.held[nodes] | (em.adj_degree[nodes] == 0)
        changed = fixed != em.fixed[nodes].all(axis=1)
        if changed.any():
            em.fixed[nodes[changed]] = fixed[changed, None]
            self.state.velocities[nodes[changed & fixed]] = 0.0
            em.forget_colour_classes()

    def _recolour(self, added: np.ndarray, n_old: int) -> None:
        """New nodes get a colour; so does any node of a new tet that shares one with another."""
        em = self.em
        new = np.arange(n_old, em.n_nodes)
        if new.size:
            em.recolour(new)
        if added.size:
            q = em.tets[added]
            c = em.colour[q]
            clash = np.zeros(q.shape, bool)
            for a in range(4):
                for b in range(a + 1, 4):
                    clash[:, b] |= c[:, a] == c[:, b]
            if clash.any():
                em.recolour(np.unique(q[clash]))
        em.forget_colour_classes()

    def _read_materials(self) -> None:
        """The material, prestrain and fibre of each original tet, from the store's labels (a sub-tet
        has its original's; after a rebase each new original tet has the label of the one it was cut from)."""
        mat = material_of_tets(self.model, self.store.labels, poisson_ratio=self.poisson_ratio)
        self.mu, self.lam, self.density, self.damping = mat["mu"], mat["lam"], mat["density"], mat["damping"]
        self.prestrain, self.fibre = prestress_of_tets(self.model, self.store.labels)

    # ------------------------------------------------------------ strokes
    def rebase(self, old_of_new: np.ndarray) -> None:
        """Follow :meth:`TissueStore.rebase <cutkit.tissue.store.TissueStore.rebase>` (called after it, between strokes).

        The live tets became the original tets ``0 .. m-1`` of a fresh cut
        state.  The per-original-tet materials are read again from the
        store's labels (each new original tet keeps the label of the old
        original tet it was cut from), and the elements are built again on the new
        numbering from the store's rest positions (the same rest shapes;
        masses summed again from them).  Node data stay: damping, fixed
        flags, colours, positions, velocities (node ids do not change).

        Parameters as :meth:`TissueBase.rebase <cutkit.relax.tissue_base.TissueBase.rebase>`.
        """
        store, old = self.store, self.em
        self._read_materials()
        m = int(np.asarray(old_of_new).shape[0])
        self.n_orig_tets = m
        n = old.n_nodes
        em = ElementModel.empty(n, store.tet_capacity)
        em.damping[:] = old.damping
        em.fixed[:] = old.fixed
        em.colour[:] = old.colour  # the same tets on the same nodes: the colouring stays valid
        em.element, em.deviatoric_smoothing = old.element, old.deviatoric_smoothing
        self.kept_forces.forget()
        self.kept_ratios.forget()
        em.reserve_rows(store.orig_tets)  # the rows in sweep order before they are filled: no copy after
        em.add_elements(store.rest_points[:n], store.orig_tets, self.mu, self.lam, self.density, self.prestrain, self.fibre,
                        ids=np.arange(m))
        self.em = em
        self.hessian_pattern = HessianPattern(em)  # the nodes are numbered afresh: built in full
        self._newton = self._newton_solver()
        self._whole_newton = {}
        self._last_load = None  # numbered as before the rebase: the next step does not rest
