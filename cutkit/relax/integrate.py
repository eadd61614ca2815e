"""Uniform time steps of the mass-spring model (paper section 5.1).

:func:`step` advances every free node by one step with

* ``"semi-implicit"``: eq. (6) as derived in docs/relaxation.md, the
  direction of motion implicit and the magnitude from the explicit
  estimate of eq. (7), implicit stiffness k_jk per spring (default);
* ``"semi-implicit-secant"``: the same with the paper's printed
  coefficient E_jk = k_jk (|x_j - x_k| - l_jk) / |x_j - x_k| (stretched
  springs only) as implicit stiffness;
* ``"symplectic-euler"``: the explicit reference.

The semi-implicit steps then give every free piece (no fixed node) the
momentum its loads give it (:mod:`cutkit.relax.momentum`).

Either Jacobi-style (every node from the old positions, eq. 7 for all
neighbours) or Gauss-Seidel (section 5.1, last paragraph: neighbours
already processed in this sweep are used as updated), the latter run in
parallel one colour class at a time.
"""

from __future__ import annotations

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _kernels as K
from cutkit.relax._volume_kernels import NodeSums, add_volume_forces
from cutkit.relax.model import Control, SpringModel, SpringState
from cutkit.relax.momentum import free_momentum_start, keep_free_momentum

METHODS = {
    "semi-implicit": K.MODE_AXIAL,
    "semi-implicit-secant": K.MODE_SECANT,
    "symplectic-euler": K.MODE_EXPLICIT,
}


def method_mode(method: str) -> int:
    try:
        return METHODS[method]
    except KeyError:
        raise InputError(f"unknown relaxation method {method!r}; choose one of {', '.join(METHODS)}") from None


def control_arrays(model: SpringModel, control: Control | None) -> tuple[np.ndarray, np.ndarray]:
    """Checked ``(f_ext (n, 3) float64, gravity (3,) float64)`` of a control."""
    n = model.n_nodes
    control = control or Control()
    if control.external_forces is None:
        f = np.zeros((n, 3))
    else:
        f = np.ascontiguousarray(control.external_forces, np.float64)
        if f.shape != (n, 3):
            raise InputError(f"external_forces must have shape ({n}, 3), got {f.shape}")
    g = np.ascontiguousarray(control.gravity, np.float64).reshape(-1)
    if g.shape != (3,):
        raise InputError(f"gravity must have 3 components, got {g.shape[0]}")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(g))):
        raise InputError("external forces and gravity must be finite")
    return f, g


def colour_classes(model: SpringModel, nodes: np.ndarray) -> list[np.ndarray]:
    """Split ``nodes`` into colour classes (ascending colour, nodes ascending).

    Returns a list of (c_i,) int64 arrays; no spring joins two nodes of one class.
    """
    nodes = np.asarray(nodes, np.int64)
    if nodes.size == 0:
        return []
    col = model.colour[nodes]
    order = np.argsort(col, kind="stable")
    nodes = nodes[order]
    counts = np.bincount(col, minlength=int(col.max()) + 1)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return [nodes[bounds[c]:bounds[c + 1]] for c in range(len(counts)) if counts[c]]


_NO_COEFFICIENTS = np.zeros(0)


