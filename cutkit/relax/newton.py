"""Projected Newton solves of the element model: implicit steps and static equilibrium.

One backward Euler step of length ``h`` minimises the incremental potential
of :mod:`cutkit.relax.elastic` (barrier included)

    G(x) = sum_i m_i / (2 h^2) |x_i - y_i|^2 + c_i m_i / (2 h) |x_i - x_i^n|^2 + W(x) - f_ext . x

by projected Newton (Smith, de Goes & Kim 2018, section 4.3; Teran et al.
2005): each element's Hessian is projected to positive semi-definite
(:mod:`cutkit.relax._newton_kernels`), the assembled system

    (M / h^2 + C M / h + K_+) d = r(x),   r = -dG/dx over the free dofs

is solved by a sparse Cholesky factorisation (cholespy) or, for large
models, by conjugate gradients preconditioned by block Jacobi or multigrid
(pyamg) (:data:`LINEAR_SOLVERS`, :data:`PRECONDITIONERS`), and an energy line search backtracks from the
longest step that inverts no element (Li et al. 2020, incremental potential
contact: filter the first trial by the first time any element's volume
reaches zero, then Armijo on G).  Every iterate keeps every element that was
not inverted non-inverted, so the barrier's invariant holds.  ``h = None``
drops inertia and damping: the same iterations solve for static equilibrium.

A solve stops on the true residual: ``||r|| <= atol`` over all free dofs
(N), the same criterion as :func:`cutkit.relax.vbd.local_step`'s ``atol``.

With ``region_rings`` set, each iteration solves only where the model is out
of balance (:func:`newton_region`): the smallest set of nodes outside of which
the residual norm is below :data:`REGION_FRACTION` of ``atol``, grown by that
many rings of the tet graph, the rest held.  Its system is small enough to
factorise (milliseconds), and the line search and the stopping test still take
the whole model's G and residual, so a solve ends only when the WHOLE model is
in balance: the slow, global modes (a wound's gaping) are never cut off, they
widen the region (issue 29, "locality without losing the slow modes").
"""

from __future__ import annotations

import contextlib
import os
import sys

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _elastic_kernels as KE
from cutkit.relax import _block_cg_kernels as KB
from cutkit.relax import _newton_kernels as KN
from cutkit.relax import anp
from cutkit.relax.elastic import ElementModel, ElementState
from cutkit.threads import numba_threads_here, one_blas_thread
from cutkit.relax.settle import rigid_modes
from cutkit.relax.hessian_pattern import HessianPattern
from cutkit.relax.vbd import (DEFAULT_ATOL_N, NEVER_STOP, SolveInfo, _node_terms, elastic_energy, elastic_forces,
                              iterate)

#: Newton iterations one solve makes before it reports that it did not converge.
DEFAULT_MAX_ITERATIONS = 50
#: Armijo's sufficient-decrease constant (Nocedal & Wright, eq. 3.4).
ARMIJO_C1 = 1e-4
#: The first trial of the line search stops short of the first element inversion by this factor
#: (Li et al. 2020, section 4.4, use 0.8 of the time of impact; here of the time of zero volume).
INVERSION_SAFETY = 0.9
#: Halvings of the step before a line search gives up (the solve then reports not converged).
MAX_BACKTRACKS = 40
#: A decrease of G this far below G's size (relative) is lost in rounding: there, a trial is
#: accepted when it lowers the residual instead.
ROUNDING = 1e-13
#: The linear solvers: ``"cholesky"`` (cholespy's sparse Cholesky factorisation), ``"cg"``
#: (conjugate gradients, smoothed-aggregation multigrid preconditioner, pyamg) or ``"auto"``.
LINEAR_SOLVERS = ("auto", "cholesky", "cg")
#: ``"auto"`` factorises systems of at most this many dofs and solves larger ones by CG
#: (docs/relaxation.md, "Linear solves": cholespy's factorisation grows steeply past it).
CHOLESKY_MAX_DOFS = 10000
#: A static system (no inertia) that has a floating piece is singular: its diagonal gets this
#: fraction of itself added (it changes the step, never the residual the solve stops on).
STATIC_SHIFT = 1e-10
#: Which Hessian a Newton iteration takes: ``"auto"`` tries the exact one first and falls back to
#: the projected one where the factorisation finds it indefinite; ``"projected"``; ``"exact"``.
HESSIANS = ("auto", "projected", "exact")
#: Relative tolerance of a CG solve (inexact Newton: the outer iteration corrects what it leaves).
CG_RTOL = 1e-2
#: No oversolving (Eisenstat & Walker, SIAM J. Sci. Comput. 17, 1996, section 2.3): an iteration
#: from residual ``res`` solves its system only to ``NO_OVERSOLVE * atol / res`` where that is looser
#: than the solver's ``cg_rtol`` (a linear model that good already lands within the tolerance) ...
NO_OVERSOLVE = 0.5
#: ... but never looser than this.
CG_RTOL_MAX = 0.5
#: An iteration after one whose line search the inversion bound cut short solves its system only to
#: this (where that is looser): near a crushed tet the step will be cut short again, so the linear
#: model's direction is taken only in part and an accurate one is wasted (inexact Newton, the forcing
#: term following how well the last step's model held: Eisenstat & Walker 1996, section 2).  On the
#: demo knee's ANP incision 16 % less relaxation time, the same opening (docs/relaxation.md).
BOUNDED_CG_RTOL = 0.3
#: CG iterations of one linear solve at most.
CG_MAX_ITERATIONS = 500
#: The multigrid hierarchy is built again after a solve that took more CG iterations than this
#: (the matrix has drifted from the one it was built on): on the cut knee a setup costs about
#: 5 s and a stale hierarchy 500 iterations, 100 s.
AMG_REBUILD_ITERATIONS = 100
#: Preconditioners of the CG path: ``"block_jacobi"`` (the inverse of each node's 3 x 3 diagonal
#: block, built from every matrix anew) or ``"amg"`` (smoothed-aggregation multigrid, pyamg, kept
#: across iterations, steps and cuts).  The first is the default: on the cut knee it reaches 10^-3 of
#: the force scale 2.2-2.8x sooner (docs/relaxation.md, "Why block Jacobi").
PRECONDITIONERS = ("block_jacobi", "amg", "two_level")
#: The two-level preconditioner's coarse grid has about this many cells over the free nodes' bounding
#: box; each cell's nodes joined through the matrix (a crack splits a cell) make one aggregate whose
#: rigid motions span the coarse space (:mod:`cutkit.relax._coarse_kernels`).  On the saved system of
#: the demo knee's first resting step after the lift, 50 and 100 cells (504 and 699 coarse dofs)
#: both halved the block-Jacobi iterations (117 and 116 against 229).
COARSE_CELLS = 50
#: An aggregate turns (rotations in its basis) only with at least this many nodes.
COARSE_MIN_TURNING_NODES = 4
#: More coarse dofs than this and the solve takes block Jacobi alone (E is factorised densely).
COARSE_MAX_DOFS = 3000
#: A local iteration's region holds the nodes that carry the residual: outside it the residual norm is
#: at most this fraction of the tolerance (:func:`newton_region`).
REGION_FRACTION = 0.1
#: A local iteration that leaves more than this fraction of the residual it started from doubles the
#: rings of the iterations after it (a mode wider than the region: the region grows to meet it).
REGION_WIDEN = 0.5
#: A region of more than this fraction of the free dofs is solved as the whole model.
REGION_MAX_FRACTION = 0.5


