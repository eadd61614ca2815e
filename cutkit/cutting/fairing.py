"""Fairing: cut nodes re-placed inside their own simplex where a cut-made tetrahedron is a sliver.

A cut node lies on an original edge (edge node E), in an original face
(notch or centre node F) or inside an original tetrahedron (T).  Where the
cut puts it (the blade's crossing, clamped by the snap limits of
:mod:`cutkit.cutting.tolerances`) a tilted blade near a vertex leaves
slivers around it (docs/cutting.md, "Angles").  After a step's
re-subdivision each such node with a tetrahedron around it below
:data:`FAIR_BELOW_DEG` is moved, with its coincident copies (the two sides
of the cut), within its simplex to where the smallest dihedral angle of the
tetrahedra around it is largest (``_kernels_fair.fair_place``, a compass
search over its weights): the cut-surface smoothing of Steinemann et al.
(2006, "Hybrid cutting of deformable solids") applied to the cut's own
nodes rather than to mesh vertices, so no vertex is moved and the
representation (one node pair per edge) stays.

What a move keeps:

* every weight stays within :data:`FAIR_MOVE_MAX` of where the cut put it
  and at least the snap limit (``EDGE_SNAP``, ``FACE_BARY_MIN``,
  ``TET_BARY_MIN``), so the cut surface is at most ``FAIR_MOVE_MAX`` of
  the simplex's size off the crossing the cut made;
* a T node moves only within the plane of its tetrahedron's other cut
  nodes (its edge and face nodes, :func:`_cut_plane`): the cut surface a
  flat blade made stays flat through it;
* the node stays in its simplex, all copies together: the mesh stays
  conforming, the original faces and edges are the same point sets, so the
  model's volume and outer surface do not change (an edge or face node on
  the surface moves within the surface's own flat triangle);
* every tetrahedron around it stays positive, and its smallest angle only
  rises.

Nodes the blade places this step (the tip tet's T, the notch nodes of the
faces the blade crossed) are left where they are, and so is a split face's
centre node (``CutMesh(centre_nodes=True)``, the midpoint of its cut line); a node on an edge or face
with coincident copies along an earlier stroke's cut moves with them.  A moved node is a moved node of the step
(``StepResult.moved_nodes``), as a moving crack front's: the physics places
it through the old shape.
"""

from __future__ import annotations

import numpy as np

from cutkit.cutting import _kernels_fair as KF
from cutkit.cutting.tolerances import EDGE_SNAP, FACE_BARY_MIN, TET_BARY_MIN

#: A cut node is re-placed when a live tetrahedron around it has a smallest dihedral angle below this (degrees).
FAIR_BELOW_DEG = 12.0
#: No weight of a re-placed node moves more than this from where the cut put it (a fraction of its
#: edge, face or tet: the cut surface stays that close to the blade's crossing).
FAIR_MOVE_MAX = 0.2
#: Where the first round leaves a sub-tet below this (degrees) in the original tets around the
#: nodes it moved, a second round looks at the poor sub-tets there that hold a moved node (0: never).
FAIR_AGAIN_BELOW_DEG = 6.0
#: Steps of the compass search over the weights, largest first.
FAIR_STEPS = np.array([0.08, 0.04, 0.02, 0.01])
#: A node moves only when its smallest angle rises by at least this (degrees): a move costs the
#: physics a re-placement.
FAIR_MIN_GAIN_DEG = 0.5
#: The smallest weight by simplex size (2: edge, 3: face, 4: tet): the cut's snap limits.
_LO = {2: EDGE_SNAP, 3: FACE_BARY_MIN, 4: TET_BARY_MIN}
#: The compass moves of k weights: one weight up, another down (i != j, in that order).
_MOVES = {k: np.array([np.eye(k)[i] - np.eye(k)[j] for i in range(k) for j in range(k) if i != j]) for k in (2, 3, 4)}


