"""Rebase a cut mesh between strokes, so that a later cut may cross an earlier one.

The cut state of :class:`~cutkit.cutting.cutmesh.CutMesh` is kept per
*original* edge, face and tetrahedron (one cut node pair per edge, one
subdivision per tetrahedron), so a tetrahedron is cut once.  When the blade
has left the tissue, no cut is in progress and nothing of that state is
needed any more: :func:`rebase` makes the current live tetrahedra the
original ones of a fresh cut state.  The next stroke then cuts the
sub-tetrahedra of the earlier strokes like any tetrahedra, and a through X
gives four pieces.

Node ids do not change (every current node becomes an original node, so
per-node arrays held elsewhere stay valid); tetrahedron ids are renumbered
(the live ones in ascending order of their old ids).  What must outlive a
rebase is kept as records on the CutMesh (:func:`init_records`): the node
and tetrahedron counts of the model as loaded, the model tetrahedron of
each original tetrahedron, which original tetrahedra and faces were made by
earlier cuts, and the model node each node takes point data from.
"""

from __future__ import annotations

import numpy as np


def init_records(cm):
    """The cutting's records on a new CutMesh (the store keeps the model's: :class:`~cutkit.tissue.store.TissueStore`).

    Sets on ``cm``:

    * ``cut_faces_before`` : set of sorted (3,) tuples, faces of the original
      tets that are cut surface of earlier strokes.
    * ``uncut_before`` : int, edges the earlier strokes met and left uncut
      (:meth:`~cutkit.cutting.cutmesh.CutMesh.edges_left_uncut`).
    """
    cm.cut_faces_before = set()
    cm.uncut_before = 0
    cm.uncut_places_before = np.zeros((0, 3))  # their rest midpoints, mm (CutMesh.uncut_edge_places)
    cm.node_rep = np.arange(cm.n_points, dtype=np.int64)  # see _node_reps
    cm.edge_twins, cm.face_twins = {}, {}  # see find_twins


def cut_surface_mask(cm, faces):
    """(k,) bool: which boundary triangles ``faces`` (k, 3) int64 of cut-made tets are cut surface.

    A triangle made of nodes of the current stroke only is on its cut
    surface (every triangle of the Fig. 2 face patterns holds a vertex of
    the original face it lies in).  Any other triangle lies in one face of
    the original tets: the face of the triangle's original vertices and the
    defining nodes of its cut nodes; it is cut surface when that face was
    (``cut_faces_before``, kept by :func:`rebase`).
    """
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    new = faces >= cm.n_orig_points
    out = new.all(axis=1)
    if not cm.cut_faces_before:
        return out
    for i in np.flatnonzero(~out).tolist():
        support = set()
        for q in faces[i].tolist():
            if q < cm.n_orig_points:
                support.add(q)
            else:
                support.update(d for d in cm._def_nodes[q].tolist() if d >= 0)
        out[i] = len(support) == 3 and tuple(sorted(support)) in cm.cut_faces_before
    return out


def cut_surface_faces(cm) -> np.ndarray:
    """(k, 3) int64 boundary triangles of the cut surface (both sides of each cut, every stroke).

    Only tets made by a cut (in this stroke or one before a
    :meth:`~CutMesh.rebase`) hold cut nodes, so the faces are looked for
    among them alone: the work follows the size of the cut, not of the
    mesh.  Which of their boundary triangles are cut surface (not a piece
    of the model's outer surface, not a face shared with an uncut tet) is
    told by :func:`cut_surface_mask`.
    """
    from cutkit.mesh.topology import boundary_faces

    m0, total = cm.orig_tets.shape[0], cm.n_tets_total
    ids = m0 + np.flatnonzero(cm._alive[m0:total])
    if cm.n_rebases:  # live original tets made by the strokes before the rebase
        ids = np.concatenate([np.flatnonzero(cm.orig_made_by_cut & cm._alive[:m0]), ids])
    if ids.shape[0] == 0:
        return np.zeros((0, 3), np.int64)
    faces, _ = boundary_faces(cm._tets[ids])
    # A face of the cut surface belongs to cut-made tets only, so appearing
    # once among them it appears once in the whole mesh: it is on the boundary.
    return faces[cut_surface_mask(cm, faces)]