class NewtonSolver:
    """Projected Newton on one :class:`~cutkit.relax.elastic.ElementModel`.

    Keeps the sparsity pattern of the model's Hessian between solves; call
    :meth:`reset` after any topology change (a cut adds and removes nodes
    and elements, so the pattern changes).

    Parameters
    ----------
    em : ElementModel
    linear : str
        One of :data:`LINEAR_SOLVERS`.
    hessian : str
        One of :data:`HESSIANS`.  The projected Hessian is positive
        semi-definite, so its step always descends, but on a slender body it
        drops the curvature that bending needs and the iterations converge
        only linearly (a cantilever: residual ratio 0.82 per iteration,
        against quadratic convergence with the exact Hessian); ``"auto"``
        takes the exact Hessian wherever it is positive definite.
    preconditioner : str
        One of :data:`PRECONDITIONERS`: what preconditions the CG solves.
    cg_rtol : float
        Relative residual each conjugate-gradient solve stops at (inexact
        Newton; default :data:`CG_RTOL`), or looser near the end of a solve
        (:data:`NO_OVERSOLVE`).
    no_oversolve : float
        An iteration from residual ``res`` solves its system only to
        ``no_oversolve * atol / res`` where that is looser than ``cg_rtol``
        (default :data:`NO_OVERSOLVE`), in (0, 1].
    region_rings : int, optional
        None: every iteration solves the whole model.  k >= 0: each iteration
        solves on :func:`newton_region` grown by k rings (doubled after an
        iteration that gains little), the rest held; the solve still stops on
        the whole model's residual.
    pattern : HessianPattern, optional
        The model's matrix pattern, shared with other solvers of ``em`` (default: its own).
    """

    def __init__(self, em: ElementModel, *, linear: str = "auto", hessian: str = "auto",
                 preconditioner: str = "block_jacobi", region_rings: int | None = None,
                 cg_rtol: float = CG_RTOL, pattern: HessianPattern | None = None,
                 no_oversolve: float = NO_OVERSOLVE):
        if linear not in LINEAR_SOLVERS:
            raise InputError(f"linear solver must be one of {', '.join(LINEAR_SOLVERS)}, not {linear!r}")
        if hessian not in HESSIANS:
            raise InputError(f"hessian must be one of {', '.join(HESSIANS)}, not {hessian!r}")
        if preconditioner not in PRECONDITIONERS:
            raise InputError(f"preconditioner must be one of {', '.join(PRECONDITIONERS)}, not {preconditioner!r}")
        if region_rings is not None and not (isinstance(region_rings, (int, np.integer)) and region_rings >= 0):
            raise InputError(f"region_rings must be None or a non-negative integer, not {region_rings!r}")
        if not (np.isfinite(cg_rtol) and 0.0 < cg_rtol < 1.0):
            raise InputError(f"cg_rtol must be in (0, 1), not {cg_rtol!r}")
        if not (np.isfinite(no_oversolve) and 0.0 < no_oversolve <= 1.0):
            raise InputError(f"no_oversolve must be in (0, 1], not {no_oversolve!r}")
        self.em = em
        self.cg_rtol = float(cg_rtol)
        self.no_oversolve = float(no_oversolve)
        self.region_rings = None if region_rings is None else int(region_rings)
        #: dofs of each local iteration's region (0: that iteration solved the whole model)
        self.region_log: list[int] = []
        self.preconditioner = preconditioner
        self.linear = linear
        self.hessian = hessian
        self.counts = {"factorisations": 0, "indefinite": 0, "pattern_builds": 0, "cg_iterations": 0,
                       "amg_setups": 0,
                       "local_iterations": 0, "global_iterations": 0}
        self._amg = None  # (hierarchy, dofs it was built on)
        self._patterns = HessianPattern(em) if pattern is None else pattern
        self._pattern = None
        self._upper = None  # the pattern's block index (block_index)
        self.reset()

    def reset(self) -> None:
        """Look at the pattern again at its next use (after a topology change: it is updated where
        the change was, :class:`~cutkit.relax.hessian_pattern.HessianPattern`).  The multigrid
        hierarchy stays: a cut only appends nodes, so it still preconditions the dofs it was built
        on (:meth:`_preconditioner`)."""
        self._patterns.changed()
        self._key = None

    # ------------------------------------------------------------ the linear system
    def _elements(self) -> KE.Elements:
        em = self.em
        m = em.n_elements
        return KE.Elements(em.tets[:m], em.Dminv[:m], em.volume[:m], em.mu[:m], em.lam[:m])

    def pattern(self, halt=None) -> KN.Pattern | None:
        """The sparsity pattern of the model's Hessian (kept, and updated after :meth:`reset`);
        None where ``halt`` ((1,) int64, optional: a waiting cut) stopped its build."""
        em = self.em
        if em.element == "anp":  # the nodal volume terms couple each node's patch
            key = (em.n_nodes, em.n_elements)
            pattern = self._pattern if key == self._key else anp.anp_pattern(em, self._elements())
            self._key = key
        else:
            pattern = self._patterns.get(halt)
            if pattern is None:
                return None
        if pattern is not self._pattern:
            self._pattern = pattern
            self._upper = None
            self.counts["pattern_builds"] += 1
        return pattern

    def matrix(self, x: np.ndarray, free: np.ndarray, diagonal_add: np.ndarray, project: int = 1, halt=None):
        """The Hessian of G at x: (3n, 3n) scipy CSR, identity rows at held dofs; None where ``halt``
        stopped the assembly.

        Parameters
        ----------
        x : (n, 3) float64
        free : (n, 3) bool
        diagonal_add : (n,) float64
            ``m / h^2 + c m / h`` per node (0 for a static solve).
        project : int
            0: exact element Hessians; 1: negative eigenvalues clamped to 0 (analytic
            eigensystem); ``_newton_kernels.CLAMP_EIGH``: the same by LAPACK's eigh.
        halt : (1,) int64, optional
            Read between chunks of elements (the neo-Hookean element): non-zero ends the assembly
            (a waiting cut waits for one chunk, not for the whole matrix).
        """

        pat = self.pattern(halt)
        if pat is None:
            return None
        data = np.empty(pat.indices.shape[0])
        if self.em.element == "anp":
            anp.assemble_anp_hessian(self.em, x, pat, int(project), data)
        elif not KN.assemble_hessian(x, reaching_free_dofs(self._elements(), free), pat, int(project), data, halt):
            return None
        return self._constrained(data, free, diagonal_add)

    def _solve_linear(self, A, r: np.ndarray, x: np.ndarray, free: np.ndarray, rtol: float, halt=None):
        """d with A d = r (conjugate gradients to ``rtol``), or None where a Cholesky factorisation finds A not positive definite or
        ``halt`` stopped the conjugate gradients (x (n, 3) and free (n, 3) bool: where A was
        assembled, for a multigrid setup)."""
        if self.linear == "cholesky" or (self.linear == "auto" and A.shape[0] <= CHOLESKY_MAX_DOFS):
            return self._factor_solve(A, r)
        if self.preconditioner in ("block_jacobi", "two_level"):
            return self._block_cg(A, r, rtol, halt, x, free)
        if self._amg is None or self._amg[1] > A.shape[0]:
            self._build_amg(A, x, free)
        d, its = pcg(A, r, self._preconditioner(A), rtol, CG_MAX_ITERATIONS, halt)
        self.counts["cg_iterations"] += its
        if d is None and halt is not None and halt[0]:
            return None  # a waiting cut: the iteration is abandoned, x stays the last iterate
        if d is None:  # negative curvature: the exact Hessian is indefinite
            self.counts["indefinite"] += 1
            return None
        if its > AMG_REBUILD_ITERATIONS:  # the hierarchy has aged (or misses the appended dofs): build it again
            self._amg = None
        return d

    def _block_cg(self, A, r: np.ndarray, rtol: float, halt=None, x=None, free=None):
        """d with A d = r by block-Jacobi conjugate gradients on A's symmetric block form
        (:mod:`cutkit.relax._block_cg_kernels`), two-level with :func:`coarse_space` of (x, free)
        where the solver's preconditioner is ``"two_level"``; None where a diagonal block or a
        search direction shows A is not positive definite, or ``halt`` stopped it."""
        pat = self.pattern()
        if self._upper is None:
            self._upper = block_index(pat)
        blocks, inv = block_system(A, pat, self._upper)
        if inv is None:  # a diagonal block is not positive definite, so neither is A
            self.counts["indefinite"] += 1
            return None
        flag = halt if halt is not None else NEVER_STOP
        coarse = coarse_space(blocks, x, free, flag) if self.preconditioner == "two_level" else None
        if flag[0]:
            return None  # a waiting cut stopped the coarse space: the iteration is abandoned
        n = self.em.n_nodes
        d = np.empty((n, 3))
        b = np.ascontiguousarray(r.reshape(n, 3))
        rows = numba_threads_here() > 1
        if coarse is None:  # the argument left out, not None: the kernel's block-Jacobi signature, compiled once
            status, its = KB.block_pcg(blocks, inv, b, rtol, CG_MAX_ITERATIONS, flag, d, rows)
        else:
            status, its = KB.block_pcg(blocks, inv, b, rtol, CG_MAX_ITERATIONS, flag, d, rows, coarse)
        self.counts["cg_iterations"] += its
        if status == KB.CG_HALTED:
            return None  # a waiting cut: the iteration is abandoned, x stays the last iterate
        if status == KB.CG_NEGATIVE_CURVATURE:  # the exact Hessian is indefinite
            self.counts["indefinite"] += 1
            return None
        return d.ravel()

    def _build_amg(self, A, x: np.ndarray, free: np.ndarray) -> None:
        """Smoothed-aggregation multigrid of A (pyamg), kept across iterations, steps and cuts.

        The near-null space is the six rigid-body modes of x on the free dofs (Vanek, Mandel &
        Brezina 1996: elasticity's aggregates must carry the rotations too); without them a CG
        solve of the knee's Newton system takes 4x the iterations (docs/relaxation.md)."""
        import pyamg

        modes = rigid_modes(x) * free.reshape(-1, 1)
        saved = np.random.get_state()
        np.random.seed(0)  # pyamg draws from numpy's global generator: a repeatable setup
        try:
            ml = pyamg.smoothed_aggregation_solver(A, B=modes, symmetry="symmetric", max_coarse=500)
        finally:
            np.random.set_state(saved)
        self._amg = (ml, A.shape[0])
        self.counts["amg_setups"] += 1

    def _preconditioner(self, A):
        """One V-cycle on the dofs the hierarchy was built on, Jacobi on the dofs a cut appended since."""
        import scipy.sparse.linalg as spla

        ml, k = self._amg
        cycle = ml.aspreconditioner(cycle="V")
        if k == A.shape[0]:
            return cycle
        inv = 1.0 / A.diagonal()[k:]

        def apply(v):
            return np.concatenate([cycle @ v[:k], inv * v[k:]])

        return spla.LinearOperator(A.shape, matvec=apply)

    # ------------------------------------------------------------ the iterations
    def solve(self, x: np.ndarray, terms: KE.NodeTerms, *, atol: float,
              max_iterations: int = DEFAULT_MAX_ITERATIONS, stop=None, smoother=None) -> SolveInfo:
        """Minimise G (of ``terms``) over x (n, 3) in place until ``||r|| <= atol`` (N).

        Parameters
        ----------
        x : (n, 3) float64
            The start, changed in place; must invert no element that should stay upright.
        terms : NodeTerms
            Inertia, damping, held components, targets and loads (``vbd._node_terms``).
        atol : float
            N: the residual norm over all free dofs the solve stops at.
        max_iterations : int
            Newton iterations before the solve gives up (reported, ``converged`` False).
        stop : (1,) int64, optional
            Read before every iteration and before every conjugate-gradient
            iteration: non-zero ends the solve at the iterate reached (every
            iterate keeps every upright element upright; an iteration whose
            linear solve it stops is abandoned, so a waiting cut waits for one
            product with the matrix, not for a Newton iteration).  Stopped
            before its first iteration is done, the result says ``taken`` False
            (stopped before the solve began, its residuals are NaN: none was
            evaluated).
        smoother : callable, optional
            ``smoother(x) -> bool``: called after each Newton iteration that leaves the
            residual above ``atol``; moves x in place (keeping every upright element
            upright) and says whether it moved it.  The residual is then evaluated
            afresh, so the solve still stops on the true residual (a composite
            nonlinear solver: Newton, then nonlinear Gauss-Seidel; Brune, Knepley,
            Smith & Tu 2015, "Composing scalable nonlinear algebraic solvers", SIAM
            Review 57(4), section 4).

        Returns
        -------
        SolveInfo
            ``iterations`` Newton iterations, ``residual`` the true final residual norm.
        """
        with one_blas_thread():  # the same sums, hence the same iterates, on every machine
            return self._solve(x, terms, atol=atol, max_iterations=max_iterations, stop=stop, smoother=smoother)

    def _solve(self, x: np.ndarray, terms: KE.NodeTerms, *, atol: float, max_iterations: int,
               stop, smoother=None) -> SolveInfo:
        """:meth:`solve` with BLAS already on one thread."""
        if stop is not None and stop[0]:
            # a cut already waits: not even the first residual (a pass over every element, 20-50 ms
            # on the knee's relaxation thread in a live session, which the cut would wait for)
            return SolveInfo(0, float("nan"), float("nan"), False, taken=False)
        em = self.em
        free = ~terms.fixed & (em.adj_degree > 0)[:, None]
        problem = _Potential(em, terms, free, self._elements())
        r = problem.residual(x)
        r0 = res = float(np.linalg.norm(r))
        it = 0
        rings = self.region_rings
        g = None  # G at x where the last line search moved it
        cut_short = False  # the last line search's first trial was shortened by the inversion bound
        while res > atol and it < max_iterations:
            if stop is not None and stop[0]:
                if it == 0:
                    return SolveInfo(0, r0, r0, False, taken=False)
                break
            d = None
            if rings is not None:
                d = self._local_direction(x, r, free, terms.inertia + terms.damping, atol, rings)
            local = d is not None
            if d is None:
                rtol = min(CG_RTOL_MAX, max(self.cg_rtol, self.no_oversolve * atol / res))
                rtol = max(rtol, BOUNDED_CG_RTOL) if cut_short else rtol
                d = self._direction(x, r, free, terms.inertia + terms.damping, rtol, stop)
                self.counts["global_iterations"] += 1
            if d is None:
                if stop is not None and stop[0] and it == 0:  # stopped within the first iteration
                    return SolveInfo(0, r0, r0, False, taken=False)
                break
            before = res
            moved, r, g, cut_short = line_search(problem, x, d, r, res, g)
            it += 1
            res = float(np.linalg.norm(r))
            if local and res > max(atol, REGION_WIDEN * before):
                rings = 2 * rings + 1  # the out-of-balance mode reaches past the region: widen it
            if not moved:
                if local:
                    continue  # the rings were doubled above: the next iteration solves a wider region
                break
            if smoother is not None and res > atol and smoother(x):
                r = problem.residual(x)
                res, g = float(np.linalg.norm(r)), None
        return SolveInfo(it, r0, res, res <= atol)

    def _local_direction(self, x, r, free, diagonal_add, atol: float, rings: int):
        """The Newton step on :func:`newton_region` (the rest held), or None where the region is
        too large to factorise or its system is not positive definite (the caller then takes the
        whole model's step)."""
        pat = self.pattern()
        region = newton_region(r, free, pat.node_ptr, pat.node_idx, REGION_FRACTION * atol, rings)
        sub = free & region[:, None]
        dofs = np.flatnonzero(sub.ravel())
        if dofs.size == 0 or dofs.size > min(CHOLESKY_MAX_DOFS, REGION_MAX_FRACTION * np.count_nonzero(free)):
            self.region_log.append(0)
            return None
        modes = {"auto": (0, 1), "projected": (1,), "exact": (0,)}[self.hessian]
        for mode in modes:
            A = self.region_matrix(x, sub, region, diagonal_add, mode)[dofs][:, dofs].tocsr()
            ds = self._factor_solve(A, r.ravel()[dofs])
            if ds is not None:
                d = np.zeros(x.size)
                d[dofs] = ds
                self.counts["local_iterations"] += 1
                self.region_log.append(int(dofs.size))
                return d.reshape(-1, 3)
        self.region_log.append(0)
        return None

    def region_matrix(self, x, sub, region, diagonal_add, mode: int):
        """:meth:`matrix` with ``sub`` free, assembled from the elements that touch ``region`` only.

        The other elements add nothing to the region's rows (the knee's whole assembly costs about
        1 s), so the rows and columns of ``sub``'s dofs equal :meth:`matrix`'s; the rest are not
        assembled.

        Parameters
        ----------
        x : (n, 3) float64
        sub : (n, 3) bool
            The free dofs, all inside ``region``.
        region : (n,) bool
        diagonal_add : (n,) float64
        mode : int
            As :meth:`matrix`'s ``project``.

        Returns
        -------
        (3n, 3n) scipy CSR float64
        """
        if self.em.element == "anp":  # a node's pressure couples its whole patch: assemble it all
            return self.matrix(x, sub, diagonal_add, mode)
        pat, el = self.pattern(), self._elements()
        ids = np.flatnonzero(region[el.tets].any(axis=1))
        part = KE.Elements(*(np.ascontiguousarray(a[ids]) for a in el))
        data = np.empty(pat.indices.shape[0])
        KN.assemble_hessian(x, part, pat._replace(element_blocks=np.ascontiguousarray(pat.element_blocks[ids])),
                            int(mode), data)
        return self._constrained(data, sub, diagonal_add)

    def _constrained(self, data: np.ndarray, free: np.ndarray, diagonal_add: np.ndarray):
        """The CSR matrix of assembled Hessian ``data`` on the pattern, with ``diagonal_add`` (n,) on
        the diagonal (or the static shift where it is all zero) and the held rows made identity."""
        import scipy.sparse as sp

        pat = self.pattern()
        add = np.repeat(np.asarray(diagonal_add, np.float64), 3)
        if not np.any(add > 0):
            add = STATIC_SHIFT * np.abs(data[pat.diagonal])
        KN.constrain(pat, ~free.ravel(), add, data)
        n3 = 3 * self.em.n_nodes
        return sp.csr_matrix((data, pat.indices, pat.indptr), shape=(n3, n3))

    def _factor_solve(self, A, r: np.ndarray):
        """d with A d = r by cholespy's sparse Cholesky factorisation; None where A is not positive
        definite."""
        self.counts["factorisations"] += 1
        d = cholesky_solve(A, r)
        if d is None:
            self.counts["indefinite"] += 1
        return d


    def _direction(self, x, r, free, diagonal_add, rtol: float, halt=None):
        """The Newton step, its linear system solved to ``rtol``: exact Hessian first (``"auto"``),
        projected where that is indefinite; None where ``halt`` ((1,) int64) stopped its conjugate
        gradients."""
        modes = {"auto": (0, 1), "projected": (1,), "exact": (0,)}[self.hessian]
        for mode in modes:
            A = self.matrix(x, free, diagonal_add, mode, halt)
            if A is None:
                return None
            d = self._solve_linear(A, r.ravel(), x, free, rtol, halt)
            if d is None and halt is not None and halt[0]:
                return None
            if d is not None:
                d = d.reshape(-1, 3)
                d[~free] = 0.0
                return d
        return None