def fair_cut_nodes(cm, originals, held) -> int:
    """Re-place the cut nodes of ``originals`` that have a sliver around them; returns how many moved.

    The live sub-tets of ``originals`` below :data:`FAIR_BELOW_DEG` name the
    nodes to look at (their cut nodes, each with its copies).  Such a node
    the blade held is looked at again at the next step (``cm.fair_pending``:
    its key and original tet): the blade moves on, or the stroke ends.  Where
    the moves leave a sub-tet below :data:`FAIR_AGAIN_BELOW_DEG` in the
    originals around them, the nodes of the poor sub-tets that hold a moved
    node are looked at once more (a second round, same rule).

    Parameters
    ----------
    cm : CutMesh
    originals : set of int
        Original tets re-subdivided by the step.
    held : set of int
        Nodes the blade placed this step: left where they are (and their copies).
    """
    mesh = KF.FairMesh(cm._x, cm._tets, cm._alive, cm.sub_start, cm.sub_count)
    groups, cm.fair_pending = _poor_groups(cm, mesh, originals, held, cm.fair_pending, FAIR_BELOW_DEG)
    moved = [group for group in groups if _fair_group(cm, mesh, *group)]
    if not moved or FAIR_AGAIN_BELOW_DEG <= 0.0:
        return len(moved)
    # a move changes its neighbours' best places (and theirs its): where a sliver is left around
    # the moves, the nodes of the poor sub-tets at a moved node are looked at once more
    around = set(np.concatenate([group[1] for group in moved]).tolist())
    if not KF.poor_tets(mesh, np.array(sorted(around), np.int64), FAIR_AGAIN_BELOW_DEG)[0].size:
        return len(moved)
    near = np.concatenate([group[0] for group in moved])
    groups, pending = _poor_groups(cm, mesh, around, held, {}, FAIR_BELOW_DEG, near)
    cm.fair_pending.update(pending)
    return len(moved) + sum(_fair_group(cm, mesh, *group) for group in groups)


def _poor_groups(cm, mesh, fresh, held, again, below, near=None):
    """The cut nodes of the live sub-tets below ``below`` (degrees) of the originals ``fresh`` (set)
    and of those an earlier step held (``again``: key -> original tet, only the nodes held), each
    once, with its coincident copies (the two sides of the cut; on an edge or face with copies along
    an earlier stroke's cut (``edge_twins``, ``face_twins``), theirs too: they must stay coincident).
    ``near`` (q,) int64 nodes, or None: only the sub-tets with a corner among them count.

    Returns
    -------
    groups : list of (copies (c,) int64, originals around (a,) int64, cut edges (list), plane)
        ``plane``: a T node's original tet (its moves keep it in :func:`_cut_plane`), else None.
    pending : dict
        The nodes the blade holds (one of ``held``) by key, with their original tet.
    """
    originals = sorted(fresh | set(again.values()))
    tets, owner = KF.poor_tets(mesh, np.array(originals, np.int64), below)
    corners = cm._tets[tets]
    if near is not None:  # only the poor tets at a node moved since they were looked at
        keep = np.isin(corners, near).any(axis=1)
        corners, owner = corners[keep], owner[keep]
    nodes = corners.ravel()
    nodes = set(nodes[nodes >= cm.n_orig_points].tolist())
    seen, out, pending = set(), [], {}

    def wanted(key, o):  # not looked at in this step yet, nor by an earlier step (unless held then)
        return key not in seen and (o in fresh or key in again)

    def add(key, o, members, copies, around, edges=(), plane=None):
        seen.update(members)
        copies = np.concatenate(copies) if len(copies) > 1 else copies[0]
        copies = copies[copies >= 0]
        if held.intersection(copies.tolist()):
            pending[key] = o
            return
        around = np.concatenate(around) if len(around) > 1 else around[0]
        out.append((copies, np.ascontiguousarray(around[around >= 0]), list(edges), plane))

    for o in np.unique(owner).tolist():
        for e in cm.tet_edges[o].tolist():
            a, b = cm.edge_node[e].tolist()
            if (a in nodes or b in nodes) and wanted(("e", e), o):
                edges = [e] + list(cm.edge_twins.get(e, ()))
                add(("e", e), o, [("e", g) for g in edges], [cm.edge_node[g] for g in edges],
                    [cm.edge_ring(g) for g in edges], edges)
        for f in cm.tet_faces[o].tolist():
            # a split face's centre node (``centre_nodes``) stays: it is the midpoint of the cut line
            if cm.face_ncut[f] != 2 and not nodes.isdisjoint(cm.face_node[f].tolist()) and wanted(("f", f), o):
                faces = [f] + list(cm.face_twins.get(f, ()))
                add(("f", f), o, [("f", g) for g in faces], [cm.face_node[g] for g in faces],
                    [cm.face_tets[g] for g in faces])
        if not nodes.isdisjoint(cm.tet_T[o].tolist()) and wanted(("t", o), o):
            add(("t", o), o, [("t", o)], [cm.tet_T[o]], [np.array([o], np.int64)], plane=o)
    return out, pending


