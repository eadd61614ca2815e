"""Vertex block descent solves of the element model: implicit steps, local steps, static equilibrium.

One implicit (backward Euler) step of length ``h`` minimises the incremental
potential of :mod:`cutkit.relax.elastic` by vertex block descent (Chen,
Macklin, Kim, Yuksel, SIGGRAPH 2024): the nodes of one colour class move in
parallel, each to the exact minimiser in its own position
(:mod:`cutkit.relax._elastic_kernels`).  Iterations stop at a residual,
never after a fixed count (:data:`DEFAULT_RTOL`).  The model
(:class:`~cutkit.relax.elastic.ElementModel`) and the state
(:class:`~cutkit.relax.elastic.ElementState`) live in :mod:`cutkit.relax.elastic`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.relax import _adjacency_kernels as KA
from cutkit.relax import _elastic_kernels as K
from cutkit.relax.elastic import ElementModel, ElementState

#: The iterations of a solve stop once the residual (the 2-norm of the
#: out-of-balance node forces, N) has fallen to this fraction of its first value...
DEFAULT_RTOL = 1e-4
#: ... or below this absolute value, N (a strain of about 1e-7 on a soft-tissue tet of 3 mm).
DEFAULT_ATOL_N = 1e-7
#: The most sweeps one solve makes before it reports that it did not converge.
DEFAULT_MAX_ITERATIONS = 10000
#: The stop flag of solves nothing interrupts (see :func:`local_step`); never written.
NEVER_STOP = np.zeros(1, np.int64)


@dataclass
class SolveInfo:
    """How a solve ended: sweeps made, residual before the first and after the last (N), node updates.

    ``taken`` is False for a :func:`local_step` stopped within its first sweep (nothing changed).
    """

    iterations: int
    initial_residual: float
    residual: float
    converged: bool
    node_updates: int = 0
    taken: bool = True


def _node_terms(em: ElementModel, x, h, f_ext, gravity, y=None):
    n = em.n_nodes
    force = np.zeros((n, 3)) if f_ext is None else np.array(f_ext, np.float64, copy=True)
    if gravity is not None and np.any(gravity):
        force += em.masses[:, None] * np.asarray(gravity, np.float64)[None, :]
    if h is None:
        zero = np.zeros(n)
        return K.NodeTerms(zero, zero, em.fixed, x, x, force)
    inertia = em.masses / (h * h)
    damping = em.damping * em.masses / h
    return K.NodeTerms(inertia, damping, em.fixed, y, x.copy(), force)


def iterate(em: ElementModel, x, terms, *, rtol=DEFAULT_RTOL, atol=DEFAULT_ATOL_N,
            max_iterations=DEFAULT_MAX_ITERATIONS, min_iterations=1, chebyshev=None, stop=None) -> SolveInfo:
    """Vertex block descent sweeps on ``x`` (in place) until the residual criterion holds.

    ``chebyshev`` (a spectral radius estimate in (0, 1)) turns on the
    Chebyshev semi-iterative acceleration that vertex block descent uses
    (Wang 2015): ``x = w (x_sweep - x_prev2) + x_prev2``.  ``stop`` ((1,)
    int64, optional) is read before each colour class: non-zero ends the
    sweep there (every node moved so far keeps its move) and the solve,
    not converged.
    """
    halt = NEVER_STOP if stop is None else stop
    offsets, nodes = em.colour_classes()
    r2 = np.zeros(em.n_nodes)
    adj = em.adjacency
    r0 = res = 0.0
    it = 0
    prev2 = prev = None
    omega = 1.0
    while it < max_iterations:
        if chebyshev is not None:
            prev2, prev = prev, x.copy()
        K.vbd_sweep(x, adj, terms, offsets, nodes, r2, halt)
        it += 1
        res = float(np.sqrt(r2.sum()))
        if halt[0]:
            return SolveInfo(it, r0 if it > 1 else res, res, False)
        if it == 1:
            r0 = res
        if it >= min_iterations and (res <= rtol * r0 or res <= atol):
            return SolveInfo(it, r0, res, True)
        if chebyshev is not None and prev2 is not None:
            rho2 = chebyshev * chebyshev
            omega = 2.0 / (2.0 - rho2) if omega == 1.0 else 4.0 / (4.0 - rho2 * omega)
            x[:] = omega * (x - prev2) + prev2
    return SolveInfo(it, r0, res, False)


def implicit_step(em: ElementModel, state: ElementState, h: float, f_ext=None, gravity=None,
                  **tolerances) -> SolveInfo:
    """Advance ``state`` by one backward Euler step of ``h`` seconds.

    Parameters
    ----------
    em : ElementModel
    state : ElementState
        Changed in place.
    h : float
        s.
    f_ext : (n, 3) float64, optional
        External node forces, N.
    gravity : (3,) float64, optional
        mm/s^2.
    **tolerances
        ``rtol``, ``atol``, ``max_iterations`` of :func:`iterate`.
    """
    chebyshev = tolerances.pop("chebyshev", None)
    x0 = state.positions.copy()
    free = ~em.fixed
    y = np.where(free, x0 + h * state.velocities, x0)
    state.positions[:] = y  # the inertial prediction is the first guess
    terms = _node_terms(em, x0, h, f_ext, gravity, y)
    info = iterate(em, state.positions, terms, chebyshev=chebyshev, **tolerances)
    state.velocities[:] = np.where(free, (state.positions - x0) / h, 0.0)
    state.time += h
    return info


def local_step(em: ElementModel, state: ElementState, h: float, f_ext, r2, seeds, *,
               atol: float, max_iterations: int = DEFAULT_MAX_ITERATIONS, chebyshev=None,
               stop=None) -> SolveInfo:
    """One backward Euler step that moves only the nodes out of balance (and their neighbours).

    A node whose out-of-balance force stays below ``tau = atol / (2 sqrt(n))``
    and that does not move (its inertial force ``m |v| / h`` below tau)
    sleeps: it keeps its position and its last residual ``r2``.  The nodes of
    ``seeds`` (touched by a cut, loaded) are awake, and so is every neighbour
    of a node still out of balance after a sweep, so a disturbance spreads
    exactly as far as it is felt.  The step ends when the residual of all
    nodes, sleeping ones with their last value, is at most ``atol``; with
    every node awake this is :func:`implicit_step`.

    Parameters
    ----------
    r2 : (n,) float64
        Squared residual of every node at its last sweep, N^2; updated in place.
    seeds : (k,) int64
        Nodes to wake.
    stop : (1,) int64, optional
        Read before every colour class of a sweep (in the kernel) and after
        every sweep: non-zero ends the step there, unconverged, with the
        positions reached (a live session's cut waiting for the tissue,
        :class:`~cutkit.simulate.tasks.HandoverLock`).  Stopped within its
        first sweep, the step is not taken: positions and time stay as they
        were and the result has 0 iterations.
    """
    x, v = state.positions, state.velocities
    n = em.n_nodes
    tau2 = (0.5 * atol) ** 2 / max(n, 1)
    movable = np.empty(n, bool)
    mark = np.zeros(n, bool)
    # a node held or left without tets (a cut's orphan) gets no residual (step_seeds): its last
    # one would otherwise stay in the sum and keep every later step from converging
    seeds = KA.step_seeds(KA.NodeKinds(em.masses, em.fixed, em.adj_degree), v, r2, float(h), float(tau2),
                          np.asarray(seeds, np.int64), (movable, mark))
    awake = KA.awake_after_sweep(em.adjacency, movable, r2, -1.0, seeds, mark)
    x0 = x.copy()
    y = x0.copy()
    y[awake] += h * np.where(em.fixed[awake], 0.0, v[awake])
    # the sweeps start from x^n, not from the inertial prediction y: from a state
    # without inverted tets no sweep makes one (_elastic_kernels.KEEP_J_FRACTION),
    # while y itself could fold a tet over
    terms = _node_terms(em, x0, h, f_ext, None, y)
    n_colours = int(em.colour.max(initial=-1)) + 1
    r0 = res = 0.0
    it = 0
    prev2 = prev = None
    omega = 1.0
    updates = 0
    stop = NEVER_STOP if stop is None else stop
    while it < max_iterations and awake.size:
        offsets, nodes = KA.colour_classes_of(em.colour, awake, n_colours)
        updates += nodes.size
        if chebyshev is not None:
            prev2, prev = prev, x.copy()
        swept = K.vbd_sweep(x, em.adjacency, terms, offsets, nodes, r2, stop)
        if it == 0 and swept < offsets.size - 1:  # stopped within the first sweep: the step is not taken
            x[:] = x0
            return SolveInfo(0, 0.0, 0.0, False, 0, taken=False)
        it += 1
        if chebyshev is not None and prev2 is not None:  # as in iterate(); nodes that slept are unchanged
            rho2 = chebyshev * chebyshev
            omega = 2.0 / (2.0 - rho2) if omega == 1.0 else 4.0 / (4.0 - rho2 * omega)
            x[:] = omega * (x - prev2) + prev2
        res = float(np.sqrt(r2.sum()))
        if it == 1:
            r0 = res
        if res <= atol or stop[0]:
            break
        awake = KA.awake_after_sweep(em.adjacency, movable, r2, tau2, awake, mark)
    KA.step_velocities(x, x0, em.fixed, float(h), v)
    state.time += h
    return SolveInfo(it, r0, res, res <= atol, updates)


def vbd_static(em: ElementModel, positions, f_ext=None, gravity=None, **tolerances) -> SolveInfo:
    """Relax ``positions`` (n, 3) float64 (in place) to static equilibrium by the sweeps of
    :func:`iterate` (``tolerances``: ``rtol``, ``atol``, ``max_iterations``, ``chebyshev``)."""
    return iterate(em, positions, _node_terms(em, positions, None, f_ext, gravity), **tolerances)


def elastic_forces(em: ElementModel, positions) -> np.ndarray:
    """Elastic node forces -dW/dx, N: (n, 3) float64 (reaction forces at held nodes)."""
    out = np.zeros((em.n_nodes, 3))
    K.node_forces(np.ascontiguousarray(positions, np.float64), em.adjacency, out)
    return out


def elastic_forces_at(em: ElementModel, positions, nodes) -> np.ndarray:
    """Elastic node forces -dW/dx on ``nodes`` (k,) int64 only, N: (k, 3) float64.

    Each node's force is the sum over its own adjacency row, the same sum
    :func:`elastic_forces` makes for it, so the values are those of the whole
    pass, bit for bit, at the cost of the nodes asked for.
    """
    nodes = np.ascontiguousarray(nodes, np.int64)
    out = np.empty((nodes.shape[0], 3))
    if nodes.size:
        K.forces_at(np.ascontiguousarray(positions, np.float64), em.adjacency, nodes, out)
    return out


def kept_volume_ratios(em: ElementModel, positions, at: np.ndarray, stale, mark: np.ndarray, J: np.ndarray,
                       below: float, stop=None) -> tuple[float, int]:
    """:func:`volume_ratio_extremes` from volume ratios kept between calls, computed again only
    where a change can reach (the kernel's docstring: ``_elastic_kernels.refresh_volume_ratios``).

    Parameters
    ----------
    em : ElementModel
    positions : (n, 3) float64
    at : (n, 3) float64
        Where ``J`` was computed (NaN: never); brought up to ``positions``.
    stale : (k,) int
        Elements to compute again whatever their corners did (added or removed).
    mark : (m,) bool
        Elements still to compute (m: the model's element rows); False where computed.
    J : (m,) float64
        The kept ratios, updated in place.
    below : float
    stop : (1,) int64, optional
        As :func:`volume_ratio_extremes`'s: raised, the result is (NaN, 0) and the rest stays marked.

    Returns
    -------
    (lowest, count) as :func:`volume_ratio_extremes` gives them, bit for bit.
    """
    x = np.ascontiguousarray(positions, np.float64)
    whole = K.refresh_volume_ratios(x, em.elements, em.adjacency, at, np.ascontiguousarray(stale, np.int64), mark,
                                    J, NEVER_STOP if stop is None else stop)
    if not whole:
        return float("nan"), 0
    lowest, count = K.kept_ratio_extremes(J, em.volume, float(below))
    return float(lowest), int(count)


def refresh_forces(em: ElementModel, positions, at: np.ndarray, stale, most: int, mark: np.ndarray,
                   forces: np.ndarray) -> int:
    """Sum again the kept elastic forces a change can reach (the kernel's docstring:
    ``_elastic_kernels.refresh_forces``), in place.

    Parameters
    ----------
    em : ElementModel
    positions : (n, 3) float64
    at : (n, 3) float64
        Where ``forces`` were summed (NaN: never); brought up to ``positions`` where summed again.
    stale : (k,) int
        Nodes to sum again whatever their position (their tets changed).
    most : int
        More moved or stale nodes than this: nothing is done and -1 returned.
    mark : (n,) bool
        Scratch, all False.
    forces : (n, 3) float64

    Returns
    -------
    int
        The nodes summed again, or -1.
    """
    return int(K.refresh_forces(np.ascontiguousarray(positions, np.float64), em.adjacency, at,
                                np.ascontiguousarray(stale, np.int64), int(most), mark, forces))


def elastic_energy(em: ElementModel, positions) -> float:
    """Total stored energy, N mm."""
    return float(K.element_energy(np.ascontiguousarray(positions, np.float64), em.elements))


def volume_ratio_extremes(em: ElementModel, positions, below: float) -> tuple[float, int]:
    """The smallest volume ratio ``J = det F`` (of each element's natural shape) at ``positions``
    (n, 3) float64 over the live elements (1.0 without any), and how many have ``J < below``: one
    pass over every element (:func:`kept_volume_ratios` keeps them between calls)."""
    lowest, count = K.volume_ratio_extremes(np.ascontiguousarray(positions, np.float64), em.elements, float(below))
    return float(lowest), int(count)
