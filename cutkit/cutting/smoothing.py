"""Vertex smoothing: a mesh vertex moved where a cut-made tetrahedron around it is a sliver.

What fairing (:mod:`cutkit.cutting.fairing`) cannot lift is led by the corner
a cut cuts off near a vertex: the sliver's other corners are the vertices of
its original tetrahedron, which fairing never moves, and its cut nodes are
held within ``FAIR_MOVE_MAX`` of the crossing.  After fairing, each live
sub-tetrahedron of the step's original tetrahedra below
:data:`SMOOTH_BELOW_DEG` has the four vertices of its original tetrahedron
looked at; the one whose move gains most moves (optimisation-based smoothing:
Freitag & Ollivier-Gooch 1997, "Tetrahedral mesh improvement using swapping
and smoothing", the smallest dihedral angle of the vertex's star maximised;
the node snapping of Nienhuys & van der Stappen 2001 and Steinemann et al.
2006 moves a vertex for the cut's sake in the same way).  The cut nodes
defined on the vertex follow it by their weights, so inside each original
tetrahedron the move is affine: the subdivision stays conforming, and a
sub-tetrahedron stays positive where its original does.

What a move keeps:

* **the model's volume, and its surface to within the move**: an interior
  vertex moves inside its star, whose boundary does not move; a boundary
  vertex moves within its flat surface (its one face plane, or the crease
  line of two); on a gently curved surface (its outer faces' normals within
  :data:`SURFACE_BEND_DEG` of their mean) within the plane that keeps the
  volume of its star exactly (the volume is linear in the move), so the
  surface moves by at most the move; at a corner or a sharper bend not at
  all;
* **the cut where the blade made it, to within the move**: a vertex moves at
  most :data:`SMOOTH_MOVE_MAX` of its shortest edge from where the cut
  state found it (all its moves together), and a cut node on one of its
  edges, faces or tetrahedra by its weight on it times that;
* **every contact**: no uncut edge of the vertex comes to cross a triangle
  the stroke's blade has swept (so no crossing the cut missed appears);
* **the tets**: every tetrahedron of the star stays positive and its
  smallest angle rises by at least :data:`SMOOTH_MIN_GAIN_DEG`, or from
  below :data:`SMOOTH_BELOW_DEG` to it (:data:`LIFT_TO_BOUND`);
* **an earlier stroke's cut closed**: a vertex on an earlier stroke's cut
  surface moves with its coincident copies (the other sides'), by the same
  move, within the cut surface's plane where that is flat (the faces of the
  two sides count as one plane); where the cut is bent and the copies lie
  inside the model, in space (the cut's faces bend with them, both sides
  alike; a stroke retracing the cut sweeps through the copies, so the
  contact rule above keeps each edge of theirs on its side);
* **what else holds**: a vertex held by the boundary conditions (any copy)
  stays unless every corner of its star is held too (inside a held tissue
  such as bone, :func:`_inside_held_tissue`: the move changes no tet with a
  free node, and the physics keeps the moved node held where the old shape
  places it); a vertex with a cut node the blade placed this step stays
  (looked at again at the next step).

Before a vertex moves for a sliver of a completely split original, the
original is re-split where its split as :func:`~cutkit.cutting.resubdivision.resubdivide`
would make it now (a fixed diagonal flipped, :func:`~cutkit.cutting.splits.flipped_split`)
lifts the sliver by more than :data:`SMOOTH_MIN_GAIN_DEG` (:data:`RESPLIT`): the
split was chosen before its nodes moved, or before its neighbours fixed their diagonals.

The move is carried to the rest configuration and the texture through the
deformation of the star's tetrahedron that holds the vertex's new place; the
vertex and its cut nodes are the step's moved nodes
(``StepResult.moved_nodes``), which the element tissue places through the
old shape of the tetrahedra around them.  The paper's springs cannot take a
moved vertex (they re-interpolate moved nodes from their defining nodes), so
a run with them turns smoothing off.
"""

from __future__ import annotations

import numpy as np

from cutkit.cutting import _kernels_fair as KF
from cutkit.cutting.resubdivision import better_split
from cutkit.cutting.snapping import (COPLANAR_TOL, _dependants, _rest_move, _star, _surface_direction,
                                     boundary_faces, crack_nodes, face_normals)