def block_system(A, pattern: KN.Pattern, upper=None):
    """A Newton matrix in the symmetric block form of :mod:`cutkit.relax._block_cg_kernels` and its
    block-Jacobi inverse.

    Parameters
    ----------
    A : (3n, 3n) scipy CSR float64
        A matrix of :meth:`NewtonSolver.matrix` (its ``data`` laid out by ``pattern``).
    pattern : Pattern
    upper : tuple, optional
        :func:`block_index` of the pattern (computed here if not given).

    Returns
    -------
    blocks : BlockMatrix
    inverse : (n, 3, 3) float64, or None where a diagonal block is not positive definite.
    """
    n = A.shape[0] // 3
    ptr, col, src, *lower = upper if upper is not None else block_index(pattern)
    blocks = KB.BlockMatrix(np.empty((n, 3, 3)), ptr, col, np.empty((col.shape[0], 3, 3)), *lower)
    KB.gather_blocks(pattern.node_ptr, pattern.diagonal, src, A.data, blocks.diag, ptr, blocks.off)
    inverse = np.empty((n, 3, 3))
    return blocks, (inverse if KB.block_jacobi(blocks.diag, inverse) else None)


def coarse_space(blocks, x: np.ndarray, free: np.ndarray, halt=NEVER_STOP):
    """The two-level preconditioner's coarse space for a Newton matrix (:mod:`cutkit.relax._coarse_kernels`).

    Parameters
    ----------
    blocks : BlockMatrix
        The matrix (:func:`block_system`).
    x : (n, 3) float64
        mm, where it was assembled.
    free : (n, 3) bool
    halt : (1,) int64
        A waiting cut's flag, read while E is summed: set, None is returned.

    Returns
    -------
    Coarse, or None where there is nothing free, more than :data:`COARSE_MAX_DOFS` coarse dofs, or
    E = W^T A W is not positive definite (then so is not A: its conjugate gradients will say so).
    """
    from scipy.linalg import lapack

    from cutkit.relax import _coarse_kernels as KC

    movable = free.any(axis=1)
    if not movable.any():
        return None
    lo, hi = x[movable].min(axis=0), x[movable].max(axis=0)
    span = np.maximum(hi - lo, 1e-9 * max(float((hi - lo).max()), 1e-12))
    h = float(np.prod(span) / COARSE_CELLS) ** (1.0 / 3.0)
    dims = np.floor(span / h).astype(np.int64) + 1
    ijk = np.clip(np.floor((x - lo) / h).astype(np.int64), 0, dims - 1)
    cell = np.ascontiguousarray((ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2])
    agg, k = cell_aggregates(blocks, cell, movable)
    if 6 * k > COARSE_MAX_DOFS:
        return None
    held = agg < 0
    count = np.bincount(agg[~held], minlength=k)
    centroid = np.zeros((k, 3))
    np.add.at(centroid, agg[~held], x[~held])
    centroid /= np.maximum(count, 1)[:, None]
    rel = np.where(held[:, None], 0.0, x - centroid[np.maximum(agg, 0)])
    turns = np.where(held, 0.0, (count[np.maximum(agg, 0)] >= COARSE_MIN_TURNING_NODES).astype(np.float64))
    c = KC.Coarse(agg, np.ascontiguousarray(rel), free.astype(np.float64), turns, np.zeros((0, 0)))
    E = KC.galerkin(blocks, c, k, halt)
    if halt[0]:
        return None
    factor, info = lapack.dpotrf(E, lower=1)  # Cholesky: fails where E is not positive definite
    if info != 0:
        return None
    inverse, info = lapack.dpotri(factor, lower=1)  # its lower triangle
    if info != 0:
        return None
    return c._replace(inv=np.ascontiguousarray(np.tril(inverse) + np.tril(inverse, -1).T))


