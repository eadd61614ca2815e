"""Kinematic cutting of a tetrahedral model: cut state and topology update.

``CutMesh`` holds the cut state that grows step by step (per-edge
intersection parameters, per-face nodes, per-original-tet tip nodes,
deferred edges) over a tissue store (:class:`cutkit.tissue.store.TissueStore`:
the original tetrahedra, their edges, faces and adjacency, the node and
tet arrays), which it changes only through the store's writers.  ``cut_step``
(in :mod:`cutkit.cutting.step`) moves the blade and calls
:meth:`CutMesh.resubdivide` on every original tetrahedron whose state
changed.

State machine of an original edge (Bielser et al. 2003 style, simplified):
UNCUT -> CUT at its first intersection parameter (clamped into
[EDGE_SNAP, 1 - EDGE_SNAP]); a cut edge never changes again, so blade
reversal and tremor cannot create new slivers.  A face is UNCUT, NOTCHED
(one cut edge: face node F on the crack front, moved with the blade while
it crosses the face), SPLIT (two cut edges: with centre nodes, F's node id
is reused as the lone-side centre node C and frozen) or, beyond the paper,
FORKED (three cut edges: a second cut crossing the first, or a swept
surface folded over the face; a centre node C with one copy per corner, the
cut a Y).  A tet's tip node T follows the tip while the tip is inside and
freezes after; it has one copy per piece of the tet.
"""

from __future__ import annotations

from operator import attrgetter

import numpy as np

from cutkit.errors import InputError
from cutkit.mesh.geometry import TET_EDGES, min_volume
from cutkit.mesh.topology import edge_to_tets
from cutkit.cutting import subdivision as S
from cutkit.cutting import _kernels_step as K
from cutkit.cutting.crumbs import init_crumbs
from cutkit.cutting.following import init_following
from cutkit.cutting.rebase import cut_twins, init_records, rebase, twin_face_bary
from cutkit.cutting.resubdivision import resubdivide
from cutkit.cutting.smoothing import init_smoothing
from cutkit.cutting.snapping import init_snapping
from cutkit.cutting.tolerances import EDGE_SNAP, FACE_BARY_MIN, TET_BARY_MIN, clamp_bary
from cutkit.tissue.store import TissueStore


_TET_EDGES_L = TET_EDGES.tolist()


def _vol(x, t):
    """Signed volume of the tet t (4,) over positions x (n, 3)."""
    return float(min_volume(x, np.asarray(t, np.int64).reshape(1, 4)))


_clamp_bary = clamp_bary


def _from_store(name: str, doc: str) -> property:
    """A read-only attribute of :class:`CutMesh` that is its store's ``name`` (looked up in C: the cut
    step reads these hundreds of times)."""
    return property(attrgetter(f"store.{name}"), doc=doc)


def _store_buffer(group: str, name: str) -> property:
    """A read-only attribute of :class:`CutMesh` that is one of its store's buffers (spare rows included)."""
    return property(attrgetter(f"store.{group}.{name}"), doc=f"the store's ``{group}.{name}``")