def advance_nodes(
    model: SpringModel,
    state: SpringState,
    nodes: np.ndarray,
    target_time: float,
    f_ext: np.ndarray,
    gravity: np.ndarray,
    mode: int,
    classes: list[np.ndarray] | None = None,
    halo: np.ndarray | None = None,
) -> None:
    """Advance ``nodes`` (no checks) to ``target_time``.

    With ``classes`` (colour classes of ``nodes``) Gauss-Seidel in place,
    else Jacobi via new arrays (the state's arrays are replaced).  ``halo``
    (``nodes`` and their neighbours, see ``_kernels.halo_nodes``) limits the
    eq. (7) predictions to where they are read; default all nodes.
    """
    n = model.n_nodes
    if halo is None:
        halo = np.arange(n, dtype=np.int64)
    x, v, ts = state.positions, state.velocities, state.time_stamps
    p = np.empty((n, 3))
    K.predict_positions(halo, target_time, x, v, ts, mode == K.MODE_EXPLICIT, p)
    vt = model.volume
    f_node, k_node = f_ext, model.node_stiffness
    if vt is not None:
        # the advanced nodes' rows of these get the volume terms added (scratch kept by the term)
        f_node, k_node = vt.scratch(n)
        volume, given, summed = vt.kernel_tets(), NodeSums(f_ext, model.node_stiffness), NodeSums(f_node, k_node)
    terms = K.NodeTerms(k_node, model.masses, model.damping, f_node, gravity)
    before = K.NodeStates(x, v, ts)

    def springs(coefficients):
        return K.NodeSprings(model.adj_offsets, model.adj_nodes, model.adj_springs, model.adj_rest,
                             model.adj_stiffness, coefficients)

    # the node lists C-contiguous: one compiled signature of relax_nodes (a strided view compiles another)
    if classes is not None:
        after = K.NodeUpdates(x, v, ts, state.accel_window, state.n_updates)
        for cls in classes:
            if vt is not None:
                # Gauss-Seidel: this class sees the new positions of the classes before it
                add_volume_forces(cls, p, volume, given, summed)
            K.relax_nodes(np.ascontiguousarray(cls), target_time, before, after, p, springs(_NO_COEFFICIENTS), terms, mode, True)
        return
    if vt is not None:
        add_volume_forces(nodes, p, volume, given, summed)
    if 4 * len(nodes) >= n:
        # a large share of the nodes: one square root per spring, not per spring end
        c = np.empty(model.n_springs)
        K.spring_coefficients(model.spring_a, model.spring_b, p, model.rest_length, model.stiffness, c)
    else:
        c = _NO_COEFFICIENTS
    x_new, v_new, ts_new = x.copy(), v.copy(), ts.copy()
    after = K.NodeUpdates(x_new, v_new, ts_new, state.accel_window, state.n_updates)
    K.relax_nodes(np.ascontiguousarray(nodes), target_time, before, after, p, springs(c), terms, mode, False)
    state.positions, state.velocities, state.time_stamps = x_new, v_new, ts_new


def step(
    model: SpringModel,
    state: SpringState,
    control: Control | None,
    dt: float,
    *,
    method: str = "semi-implicit",
    gauss_seidel: bool = False,
) -> None:
    """Advance every free node of ``state`` by ``dt`` seconds (in place).

    Parameters
    ----------
    model : SpringModel
    state : SpringState
        Modified in place (its arrays may be replaced).
    control : Control or None
    dt : float
        Time step, s.
    method : {"semi-implicit", "semi-implicit-secant", "symplectic-euler"}
    gauss_seidel : bool
        Use the positions of neighbours already updated in this step.
    """
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"time step must be a positive number of seconds, got {dt}")
    mode = method_mode(method)
    f, g = control_arrays(model, control)
    target = state.time + dt
    nodes = model.free_nodes
    classes = colour_classes(model, nodes) if gauss_seidel else None
    # symplectic Euler keeps momentum by itself; the semi-implicit steps are given it
    keep = mode != K.MODE_EXPLICIT and synchronised(model, state)
    start = free_momentum_start(model, state) if keep else None
    advance_nodes(model, state, nodes, target, f, g, mode, classes)
    state.time_stamps[model.fixed] = target  # held nodes are "at" every time
    state.time = target
    keep_free_momentum(model, state, start, f, g)


def synchronised(model: SpringModel, state: SpringState, eps: float = 0.0) -> bool:
    """Whether every free node's time stamp is within ``eps`` s of ``state.time``."""
    ts = state.time_stamps[~model.fixed]
    return bool(ts.size == 0 or np.all(np.abs(ts - state.time) <= eps))


def spring_forces(model: SpringModel, positions: np.ndarray) -> np.ndarray:
    """Physical spring force on each node, N: (n, 3) float64."""
    x = np.ascontiguousarray(positions, np.float64)
    return K.spring_forces(x, model.adj_offsets, model.adj_nodes, model.adj_rest, model.adj_stiffness)


def spring_energy(model: SpringModel, positions: np.ndarray) -> float:
    """Elastic energy sum 1/2 k (|d| - l)^2, N mm (= mJ)."""
    d = positions[model.springs[:, 1]] - positions[model.springs[:, 0]]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    return float(0.5 * np.sum(model.stiffness * (length - model.rest_length) ** 2))


def kinetic_energy(model: SpringModel, state: SpringState) -> float:
    """Kinetic energy 1/2 sum m |v|^2, N mm."""
    return float(0.5 * np.sum(model.masses * np.einsum("ij,ij->i", state.velocities, state.velocities)))


def total_momentum(model: SpringModel, state: SpringState) -> np.ndarray:
    """Total momentum sum m v, (3,) float64, t mm/s."""
    return (model.masses[:, None] * state.velocities).sum(axis=0)