def cell_aggregates(blocks, cell: np.ndarray, movable: np.ndarray) -> tuple[np.ndarray, int]:
    """The coarse space's aggregates: the movable nodes of one cell joined through the blocks of a
    Newton matrix (:func:`~cutkit.relax._graph_kernels.graph_components` of that graph).

    Parameters
    ----------
    blocks : BlockMatrix
    cell : (n,) int64
        Each node's cell.
    movable : (n,) bool

    Returns
    -------
    agg : (n,) int64
        Each node's aggregate, numbered by first node; -1 where not movable.
    k : int
        Aggregates.
    """
    from cutkit.collision.adjacency import csr_adjacency
    from cutkit.relax._graph_kernels import graph_components

    n = cell.shape[0]
    rows = np.repeat(np.arange(n), np.diff(blocks.ptr))
    keep = movable[rows] & movable[blocks.col] & (cell[rows] == cell[blocks.col])
    offsets, neighbours, _ = csr_adjacency(np.stack([rows[keep], blocks.col[keep]], axis=1), n)
    _, labels = graph_components(offsets, neighbours)
    # components are numbered by their smallest node; the movable ones, renumbered in that order
    kept, agg = np.unique(labels[movable], return_inverse=True)
    out = np.full(n, -1, np.int64)
    out[movable] = agg
    return out, int(kept.size)


