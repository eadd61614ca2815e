"""Topology edits of a running mass-spring model (cuts, section 3).

A cut adds nodes (split edges, duplicated cut-surface nodes) and replaces
springs.  These functions edit a :class:`SpringModel` and its
:class:`SpringState` in place without a restart: total mass and total
momentum are kept exactly (a new node takes its mass, with its momentum,
from parent nodes), the CSR spring graph is rebuilt and only the touched
nodes are recoloured.  New nodes enter node list 0, the finest step
(section 5.2).
"""

from __future__ import annotations

import numpy as np

from cutkit.errors import InputError
from cutkit.relax.model import SpringModel, SpringState


def _mass_taken(model: SpringModel, parents: np.ndarray, weights: np.ndarray):
    """Checked mass fractions of :func:`add_nodes`.

    Returns
    -------
    par : (p, q) int64
        ``parents`` with the -1 padding replaced by 0.
    dm : (p, q) float64
        Mass each new node takes from each parent (0 for padding).
    taken : (n,) float64
        Fraction of its mass each existing node gives away, < 1.
    """
    n = model.n_nodes
    valid = parents >= 0
    if np.any(parents >= n):
        raise InputError(f"add_nodes: parent index outside 0..{n - 1}")
    if np.any(weights[valid] < 0):
        raise InputError("add_nodes: mass fractions must be >= 0")
    taken = np.bincount(parents[valid], weights[valid], minlength=n)
    if np.any(taken >= 1.0):
        bad = int(np.flatnonzero(taken >= 1.0)[0])
        raise InputError(f"add_nodes: node {bad} would give away {taken[bad]:.3g} >= 1 of its mass")
    par = np.where(valid, parents, 0)
    dm = np.where(valid, weights * model.masses[par], 0.0)  # (p, q)
    return par, dm, taken


def _append_state(state: SpringState, positions, velocities, stamps, fixed) -> None:
    """Append p new nodes to ``state``: positions, velocities and time stamps (p, 3), (p, 3), (p,), an empty
    acceleration window, and node list 0 (the finest, section 5.2), -1 for ``fixed`` ones."""
    p = positions.shape[0]
    state.positions = np.concatenate([state.positions, positions])
    state.velocities = np.concatenate([state.velocities, velocities])
    state.time_stamps = np.concatenate([state.time_stamps, stamps])
    state.accel_window = np.concatenate([state.accel_window, np.zeros((p, state.accel_window.shape[1]))])
    state.n_updates = np.concatenate([state.n_updates, np.zeros(p, np.int64)])
    # section 5.2: nodes made by a cut enter the finest list
    state.node_list = np.concatenate([state.node_list, np.where(fixed, -1, 0).astype(np.int32)])


def add_nodes(
    model: SpringModel,
    state: SpringState,
    rest_positions: np.ndarray,
    positions: np.ndarray,
    parents: np.ndarray,
    weights: np.ndarray,
    *,
    fixed: np.ndarray | None = None,
) -> np.ndarray:
    """Append nodes that take their mass and momentum from parent nodes.

    New node i receives the fraction ``weights[i, q]`` of the mass of node
    ``parents[i, q]`` (which loses it) together with that mass's momentum,
    so ``sum(m)`` and ``sum(m v)`` are unchanged.  A cut duplicating node p
    into p and p' is ``parents=[[p]], weights=[[0.5]]``; a node splitting
    edge (a, b) at parameter s could take ``[[a, b]], [[(1 - s) w, s w]]``.

    Parameters
    ----------
    rest_positions, positions : (p, 3) float64, mm
    parents : (p, q) int64
        Parent nodes; -1 pads unused entries.
    weights : (p, q) float64
        Fraction of each parent's current mass moved to the new node, >= 0;
        the fractions taken from one parent over all new nodes sum to < 1.
    fixed : (p,) bool, optional
        New nodes held where they are made (velocity 0; the momentum of the
        mass they take is then dropped, as for any held node).

    Returns
    -------
    new_ids : (p,) int64
    """
    rest_positions = np.ascontiguousarray(rest_positions, np.float64).reshape(-1, 3)
    positions = np.ascontiguousarray(positions, np.float64).reshape(-1, 3)
    parents = np.atleast_2d(np.asarray(parents, np.int64))
    weights = np.atleast_2d(np.asarray(weights, np.float64))
    p = rest_positions.shape[0]
    n = model.n_nodes
    if positions.shape[0] != p or parents.shape[0] != p or weights.shape != parents.shape:
        raise InputError(
            f"add_nodes: rest_positions {rest_positions.shape}, positions {positions.shape}, "
            f"parents {parents.shape} and weights {weights.shape} disagree"
        )
    par, dm, taken = _mass_taken(model, parents, weights)
    new_mass = dm.sum(axis=1)
    if np.any(new_mass <= 0):
        raise InputError("add_nodes: every new node needs a positive mass from its parents")
    momentum = np.einsum("pq,pqc->pc", dm, state.velocities[par])
    new_vel = momentum / new_mass[:, None]
    masses = model.masses * (1.0 - taken)
    # the new node inherits the mass-weighted mean of its parents' damping and time stamp
    damp = (dm * model.damping[par]).sum(axis=1) / new_mass
    stamps = (dm * state.time_stamps[par]).sum(axis=1) / new_mass
    if fixed is None:
        fixed = np.zeros(p, bool)
    fixed = np.asarray(fixed, bool).reshape(p)

    model.rest_positions = np.concatenate([model.rest_positions, rest_positions])
    model.masses = np.concatenate([masses, new_mass])
    model.damping = np.concatenate([model.damping, damp])
    model.fixed = np.concatenate([model.fixed, fixed])
    model.prescribed_displacement = np.concatenate([model.prescribed_displacement, positions - rest_positions])
    model.prescribed_displacement[n:][~fixed] = 0.0
    _append_state(state, positions, np.where(fixed[:, None], 0.0, new_vel), stamps, fixed)
    model.rebuild_adjacency(recolour=False)
    model.colour = np.concatenate([model.colour, np.full(p, -1, np.int32)])
    new_ids = np.arange(n, n + p, dtype=np.int64)
    recolour(model, new_ids)
    return new_ids