def rebase(cm):
    """Make the live tetrahedra of ``cm`` the original ones of a fresh cut state (in place).

    Call it only while no cut is in progress (the blade out of the tissue):
    the crack fronts, tip nodes and the blade's previous pose are dropped.

    Parameters
    ----------
    cm : CutMesh

    Returns
    -------
    old_ids : (k,) int64
        Old tet id (CutMesh numbering before the call) of each new original
        tetrahedron ``i``; node ids are unchanged.
    """
    from cutkit.cutting.crumbs import crumb_volume

    cut_faces = {tuple(f) for f in np.sort(cut_surface_faces(cm), axis=1).tolist()}
    node_rep = _node_reps(cm)
    crumbs_before = crumb_volume(cm)
    uncut, uncut_places = cm.edges_left_uncut(), cm.uncut_edge_places()
    ids = cm.store.rebase()  # the one renumbering: every holder of the store sees it
    fresh = type(cm).over(cm.store, blade_length=cm.blade_length, centre_nodes=cm.centre_nodes,
                          compact_splits=cm.compact_splits, snap_vertices=cm.snap_vertices,
                          fair_nodes=cm.fair_nodes, smooth_vertices=cm.smooth_vertices,
                          follow_wounds=cm.follow_wounds)
    fresh.cut_faces_before = cut_faces
    # the cut's nodes are vertices of original tets now, which vertex smoothing may move (it never
    # moves a cut node of a subdivided original): the next finish_stroke looks at every cut-made tet
    # (rebase_if_left and the session call it right after the rebase)
    fresh.whole_look_due = bool(cut_faces)
    fresh.uncut_before, fresh.uncut_places_before = uncut, uncut_places
    fresh.followed_before = cm.edges_followed()
    fresh.step_count = cm.step_count
    fresh.started_inside = cm.started_inside
    fresh.node_rep = node_rep
    fresh.model_volume = cm.model_volume  # crumbs are measured against the model as loaded
    fresh.crumb_volume_before = crumbs_before
    fresh.crumb_count = cm.crumb_count
    fresh.snapped_nodes, fresh.snap_counts = cm.snapped_nodes, cm.snap_counts  # snapping.py
    find_twins(fresh)
    # replace the whole state: caches keyed by the old numbering (surface BVH, sweep buffers) go too
    vars(cm).clear()
    vars(cm).update(vars(fresh))
    return ids


def _node_reps(cm):
    """(n_points,) int64 the lowest id among each node's coincident copies (the two sides of a cut).

    Copies of a cut node are made with the same defining nodes and weights
    (edge nodes, centre nodes, the T nodes of a complete split), so their
    definitions, taken on the defining nodes' own representatives, are equal.
    """
    rep = np.arange(cm.n_points, dtype=np.int64)
    rep[:cm.n_orig_points] = cm.node_rep
    seen = {}
    for i in range(cm.n_orig_points, cm.n_points):
        d = cm._def_nodes[i]
        key = tuple(sorted((int(rep[q]), float(w)) for q, w in zip(d.tolist(), cm._def_w[i].tolist()) if q >= 0))
        rep[i] = seen.setdefault(key, i)
    return rep


def _twins(rows, rep):
    """Dict: row -> the other rows (k, c) int64 of ``rows`` whose nodes' representatives are the same."""
    keys = np.sort(rep[rows], axis=1)
    n = int(rep.max(initial=0)) + 1
    if keys.shape[0] and float(n) ** keys.shape[1] < 2.0 ** 62:
        # each row as one int64 in the rows' lexicographic order: a plain sort, which numpy runs
        # without the GIL (a live session's main loop goes on beside it) and faster than rows
        flat = np.zeros(keys.shape[0], np.int64)
        for col in range(keys.shape[1]):
            flat = flat * n + keys[:, col]
        _, inv, cnt = np.unique(flat, return_inverse=True, return_counts=True)
    else:
        _, inv, cnt = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    # only the rows of groups of several (the copies along earlier cuts, a few thousand of some
    # hundred thousand rows): splitting every group into its own array cost a second on the knee
    shared = np.flatnonzero(cnt[inv] > 1)
    order = shared[np.argsort(inv[shared], kind="stable")]  # by group, rows ascending within one
    cuts = np.flatnonzero(np.diff(inv[order])) + 1
    out = {}
    for members in (g.tolist() for g in np.split(order, cuts) if g.size > 1):
        for r in members:
            out[r] = [q for q in members if q != r]
    return out


def find_twins(cm):
    """Set ``cm.edge_twins`` and ``cm.face_twins``: coincident copies of edges and faces along earlier cuts.

    The two sides of an earlier cut hold coincident copies of the same
    edges and faces; a later stroke must cut them alike, or a node on one
    side would lie inside a face of the other (a hanging node).
    """
    cm.edge_twins = _twins(cm.edges, cm.node_rep)
    cm.face_twins = _twins(cm.faces, cm.node_rep)


def cut_twins(cm, e, s, twins):
    """Cut edge ``e`` at parameter ``s`` together with its coincident copies ``twins`` (list); returns touched tets.

    All are cut, at the same point, or none: refused when one is cut
    already (a copy numbered apart met first at another point), deferred
    (kept in ``pending_edges`` under ``e``) when one would split a sheet
    (see :meth:`CutMesh.try_cut_edge`).
    """
    group = [e] + list(twins)
    if any(np.isfinite(cm.edge_t[g]) for g in group):
        cm.refused_edges.add(e)
        return []
    if any(cm._splits_a_sheet(g) for g in group):
        cm.pending_edges.setdefault(e, s)
        return []
    first = cm.node_rep[cm.edges[e, 0]]
    touched = []
    for g in group:
        cm.pending_edges.pop(g, None)
        # a copy numbered the other way round is cut at 1 - s (the clamp is symmetric)
        touched += cm._cut_edge(g, s if cm.node_rep[cm.edges[g, 0]] == first else 1.0 - s)
    cm._retry_pending(touched)
    return touched


def twin_face_bary(cm, f, g, bary):
    """(3,) float64 barycentric weights ``bary`` (3,) on face ``f`` re-ordered for its coincident copy ``g``."""
    rf = cm.node_rep[cm.faces[f]].tolist()
    return np.array([bary[rf.index(r)] for r in cm.node_rep[cm.faces[g]].tolist()])