def reaching_free_dofs(el: KE.Elements, free: np.ndarray) -> KE.Elements:
    """``el`` with the elements none of whose twelve dofs is free read as inactive (volume 0).

    Such an element (bone held by the boundary conditions: 20,182 of the demo knee's 173,908)
    writes only rows and columns of held dofs, which :meth:`NewtonSolver._constrained` then
    clears (its diagonal set to 1), so the assembly leaves it out and the matrix is the same to
    the bit (tests/test_newton.py).

    Parameters
    ----------
    el : Elements
    free : (n, 3) bool
    """
    none_free = ~free.any(axis=1)
    t = el.tets
    out = none_free[t[:, 0]] & none_free[t[:, 1]] & none_free[t[:, 2]] & none_free[t[:, 3]]
    if not out.any():
        return el
    return el._replace(volume=np.where(out, 0.0, el.volume))


def block_index(pattern: KN.Pattern) -> tuple:
    """The symmetric block form's index of ``pattern``: the blocks above the diagonal
    (``_block_cg_kernels.upper_blocks``: row pointers, columns, positions in ``node_idx``) and the
    same by column (``lower_blocks``: pointers, rows, positions), six int64 arrays."""
    ptr, col, src = KB.upper_blocks(pattern.node_ptr, pattern.node_idx)
    return (ptr, col, src, *KB.lower_blocks(ptr, col, pattern.node_ptr.shape[0] - 1))