def _cut_plane(cm, o):
    """(3,) unit normal of the plane through original tet ``o``'s cut nodes (its edge and face nodes), or
    None when they are fewer than three."""
    e = cm.tet_edges[o]
    nodes = [cm.edge_node[e[np.isfinite(cm.edge_t[e])], 0], cm.face_node[cm.tet_faces[o], 0]]
    nodes = np.concatenate(nodes)
    nodes = nodes[nodes >= 0]
    if nodes.size < 3:
        return None
    p = cm._x[nodes]
    return np.linalg.svd(p - p.mean(axis=0))[2][2]


def _plane_moves(x_corners, normal):
    """(8, 4) moves of a T node's four weights that keep it in the plane with ``normal`` (3,): the
    weight directions d with sum(d) = 0 and d . (x_corners @ normal) = 0, each scaled to a largest
    entry of 1, both ways, and their diagonals."""
    basis = np.linalg.svd(np.vstack([np.ones(4), x_corners @ normal]))[2][2:]
    d = np.vstack([basis, basis[0] + basis[1], basis[0] - basis[1]])
    d /= np.abs(d).max(axis=1, keepdims=True)
    return np.vstack([d, -d])


def _fair_group(cm, mesh, copies, around, edges, plane) -> int:
    """Re-place one node and its copies where the search gains; returns 1 if it moved."""
    node = int(copies[0])
    k = int((cm._def_nodes[node] >= 0).sum())
    corners, w0 = cm._def_nodes[node, :k].copy(), cm._def_w[node, :k].copy()  # copies: moving rewrites the rows
    # the box is around where the cut put the node: its weights before its first fairing, unless
    # the cut has placed it again since (its weights are not those the last fairing gave it)
    cut_at, faired_to = cm.fair_origin.get(node, (w0, None))
    w_cut = cut_at if faired_to is not None and np.array_equal(faired_to, w0) else w0
    limits = np.array([_LO[k], FAIR_MOVE_MAX, FAIR_BELOW_DEG])
    normal = None if plane is None else _cut_plane(cm, plane)
    moves = _MOVES[k] if normal is None else _plane_moves(cm._x[corners], normal)
    w, angle, start = KF.fair_place(mesh, around, copies, corners, w0, w_cut, limits, FAIR_STEPS, moves)
    if not angle >= start + FAIR_MIN_GAIN_DEG:
        return 0
    cm.fair_origin[node] = (w_cut, w.copy())
    # a copy along an earlier cut is defined on coincident copies of the corners (equal node_rep)
    weight_of = dict(zip(cm.node_rep[corners].tolist(), w.tolist()))
    for c in copies.tolist():
        parents = cm._def_nodes[c, :k].copy()
        cm._move_node(c, parents, np.array([weight_of[r] for r in cm.node_rep[parents].tolist()]))
    for e in edges:  # the edge's cut parameter follows its node (read by the face and T placements)
        cm.edge_t[e] = weight_of[int(cm.node_rep[cm.edges[e, 1]])]
    return 1


def load_fair_kernels() -> float:
    """Load (or compile) the fairing's kernels with the argument types a cut step passes, on one unit
    tetrahedron with a node inside it; a live session calls it before its clock starts (the warm-up's
    short cut may make no sliver to fair).  Returns the search's smallest angle, degrees."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.25, 0.25, 0.25]])
    tets = np.array([[4, 1, 2, 3], [0, 4, 2, 3], [0, 1, 4, 3], [0, 1, 2, 4]], np.int64)
    mesh = KF.FairMesh(x, tets, np.ones(4, bool), np.zeros(1, np.int64), np.array([4], np.int64))
    KF.poor_tets(mesh, np.zeros(1, np.int64), FAIR_BELOW_DEG)
    w0 = np.full(4, 0.25)
    limits = np.array([_LO[4], FAIR_MOVE_MAX, np.inf])
    _, angle, _ = KF.fair_place(mesh, np.zeros(1, np.int64), np.array([4], np.int64), np.arange(4, dtype=np.int64),
                                w0, w0.copy(), limits, FAIR_STEPS, _MOVES[4])
    return float(angle)
