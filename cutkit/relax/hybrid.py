"""Vertex block descent steps finished by a local projected Newton polish.

Vertex block descent (:func:`cutkit.relax.vbd.local_step`) moves one node at
a time; where one stiff coupling dominates (a tet crushed into the barrier
band near a cut, J ~ 1e-3) its Gauss-Seidel sweeps stall and the step ends
at its sweep cap out of balance (docs/relaxation.md, "Limits").  The
residual left is local: a few nodes around the crushed tets.  A projected
Newton iteration on those nodes and a ring or two around them
(:class:`~cutkit.relax.newton.NewtonSolver` with ``region_rings``; Smith, de
Goes & Kim 2018 for the projection, Li et al. 2020 for the line search that
keeps every tet upright) solves the coupling the sweeps cannot, on a system
small enough to factorise.

:func:`polish_step` finishes the backward Euler step the sweeps began: the
same incremental potential (inertial target ``x^n + h v^n``, damping, the
loads), started from where the sweeps stopped, until the WHOLE model's true
residual is at most ``atol``; the velocities are then ``(x - x^n) / h``, as
a sweep step sets them.
"""

from __future__ import annotations

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _adjacency_kernels as KA
from cutkit.relax.elastic import ElementModel, ElementState
from cutkit.relax.newton import NewtonSolver
from cutkit.relax.vbd import SolveInfo, _node_terms

#: Rings of the tet graph a polish grows its region by around the nodes out of balance
#: (:func:`cutkit.relax.newton.newton_region`; doubled by the solver after an iteration that gains little).
POLISH_RINGS = 1
#: Newton iterations one polish makes at most (the step is then reported unconverged).
POLISH_MAX_ITERATIONS = 30


def polish_step(em: ElementModel, state: ElementState, x0: np.ndarray, v0: np.ndarray, h: float,
                f_ext: np.ndarray, *, atol: float, solver: NewtonSolver,
                max_iterations: int = POLISH_MAX_ITERATIONS) -> SolveInfo:
    """Finish a backward Euler step from (x0, v0) by local projected Newton on ``state.positions``.

    The step's potential is that of :func:`cutkit.relax.newton.newton_step`
    from (x0, v0); the iterations start from ``state.positions`` (where the
    sweeps stopped; it must invert no tet) and end when the residual norm over
    all free dofs of the whole model is at most ``atol``.  Every iterate keeps
    every upright tet upright (the line search's step bound).  Time is not
    advanced (the sweeps did).

    Parameters
    ----------
    em : ElementModel
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
    solver : NewtonSolver
        Of ``em``, with ``region_rings`` set for a local polish (keeps the pattern between steps).
    max_iterations : int
        Newton iterations at most.

    Returns
    -------
    SolveInfo
        ``iterations`` Newton iterations; ``initial_residual`` and ``residual`` the whole
        model's true residual norms before and after, N.
    """
    n = em.n_nodes
    x0 = _nodes(x0, n, "x0")
    v0 = _nodes(v0, n, "v0")
    f_ext = _nodes(f_ext, n, "f_ext")
    if not (np.isfinite(h) and h > 0):
        raise InputError(f"h must be a positive number, got {h}")
    if not (np.isfinite(atol) and atol > 0):
        raise InputError(f"atol must be a positive number, got {atol}")
    if solver.em is not em:
        raise InputError("the Newton solver must be one of this element model")
    free = ~em.fixed
    y = np.where(free, x0 + h * v0, x0)
    terms = _node_terms(em, x0, h, f_ext, None, y)
    info = solver.solve(state.positions, terms, atol=float(atol), max_iterations=int(max_iterations))
    KA.step_velocities(state.positions, x0, em.fixed, float(h), state.velocities)
    return info


def _nodes(a, n: int, name: str) -> np.ndarray:
    a = np.ascontiguousarray(a, np.float64)
    if a.shape != (n, 3):
        raise InputError(f"{name} must have shape ({n}, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be finite")
    return a