from cutkit.mesh.geometry import cross_rows, tet_volume_gradients
from cutkit.mesh.quality import min_dihedral_angles

#: A cut-made tetrahedron below this smallest dihedral angle (degrees) has its original's vertices
#: looked at (the bound the cut keeps, docs/cutting.md, "Quality").
SMOOTH_BELOW_DEG = 5.0
#: A vertex moves at most this fraction of its shortest edge from where the cut state found it.
SMOOTH_MOVE_MAX = 0.4
#: Steps of the compass search, as fractions of the vertex's shortest edge, largest first.
SMOOTH_STEPS = np.array([0.1, 0.05, 0.02, 0.01])
#: A vertex moves only when the smallest angle of its star rises by at least this (degrees): a move
#: costs the physics a re-placement of the star.
SMOOTH_MIN_GAIN_DEG = 0.2
#: A move that gains less than :data:`SMOOTH_MIN_GAIN_DEG` is still taken where it lifts its star from
#: below :data:`SMOOTH_BELOW_DEG` to it (a sliver just under the bound, which no move lifts by the gain).
LIFT_TO_BOUND = True
#: A vertex on the model's outer surface where the normals of its boundary faces are all within this
#: angle (degrees) of their area-weighted mean moves in the plane that keeps the volume
#: (:func:`_on_a_gentle_surface`); the surface then moves by at most the move.
SURFACE_BEND_DEG = 30.0
#: Looks at the poor tets per call at most (another only after one that moved a vertex): a move can
#: open a move of another vertex that did not gain before (docs/cutting.md, "Angles").
SMOOTH_PASSES = 3
#: The look re-splits a completely split original whose split as it would be made now lifts its
#: sliver (:func:`~cutkit.cutting.resubdivision.better_split`), before moving a vertex for it.
RESPLIT = True
#: Up to this many nodes a sorted face's three node numbers fit one int64 (n**3 < 2**63).
_ROW_KEY_MAX_NODES = 2_000_000
#: :func:`_best_move`'s answer for a vertex with a cut node the blade placed this step.
_HELD = "held"
#: Directions of an interior vertex: the axes and the cube diagonals, both ways.
_SPACE = np.vstack([np.eye(3), -np.eye(3),
                    np.array([[i, j, k] for i in (1, -1) for j in (1, -1) for k in (1, -1)]) / np.sqrt(3.0)])


def init_smoothing(cm, enabled: bool) -> None:
    """Smoothing state of a new cut state (a :class:`~cutkit.cutting.cutmesh.CutMesh`, or a rebase's)."""
    cm.smooth_vertices = bool(enabled)
    cm.smoothed_from = {}  # vertex -> (3,) where the cut state found it (its moves' budget)
    cm.smooth_pending = set()  # original tets looked at again at the next step (a cut node the blade holds)
    cm.stroke_swept = []  # (2, 3, 3) the swept triangles of each step of the stroke
    cm.whole_look_due = False  # a step changed the cut since the last look at every cut-made tet


def pend_every_cut_made_tet(cm) -> None:
    """A stroke's end (:func:`~cutkit.cutting.step.finish_stroke`): every original tet the cut
    subdivided, and every tet an earlier stroke made (an original of this cut state since the
    rebase), is looked at by the next :func:`smooth_vertices_around`, once after each change to the
    cut (``cm.whole_look_due``): a sliver a step left where no later step of the stroke re-subdivided
    its original, or an earlier stroke's, is looked at with nothing held."""
    if not (cm.smooth_vertices and cm.whole_look_due):
        return
    m0 = cm.store.n_orig_tets
    made = np.flatnonzero(cm.store.orig_made_by_cut[:m0] | (cm.sub_count[:m0] > 0))
    cm.smooth_pending |= set(made.tolist())
    cm.whole_look_due = False