def cholesky_solve(A, b: np.ndarray):
    """d with A d = b by cholespy's sparse Cholesky factorisation (CHOLMOD).

    Parameters
    ----------
    A : (k, k) scipy CSR float64
        Symmetric.
    b : (k,) float64

    Returns
    -------
    (k,) float64, or None where A is not positive definite.
    """
    import cholespy

    try:
        with _quiet_stderr():  # CHOLMOD reports an indefinite matrix on stderr as well
            L = cholespy.CholeskySolverD(A.shape[0], A.indptr.astype(np.int32, copy=False),
                                         A.indices.astype(np.int32, copy=False), A.data, cholespy.MatrixType.CSR)
    except ValueError:
        return None
    d = np.zeros_like(b)
    L.solve(np.ascontiguousarray(b), d)
    return d


def out_of_balance_nodes(r: np.ndarray, outside: float) -> np.ndarray:
    """The smallest set of nodes (largest residuals first) outside of which the residual norm is at
    most ``outside`` (N): (k,) int64, largest residual first, of ``r`` (n, 3) float64 N."""
    r2 = np.einsum("ij,ij->i", r, r)
    order = np.argsort(-r2, kind="stable")
    # tail[k]: the squared residual of every node after the k largest
    tail = np.concatenate([np.cumsum(r2[order][::-1])[::-1], [0.0]])
    return order[:int(np.argmax(tail <= outside * outside))]


def newton_region(r: np.ndarray, free: np.ndarray, node_ptr: np.ndarray, node_idx: np.ndarray,
                  outside: float, rings: int) -> np.ndarray:
    """The nodes a local Newton iteration solves for: where the model is out of balance, and around.

    The seed is the smallest set of nodes (largest residuals first) outside of which the residual
    norm is at most ``outside``; it grows by ``rings`` rings of the node graph.

    Parameters
    ----------
    r : (n, 3) float64
        N: the residual (zero at held dofs).
    free : (n, 3) bool
    node_ptr, node_idx : (n + 1,) and (k,) int
        Each node's neighbours (CSR, ``Pattern.node_ptr`` / ``node_idx``).
    outside : float
        N: the residual norm the region may leave out.
    rings : int
        >= 0.

    Returns
    -------
    (n,) bool
        The region; nodes with no free dof are left out.
    """
    region = np.zeros(r.shape[0], bool)
    region[out_of_balance_nodes(r, outside)] = True
    counts = np.diff(node_ptr)
    for _ in range(int(rings)):
        region[node_idx[np.repeat(region, counts)]] = True
    return region & free.any(axis=1)


def node_block_inverse(A, pattern: KN.Pattern):
    """The block-Jacobi preconditioner of a Newton matrix: each node's 3 x 3 diagonal block inverted.

    Parameters
    ----------
    A : (3n, 3n) scipy CSR float64
        A matrix of :meth:`NewtonSolver.matrix` (its ``data`` laid out by ``pattern``).
    pattern : Pattern
        The pattern A was assembled on.

    Returns
    -------
    (3n, 3n) scipy CSR float64, or None
        Block-diagonal: ``M @ r`` applies the inverses node by node.  None where a block is not
        positive definite (then neither is A: an exact Hessian's indefinite step, which the
        caller takes projected).
    """
    import scipy.sparse as sp

    n = A.shape[0] // 3
    # entry (3i + a, 3i + b) sits b - a after the diagonal entry of row 3i + a (_newton_kernels' layout)
    offset = np.arange(3)[None, None, :] - np.arange(3)[None, :, None]
    blocks = A.data[pattern.diagonal.reshape(n, 3)[:, :, None] + offset]
    try:
        np.linalg.cholesky(blocks)
    except np.linalg.LinAlgError:
        return None
    inverse = np.linalg.inv(blocks)
    return sp.bsr_matrix((inverse, np.arange(n), np.arange(n + 1)), shape=A.shape).tocsr()


