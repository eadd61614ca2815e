"""Momentum of the free pieces over a step of the springs' semi-implicit integrator.

The semi-implicit step of eq. (6) (docs/relaxation.md) divides each node's
force by its own implicit mass ``m + h D + h^2 K``, so the equal and opposite
forces of a spring no longer give equal and opposite momentum changes; the
adaptive node lists (section 5.2) and Gauss-Seidel sweeps also take the two
ends of a spring at different estimates.  Held tissue does not notice (its
fixed nodes take any net impulse), but a piece a cut sets loose gains a
spurious net impulse every step and drifts away.

Over a step that starts and ends with every node at one time (a
synchronised interval), :func:`keep_free_momentum` gives each *free piece*
(a component of the spring graph holding no fixed node) the momentum change
its external loads give it: gravity, the external forces and its nodes'
damping, taken implicitly (``-h D v'``, as in the step).  The difference is
removed as one velocity ``delta`` added to every node of the piece, and the
positions move by ``h delta`` (the step's ``x' = x + h v'``), so internal
motion is untouched and the centre of mass follows Newton's second law
exactly, to rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import weakref

import numpy as np

from cutkit.relax._graph_kernels import graph_components
from cutkit.relax.model import SpringModel, SpringState


#: The components of each live spring model's graph, by ``id(model)``: ``(weak reference to the model,
#: topology key, n_pieces, labels)``, dropped when the model is.  Kept here, not on the model, so that
#: only the model's own code writes its fields.
_PIECES: dict = {}


def spring_pieces(model: SpringModel) -> tuple[int, np.ndarray]:
    """The components of the spring graph, cached on the model's topology.

    Returns
    -------
    n_pieces : int
    labels : (n,) int64
        The piece of each node.
    """
    key = (model.topology_version, model.n_nodes)
    cached = _PIECES.get(id(model))
    if cached is not None and cached[0]() is model and cached[1] == key:
        return cached[2], cached[3]
    n_pieces, labels = graph_components(model.adj_offsets, model.adj_nodes)
    ident = id(model)
    ref = weakref.ref(model, lambda _: _PIECES.pop(ident, None))
    _PIECES[ident] = (ref, key, int(n_pieces), labels)
    return int(n_pieces), labels


def held_pieces(model: SpringModel) -> tuple[np.ndarray, np.ndarray]:
    """Which pieces of the spring graph hold a fixed node.

    Returns
    -------
    labels : (n,) int64  the piece of each node (:func:`spring_pieces`)
    held : (p,) bool
    """
    n_pieces, labels = spring_pieces(model)
    return labels, np.bincount(labels, weights=model.fixed, minlength=n_pieces) > 0


@dataclass
class MomentumStart:
    """The free pieces' momenta at the start of a synchronised interval.

    Attributes
    ----------
    time : float  s
    nodes : (k,) int64  the nodes of free pieces
    piece : (k,) int64  their piece, numbered 0 .. p - 1
    momentum : (p, 3) float64  t mm/s
    """

    time: float
    nodes: np.ndarray
    piece: np.ndarray
    momentum: np.ndarray


def free_momentum_start(model: SpringModel, state: SpringState) -> MomentumStart | None:
    """Record the free pieces' momenta now (every node at ``state.time``); None when there is no free piece."""
    labels, held = held_pieces(model)
    if held.all():
        return None
    nodes = np.flatnonzero(~held[labels])
    _, piece = np.unique(labels[nodes], return_inverse=True)
    piece = piece.ravel().astype(np.int64)
    return MomentumStart(float(state.time), nodes, piece, _sums(piece, model.masses[nodes, None] * state.velocities[nodes]))


def keep_free_momentum(model: SpringModel, state: SpringState, start: MomentumStart | None,
                       f_ext: np.ndarray, gravity: np.ndarray) -> None:
    """Give every free piece the momentum its loads give it over the interval since ``start`` (in place).

    Call it when every node has reached ``state.time`` again, with the same
    topology as at ``start``.

    Parameters
    ----------
    model : SpringModel
    state : SpringState
    start : MomentumStart or None
        From :func:`free_momentum_start` at the interval's start.
    f_ext : (n, 3) float64
        The external forces over the interval, N.
    gravity : (3,) float64
        mm/s^2.
    """
    if start is None or start.nodes.size == 0:
        return
    h = float(state.time) - start.time
    if not h > 0.0:
        return
    nodes, piece = start.nodes, start.piece
    m = model.masses[nodes]
    d = model.damping[nodes] * m  # the step's damping coefficient D (eq. 4), t/s
    v = state.velocities[nodes]
    mass = _sums(piece, m[:, None])[:, 0]
    load = _sums(piece, f_ext[nodes] + m[:, None] * gravity)
    drag = _sums(piece, d[:, None] * v)
    d_sum = _sums(piece, d[:, None])[:, 0]
    now = _sums(piece, m[:, None] * v)
    # M delta + P1 = P0 + h (F + M g) - h sum D (v + delta)   (implicit damping, as the step)
    delta = (start.momentum - now + h * (load - drag)) / (mass + h * d_sum)[:, None]
    state.velocities[nodes] += delta[piece]
    state.positions[nodes] += h * delta[piece]


def _sums(piece, values):
    """(p, c) float64 sums of ``values`` (k, c) per ``piece`` (k,)."""
    p = int(piece.max()) + 1 if piece.size else 0
    return np.stack([np.bincount(piece, weights=values[:, c], minlength=p) for c in range(values.shape[1])], axis=1)
