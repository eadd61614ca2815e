"""Static equilibrium of a whole element model: the settle before a cut.

Vertex block descent removes an out-of-balance force quickly where it is
local (a cut) but slowly where it spans the model: the settle of a
prestressed model is such a problem (on the demo knee, 600 sweeps leave 0.5 %
of the first residual; docs/relaxation.md).  The settle therefore takes
modified Newton steps with the model's *linear* stiffness

    K du = r(x),    x <- x + s du

where ``r`` is the exact out-of-balance force of the stable neo-Hookean
energy and ``K`` the small-strain stiffness of the same elements (assembled
once), solved by conjugate gradients preconditioned with smoothed-aggregation
algebraic multigrid (pyamg, with the six rigid-body modes as near-null
space).  ``s`` halves until the potential energy decreases, so a step can
never go uphill.  Iterations stop on the same residual criterion as the
sweeps of :mod:`cutkit.relax.elastic`.
"""

from __future__ import annotations

import numpy as np

from cutkit.relax.elastic import ElementModel
from cutkit.relax.vbd import SolveInfo, elastic_energy, elastic_forces
from cutkit.threads import one_blas_thread

#: Relative tolerance of each inner linear solve (inexact Newton: the outer
#: iteration corrects what the inner one leaves).
LINEAR_RTOL = 1e-3
#: Step halvings before a Newton step is given up.
MAX_HALVINGS = 8
#: Seed of the random vectors pyamg's setup draws.
AMG_SEED = 0
#: A rise of the potential energy at most this times its size is rounding, not a rise: a step that
#: near the solution changes the energy by less than its sums round (about 1e-17 N mm for a
#: residual of 1e-8 N on a small block) is taken where it lowers the residual instead.
ENERGY_ROUNDING = 1e-12


def linear_stiffness(em: ElementModel):
    """Small-strain stiffness matrix of the active elements, (3n, 3n) scipy CSR, N/mm.

    Block (i, j) of an element is ``V [mu (b_i . b_j) I + mu b_j b_i^T + lam b_i b_j^T]``
    with b the rows of its gradient operator: the linearisation of its energy at rest.
    """
    import scipy.sparse as sp

    n = em.n_nodes
    act = np.flatnonzero(em.volume[: em.n_elements] > 0)
    D = em.Dminv[act]
    B = np.concatenate([-D.sum(axis=1, keepdims=True), D], axis=1)  # (m, 4, 3)
    V, mu, lam = em.volume[act], em.mu[act], em.lam[act]
    bb = np.einsum("mic,mjc->mij", B, B)
    Ke = (mu * V)[:, None, None, None, None] * (bb[..., None, None] * np.eye(3)
                                               + np.einsum("mjr,mic->mijrc", B, B))
    Ke += (lam * V)[:, None, None, None, None] * np.einsum("mir,mjc->mijrc", B, B)
    dof = 3 * em.tets[act][:, :, None] + np.arange(3)  # (m, 4, 3)
    rows = np.broadcast_to(dof[:, :, None, :, None], Ke.shape).ravel()
    cols = np.broadcast_to(dof[:, None, :, None, :], Ke.shape).ravel()
    return sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(3 * n, 3 * n))


def rigid_modes(x: np.ndarray) -> np.ndarray:
    """(3n, 6) float64: translations and rotations about the centroid of positions x (n, 3)
    (the near-null space of a linear elastic stiffness, for smoothed-aggregation multigrid)."""
    n = x.shape[0]
    c = x - x.mean(axis=0)
    B = np.zeros((n, 3, 6))
    for a in range(3):
        B[:, a, a] = 1.0
    B[:, 1, 3], B[:, 2, 3] = -c[:, 2], c[:, 1]
    B[:, 0, 4], B[:, 2, 4] = c[:, 2], -c[:, 0]
    B[:, 0, 5], B[:, 1, 5] = -c[:, 1], c[:, 0]
    return B.reshape(3 * n, 6)


def settle_static(em: ElementModel, x: np.ndarray, f_ext=None, *, rtol: float = 1e-3, atol: float = 0.0,
                  max_iterations: int = 50) -> SolveInfo:
    """Bring ``x`` (n, 3) to static equilibrium in place; ``iterations`` counts Newton steps."""
    with one_blas_thread():  # the same sums on every machine: docs/relaxation.md
        return _settle_static(em, x, f_ext, rtol=rtol, atol=atol, max_iterations=max_iterations)


def _settle_static(em: ElementModel, x: np.ndarray, f_ext, *, rtol: float, atol: float,
                   max_iterations: int) -> SolveInfo:
    """:func:`settle_static` with BLAS on one thread."""
    import pyamg
    import scipy.sparse.linalg as spla

    f_ext = np.zeros_like(x) if f_ext is None else np.asarray(f_ext, np.float64)
    free = (~em.fixed).ravel() & np.repeat(em.adj_degree > 0, 3)
    K = linear_stiffness(em)[free][:, free].tocsr()
    # pyamg estimates spectral radii from random vectors of numpy's global generator: seed it
    # for the setup (and give the caller's state back) so that a settle is repeatable
    saved = np.random.get_state()
    np.random.seed(AMG_SEED)
    try:
        ml = pyamg.smoothed_aggregation_solver(K, B=rigid_modes(x)[free], symmetry="symmetric", max_coarse=500)
    finally:
        np.random.set_state(saved)
    M = ml.aspreconditioner(cycle="V")

    def residual(xx):
        return (elastic_forces(em, xx) + f_ext).ravel()[free]

    def potential(xx):
        return elastic_energy(em, xx) - float(np.sum(f_ext * xx))

    r = residual(x)
    r0 = res = float(np.linalg.norm(r))
    it = 0
    while it < max_iterations and not (res <= rtol * r0 or res <= atol):
        du, _ = spla.cg(K, r, rtol=LINEAR_RTOL, M=M, maxiter=500)
        e0 = potential(x)
        s = 1.0
        for _ in range(MAX_HALVINGS):
            trial = x.copy()
            trial.reshape(-1)[free] += s * du
            e = potential(trial)
            if e <= e0 or (e - e0 <= ENERGY_ROUNDING * abs(e0)
                           and float(np.linalg.norm(residual(trial))) < res):
                break
            s *= 0.5
        else:
            break  # no step lowers the energy: at the floor of what the linear model can find
        x[:] = trial
        r = residual(x)
        res = float(np.linalg.norm(r))
        it += 1
    return SolveInfo(it, r0, res, res <= rtol * r0 or res <= atol)
