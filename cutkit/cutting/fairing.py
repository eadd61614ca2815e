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
* the node stays in its simplex, all copies together: the mesh stays
  conforming, the original faces and edges are the same point sets, so the
  model's volume and outer surface do not change (an edge or face node on
  the surface moves within the surface's own flat triangle);
* every tetrahedron around it stays positive, and its smallest angle only
  rises.

Nodes the blade places this step (the tip tet's T, the notch nodes of the
faces the blade crossed) are left where they are; a node on an edge or face
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
#: Steps of the compass search over the weights, largest first.
FAIR_STEPS = np.array([0.08, 0.04, 0.02, 0.01])
#: A node moves only when its smallest angle rises by at least this (degrees): a move costs the
#: physics a re-placement.
FAIR_MIN_GAIN_DEG = 0.5
#: The smallest weight by simplex size (2: edge, 3: face, 4: tet): the cut's snap limits.
_LO = {2: EDGE_SNAP, 3: FACE_BARY_MIN, 4: TET_BARY_MIN}


def fair_cut_nodes(cm, originals, held) -> int:
    """Re-place the cut nodes of ``originals`` whose tetrahedra include a sliver; returns how many moved.

    An original with a node the blade held is looked at again at the next
    step (``cm.fair_pending``): the blade moves on, or the stroke ends.

    Parameters
    ----------
    cm : CutMesh
    originals : iterable of int
        Original tets re-subdivided by the step.
    held : set of int
        Nodes the blade placed this step: left where they are (and their copies).
    """
    moved, pending = 0, set()
    for o, copies, around, edges in _node_groups(cm, sorted(set(originals) | cm.fair_pending)):
        if held.intersection(copies.tolist()):
            pending.add(o)
            continue
        moved += _fair_group(cm, copies, around, edges)
    cm.fair_pending = pending
    return moved


def _node_groups(cm, originals):
    """[(original, copies (c,) int64, originals around (list), cut edges (list))] of the cut nodes of ``originals``,
    each once; a node on an edge or face with coincident copies along an earlier stroke's cut
    (``edge_twins``, ``face_twins``) comes with theirs (they must stay coincident)."""
    seen, out = set(), []
    for o in originals:
        if o not in cm.subtets:
            continue
        for e in cm.tet_edges[o].tolist():
            if e in seen or not np.isfinite(cm.edge_t[e]):
                continue
            edges = [e] + list(cm.edge_twins.get(e, ()))
            seen.update(edges)
            copies = np.concatenate([cm.edge_node[g][cm.edge_node[g] >= 0] for g in edges])
            out.append((o, copies, [t for g in edges for t in cm.edge_ring(g).tolist()], edges))
        for f in cm.tet_faces[o].tolist():
            if -1 - f in seen or cm.face_node[f, 0] < 0:
                continue
            faces = [f] + list(cm.face_twins.get(f, ()))
            seen.update(-1 - g for g in faces)
            copies = np.concatenate([cm.face_node[g][cm.face_node[g] >= 0] for g in faces])
            out.append((o, copies, [t for g in faces for t in cm.face_tets[g].tolist() if t >= 0], []))
        if cm.tet_T[o, 0] >= 0:
            out.append((o, cm.tet_T[o][cm.tet_T[o] >= 0], [o], []))
    return out


def _fair_group(cm, copies, around, edges) -> int:
    """Re-place one node and its copies if a tet around it is a sliver; returns 1 if it moved."""
    ids = np.array([t for o in around for t in cm.subtets.get(o, ())], np.int64)
    tets = cm._tets[ids[cm._alive[ids]]]
    tets = np.ascontiguousarray(tets[np.isin(tets, copies).any(axis=1)])
    if tets.shape[0] == 0:
        return 0
    node = int(copies[0])
    k = int((cm._def_nodes[node] >= 0).sum())
    corners, w0 = cm._def_nodes[node, :k].copy(), cm._def_w[node, :k].copy()  # copies: moving rewrites the rows
    now = _smallest_angle(cm, tets)
    if now >= FAIR_BELOW_DEG:
        return 0
    # the box is around where the cut put the node: its weights before its first fairing, unless
    # the cut has placed it again since (its weights are not those the last fairing gave it)
    cut_at, faired_to = cm.fair_origin.get(node, (w0, None))
    w_cut = cut_at if faired_to is not None and np.array_equal(faired_to, w0) else w0
    w, angle = KF.fair_place(cm._x, tets, np.ascontiguousarray(copies, np.int64), corners, w0, w_cut,
                             _LO[k], FAIR_MOVE_MAX, FAIR_STEPS)
    if not angle >= now + FAIR_MIN_GAIN_DEG:
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


def _smallest_angle(cm, tets) -> float:
    from cutkit.mesh.quality import min_dihedral_angles

    return float(min_dihedral_angles(cm._x, tets).min())
