"""The run-time tissue store: the nodes and tetrahedra of a cut tissue on one numbering.

:class:`TissueStore` holds what the cutting and the physics share (node
positions in the cut's configuration, rest positions, texture coordinates,
the defining nodes and weights of cut nodes; tet corners, alive flags,
origin tets, labels), the topology of its original tetrahedra (edges,
faces, neighbours, outward boundary faces) and the records a rebase keeps
(which model tet and node each one comes from, which tets a cut made).  It
is the only writer of those arrays: the cutting changes them through its
methods (:meth:`add_node`, :meth:`move_node`, :meth:`add_tets`,
:meth:`remove_tets`, ...), which log the step's change
(:attr:`step_log`) from which the cutting builds its
:class:`~cutkit.tissue.TopologyDelta`; the physics reads the views
(:attr:`rest_points`, :attr:`tet_corners`, ...) and keeps its own state
(current positions, velocities) on the same node numbering.
:meth:`rebase` renumbers the tetrahedra in place, in one place, so every
holder of a store sees the new numbering.

Node ids never change.  Tet ids ``< n_orig_tets`` are the original tets
(the model's, or the live tets at the last rebase); a cut appends tets and
marks the ones it replaces dead.

The node and tet arrays have spare rows (:attr:`node_buffers`,
:attr:`tet_buffers`: capacity, not count); rows past :attr:`n_nodes` hold
no node, and the cutting's cone search may use the first of them as
scratch (:meth:`reserve_nodes`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from cutkit.errors import InputError
from cutkit.mesh.topology import face_topology, unique_edges
from cutkit.tissue import _store_kernels as K

#: Spare node rows a store starts with (doubled when a cut needs more).
NODE_ROOM = 1024
#: Spare tet rows a store starts with: this fraction of its original tets, at least
#: :data:`TET_ROOM_MIN`.  A stroke that cuts a few hundred tets adds a few thousand, and growing
#: the rows copies every tet array of the store and of the physics (76 ms on the demo knee's
#: 172k tets, on the thread a live cut waits for), so two or three strokes fit without it.
TET_ROOM_FRACTION = 0.125
TET_ROOM_MIN = 4096
#: Texture coordinates placeholder for the node kernels (no texture).
_NO_UVW = np.zeros((0, 3))


class NodeBuffers(NamedTuple):
    """The node arrays of a :class:`TissueStore`, with spare rows (capacity ``c``)."""

    x: np.ndarray  #: (c, 3) float64 positions in the cut's configuration, mm
    X: np.ndarray  #: (c, 3) float64 rest positions, mm
    uvw: np.ndarray | None  #: (c, 3) float64 texture coordinates, or None
    parents: np.ndarray  #: (c, 4) int64 original nodes a cut node interpolates, -1 padded
    weights: np.ndarray  #: (c, 4) float64 their weights
    held: np.ndarray  #: (c,) bool held by the boundary conditions (fixed or prescribed)


class TetBuffers(NamedTuple):
    """The tet arrays of a :class:`TissueStore`, with spare rows (capacity ``c``)."""

    corners: np.ndarray  #: (c, 4) int64, positively oriented at rest
    alive: np.ndarray  #: (c,) bool
    origin: np.ndarray  #: (c,) int64 original tet each tet subdivides (itself for an original tet)


@dataclass
class StepLog:
    """What the store's writers changed since :meth:`TissueStore.begin_step`, in order.

    ``moved_from`` maps a node to its rest position before the step's first move of it.
    """

    added_nodes: list = field(default_factory=list)
    moved_nodes: list = field(default_factory=list)
    moved_from: dict = field(default_factory=dict)
    removed_tets: list = field(default_factory=list)
    added_tets: list = field(default_factory=list)


class TissueStore:
    """Nodes and tetrahedra of a run-time tissue (see the module docstring).

    Parameters
    ----------
    points : (n, 3) float64
        Positions of the nodes in the cut's configuration, mm.
    tets : (m, 4) int64
        Positively oriented.
    rest_points : (n, 3) float64, optional
        Rest positions (default: ``points``).
    texcoords : (n, 3) float64, optional
    labels : (m,) int32, optional
        Tissue label of each tet (default 0).
    held : (n,) bool, optional
        Nodes the boundary conditions hold, fixed or prescribed (default none).  A
        cut node between held nodes only is held too.

    Attributes
    ----------
    n_nodes : int
    n_orig_nodes : int
        Nodes at construction (or the last rebase): the ones a cut node may interpolate.
    orig_tets : (m, 4) int64
    labels : (m,) int32
    edges, tet_edges, faces, tet_faces, face_tets, neighbors
        Topology of the original tets (:func:`cutkit.mesh.topology.unique_edges`, :func:`face_topology`).
    boundary_faces : (b, 3) int64, boundary_face_tet : (b,) int64
        The original tets' outward boundary faces and the tet of each (read-only).
    n_model_nodes, n_model_tets : int
        Nodes and tets of the model as loaded (nodes with a larger id were made by cuts).
    model_tet : (m,) int64
        Model tet of each original tet.
    orig_made_by_cut : (m,) bool
        Original tets made by a cut before the last rebase.
    model_node : (n_orig_nodes,) int64
        Model node each original node takes point data from.
    n_rebases : int
    step_log : StepLog
    """

    def __init__(self, points, tets, rest_points=None, texcoords=None, labels=None, held=None):
        points = np.ascontiguousarray(points, np.float64)
        tets = np.ascontiguousarray(tets, np.int64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"points: shape {points.shape}, expected (n, 3)")
        if tets.ndim != 2 or tets.shape[1] != 4:
            raise InputError(f"tets: shape {tets.shape}, expected (m, 4)")
        n0, m0 = points.shape[0], tets.shape[0]
        held = np.zeros(n0, bool) if held is None else np.asarray(held, bool)
        if held.shape != (n0,):
            raise InputError(f"held: shape {held.shape}, expected ({n0},)")
        self._set_original(points, rest_points, texcoords, tets, labels, held)
        self.n_model_nodes, self.n_model_tets = n0, m0
        self.model_tet = np.arange(m0, dtype=np.int64)
        self.orig_made_by_cut = np.zeros(m0, bool)
        self.model_node = np.arange(n0, dtype=np.int64)
        self.n_rebases = 0

    @classmethod
    def from_model(cls, model) -> TissueStore:
        """The store of a :class:`~cutkit.model.tetmodel.TetModel` (rest = cut configuration; held: the
        nodes its boundary conditions fix or prescribe)."""
        return cls(model.points, model.tets, texcoords=model.texcoords, labels=model.labels,
                   held=model.boundary.held_mask(len(model.points)))

    def _set_original(self, points, rest_points, texcoords, tets, labels, held) -> None:
        """Make ``tets`` the original tets over the nodes ``points`` (every node an original one)."""
        n0, m0 = points.shape[0], tets.shape[0]
        self.n_orig_nodes = self.n_nodes = n0
        self.orig_tets = tets
        self.labels = np.zeros(m0, np.int32) if labels is None else np.asarray(labels, np.int32)
        self.edges, self.tet_edges = unique_edges(tets)
        topo = face_topology(tets)
        self.faces, self.tet_faces, self.face_tets, self.neighbors = (topo.faces, topo.tet_faces, topo.face_tets,
                                                                      topo.neighbors)
        self.boundary_faces, self.boundary_face_tet = topo.boundary_faces, topo.boundary_face_tet
        self.boundary_faces.flags.writeable = self.boundary_face_tet.flags.writeable = False
        cap = n0 + NODE_ROOM
        uvw = None if texcoords is None else _with_room(np.asarray(texcoords, np.float64), cap)
        X = points if rest_points is None else np.asarray(rest_points, np.float64)
        self.node_buffers = NodeBuffers(_with_room(points, cap), _with_room(X, cap), uvw,
                                        -np.ones((cap, 4), np.int64), np.zeros((cap, 4)), _with_room(held, cap))
        tcap = m0 + max(TET_ROOM_MIN, int(TET_ROOM_FRACTION * m0))
        self.tet_buffers = TetBuffers(_with_room(tets, tcap), _with_room(np.ones(m0, bool), tcap),
                                      _with_room(np.arange(m0, dtype=np.int64), tcap))
        self.n_tets_total = m0
        self.step_log = StepLog()

    # ------------------------------------------------------------------ views
    @property
    def n_orig_tets(self) -> int:
        return int(self.orig_tets.shape[0])

    @property
    def points(self) -> np.ndarray:
        """(n_nodes, 3) float64 positions in the cut's configuration (a view)."""
        return self.node_buffers.x[:self.n_nodes]

    @property
    def rest_points(self) -> np.ndarray:
        """(n_nodes, 3) float64 rest positions (a view)."""
        return self.node_buffers.X[:self.n_nodes]

    @property
    def texcoords(self) -> np.ndarray | None:
        """(n_nodes, 3) float64 texture coordinates (a view), or None."""
        uvw = self.node_buffers.uvw
        return None if uvw is None else uvw[:self.n_nodes]

    @property
    def held(self) -> np.ndarray:
        """(n_nodes,) bool nodes the boundary conditions hold (a view)."""
        return self.node_buffers.held[:self.n_nodes]

    @property
    def defining_nodes(self) -> np.ndarray:
        """(n_nodes, 4) int64 original nodes each node interpolates, -1 padded (a view)."""
        return self.node_buffers.parents[:self.n_nodes]

    @property
    def defining_weights(self) -> np.ndarray:
        """(n_nodes, 4) float64 the interpolation weights of :attr:`defining_nodes` (a view)."""
        return self.node_buffers.weights[:self.n_nodes]

    @property
    def tet_capacity(self) -> int:
        """Tet ids the arrays have room for before they grow (:data:`TET_ROOM_FRACTION`)."""
        return int(self.tet_buffers.corners.shape[0])

    @property
    def tet_corners(self) -> np.ndarray:
        """(n_tets_total, 4) int64 corners of every tet id, dead ones included (a view)."""
        return self.tet_buffers.corners[:self.n_tets_total]

    @property
    def tet_origins(self) -> np.ndarray:
        """(n_tets_total,) int64 original tet of every tet id, dead ones included (a view)."""
        return self.tet_buffers.origin[:self.n_tets_total]

    @property
    def tet_alive(self) -> np.ndarray:
        """(n_tets_total,) bool whether each tet id is alive (a view)."""
        return self.tet_buffers.alive[:self.n_tets_total]

    @property
    def tets(self) -> np.ndarray:
        """(k, 4) int64 alive tetrahedra (a copy)."""
        return self.tet_corners[self.tet_alive]

    @property
    def tet_origin(self) -> np.ndarray:
        """(k,) int64 original tet of each alive tet."""
        return self.tet_origins[self.tet_alive]

    def made_by_cut(self, ids) -> np.ndarray:
        """(k,) bool: whether each tet of ``ids`` (k,) int64 was made by a cut, in any stroke."""
        ids = np.asarray(ids, np.int64)
        return (ids >= self.n_orig_tets) | self.orig_made_by_cut[self.tet_buffers.origin[ids]]

    def node_model_source(self, nodes) -> np.ndarray:
        """(k,) int64 model node each of ``nodes`` (k,) int64 takes point data from.

        A node made since the last rebase takes its first defining (original)
        node's source; an original node its recorded one.
        """
        nodes = np.asarray(nodes, np.int64)
        first = np.where(nodes < self.n_orig_nodes, nodes, self.node_buffers.parents[nodes, 0])
        return self.model_node[first]

    # ------------------------------------------------------------------ writers: nodes
    def begin_step(self) -> None:
        """Start a new :attr:`step_log` (a cut step begins)."""
        self.step_log = StepLog()

    def reserve_nodes(self, k: int) -> None:
        """Make room for ``k`` more node rows past :attr:`n_nodes` (the arrays double as needed)."""
        while self.n_nodes + k > self.node_buffers.x.shape[0]:
            cap = 2 * self.node_buffers.x.shape[0]
            b = self.node_buffers
            self.node_buffers = NodeBuffers(_with_room(b.x, cap), _with_room(b.X, cap),
                                            None if b.uvw is None else _with_room(b.uvw, cap),
                                            _with_room(b.parents, cap, -1), _with_room(b.weights, cap),
                                            _with_room(b.held, cap))

    def add_node(self, nodes, w, lo=None) -> int:
        """A new node defined by weights ``w`` (k,) on original ``nodes`` (k,); returns its id.

        With ``lo`` the weights are first clamped to at least ``lo``
        (:func:`cutkit.mesh.geometry.clamp_bary`).  A node between held nodes
        only (a cut into a held tissue) is held.  Logged as an added node.
        """
        self.reserve_nodes(1)
        i = self.n_nodes
        self.n_nodes += 1
        self._place(i, nodes, w, lo)
        held = self.node_buffers.held
        held[i] = bool(held[np.asarray(nodes, np.int64)].all())
        self.step_log.added_nodes.append(i)
        return i

    def move_node(self, i, nodes, w, lo=None) -> None:
        """Define node ``i`` anew by weights ``w`` on original ``nodes`` (as :meth:`add_node`); logged as moved.

        The log keeps the rest position before the step's first move of the
        node: the physics maps the node's new place through the old shape of
        the tets around it.
        """
        moved_from = self.step_log.moved_from
        if i not in moved_from:
            moved_from[i] = self.node_buffers.X[i].copy()
        self._place(i, nodes, w, lo)
        self.step_log.moved_nodes.append(i)

    def move_nodes(self, ids, nodes, w, lo: float) -> None:
        """:meth:`move_node` of nodes ``ids`` (p,) int64 by weights ``w`` (p, k) float64 on original
        ``nodes`` (p, k) int64, each clamped to at least ``lo``, in one kernel call."""
        moved_from = self.step_log.moved_from
        b = self.node_buffers
        first = [i for i in ids.tolist() if i not in moved_from]
        moved_from.update(zip(first, b.X[first]))  # rows of a fresh array (fancy indexing copies)
        K.set_nodes_clamped(b.x, b.X, _NO_UVW if b.uvw is None else b.uvw, b.parents, b.weights,
                            np.ascontiguousarray(ids, np.int64), np.ascontiguousarray(nodes, np.int64),
                            np.ascontiguousarray(w, np.float64), float(lo))
        self.step_log.moved_nodes.extend(ids.tolist())

    def _place(self, i, nodes, w, lo) -> None:
        b = self.node_buffers
        uvw = _NO_UVW if b.uvw is None else b.uvw
        nodes, w = np.asarray(nodes, np.int64), np.asarray(w, np.float64)
        if lo is None:
            K.set_node(b.x, b.X, uvw, b.parents, b.weights, i, nodes, w)
        else:
            K.set_node_clamped(b.x, b.X, uvw, b.parents, b.weights, i, nodes, w, float(lo))

    def move_original_node(self, v, dx, dX, duvw=None) -> None:
        """Move original node ``v`` by ``dx`` (3,) in the cut's configuration, ``dX`` (3,) at rest and
        ``duvw`` (3,) in texture (or None); logged as moved."""
        b = self.node_buffers
        moved_from = self.step_log.moved_from
        if v not in moved_from:
            moved_from[v] = b.X[v].copy()
        b.x[v] += dx
        b.X[v] += dX
        if duvw is not None and b.uvw is not None:
            b.uvw[v] += duvw
        self.step_log.moved_nodes.append(v)

    # ------------------------------------------------------------------ writers: tets
    def add_tets(self, new, origin: int) -> list:
        """Append the tets ``new`` (list of 4-tuples) subdividing original tet ``origin``; returns their ids.

        The ids are contiguous.  Logged as added.
        """
        k = len(new)
        n0 = self.n_tets_total
        while n0 + k > self.tet_buffers.corners.shape[0]:
            cap = self.tet_buffers.corners.shape[0] * 2
            self.tet_buffers = TetBuffers(*(_with_room(a[:n0], cap) for a in self.tet_buffers))
        b = self.tet_buffers
        b.corners[n0:n0 + k] = new
        b.alive[n0:n0 + k] = True
        b.origin[n0:n0 + k] = origin
        self.n_tets_total = n0 + k
        ids = list(range(n0, n0 + k))
        self.step_log.added_tets.extend(ids)
        return ids

    def remove_tets(self, ids) -> None:
        """Mark the live tets ``ids`` (k,) int64 dead; logged as removed."""
        ids = np.asarray(ids, np.int64)
        self.tet_buffers.alive[ids] = False
        self.step_log.removed_tets.extend(ids.tolist())

    # ------------------------------------------------------------------ rebase
    def rebase(self) -> np.ndarray:
        """Make the live tets the original ones, in place (between strokes: no cut in progress).

        Every node becomes an original node (node ids unchanged); the live
        tets are renumbered in ascending order of their old ids.  The records
        (model tet, made by a cut, model node) follow.

        Returns
        -------
        old_ids : (k,) int64
            Old tet id of each new original tet.
        """
        n = self.n_nodes
        ids = np.flatnonzero(self.tet_alive)
        origin = self.tet_buffers.origin[ids]
        made = self.made_by_cut(ids)
        model_node = self.node_model_source(np.arange(n))
        model_tet = self.model_tet[origin]
        b = self.node_buffers
        self._set_original(b.x[:n].copy(), b.X[:n].copy(), None if b.uvw is None else b.uvw[:n].copy(),
                           self.tet_buffers.corners[ids], self.labels[origin], b.held[:n].copy())
        self.model_tet, self.orig_made_by_cut, self.model_node = model_tet, made, model_node
        self.n_rebases += 1
        return ids


def _with_room(a: np.ndarray, rows: int, fill=0) -> np.ndarray:
    """``a`` copied into the first rows of a new array of ``rows`` rows, the rest ``fill``."""
    out = np.full((rows,) + a.shape[1:], fill, a.dtype)
    out[:a.shape[0]] = a
    return out


__all__ = ["NODE_ROOM", "TET_ROOM_FRACTION", "TET_ROOM_MIN", "NodeBuffers", "StepLog", "TetBuffers",
           "TissueStore"]