def smooth_vertices_around(cm, originals, held) -> int:
    """Move vertices of the originals ``originals`` (set of int, re-subdivided this step) and of those
    an earlier step left pending, where a live sub-tet of theirs (or the original itself, uncut) is
    below :data:`SMOOTH_BELOW_DEG`; the poorest first, each the best of its original's four vertices.  ``held`` (set of int): cut
    nodes the blade placed this step.  Returns the vertices moved."""
    fresh = set(originals) | cm.smooth_pending
    cm.smooth_pending = set()
    if not fresh:
        return 0
    moved = 0
    for _ in range(SMOOTH_PASSES):
        resplit = set()
        now = _smooth_pass(cm, np.array(sorted(fresh), np.int64), held, resplit)
        moved += now
        if not now:
            break
        fresh |= resplit  # a re-split's neighbours, re-made to follow its diagonals
    return moved


def _smooth_pass(cm, fresh, held, resplit) -> int:
    """One look at the poor tets of the originals ``fresh`` (k,) int64, the poorest first; the
    originals across the faces of one it re-split are added to ``resplit`` (set of int)."""
    mesh = KF.FairMesh(cm._x, cm._tets, cm._alive, cm.sub_start, cm.sub_count)
    tets, owner = KF.poor_tets(mesh, fresh, SMOOTH_BELOW_DEG)
    whole = fresh[(cm.sub_count[fresh] == 0) & cm._alive[fresh]]  # an earlier stroke's tet, uncut since
    whole = whole[min_dihedral_angles(cm._x, cm._tets[whole]) < SMOOTH_BELOW_DEG] if whole.size else whole
    tets, owner = np.concatenate([tets, whole]), np.concatenate([owner, whole])
    if not tets.size:
        return 0
    order = np.argsort(min_dihedral_angles(cm._x, cm._tets[tets]), kind="stable")
    moved = 0
    looked = {}  # vertex -> its best move (or None, _HELD) since the cut state last changed: poor tets share vertices
    for t, o in zip(tets[order].tolist(), owner[order].tolist()):
        if not cm._alive[t] or min_dihedral_angles(cm._x, cm._tets[t:t + 1]).min() >= SMOOTH_BELOW_DEG:
            continue  # a move before lifted it
        if held and not held.isdisjoint(cm._tets[t].tolist()):
            cm.smooth_pending.add(o)  # the blade is at it: it may change again at the next step
            continue
        if RESPLIT and t != o and cm.compact_splits and cm.completely_split(o) and better_split(cm, o, SMOOTH_MIN_GAIN_DEG):
            cm.resubdivide(o)  # another split of the same cut lifts it (resubdivision.better_split)
            resplit.update(int(n) for n in cm.face_tets[cm.tet_faces[o]].ravel() if n >= 0)
            moved += 1
            looked.clear()
            continue
        best = None
        for v in cm.orig_tets[o].tolist():
            option = looked[v] if v in looked else looked.setdefault(v, _best_move(cm, v, held))
            if option is _HELD:
                cm.smooth_pending.add(o)  # the blade is at one of its cut nodes: looked at again next step
            elif option is not None and (best is None or option[-1] > best[-1]):
                best = option
        if best is not None:
            _apply(cm, *best[:-1])
            moved += 1
            looked.clear()
    return moved


def _copies(cm, v) -> np.ndarray:
    """(c,) int64 ``v`` and its coincident copies along an earlier stroke's cut (equal ``node_rep``)."""
    if v not in crack_nodes(cm):
        return np.array([v], np.int64)
    reps = cm.node_rep[:cm.n_orig_points]
    others = np.flatnonzero(reps == reps[v])
    others = others[(others != v) & (np.diff(cm.node_tet_off)[others] > 0)]  # a copy with tets around it
    return np.concatenate([[v], others]).astype(np.int64)