def add_springs(
    model: SpringModel,
    springs: np.ndarray,
    stiffness: np.ndarray,
    rest_length: np.ndarray | None = None,
) -> np.ndarray:
    """Append springs.

    Parameters
    ----------
    springs : (a, 2) int64
        Node pairs (distinct nodes).
    stiffness : (a,) float64, N/mm
    rest_length : (a,) float64, mm, optional
        Defaults to the distance of the rest positions.

    Returns
    -------
    new_ids : (a,) int64
    """
    springs = np.atleast_2d(np.asarray(springs, np.int64))
    a = springs.shape[0]
    n = model.n_nodes
    if springs.shape[1] != 2:
        raise InputError(f"add_springs: springs must have shape (a, 2), got {springs.shape}")
    if a and (springs.min() < 0 or springs.max() >= n):
        raise InputError(f"add_springs: spring node index outside 0..{n - 1}")
    if np.any(springs[:, 0] == springs[:, 1]):
        raise InputError("add_springs: a spring joins a node to itself")
    stiffness = np.broadcast_to(np.asarray(stiffness, np.float64), (a,))
    if np.any(stiffness < 0):
        raise InputError("add_springs: stiffness must be >= 0")
    if rest_length is None:
        d = model.rest_positions[springs[:, 1]] - model.rest_positions[springs[:, 0]]
        rest_length = np.sqrt(np.einsum("ij,ij->i", d, d))
    rest_length = np.broadcast_to(np.asarray(rest_length, np.float64), (a,))
    s0 = model.n_springs
    model.springs = np.concatenate([model.springs, springs])
    model.stiffness = np.concatenate([model.stiffness, stiffness])
    model.rest_length = np.concatenate([model.rest_length, rest_length])
    model.rebuild_adjacency(recolour=False)
    recolour(model, np.unique(springs))
    return np.arange(s0, s0 + a, dtype=np.int64)


def remove_springs(model: SpringModel, spring_ids: np.ndarray) -> np.ndarray:
    """Remove springs; the others are renumbered in order.

    Parameters
    ----------
    spring_ids : (r,) int64

    Returns
    -------
    old_ids : (s - r,) int64
        Former index of each remaining spring.
    """
    ids = np.unique(np.asarray(spring_ids, np.int64))
    if ids.size and (ids[0] < 0 or ids[-1] >= model.n_springs):
        raise InputError(f"remove_springs: spring index outside 0..{model.n_springs - 1}")
    keep = np.ones(model.n_springs, bool)
    keep[ids] = False
    model.springs = model.springs[keep]
    model.stiffness = model.stiffness[keep]
    model.rest_length = model.rest_length[keep]
    # removing edges never breaks a proper colouring
    model.rebuild_adjacency(recolour=False)
    return np.flatnonzero(keep)


def recolour(model: SpringModel, nodes: np.ndarray) -> None:
    """Give each node the smallest colour none of its neighbours has (``model.colour``, in place).

    Parameters
    ----------
    model : SpringModel
    nodes : (k,) int64
        The nodes to colour again (those whose springs changed).
    """
    off, adj, col = model.adj_offsets, model.adj_nodes, model.colour
    for k in np.asarray(nodes, np.int64):
        nb = col[adj[off[k]:off[k + 1]]]
        if col[k] >= 0 and not np.any(nb == col[k]):
            continue
        used = np.zeros(len(nb) + 2, bool)
        nb = nb[(nb >= 0) & (nb < len(used))]
        used[nb] = True
        col[k] = int(np.flatnonzero(~used)[0])