class CutMesh:
    """A tetrahedral model being cut: the cut state over a :class:`~cutkit.tissue.store.TissueStore`.

    ``CutMesh(points, tets, ...)`` makes a store of its own;
    :meth:`over` cuts a store a session shares with its physics.

    Parameters
    ----------
    points : (n, 3) float64  current positions of the original nodes, mm
    tets : (m, 4) int64  positively oriented
    rest_points : (n, 3) float64, optional  rest positions (default: points)
    texcoords : (n, 3) float64, optional
    labels : (m,) int32, optional
    blade_length : float  mm
    centre_nodes : bool  use the Fig. 2c centre node in split faces (default False: fewer, better tets)
    compact_splits : bool  cone complete splits to a vertex per side (see _compact_split)
    fair_nodes : bool  re-place cut nodes around slivers within their simplex after each step (:mod:`.fairing`)
    snap_vertices : bool  move an uncut vertex away from the cut before an edge is cut near it (:mod:`.snapping`)
    smooth_vertices : bool  move a vertex of a sliver's original tet where that lifts it, after fairing
        (:mod:`.smoothing`; the element tissue takes moved vertices, the paper's springs do not)
    follow_wounds : bool  a blade inside an earlier stroke's wound follows its walls instead of slicing
        them (:mod:`.following`)
    """

    # What the cut reads of its tissue store that a step changes, under the cut's names (the store's
    # arrays and counts: one truth; the original tets' topology is bound in _cut_over).
    n_points = _from_store("n_nodes", "int nodes so far")
    n_tets_total = _from_store("n_tets_total", "int tet ids so far")
    points = _from_store("points", "(n, 3) float64 positions in the cut's configuration (a view)")
    rest_points = _from_store("rest_points", "(n, 3) float64 rest positions (a view)")
    texcoords = _from_store("texcoords", "(n, 3) float64 texture coordinates (a view) or None")
    tets = _from_store("tets", "(k, 4) int64 alive tetrahedra (a copy)")
    tet_origin = _from_store("tet_origin", "(k,) int64 original tet of each alive tet")
    tet_capacity = _from_store("tet_capacity", "tet ids the arrays have room for before they grow")
    tet_corners = _from_store("tet_corners", "(n_tets_total, 4) int64 (a view)")
    tet_origins = _from_store("tet_origins", "(n_tets_total,) int64 (a view)")
    tet_alive = _from_store("tet_alive", "(n_tets_total,) bool (a view)")
    defining_nodes = _from_store("defining_nodes", "(n, 4) int64 (a view)")
    defining_weights = _from_store("defining_weights", "(n, 4) float64 (a view)")
    n_model_points = _from_store("n_model_nodes", "int nodes of the model as loaded")
    n_model_tets = _from_store("n_model_tets", "int tets of the model as loaded")
    model_tet = _from_store("model_tet", "(m0,) int64 model tet of each original tet")
    orig_made_by_cut = _from_store("orig_made_by_cut", "(m0,) bool original tets made by earlier strokes")
    model_node = _from_store("model_node", "(n0,) int64 model node each original node takes point data from")
    n_rebases = _from_store("n_rebases", "int")
    _x = _store_buffer("node_buffers", "x")
    _X = _store_buffer("node_buffers", "X")
    _uvw = _store_buffer("node_buffers", "uvw")
    _def_nodes = _store_buffer("node_buffers", "parents")
    _def_w = _store_buffer("node_buffers", "weights")
    _tets = _store_buffer("tet_buffers", "corners")
    _alive = _store_buffer("tet_buffers", "alive")
    _tet_orig = _store_buffer("tet_buffers", "origin")

    def __init__(self, points, tets, rest_points=None, texcoords=None, labels=None,
                 blade_length=20.0, centre_nodes=False, compact_splits=True, snap_vertices=False, fair_nodes=True,
                 smooth_vertices=True, follow_wounds=True):
        store = TissueStore(points, tets, rest_points=rest_points, texcoords=texcoords, labels=labels)
        self._cut_over(store, blade_length, centre_nodes, compact_splits, snap_vertices, fair_nodes, smooth_vertices,
                       follow_wounds)

    @classmethod
    def over(cls, store: TissueStore, blade_length=20.0, centre_nodes=False, compact_splits=True,
             snap_vertices=False, fair_nodes=True, smooth_vertices=True, follow_wounds=True) -> CutMesh:
        """The cut state of the tissue ``store`` (nothing cut since its last rebase); cuts write into it."""
        cm = cls.__new__(cls)
        cm._cut_over(store, blade_length, centre_nodes, compact_splits, snap_vertices, fair_nodes, smooth_vertices,
                     follow_wounds)
        return cm

    def _cut_over(self, store, blade_length, centre_nodes, compact_splits, snap_vertices, fair_nodes, smooth_vertices,
                  follow_wounds):
        if not blade_length > 0:
            raise InputError(f"blade_length: {blade_length}, expected > 0")
        self.store = store
        # the store's topology of its original tets: the same arrays, read here at every step; they change
        # only at a rebase, which makes the cut state anew over the renumbered store
        self.orig_tets, self.labels, self.n_orig_points = store.orig_tets, store.labels, store.n_orig_nodes
        self.edges, self.tet_edges = store.edges, store.tet_edges
        self.faces, self.tet_faces, self.face_tets, self.neighbors = (store.faces, store.tet_faces, store.face_tets,
                                                                      store.neighbors)
        self.orig_boundary_faces, self.orig_boundary_face_tet = store.boundary_faces, store.boundary_face_tet
        self.blade_length = float(blade_length)
        self.centre_nodes = bool(centre_nodes)
        self.compact_splits = bool(compact_splits)
        self.fair_nodes = bool(fair_nodes)
        self.fair_pending = {}  # nodes the blade held at the last step: key -> original tet (fairing.py)
        self.fair_origin = {}  # faired node -> (weights where the cut put it, weights fairing gave it)
        m0 = store.n_orig_tets
        # edge -> tets ring (CSR), built once
        self.edge_tet_off, self.edge_tet_idx = edge_to_tets(self.tet_edges, self.edges.shape[0])
        # face -> its 3 global edges
        self.face_edges = np.zeros((self.faces.shape[0], 3), np.int64)
        self.face_edges[self.tet_faces.ravel()] = self.tet_edges[:, S.FACE_EDGES].reshape(-1, 3)
        self._sweep_buf = None  # work buffers of the local traversal (sweep_buffers)
        self.subtets = {}  # original tet -> list of current tet ids (only for cut tets)
        # ---- cut state
        self.edge_t = np.full(self.edges.shape[0], np.nan)
        self.edge_node = -np.ones((self.edges.shape[0], 2), np.int64)
        # F, or the copies of C: per side (lone, pair) of a split face, per vertex (in faces[f]'s order) of a forked one
        self.face_node = -np.ones((self.faces.shape[0], 3), np.int64)
        self.face_ncut = np.zeros(self.faces.shape[0], np.int64)  # cut edges per face (kept by try_cut_edge)
        self.face_diag = -np.ones(self.faces.shape[0], np.int64)  # split face: its quad's diagonal vertex (splits.py)
        self.pending_edges = {}  # edge -> first parameter, deferred (see try_cut_edge)
        self.retried_edges = []  # deferred edges cut later (drained by cut_step)
        self.refused_edges = set()  # edges the blade met and could not cut (see edges_left_uncut)
        self.face_bary = {}  # face -> (3,) bary of the latest blade crossing
        self.tip_bary = {}  # original tet -> (4,) tip bary while inside
        self.tet_T = -np.ones((m0, 4), np.int64)  # T's copies, one per piece
        self.stamp = np.zeros(m0, np.int64)  # visited stamps (no per-step reset)
        self.step_count = 0
        self.active_tets = np.zeros(0, np.int64)
        self.previous_active_tets = np.zeros(0, np.int64)
        self.tip_tet = -1
        self.prev_pose = None
        self.started_inside = False  # the blade's first pose lay inside the tissue (cut_step)
        init_records(self)  # what outlives a rebase (model counts, earlier strokes' cut surface)
        init_crumbs(self)  # pieces cut loose below CRUMB_VOLUME_FRACTION of the model are removed
        init_snapping(self, snap_vertices)  # vertices moved away from the cut instead of slivers
        init_smoothing(self, smooth_vertices)  # vertices moved where a sliver is left after fairing
        init_following(self, follow_wounds)  # a blade inside an earlier cut's wound follows its walls

    @classmethod
    def from_model(cls, model, blade_length=20.0, centre_nodes=False, compact_splits=True, snap_vertices=False,
                   fair_nodes=True, smooth_vertices=True, follow_wounds=True):
        """Cut state of a :class:`~cutkit.model.tetmodel.TetModel` (rest = current positions)."""
        return cls(model.points, model.tets, texcoords=model.texcoords, labels=model.labels,
                   blade_length=blade_length, centre_nodes=centre_nodes, compact_splits=compact_splits,
                   snap_vertices=snap_vertices, fair_nodes=fair_nodes, smooth_vertices=smooth_vertices,
                   follow_wounds=follow_wounds)

    def rebase(self):
        """Make the live tets the original ones of a fresh cut state (blade out); see :func:`.rebase.rebase`.

        Returns
        -------
        old_ids : (k,) int64  old tet id of each new original tet (node ids unchanged)
        """
        return rebase(self)

    # ------------------------------------------------------------------ nodes (written through the store)
    def _new_node(self, nodes, w, lo=None):
        return self.store.add_node(nodes, w, lo)

    def _move_node(self, i, nodes, w, lo=None):
        self.store.move_node(i, nodes, w, lo)

    def move_original_node(self, v, dx, dX, duvw=None):
        """Move original node ``v`` by ``dx`` (3,) current, ``dX`` (3,) rest, ``duvw`` (3,) texture (or None).

        Recorded as a moved node of the step (:mod:`.snapping`: a vertex moved away from the cut).
        """
        self.store.move_original_node(v, dx, dX, duvw)

    def reinterpolate_node(self, i, nodes, w):
        """Place cut node ``i`` again by its weights ``w`` (k,) on original ``nodes`` (k,) (one moved)."""
        self._move_node(i, nodes, w)

    # ------------------------------------------------------------------ cut state
    def edge_ring(self, e):
        return self.edge_tet_idx[self.edge_tet_off[e]:self.edge_tet_off[e + 1]]

    def face_cut_count(self, f):
        """Number of cut edges of global face f (0 to 3)."""
        return int(self.face_ncut[f])

    def faces_of_edge(self, e):
        """Set of the global faces around global edge e."""
        out = set()
        for t in self.edge_ring(e).tolist():
            k = self.tet_edges[t].tolist().index(e)
            i, j = _TET_EDGES_L[k]
            for lf in range(4):
                if lf != i and lf != j:
                    out.add(int(self.tet_faces[t, lf]))
        return out

    def _splits_a_sheet(self, e):
        """Whether cutting edge e would leave some tet of its ring with two opposite cut edges only.

        Such a tet (mask {01, 23}, {02, 13} or {03, 12}) has all four faces
        notched and its single crack-front node T would join two crack
        sheets at one point: a non-manifold boundary vertex.
        """
        for t in self.edge_ring(e).tolist():
            k = self.tet_edges[t].tolist().index(e)
            if self.tet_mask(t) | (1 << k) in S.OPPOSITE_MASKS:
                return True
        return False

    def try_cut_edge(self, e, s):
        """Cut global edge ``e`` at parameter ``s`` (from edges[e,0]); returns touched tets.

        Nothing is done (an empty list returned) when it is cut already: an
        edge is cut once, at its first crossing.  Deferred (kept in
        ``pending_edges`` and an empty list returned) when the cut would give a
        tet two opposite cut edges only (see :meth:`_splits_a_sheet`); a
        deferred edge is cut as soon as an edge cut linking the two sheets
        is made in one of its tets.  A face may get a third cut edge (a
        forked face: a second cut crossing the first, or a folded sweep).
        """
        if np.isfinite(self.edge_t[e]):
            return []
        if int(e) in self.edge_twins:  # a copy along an earlier cut (after a rebase): cut all alike
            return cut_twins(self, int(e), float(s), self.edge_twins[int(e)])
        if self._splits_a_sheet(e):
            self.pending_edges.setdefault(int(e), float(s))
            return []
        self.pending_edges.pop(int(e), None)
        touched = self._cut_edge(e, s)
        self._retry_pending(touched)
        return touched

    def edges_left_uncut(self):
        """Edges the blade met and the cut left uncut, over every stroke so far (int).

        An edge is left uncut when it is still deferred (two opposite cut
        edges alone in a tet) where the blade stopped, or when it has
        coincident copies along an earlier stroke's cut and one of them was
        cut already at another point (:func:`.rebase.cut_twins`).  Edges met
        on their boundary (at an end) count too.  Such an edge stays joined:
        a thin bridge across the wound.
        """
        mine = self.refused_edges.union(self.pending_edges)
        return self.uncut_before + sum(1 for e in mine if not np.isfinite(self.edge_t[e]))

    def edges_followed(self):
        """Crossings the blade made inside an earlier stroke's wound and followed instead of cutting (int,
        every stroke so far; :mod:`.following`).  Not edges left uncut: the wound parts the tissue there."""
        return self.followed_before + len(self.followed_edges)

    def uncut_edge_places(self):
        """(k, 3) float64 rest midpoints, mm, of the edges :meth:`edges_left_uncut` counts (every stroke's)."""
        mine = sorted(e for e in self.refused_edges.union(self.pending_edges) if not np.isfinite(self.edge_t[e]))
        here = self._X[self.edges[mine]].mean(axis=1) if mine else np.zeros((0, 3))
        return np.vstack([self.uncut_places_before, here])

    def _retry_pending(self, touched):
        """Cut the deferred edges of the tets in ``touched`` (list, extended in place) that are now allowed."""
        if not self.pending_edges:
            return
        todo = list(dict.fromkeys(touched))
        seen = set(todo)
        while todo:
            t = todo.pop()
            for e in self.tet_edges[t].tolist():
                if e not in self.pending_edges or np.isfinite(self.edge_t[e]):
                    continue
                if e in self.edge_twins:  # re-deferred by cut_twins while still not allowed
                    more = cut_twins(self, e, self.pending_edges.pop(e), self.edge_twins[e])
                    self.retried_edges.extend([e] if more else [])
                    todo.extend(u for u in more if u not in seen)
                    seen.update(more)
                    touched.extend(more)
                    continue
                if self._splits_a_sheet(e):
                    continue
                more = self._cut_edge(e, self.pending_edges.pop(e))
                self.retried_edges.append(e)
                for u in more:
                    if u not in seen:
                        seen.add(u)
                        touched.append(u)
                        todo.append(u)

    def _cut_edge(self, e, s):
        """Make the cut of edge e at parameter s (checks done); returns the tets of its ring."""
        faces = self.faces_of_edge(e)
        s = min(max(float(s), EDGE_SNAP), 1.0 - EDGE_SNAP)
        self.edge_t[e] = s
        for f in faces:
            self.face_ncut[f] += 1
        a, b = self.edges[e]
        for c in range(2):
            self.edge_node[e, c] = self._new_node([a, b], [1 - s, s])
        for f in faces:
            self._update_face_node(f)
        return self.edge_ring(e).tolist()

    def _edge_bary_on_face(self, e, fv, b, weight):
        """Add ``weight`` x the edge node of cut edge e to the face bary b (3,) over vertices fv (list)."""
        a_, b_ = self.edges[e].tolist()
        s = float(self.edge_t[e])
        b[fv.index(a_)] += weight * (1 - s)
        b[fv.index(b_)] += weight * s
        return a_, b_

    def _update_face_node(self, f):
        """Create or move the node(s) of global face f after its cut state or crossing changed."""
        n = self.face_cut_count(f)
        if n == 1:  # the notch node F: where the blade crossed the face
            b = self.face_bary.get(f)
            if b is None:
                # default crack tip: halfway from the edge node to the opposite vertex
                fv = self.faces[f].tolist()
                e = next(e for e in self.face_edges[f].tolist() if self.edge_t[e] == self.edge_t[e])
                b = [0.0, 0.0, 0.0]
                a_, b_ = self._edge_bary_on_face(e, fv, b, 0.5)
                opp = [i for i in range(3) if fv[i] != a_ and fv[i] != b_][0]
                b[opp] += 0.5
            i = int(self.face_node[f, 0])
            if i < 0:
                self.face_node[f, 0] = self._new_node(self.faces[f], b, FACE_BARY_MIN)
            else:
                self._move_node(i, self.faces[f], b, FACE_BARY_MIN)
        elif n == 3:
            self._fork_face(f)
        elif n == 2 and self.centre_nodes:
            # centre node C on the cut line: midpoint of the two edge nodes (Fig. 2c)
            fv = self.faces[f].tolist()
            b = [0.0, 0.0, 0.0]
            for e in self.face_edges[f].tolist():
                if self.edge_t[e] == self.edge_t[e]:  # cut (not NaN)
                    self._edge_bary_on_face(e, fv, b, 0.5)
            b = _clamp_bary(b, 1e-3)  # already interior: edge params are snapped
            if self.face_node[f, 0] < 0:
                self.face_node[f, 0] = self._new_node(fv, b)
            else:
                self._move_node(self.face_node[f, 0], fv, b)
            if self.face_node[f, 1] < 0:
                self.face_node[f, 1] = self._new_node(fv, b)

    def _fork_face(self, f):
        """Place the copies of the centre node C of a face with three cut edges (one per vertex).

        C goes to the mean of the three edge nodes (inside the triangle they
        make, so each corner's quad is star-shaped from the corner), clamped
        like F.  Node ids made before (F, or the copies of a split face's C)
        are reused and moved.
        """
        fv = self.faces[f].tolist()
        b = [0.0, 0.0, 0.0]
        for e in self.face_edges[f].tolist():
            self._edge_bary_on_face(e, fv, b, 1.0 / 3.0)
        for c in range(3):
            i = int(self.face_node[f, c])
            if i < 0:
                self.face_node[f, c] = self._new_node(fv, b, FACE_BARY_MIN)
            else:
                self._move_node(i, fv, b, FACE_BARY_MIN)

    def set_face_crossing(self, f, bary):
        """Record where the blade crosses face ``f`` (and its copies along an earlier cut); moves notch nodes F."""
        for g in self.face_twins.get(int(f), ()):
            self._set_face_crossing(g, twin_face_bary(self, int(f), g, bary))
        return self._set_face_crossing(f, bary)

    def set_face_crossings(self, faces, bary):
        """:meth:`set_face_crossing` of faces ``faces`` (k,) int64 at ``bary`` (k, 3) float64, in order (a
        face crossed twice keeps the later crossing); each notch node F is moved once."""
        fl = faces.tolist()
        bary = np.array(bary, np.float64)  # own rows: the sweep's event buffer is used again
        if self.face_twins and not self.face_twins.keys().isdisjoint(fl):
            for f, b in zip(fl, bary):  # copies along an earlier cut: one crossing after the other
                self.set_face_crossing(f, b)
            return
        self.face_bary.update(zip(fl, bary))
        notched = np.array(list(dict.fromkeys(faces[self.face_ncut[faces] == 1].tolist())), np.int64)
        node = self.face_node[notched, 0]
        for f in notched[node < 0].tolist():  # none yet: made as the edge cut makes it
            self._update_face_node(f)
        notched = notched[node >= 0]
        if notched.size:  # each notch node F to its face's latest crossing (_update_face_node)
            self.store.move_nodes(self.face_node[notched, 0], self.faces[notched],
                                  np.array([self.face_bary[f] for f in notched.tolist()]), FACE_BARY_MIN)

    def _set_face_crossing(self, f, bary):
        self.face_bary[f] = np.asarray(bary, np.float64)
        if self.face_ncut[f] == 1:
            self._update_face_node(f)
            return True
        return False

    def move_tip_node(self, o):
        """Move the T node(s) of a cut tet to its recorded tip (no topology change)."""
        if self.tet_T[o, 0] < 0 or o not in self.tip_bary:
            return
        for c in range(self.tet_T.shape[1]):
            if self.tet_T[o, c] >= 0:
                self._move_node(self.tet_T[o, c], self.orig_tets[o], self.tip_bary[o], TET_BARY_MIN)

    # ------------------------------------------------------------------ subdivision
    def tet_mask(self, o):
        """6-bit mask of the cut edges of original tet o (bit k = local edge TET_EDGES[k])."""
        return int(K.tet_mask(self.tet_edges, self.edge_t, o))

    def completely_split(self, o):
        """Whether original tet ``o``'s cut edges split it in two (Fig. 3 corner or quad; not a general tet)."""
        return S.CLASSIFY_TABLE[S.REDUCE_TABLE[self.tet_mask(o)]][0] in ("corner", "quad")

    def cut_tables(self):
        """The cut state as the step kernels read it (``_kernels_step.CutTables``; views, no copy)."""
        return K.CutTables(self.orig_tets, self.tet_edges, self.tet_faces, self.edges, self.edge_t, self.edge_node,
                           self.face_node, self.face_ncut, self._def_nodes, self._def_w, self.face_diag,
                           self.node_rep)

    def resubdivide(self, o):
        """Re-subdivide original tet ``o`` from scratch from its cut state (:func:`.resubdivision.resubdivide`)."""
        resubdivide(self, o)

    def _vol0(self, o):
        """Signed volume of original tet o at the current positions."""
        return _vol(self._x, self.orig_tets[o])

    def remove_tets(self, ids):
        """Take the live tets ``ids`` (k,) int64 out of the mesh (listed in the step's ``removed_tets``).

        Their original tets keep their cut state; a later re-subdivision of
        one of them makes its sub-tets again (crumbs: :mod:`.crumbs`).
        """
        self.store.remove_tets(ids)

    def sweep_buffers(self) -> dict:
        """The work buffers of the local traversal (``step._sweep``), made on first use and kept.

        Returns
        -------
        dict
            ``stack`` (s,) int64, ``active`` (k,) int64, ``ev_id`` (q, 2) int64, ``ev_val``
            (q, 3) float64, ``counts`` (3,) int64; the caller may replace a short one by a
            longer one in the dict.
        """
        if self._sweep_buf is None:
            self._sweep_buf = {"stack": np.empty(256, np.int64), "active": np.empty(64, np.int64),
                               "ev_id": np.empty((128, 2), np.int64), "ev_val": np.empty((128, 3)),
                               "counts": np.zeros(3, np.int64)}
        return self._sweep_buf