def _directions(cm, group, stars):
    """(d, 3) unit directions the vertex copies ``group`` may move along together (within their flat
    surface where they are on the boundary, an earlier cut's surface included; in space where they
    are inside the model on a bent earlier cut, :func:`_inside_a_bent_cut`; in the plane that keeps
    the volume where they are on a gently curved surface, :func:`_on_a_gentle_surface`), or None (a
    corner, a sharply bent surface)."""
    faces = np.concatenate([boundary_faces(cm, v, star) for v, star in zip(group.tolist(), stars)])
    face_n, normals = face_normals(cm, faces), []
    for n in face_n:
        if all(abs(abs(float(n @ m)) - 1.0) > COPLANAR_TOL for m in normals):
            normals.append(n)  # a crack's faces seen from its two sides are one plane
            if len(normals) > 2:
                break  # more than two: what follows reads the faces, not how many planes
    if len(normals) == 0:
        return _SPACE
    if len(normals) == 1:
        return _plane_directions(normals[0])
    line = None
    if len(normals) == 2:
        line = _surface_direction(np.array(normals), cross_rows(normals[0], normals[1]))  # the crease, or None
    if line is not None:
        line = line / np.linalg.norm(line)
        return np.array([line, -line])
    sides = _earlier_cut_sides(cm, faces)
    if _inside_a_bent_cut(sides):
        return _SPACE
    return _volume_plane(cm, group, stars) if _on_a_gentle_surface(cm, faces, face_n, sides) else None


def _plane_directions(normal) -> np.ndarray:
    """(8, 3) unit directions in the plane of unit ``normal`` (3,): two axes and their diagonals, both ways."""
    u = cross_rows(normal, np.eye(3)[int(np.argmin(np.abs(normal)))])
    u /= np.linalg.norm(u)
    w = cross_rows(normal, u)
    d = np.array([u, w, (u + w) / np.sqrt(2.0), (u - w) / np.sqrt(2.0)])
    return np.vstack([d, -d])


def _earlier_cut_sides(cm, faces):
    """(paired, earlier) (k,) bool each for boundary faces ``faces`` (k, 3) int64 of vertex copies'
    stars: a face met from both sides (its corners' coincident copies twice among ``faces``), a face
    of an earlier stroke's cut (``cm.cut_faces_before``); None where some corners come more than
    twice."""
    rows = np.sort(cm.node_rep[faces], axis=1)
    n = cm.node_rep.shape[0]
    if n <= _ROW_KEY_MAX_NODES:  # one integer per row, in the rows' order: np.unique on it is far faster
        rows = (rows[:, 0] * np.int64(n) + rows[:, 1]) * np.int64(n) + rows[:, 2]
    _, inverse, count = np.unique(rows, axis=0 if rows.ndim == 2 else None, return_inverse=True,
                                  return_counts=True)
    if (count > 2).any():
        return None
    earlier = np.array([tuple(f) in cm.cut_faces_before for f in np.sort(faces, axis=1).tolist()], bool)
    return count[inverse.ravel()] == 2, earlier


def _inside_a_bent_cut(sides) -> bool:
    """Whether vertex copies whose stars' boundary faces have ``sides`` (:func:`_earlier_cut_sides`)
    lie inside the model on an earlier stroke's bent cut and may move in space together: every one
    of those faces is a face of the earlier cut met from both sides, so the stars together fill a
    ball whose boundary does not move (the volume is kept, the cut's two sides stay coincident at
    rest).  A single vertex qualifies too: on the cut's front line inside the model its star holds
    both sides."""
    if sides is None or not len(sides[0]):
        return False
    paired, earlier = sides
    return bool(paired.all() and earlier.all())


def _on_a_gentle_surface(cm, faces, normals, sides) -> bool:
    """Whether vertex copies whose stars' boundary faces are ``faces`` (k, 3) int64, with unit
    ``normals`` (k, 3) float64 and ``sides`` (:func:`_earlier_cut_sides`), lie on the model's outer
    surface where it bends gently: the faces that are not an earlier cut met from both sides (the
    outer surface) have normals within :data:`SURFACE_BEND_DEG` of their area-weighted mean, and the
    faces of an earlier cut among them are met from both sides.  Such copies move in the plane that
    keeps the model's volume (:func:`_volume_plane`); the outer surface then moves by at most the
    move."""
    if sides is None:
        return False
    paired, earlier = sides
    if (paired != earlier).any() or paired.all():  # half of a cut, or no outer surface (the bent cut's case)
        return False
    x, outer = cm._x, faces[~paired]
    area = np.linalg.norm(cross_rows(x[outer[:, 1]] - x[outer[:, 0]], x[outer[:, 2]] - x[outer[:, 0]]), axis=1)
    mean = area @ normals[~paired]
    size = float(np.linalg.norm(mean))
    return size > 0.0 and bool((normals[~paired] @ (mean / size) >= np.cos(np.radians(SURFACE_BEND_DEG))).all())