@contextlib.contextmanager
def _quiet_stderr():
    """File descriptors 1 and 2 to /dev/null for the block (CHOLMOD's printf of an indefinite matrix)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])


def pcg(A, b: np.ndarray, M, rtol: float, max_iterations: int, halt=None):
    """Preconditioned conjugate gradients for A d = b, stopped at ``||b - A d|| <= rtol ||b||``;
    (None, iterations) at negative curvature (an indefinite exact Hessian: the caller takes the
    projected one) and where ``halt`` ((1,) int64, a waiting cut's flag) is set, read before every
    iteration.  Returns (d, iterations)."""
    d = np.zeros_like(b)
    r = b.copy()
    z = M @ r
    p = z.copy()
    rz = float(r @ z)
    stop = rtol * float(np.linalg.norm(b))
    for k in range(max_iterations):
        if halt is not None and halt[0]:
            return None, k
        Ap = A @ p
        curvature = float(p @ Ap)
        if not curvature > 0.0:
            return None, k
        alpha = rz / curvature
        d += alpha * p
        r -= alpha * Ap
        if np.linalg.norm(r) <= stop:
            return d, k + 1
        z = M @ r
        rz, rz_old = float(r @ z), rz
        p = z + (rz / rz_old) * p
    return d, max_iterations


class _Potential:
    """G and its true residual -dG/dx (zero at held dofs) for one step's node terms."""

    def __init__(self, em: ElementModel, terms: KE.NodeTerms, free: np.ndarray, el: KE.Elements):
        self.em, self.t, self.free, self.el = em, terms, free, el

    def residual(self, x: np.ndarray) -> np.ndarray:
        """(n, 3) float64 N."""
        t = self.t
        forces = anp.anp_forces if self.em.element == "anp" else elastic_forces
        r = (forces(self.em, x) + t.force - t.inertia[:, None] * (x - t.target)
             - t.damping[:, None] * (x - t.previous))
        r[~self.free] = 0.0
        return r

    def energy(self, x: np.ndarray) -> float:
        """G(x), N mm."""
        t, f = self.t, self.free
        kin = 0.5 * np.sum(t.inertia[:, None] * np.where(f, x - t.target, 0.0) ** 2)
        damp = 0.5 * np.sum(t.damping[:, None] * np.where(f, x - t.previous, 0.0) ** 2)
        stored = anp.anp_energy if self.em.element == "anp" else elastic_energy
        return float(stored(self.em, x) + kin + damp - np.sum(np.where(f, t.force * x, 0.0)))


def line_search(problem, x: np.ndarray, d: np.ndarray, r: np.ndarray, res: float, g0: float | None = None):
    """Backtracking (Armijo) along d from the longest step that inverts no element.

    The first trial is ``min(1, INVERSION_SAFETY a0)`` with a0 the first
    step length at which an upright element's volume reaches zero
    (``_newton_kernels.step_bound``); each element's volume is a cubic in
    the step length that is positive on [0, a0), so no trial inverts one.
    x is changed in place when moved.

    Parameters
    ----------
    problem : object
        ``el`` (:class:`~cutkit.relax._elastic_kernels.Elements`, the elements the step bound
        keeps upright), ``energy(x) -> float`` (G, N mm) and ``residual(x) -> (n, 3) float64``
        (-dG/dx, N): the whole model's step (``_Potential``) or a region's
        (:mod:`cutkit.relax.hybrid`).
    x : (n, 3) float64
        mm; changed in place when moved.
    d : (n, 3) float64
        The direction, mm.
    r : (n, 3) float64
        The residual at x, N.
    res : float
        Its norm, N.
    g0 : float, optional
        G at x where the caller has it (the last line search's accepted value on the same
        ``problem``): the number :meth:`energy` would give, one pass over the elements fewer.

    Returns
    -------
    moved : bool
    r : (n, 3) float64
        The residual at x (the new x where moved), N.
    g : float or None
        G at x where moved (the next line search's ``g0``), else None.
    cut_short : bool
        The first trial was shortened by the inversion bound (a0 <= 1).
    """
    slope = float(np.sum(r * d))  # -dG/da at a = 0
    if not slope > 0.0:
        return False, r, None, False
    a0 = KN.step_bound(x, d, problem.el, 1.0)
    cut_short = not a0 > 1.0
    a = INVERSION_SAFETY * a0 if cut_short else 1.0
    g0 = problem.energy(x) if g0 is None else g0
    for _ in range(MAX_BACKTRACKS):
        trial = x + a * d
        g = problem.energy(trial)
        if g <= g0 - ARMIJO_C1 * a * slope:
            x[:] = trial
            return True, problem.residual(x), g, cut_short
        if a * slope <= ROUNDING * max(abs(g0), 1e-300):  # below what G can resolve: go by the residual
            rt = problem.residual(trial)
            if np.linalg.norm(rt) < res:
                x[:] = trial
                return True, rt, g, cut_short
        a *= 0.5
    return False, r, None, cut_short


def _free_terms(em: ElementModel, x, h, f_ext, gravity, y=None) -> KE.NodeTerms:
    f_ext = None if f_ext is None else _check_nodes(em, f_ext, "f_ext")
    return _node_terms(em, x, h, f_ext, gravity, y)


def _check_nodes(em: ElementModel, a, name: str) -> np.ndarray:
    a = np.ascontiguousarray(a, np.float64)
    if a.shape != (em.n_nodes, 3):
        raise InputError(f"{name} must have shape ({em.n_nodes}, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be finite")
    return a


def newton_step(em: ElementModel, state: ElementState, h: float, f_ext=None, gravity=None, *,
                atol: float = DEFAULT_ATOL_N, max_iterations: int = DEFAULT_MAX_ITERATIONS,
                solver: NewtonSolver | None = None, stop=None) -> SolveInfo:
    """Advance ``state`` by one backward Euler step of ``h`` s, solved by projected Newton.

    Parameters
    ----------
    em : ElementModel
    state : ElementState
        Changed in place (positions, velocities, time).
    h : float
        s, > 0.
    f_ext : (n, 3) float64, optional
        External node forces, N.
    gravity : (3,) float64, optional
        mm/s^2.
    atol : float
        N: the step ends when the residual norm over all free dofs is at most this.
    max_iterations : int
    solver : NewtonSolver, optional
        Keeps the pattern between steps (default: a new one).
    stop : (1,) int64, optional
        As :meth:`NewtonSolver.solve`'s; a step stopped before its first
        iteration is not taken (positions and time stay).

    Returns
    -------
    SolveInfo
    """
    if not (np.isfinite(h) and h > 0):
        raise InputError(f"h must be a positive number, got {h}")
    solver = solver or NewtonSolver(em)
    x0 = state.positions.copy()
    free = ~em.fixed
    y = np.where(free, x0 + h * state.velocities, x0)
    # the iterations start from x^n, which inverts no element; y itself might fold one
    terms = _free_terms(em, x0, h, f_ext, gravity, y)
    info = solver.solve(state.positions, terms, atol=float(atol), max_iterations=int(max_iterations), stop=stop)
    if not info.taken:
        return info
    state.velocities[:] = np.where(free, (state.positions - x0) / h, 0.0)
    state.time += h
    return info


def rest_step(em: ElementModel, state: ElementState, h: float, f_ext, *, atol: float, sweeps: int,
              max_iterations: int, solver: NewtonSolver, stop=None, smoothing: int = 0) -> tuple[SolveInfo, int]:
    """One backward Euler step of ``h`` s from ``state``, for a tissue at rest: up to ``sweeps``
    vertex block descent sweeps of the whole model (:func:`~cutkit.relax.vbd.iterate`), which
    settle a small local change in milliseconds, then projected Newton on the same step until the
    whole model's true residual is at most ``atol`` (N), which the soft global modes need.  After
    each Newton iteration that leaves the step out of balance, up to ``smoothing`` more sweeps
    (fewer where they bring it within ``atol``): the Newton step carries the soft modes, the sweeps
    the short-range rest its linear model missed, which another Newton iteration would cost a
    matrix assembly and a linear solve to remove (:data:`~cutkit.relax.elastic_tissue.REST_SMOOTHING_SWEEPS`).

    Parameters
    ----------
    em : ElementModel
    state : ElementState
        Changed in place (positions, velocities, time) where the step is taken.
    h : float
        s, > 0.
    f_ext : (n, 3) float64
        N.
    atol : float
        N.
    sweeps : int
        Sweeps at most before Newton (0: Newton only, as :func:`newton_step`).
    max_iterations : int
        Newton iterations at most.
    solver : NewtonSolver
    stop : (1,) int64, optional
        Read before every sweep and as :meth:`NewtonSolver.solve` reads it.
    smoothing : int
        Sweeps at most after each Newton iteration that leaves the residual above ``atol``.

    Returns
    -------
    info : SolveInfo
        The Newton solve's (``iterations`` Newton iterations, ``residual`` the true one);
        ``taken`` False where nothing moved.
    swept : int
        The sweeps made, before Newton and between its iterations.
    """
    x0 = state.positions.copy()
    free = ~em.fixed
    terms = _free_terms(em, x0, h, f_ext, None, np.where(free, x0 + h * state.velocities, x0))
    swept = _sweeps(em, state.positions, terms, atol, sweeps, stop)

    def smoother(x) -> bool:
        nonlocal swept
        made = _sweeps(em, x, terms, atol, smoothing, stop)
        swept += made
        return made > 0

    info = solver.solve(state.positions, terms, atol=float(atol), max_iterations=int(max_iterations), stop=stop,
                        smoother=smoother if smoothing > 0 else None)
    if not info.taken and swept == 0:
        return info, 0
    state.velocities[:] = np.where(free, (state.positions - x0) / h, 0.0)
    state.time += h
    return SolveInfo(info.iterations, info.initial_residual, info.residual, info.converged), swept


def _sweeps(em: ElementModel, x: np.ndarray, terms: KE.NodeTerms, atol: float, most: int, stop) -> int:
    """Up to ``most`` vertex block descent sweeps of the whole model on x (in place), fewer where one
    brings the sweeps' residual within ``atol`` (N) or ``stop`` is raised; returns the sweeps made."""
    made = 0
    while made < most and not (stop is not None and stop[0]):
        made += 1
        if iterate(em, x, terms, rtol=0.0, atol=float(atol), max_iterations=1, stop=stop).converged:
            break
    return made


def finish_step(em: ElementModel, state: ElementState, x0: np.ndarray, v0: np.ndarray, h: float, f_ext, *,
                atol: float, max_iterations: int, solver: NewtonSolver, stop=None) -> SolveInfo:
    """Finish on the whole model a backward Euler step from (x0, v0) that another method left out of balance.

    Projected Newton (``solver``) from the iterate ``state.positions``
    (where the sweeps and the local polish stopped; it must invert no tet)
    until the step's true residual over all free dofs is at most ``atol``
    (N): the potential is :func:`newton_step`'s from (x0, v0).  Velocities
    are set to ``(x - x0) / h`` (0 at held dofs); time is not advanced (the
    sweeps did).

    Parameters
    ----------
    em : ElementModel
    state : ElementState
        Positions and velocities changed in place.
    x0, v0 : (n, 3) float64
        The step's start, mm and mm/s.
    h : float
        s, > 0.
    f_ext : (n, 3) float64
        N.
    atol : float
        N.
    max_iterations : int
    solver : NewtonSolver
    stop : (1,) int64, optional
        As :meth:`NewtonSolver.solve` reads it.

    Returns
    -------
    SolveInfo
        Newton iterations; ``residual`` the true one, N.
    """
    free = ~em.fixed
    terms = _free_terms(em, x0, h, f_ext, None, np.where(free, x0 + h * v0, x0))
    info = solver.solve(state.positions, terms, atol=float(atol), max_iterations=int(max_iterations), stop=stop)
    if info.taken:
        state.velocities[:] = np.where(free, (state.positions - x0) / h, 0.0)
    return info


def newton_static(em: ElementModel, positions, f_ext=None, gravity=None, *, rtol: float = 1e-6,
                  atol: float = DEFAULT_ATOL_N, max_iterations: int = DEFAULT_MAX_ITERATIONS,
                  solver: NewtonSolver | None = None) -> SolveInfo:
    """Relax ``positions`` in place to static equilibrium by projected Newton.

    Parameters
    ----------
    em : ElementModel
    positions : (n, 3) float64
        mm; changed in place.
    f_ext : (n, 3) float64, optional
        External node forces, N.
    gravity : (3,) float64, optional
        mm/s^2.
    rtol, atol : float
        The solve stops when the residual norm over all free dofs is at most
        ``rtol`` times its first value or ``atol`` (N).
    max_iterations : int
        Newton iterations at most (``converged`` False beyond).
    solver : NewtonSolver, optional

    Returns
    -------
    SolveInfo
        ``initial_residual`` and ``residual`` are true residual norms, N.
    """
    solver = solver or NewtonSolver(em)
    terms = _free_terms(em, positions, None, f_ext, gravity)
    free = ~terms.fixed & (em.adj_degree > 0)[:, None]
    with one_blas_thread():
        r0 = float(np.linalg.norm(_Potential(em, terms, free, solver._elements()).residual(positions)))
    info = solver.solve(positions, terms, atol=max(float(atol), float(rtol) * r0), max_iterations=int(max_iterations))
    return info
