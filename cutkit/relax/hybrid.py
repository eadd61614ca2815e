"""Vertex block descent steps finished by a local projected Newton polish.

Vertex block descent (:func:`cutkit.relax.vbd.local_step`) moves one node at
a time; where one stiff coupling dominates (a tet crushed into the barrier
band near a cut, J ~ 1e-3) its Gauss-Seidel sweeps stall and the step ends
at its sweep cap out of balance (docs/relaxation.md, "Limits").  The
residual left is local: on the demo knee incision 4-8 nodes around the
crushed tets carry all of it but half the tolerance.  Projected Newton
iterations on those nodes and a ring around them (Smith, de Goes & Kim 2018
for the projection; Li et al. 2020 for the line search that keeps every tet
upright) solve the coupling the sweeps cannot, on a system of a few hundred
dofs.

:func:`polish_step` finishes the backward Euler step the sweeps began: the
same incremental potential (inertial target ``x^n + h v^n``, damping, the
loads), started from where the sweeps stopped, until the WHOLE model's true
residual is at most ``atol``; the velocities are then ``(x - x^n) / h``, as
a sweep step sets them.  Nothing in an iteration is proportional to the
model but two O(n) vector operations: the region's system is assembled from
the elements that touch it on its own small pattern, the line search's
potential is the part of ``G`` those elements and the region's nodes carry
(the rest does not change along the step), and the residual is recomputed at
the nodes of those elements only (:func:`~cutkit.relax._elastic_kernels.forces_at`,
the same sums as the whole model's forces).
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _adjacency_kernels as KA
from cutkit.relax import _elastic_kernels as KE
from cutkit.relax import _newton_kernels as KN
from cutkit.relax.elastic import ElementModel, ElementState
from cutkit.relax.newton import CHOLESKY_MAX_DOFS, line_search, cholesky_solve, out_of_balance_nodes
from cutkit.relax.vbd import NEVER_STOP, SolveInfo, elastic_forces
from cutkit.threads import one_blas_thread

#: Rings of the tet graph a polish grows its region by around the nodes out of balance (doubled
#: after an iteration that leaves more residual outside its region than in it: a mode wider than the
#: region).  Near the barrier a step that lowers G can raise the residual inside the region (the
#: step bound cuts it short); widening on that, as the local Newton does after an iteration that
#: misses half its residual (:data:`~cutkit.relax.newton.REGION_WIDEN`), grew the knee's regions to
#: 19,000 nodes, where iterating on the same few dozen brings the residual down.
POLISH_RINGS = 1
#: A polish's region leaves out at most this fraction of the step tolerance in residual norm
#: (:func:`~cutkit.relax.newton.out_of_balance_nodes`; on the demo knee incision 4-8 nodes carry all
#: but half the tolerance, 300-700 all but a tenth of it).
POLISH_REGION_FRACTION = 0.5
#: Newton iterations one polish makes at most (the step is then reported unconverged).
POLISH_MAX_ITERATIONS = 30
#: The Hessians a polish iteration tries in turn (0 exact, 1 projected: negative eigenvalues clamped):
#: projected while the steps are cut short by the step bound (an exact Newton step near a crushed
#: tet heads for inversion, and cut at 0.9 of the way there it raised the knee's residual 40-fold
#: over 30 iterations); exact first once a full step inverts nothing (quadratic convergence).
POLISH_PROJECT = {False: (1,), True: (0, 1)}
#: The parts of a polish that :func:`polish_step` times (``timings``), s.
TIMED = ("region", "assembly", "factorisation", "line_search", "residual")


def polish_step(em: ElementModel, state: ElementState, x0: np.ndarray, v0: np.ndarray, h: float,
                f_ext: np.ndarray, *, atol: float, residual: np.ndarray | None = None,
                rings: int = POLISH_RINGS, fraction: float = POLISH_REGION_FRACTION,
                max_iterations: int = POLISH_MAX_ITERATIONS, timings: dict | None = None):
    """Finish a backward Euler step from (x0, v0) by local projected Newton on ``state.positions``.

    The step's potential is that of :func:`cutkit.relax.newton.newton_step`
    from (x0, v0); the iterations start from ``state.positions`` (where the
    sweeps stopped; it must invert no tet) and end when the residual norm over
    all free dofs of the whole model is at most ``atol``.  Each solves on the
    nodes out of balance (:func:`~cutkit.relax.newton.out_of_balance_nodes`
    with ``fraction * atol`` left out) grown by ``rings`` rings, the rest held;
    every iterate keeps every upright tet upright (the line search's step
    bound).  Time is not advanced (the sweeps did).

    Parameters
    ----------
    em : ElementModel
        Linear stable neo-Hookean tets (``element == "nh"``).
    state : ElementState
        Positions changed in place; velocities set to ``(x - x0) / h`` (0 in held directions).
    x0, v0 : (n, 3) float64
        Positions and velocities at the start of the step, mm and mm/s.
    h : float
        s, > 0.
    f_ext : (n, 3) float64
        External node forces, N.
    atol : float
        N, > 0.
    residual : (n, 3) float64, optional
        The step's residual at ``state.positions`` if known (saves one whole-model force sum).
    rings : int
        >= 0.
    fraction : float
        In (0, 1].
    max_iterations : int
        Newton iterations at most.
    timings : dict, optional
        Seconds spent in each part of :data:`TIMED` are added to it.

    Returns
    -------
    info : SolveInfo
        ``iterations`` Newton iterations; ``initial_residual`` and ``residual`` the whole
        model's true residual norms before and after, N.
    residual : (n, 3) float64
        The step's residual at the final positions, N (0 at held dofs and at nodes without tets).
    """
    n = em.n_nodes
    x0, v0, f_ext = (_nodes(a, n, name) for a, name in ((x0, "x0"), (v0, "v0"), (f_ext, "f_ext")))
    if em.element != "nh":
        raise InputError(f"the polish solves linear stable neo-Hookean tets, not element {em.element!r}")
    if not (np.isfinite(h) and h > 0):
        raise InputError(f"h must be a positive number, got {h}")
    if not (np.isfinite(atol) and atol > 0):
        raise InputError(f"atol must be a positive number, got {atol}")
    if not (isinstance(rings, (int, np.integer)) and rings >= 0):
        raise InputError(f"rings must be a non-negative integer, not {rings!r}")
    if not (np.isfinite(fraction) and 0.0 < fraction <= 1.0):
        raise InputError(f"fraction must be in (0, 1], not {fraction!r}")
    step = _Step(em, x0, v0, f_ext, float(h))
    r = step.residual(state.positions) if residual is None else np.array(_nodes(residual, n, "residual"))
    r[~step.free] = 0.0
    timer = _Timer(timings)
    with one_blas_thread():  # the same sums, hence the same iterates, on every machine
        info, r = _iterate(step, state.positions, r, float(atol), int(rings), float(fraction),
                           int(max_iterations), timer)
    KA.step_velocities(state.positions, x0, em.fixed, float(h), state.velocities)
    return info, r


def _iterate(step, x, r, atol, rings, fraction, max_iterations, timer):
    """The Newton iterations of :func:`polish_step` on x in place from its residual r; (info, r).

    Each iterate lowers G but near the barrier may raise the residual (the step bound cuts a step
    short by a crushed tet): a polish that ends above its tolerance leaves x at its iterate of
    least residual (the sweeps' end included), so it never hands on more than it was given."""
    res = r0 = float(np.linalg.norm(r))
    best = (res, x.copy(), r)
    it = 0
    full = False  # the last step was not cut short by the step bound
    while res > atol and it < max_iterations:
        with timer("region"):
            region = step.region(r, fraction * atol, rings)
        if 3 * region.size > CHOLESKY_MAX_DOFS:
            break  # the out-of-balance mode spans the model: more than a polish can factorise
        local = _Region(step, region, r)
        d = local.direction(x, r, timer, POLISH_PROJECT[full])
        if d is None:
            break
        full = KN.step_bound(x, d, local.el, 1.0) > 1.0
        with timer("line_search"):
            moved, r, _, _ = line_search(local, x, d, r, res)
        it += 1
        with timer("residual"):
            res = float(np.linalg.norm(r))
            inside = float(np.linalg.norm(r[region]))
        if res > atol and (res * res - inside * inside > inside * inside or not moved):
            rings = 2 * rings + 1  # the out-of-balance mode reaches past the region: widen it
        if res < best[0] and res > atol:
            best = (res, x.copy(), r)
    if res > best[0]:
        res, x[:], r = best
    return SolveInfo(it, r0, res, res <= atol), r


class _Step:
    """One backward Euler step's node terms: inertia ``a = m / h^2`` towards ``y = x0 + h v0``,
    damping ``c = c m / h`` towards x0, the loads; ``free`` (n, 3) the dofs that move."""

    def __init__(self, em: ElementModel, x0, v0, f_ext, h: float):
        self.em, self.x0, self.f = em, x0, f_ext
        self.free = ~em.fixed & (em.adj_degree > 0)[:, None]
        self.y = np.where(em.fixed, x0, x0 + h * v0)
        self.a = (em.masses / (h * h))[:, None]
        self.c = (em.damping * em.masses / h)[:, None]

    def residual(self, x) -> np.ndarray:
        """(n, 3) float64 N: -dG/dx of the whole model, 0 at held dofs."""
        r = elastic_forces(self.em, x) + self.f - self.a * (x - self.y) - self.c * (x - self.x0)
        r[~self.free] = 0.0
        return r

    def region(self, r, outside: float, rings: int) -> np.ndarray:
        """(k,) int64 ascending: the nodes out of balance grown by ``rings`` rings, those with a free dof."""
        nodes = np.sort(out_of_balance_nodes(r, outside))
        adj = self.em.adjacency
        for _ in range(rings):
            nodes = np.unique(self.em.tets[KA.tets_around(adj, nodes)])
        return nodes[self.free[nodes].any(axis=1)]


class _Region:
    """The elements that touch a region, its nodes' terms, and the line search's view of them.

    ``el`` (global node ids) serves :func:`~cutkit.relax.newton.line_search`'s step bound;
    :meth:`energy` is the part of G that changes when only the region's nodes move and
    :meth:`residual` the whole model's residual with the rows of those elements' nodes summed again.
    """

    def __init__(self, step: _Step, region: np.ndarray, base: np.ndarray):
        em = step.em
        self.step, self.region, self.base = step, region, base
        ids = KA.tets_around(em.adjacency, region)
        tets = np.ascontiguousarray(em.tets[ids])
        self.el = KE.Elements(tets, *(np.ascontiguousarray(a[ids]) for a in (em.Dminv, em.volume, em.mu, em.lam)))
        self.nodes, local = np.unique(tets, return_inverse=True)  # the region and the ring it is held by
        self.local_tets = np.ascontiguousarray(local.reshape(-1, 4).astype(np.int64))
        self.moves = step.free[self.nodes] & np.isin(self.nodes, region)[:, None]  # (k, 3)

    def direction(self, x, r, timer, projects):
        """The Newton step (n, 3) on the region with the first Hessian of ``projects``
        (:data:`POLISH_PROJECT`) that factorises; None where none does."""
        k = self.nodes.shape[0]
        with timer("assembly"):
            el = self.el._replace(tets=self.local_tets)
            ptr, idx, _ = KN.node_neighbours(el.tets, el.volume, k, NEVER_STOP)
            pat = KN.Pattern(ptr, idx, KN.element_blocks(el.tets, el.volume, ptr, idx, NEVER_STOP)[0],
                             *KN.scalar_pattern(ptr, idx))
            held = ~self.moves.ravel()
            add = np.repeat((self.step.a + self.step.c)[self.nodes, 0], 3)
            xl = np.ascontiguousarray(x[self.nodes])
            b = np.where(held, 0.0, r[self.nodes].ravel())
        for project in projects:
            with timer("assembly"):
                data = np.empty(pat.indices.shape[0])
                KN.assemble_hessian(xl, el, pat, project, data)
                KN.constrain(pat, held, add, data)
                A = _csr(data, pat, 3 * k)
            with timer("factorisation"):
                dl = cholesky_solve(A, b)
            if dl is not None:
                d = np.zeros_like(x)
                d[self.nodes] = np.where(self.moves, dl.reshape(-1, 3), 0.0)
                return d
        return None

    def energy(self, x) -> float:
        """N mm: the elastic energy of the region's elements and the inertia, damping and loads of its
        moving dofs (the rest of G does not change when only they move)."""
        s, q = self.step, self.region
        m = s.free[q]
        kin = s.a[q] * (x[q] - s.y[q]) ** 2 + s.c[q] * (x[q] - s.x0[q]) ** 2
        return float(KE.element_energy(x, self.el) + np.sum(np.where(m, 0.5 * kin - s.f[q] * x[q], 0.0)))

    def residual(self, x) -> np.ndarray:
        """(n, 3) float64 N: the step's residual at x, which differs from the base only at the
        nodes of the region's elements (only the region moved)."""
        s, k = self.step, self.nodes
        r = self.base.copy()
        f = np.empty((k.shape[0], 3))
        KE.forces_at(x, s.em.adjacency, k, f)
        r[k] = np.where(s.free[k], f + s.f[k] - s.a[k] * (x[k] - s.y[k]) - s.c[k] * (x[k] - s.x0[k]), 0.0)
        return r


def _csr(data, pat, n3: int):
    import scipy.sparse as sp

    return sp.csr_matrix((data, pat.indices, pat.indptr), shape=(n3, n3))


class _Timer:
    """Adds the seconds of each ``with timer(part):`` block to ``timings[part]`` (nothing when None)."""

    def __init__(self, timings: dict | None):
        self.timings = timings

    @contextmanager
    def __call__(self, part: str):
        if self.timings is None:
            yield
            return
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[part] = self.timings.get(part, 0.0) + time.perf_counter() - t0


def _nodes(a, n: int, name: str) -> np.ndarray:
    a = np.ascontiguousarray(a, np.float64)
    if a.shape != (n, 3):
        raise InputError(f"{name} must have shape ({n}, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be finite")
    return a