def _volume_plane(cm, group, stars):
    """(8, 3) unit directions in the plane in which moving the copies ``group`` together (their cut
    nodes by their weights) keeps the volume of their stars' original tets exactly, or None where
    that volume does not change.  Inside each original the move is affine, so its live sub-tets
    and crumbs still fill it: the model's volume plus the crumbs' is kept.  An original's volume is
    linear in the move (:func:`~cutkit.mesh.geometry.tet_volume_gradients`), so the plane is the
    same after any move within it."""
    g = np.zeros(3)
    for v, star in zip(group.tolist(), stars):
        t = cm.orig_tets[star]
        g += tet_volume_gradients(cm._x, t)[t == v].sum(axis=0)
    size = float(np.linalg.norm(g))
    return _plane_directions(g / size) if size > 0.0 else None


def live_tets(cm, star) -> np.ndarray:
    """(k,) int64 the live tets of the original tets ``star`` (q,) int64: their sub-tets, or themselves
    uncut."""
    ids = [np.arange(cm.sub_start[o], cm.sub_start[o] + cm.sub_count[o]) if cm.sub_count[o] else np.array([o])
           for o in star.tolist()]
    ids = np.concatenate(ids).astype(np.int64) if ids else np.zeros(0, np.int64)
    return ids[cm._alive[ids]]


def _followers(cm, group):
    """(ids (k,) int64, weights (k,) float64): the cut nodes defined on a node of ``group`` and their
    weight on it."""
    ids = np.concatenate([_dependants(cm, v) for v in group.tolist()])
    on = (cm._def_nodes[ids][..., None] == group).any(axis=-1)  # np.isin for a handful of copies
    w = on * cm._def_w[ids]
    return ids, w.sum(axis=1)


def _far_ends(cm, group, stars):
    """(all (k,) int64, uncut (u,) int64): the far ends of the edges of the copies ``group`` in their
    stars, and of those not cut."""
    far, uncut = [], []
    for v, star in zip(group.tolist(), stars):
        edges = np.unique(cm.tet_edges[star].ravel())
        edges = edges[(cm.edges[edges] == v).any(axis=1)]
        ends = np.where(cm.edges[edges, 0] == v, cm.edges[edges, 1], cm.edges[edges, 0])
        far.append(ends)
        uncut.append(ends[~np.isfinite(cm.edge_t[edges])])
    return np.concatenate(far), np.concatenate(uncut)


def _best_move(cm, v, held):
    """(copies, their stars, dx (3,), follower ids, angle after) of the best move of vertex ``v`` (with
    its coincident copies); None where it has none; :data:`_HELD` where a cut node of its own is in
    ``held`` (set of int).  Reads the cut state only: :func:`_smooth_pass` reuses the answer until
    the state changes."""
    group = _copies(cm, v)
    stars = [_star(cm, g) for g in group.tolist()]
    if cm.store.held[group].any() and not _inside_held_tissue(cm, stars):
        return None
    directions = _directions(cm, group, stars)
    if directions is None:
        return None
    ids, weights = _followers(cm, group)
    if held and not held.isdisjoint(ids.tolist()):
        return _HELD
    x = cm._x
    far, uncut = _far_ends(cm, group, stars)
    h = float(np.linalg.norm(x[far] - x[v], axis=1).min())
    budget = SMOOTH_MOVE_MAX * h - float(np.linalg.norm(x[v] - cm.smoothed_from.get(v, x[v])))
    if not budget > 0.0:
        return None
    nodes, local = np.unique(cm._tets[np.concatenate([live_tets(cm, star) for star in stars])], return_inverse=True)
    present = _sorted_has(nodes, group)  # a copy can be a corner of none of its star's live tets (a crumb took it)
    if not present[0]:
        return None
    share = np.zeros(nodes.size)
    share[np.searchsorted(nodes, group[present])] = 1.0
    inside = _sorted_has(nodes, ids)
    share[np.searchsorted(nodes, ids[inside])] = weights[inside]
    problem = KF.VertexStar(np.ascontiguousarray(x[nodes]), local.reshape(-1, 4).astype(np.int64), share,
                            int(np.searchsorted(nodes, v)), np.ascontiguousarray(x[uncut]),
                            _swept_near(cm, x[nodes]))
    dx, angle, start = KF.vertex_place(problem, directions, SMOOTH_STEPS * h, budget)
    if not (angle >= start + SMOOTH_MIN_GAIN_DEG or (LIFT_TO_BOUND and angle >= SMOOTH_BELOW_DEG > start)):
        return None
    return group, stars, dx, ids, angle


def _inside_held_tissue(cm, stars) -> bool:
    """Whether every corner of every original tet of ``stars`` (list of (k,) int64) is held by the
    boundary conditions: a held vertex there (inside a held tissue such as bone, or on its outer
    surface) may move, since no tet with a free node changes (the cut nodes inside are held too, the
    store's rule) and the physics places the held nodes through the old shape, where they stay."""
    held = cm.store.held
    return all(bool(held[cm.orig_tets[star]].all()) for star in stars)


def _sorted_has(nodes, query) -> np.ndarray:
    """(q,) bool: which of ``query`` (q,) int64 are in ``nodes`` (k,) int64, sorted and unique (what
    :func:`numpy.isin` gives, by a binary search)."""
    if not nodes.size:
        return np.zeros(query.shape, bool)
    at = np.minimum(np.searchsorted(nodes, query), nodes.size - 1)
    return nodes[at] == query


def _swept_near(cm, points) -> np.ndarray:
    """(h, 3, 3) float64 the stroke's swept triangles whose box meets the box of ``points`` (k, 3)."""
    if not cm.stroke_swept:
        return np.zeros((0, 3, 3))
    tris = np.concatenate(cm.stroke_swept)
    lo, hi = points.min(axis=0), points.max(axis=0)
    near = (tris.max(axis=1) >= lo).all(axis=1) & (tris.min(axis=1) <= hi).all(axis=1)
    return np.ascontiguousarray(tris[near])


def _apply(cm, group, stars, dx, followers) -> None:
    """Move the vertex copies ``group`` by ``dx`` (3,), each at rest and in texture through the tet of
    its star that holds its new place, and their cut nodes by their weights; all recorded as the
    step's moved nodes."""
    for v, star in zip(group.tolist(), stars):
        cm.smoothed_from.setdefault(v, cm._x[v].copy())
        dX, duvw = _rest_move(cm, _holder(cm, star, cm._x[v] + dx), dx)
        cm.move_original_node(v, dx, dX, duvw)
    for i in followers.tolist():
        k = cm._def_nodes[i] >= 0
        cm.reinterpolate_node(i, cm._def_nodes[i, k], cm._def_w[i, k])


def _holder(cm, star, p) -> int:
    """The original tet of ``star`` whose smallest barycentric coordinate of ``p`` (3,) is largest."""
    t = cm.orig_tets[star]
    x = cm._x
    T = np.transpose(x[t[:, 1:]] - x[t[:, :1]], (0, 2, 1))
    b = np.linalg.solve(T, (p - x[t[:, 0]])[:, :, None])[:, :, 0]
    bary = np.column_stack([1.0 - b.sum(axis=1), b])
    return int(star[int(np.argmax(bary.min(axis=1)))])


def load_smooth_kernels() -> float:
    """Load (or compile) the smoothing's search kernel with the argument types a cut step passes, on
    one unit tetrahedron whose vertex 0 moves (no swept triangle); a live session calls it before its
    clock starts (its warm-up cut may leave no sliver).  Returns the angle the search reaches, degrees."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    problem = KF.VertexStar(x, np.array([[0, 1, 2, 3]], np.int64), np.array([1.0, 0.0, 0.0, 0.0]), 0,
                            np.ascontiguousarray(x[1:]), np.zeros((0, 3, 3)))
    _, angle, _ = KF.vertex_place(problem, _SPACE, SMOOTH_STEPS, SMOOTH_MOVE_MAX)
    return float(angle)
