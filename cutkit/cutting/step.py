"""One cut step: volume collision (paper section 4.2) and the topology update.

The blade is the segment from the tip P back to Q = P - blade_length * a.
Between two poses it sweeps the quad (P0, Q0, Q1, P1), taken as the two
triangles (P0, Q0, Q1) and (P0, Q1, P1).

Per step:

1. ``find_trajectory_tetra``: walk from the previous tip tetrahedron across
   faces towards the new tip (the paper's findTrajectoryTetra, numba
   kernel ``_kernels_step.walk``).  With no tip tetrahedron (tip outside),
   the entry comes from the surface collision: boundary faces met by the
   whole blade, i.e. its swept quad or its new pose (``SurfaceBVH``,
   refitted to moved nodes).
2. ``markSwapFace``-style local traversal (numba kernel
   ``_kernels_step.sweep``): from the seeds (tip tetrahedra, entry
   tetrahedra, previous active tetrahedra), visit neighbours while the
   swept surface or the blade meets them.  The kernel returns the step's
   events in visit order (edges met by the swept surface, faces crossed by
   the blade); they are replayed here through the cut state machine of
   :mod:`cutkit.cutting.cutmesh` (every original edge met is cut, notch
   nodes F follow the blade).  Visits are marked with a per-tet stamp =
   step counter (no reset); the kernel's buffers live on the CutMesh.
3. Every original tetrahedron whose cut state changed is re-subdivided.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.errors import InputError
from cutkit.cutting import _kernels_step as KS
from cutkit.cutting.contact import touches_only
from cutkit.cutting.crumbs import remove_crumbs
from cutkit.cutting.fairing import fair_cut_nodes
from cutkit.cutting.following import followed_in_step
from cutkit.cutting.smoothing import live_tets, pend_every_cut_made_tet, smooth_vertices_around
from cutkit.cutting.snapping import new_crossings, recrossed, snap_away
from cutkit.cutting.cutmesh import CutMesh
from cutkit.tissue.delta import TopologyDelta, twins_of

#: Maximum number of face crossings of the tip walk per step.
MAX_WALK = 10000
#: Entry tets from which the tip walk is tried per step (a blade entering
#: edge-first may meet many faces; the tip, if inside, is near the first).
MAX_ENTRY_WALKS = 8


@dataclass
class StepResult:
    """Topology change of one step (flat arrays).

    Attributes
    ----------
    added_nodes : (a,) int64   new node ids
    moved_nodes : (b,) int64   existing cut nodes re-interpolated (tip/front)
    moved_from : (b, 3) float64  their rest positions before the step
    removed_tets : (r,) int64  tet ids (CutMesh numbering) alive before the step, not after
    added_tets : (c,) int64    new tet ids alive after the step (net of tets made and unmade in it)
    cut_edges : (e,) int64     original edges cut in this step
    active_tets : (k,) int64   original tets the blade touches now
    tip_tet : int              original tet containing the tip, -1 if outside
    delta : TopologyDelta      the same change as the physics receive it (cutkit.tissue.delta)
    """

    added_nodes: np.ndarray
    moved_nodes: np.ndarray
    moved_from: np.ndarray
    removed_tets: np.ndarray
    added_tets: np.ndarray
    cut_edges: np.ndarray
    active_tets: np.ndarray
    tip_tet: int
    delta: TopologyDelta


def find_trajectory_tetra(cm: CutMesh, start: int, target) -> int:
    """Original tet containing ``target`` reached by walking from ``start``; -1 if it leaves.

    The paper's findTrajectoryTetra (numba kernel ``_kernels_step.walk``):
    cross the face opposite the most negative barycentric coordinate.
    """
    return int(KS.walk(cm._x, cm.orig_tets, cm.neighbors, int(start), np.asarray(target, np.float64), MAX_WALK))


def tet_containing(points, tets, p) -> int:
    """The first tet of ``tets`` (in index order) that contains the point ``p``, or -1.

    An O(m) scan (kernel ``_kernels_step.locate``): for a start, not for every step.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64
    p : (3,) float64
    """
    return int(KS.locate(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(tets, np.int64),
                         np.asarray(p, np.float64).reshape(3)))


def surface_bvh(cm: CutMesh, crack: bool = False):
    """The hierarchy of the original tets' boundary faces that surface collision walks, built once.

    Built on first use (O(mesh)) and kept on ``cm`` until its next
    :meth:`~CutMesh.rebase`; a session builds it before the blade comes
    (the first cut step would stall for it).  With ``crack``: the cut
    surface of the strokes before the last rebase only (see
    :func:`_surface_seeds`).

    Returns
    -------
    bvh : cutkit.collision.SurfaceBVH
    face_tet : (f,) int64
        Original tet of each face of ``bvh``.
    """
    key = "_crack_bvh" if crack else "_bvh"
    bvh = getattr(cm, key, None)
    if bvh is None:
        from cutkit.collision import SurfaceBVH
        faces, face_tet = cm.orig_boundary_faces, cm.orig_boundary_face_tet
        if crack:
            keep = [tuple(f) in cm.cut_faces_before for f in np.sort(faces, axis=1).tolist()]
            faces, face_tet = faces[keep], face_tet[keep]
        bvh = SurfaceBVH.build(cm._x[:cm.n_orig_points].copy(), faces)
        setattr(cm, key, bvh)
        setattr(cm, key + "_face_tet", face_tet)
    return bvh, getattr(cm, key + "_face_tet")


def _surface_seeds(cm, P0, Q0, P1, Q1, crack=False):
    """Original tets of the boundary faces the blade met between two poses (surface collision, 4.1).

    The whole blade counts, not only its tip: the faces met by the swept
    quad (P0, Q0, Q1, P1) or by the blade at its new pose
    (:func:`cutkit.collision.swept_faces`), so a blade entering edge-first
    (a cleaver, a through-cut with the tip outside, a one-step guillotine)
    is found.  The surface BVH (:func:`surface_bvh`) is refitted at every
    call (``SurfaceBVH.update``: only nodes that left their tolerance box
    cost anything) so surface entry follows a deforming mesh.

    With ``crack``, only the cut surface of the strokes before the last
    :meth:`~CutMesh.rebase` is looked at (its own BVH): the boundary faces
    the tets across an earlier cut are reached through, since no face
    adjacency links the two sides.
    """
    from cutkit.collision import swept_faces

    pts = cm._x[:cm.n_orig_points]
    bvh, face_tet = surface_bvh(cm, crack)
    bvh.update(pts)
    faces, _ = swept_faces(bvh, pts, P0, Q0, P1, Q1)
    return face_tet[faces].tolist()


def _sweep(cm, stamp, seeds, swept, blade, P0):
    """Run ``_kernels_step.sweep`` in buffers kept on ``cm`` (grown by doubling when short).

    Returns views: active (k,) int64, events (q, 2) int64 (kind, id), values (q, 3) float64.
    """
    buf = cm.sweep_buffers()
    seeds = list(dict.fromkeys(seeds))  # first occurrences, in order
    while len(seeds) + 4 > buf["stack"].size:
        buf["stack"] = np.empty(2 * buf["stack"].size, np.int64)
    buf["stack"][:len(seeds)] = seeds
    counts = buf["counts"]
    counts[:] = (len(seeds), 0, 0)
    mesh = KS.SweepMesh(cm.orig_tets, cm.neighbors, cm.tet_edges, cm.tet_faces, cm.edges, cm.faces, cm.edge_t)
    cut = KS.SweepBlade(swept, blade, P0)

    def buffers():
        return KS.SweepBuffers(buf["stack"], buf["active"], buf["ev_id"], buf["ev_val"], counts)

    while not KS.sweep(cm._x, mesh, cm.stamp, stamp, cut, buffers()):
        for name in ("stack", "active", "ev_id", "ev_val"):  # grow, keep the progress
            old = buf[name]
            new = np.empty((2 * old.shape[0],) + old.shape[1:], old.dtype)
            new[:old.shape[0]] = old
            buf[name] = new
    n_active, n_ev = int(counts[1]), int(counts[2])
    return buf["active"][:n_active], buf["ev_id"][:n_ev], buf["ev_val"][:n_ev]


def cut_step(cm: CutMesh, tip, a) -> StepResult:
    """Move the blade to pose (tip, a) and update the cut.

    Parameters
    ----------
    cm : CutMesh
    tip : (3,) float64  blade tip, mm
    a : (3,) float64  unit vector along the blade, handle to tip
    """
    tip, a = _blade_pose(tip, a)
    cm.store.begin_step()
    n_nodes_before = cm.n_points
    cm.step_count += 1
    stamp = cm.step_count
    P1, Q1 = tip, tip - cm.blade_length * a
    if cm.prev_pose is None:
        P0, Q0 = P1, Q1
        cm.stroke_swept = []  # a new stroke (smoothing.py keeps its moves off what it swept)
    else:
        P0, Q0 = cm.prev_pose
    # 1. seeds: the tip walk, then the surface entry
    seeds, tip_tet = _step_seeds(cm, P0, Q0, P1, Q1)
    swept = np.array([[P0, Q0, Q1], [P0, Q1, P1]])
    cm.stroke_swept.append(swept)
    blade = np.array([Q1, P1])
    # 2. local traversal (numba); its events are replayed in visit order
    active, ev_id, ev_val = _sweep(cm, stamp, seeds, swept, blade, P0)
    changed, cut_edges = _replay_events(cm, ev_id, ev_val, swept, P1 if tip_tet >= 0 else None)
    _follow_tip(cm, tip_tet, P1, changed)
    # 3. re-subdivide every original tet whose cut state changed
    # (complete splits first: they choose the diagonals of their split faces, splits.compact_split)
    for o in sorted(changed, key=lambda o: (not cm.completely_split(o), o)):
        cm.resubdivide(o)
    # 4. cut nodes around slivers re-placed within their simplex, but for those the blade placed (fairing.py)
    held = None
    if cm.fair_nodes and (changed or cm.fair_pending):
        held = _blade_placed_nodes(cm, tip_tet, ev_id)
        fair_cut_nodes(cm, changed, held)
    # 5. a vertex of a sliver's original tet moved where that lifts it (smoothing.py), in the
    # originals re-subdivided and in those whose sub-tets changed shape without it: around a node the
    # step moved (the blade's notch nodes, fairing's moves: a cut node is a corner in every tet
    # around its edge or face)
    if cm.smooth_vertices:
        cm.whole_look_due |= bool(changed) or len(cm.store.step_log.moved_nodes) > 0
        reshaped = changed | originals_holding(cm, cm.store.step_log.moved_nodes)
        if reshaped or cm.smooth_pending:
            held = _blade_placed_nodes(cm, tip_tet, ev_id) if held is None else held
            smooth_vertices_around(cm, reshaped, held)
    cm.previous_active_tets = cm.active_tets
    cm.active_tets = np.unique(active)
    cm.prev_pose = (P1, Q1)
    return _step_result(cm, n_nodes_before, cut_edges, tip_tet)


def originals_holding(cm: CutMesh, nodes) -> set:
    """The original tets (set of int) that hold one of ``nodes`` (iterable of int): an original node
    in its star, a cut node in its defining simplex (every tet around its edge, the two at its face,
    its tet); kernel ``_kernels_step.originals_holding``."""
    nodes = np.unique(np.fromiter(nodes, np.int64))
    if not nodes.size:
        return set()
    parents = np.full((nodes.size, 4), -1, np.int64)
    cut = nodes >= cm.n_orig_points
    parents[~cut, 0] = nodes[~cut]
    parents[cut] = cm._def_nodes[nodes[cut]]
    room = int((cm.node_tet_off[parents[:, 0] + 1] - cm.node_tet_off[parents[:, 0]]).sum())
    out = np.empty(room, np.int64)
    k = KS.originals_holding(cm.node_tet_off, cm.node_tet_idx, cm.orig_tets, parents, out)
    return set(out[:k].tolist())


def _blade_pose(tip, a):
    """The pose checked and normalised: tip (3,) float64 and unit a (3,) float64."""
    tip = np.asarray(tip, np.float64).reshape(-1)
    a = np.asarray(a, np.float64).reshape(-1)
    if tip.shape != (3,) or a.shape != (3,) or not np.all(np.isfinite(tip)) or not np.all(np.isfinite(a)):
        raise InputError("blade pose: tip and a must be finite 3-vectors")
    na = np.linalg.norm(a)
    if na == 0:
        raise InputError("blade pose: a is the zero vector")
    return tip, a / na


def _blade_placed_nodes(cm: CutMesh, tip_tet: int, ev_id) -> set:
    """The nodes the blade placed this step: the T nodes of the tet the tip is in and the notch nodes of
    the faces the blade crossed (the crack front)."""
    faces = ev_id[ev_id[:, 0] == KS.EV_FACE, 1]
    held = set(cm.face_node[faces].ravel().tolist())
    if tip_tet >= 0:
        held.update(cm.tet_T[tip_tet].tolist())
    held.discard(-1)
    return held


def _step_seeds(cm: CutMesh, P0, Q0, P1, Q1):
    """Seeds of the local traversal (list of original tets) and the tip's original tet (-1: outside).

    The paper's findTrajectoryTetra from the last tip tet; with the tip
    outside, the entry from the surface collision of the whole blade.
    """
    seeds = cm.active_tets.tolist()
    tip_tet = -1
    if cm.tip_tet >= 0:
        tip_tet = find_trajectory_tetra(cm, cm.tip_tet, P1)
    if tip_tet < 0:
        ent = _surface_seeds(cm, P0, Q0, P1, Q1)
        seeds.extend(ent)
        for o in list(dict.fromkeys(ent))[:MAX_ENTRY_WALKS]:
            tip_tet = find_trajectory_tetra(cm, o, P1)
            if tip_tet >= 0:
                break
        if not ent and cm.prev_pose is None:
            # the first pose met no boundary face: the whole blade is outside, or inside the
            # tissue (put there, not drawn in); then the cut starts where it lies
            tip_tet = tet_containing(cm._x, cm.orig_tets, P1)
            cm.started_inside = tip_tet >= 0
    elif cm.cut_faces_before:
        # the tip is inside, but the blade may reach across an earlier stroke's cut
        seeds.extend(_surface_seeds(cm, P0, Q0, P1, Q1, crack=True))
    if tip_tet >= 0:
        seeds.append(tip_tet)
    if cm.tip_tet >= 0:
        seeds.append(cm.tip_tet)
    return seeds, tip_tet


def _replay_events(cm: CutMesh, ev_id, ev_val, swept, tip=None):
    """Replay the traversal's events through the cut state machine, in visit order (``tip`` (3,): the
    blade's tip where it is inside the tissue, else None).

    Returns the set of original tets whose cut state changed and the list
    of original edges cut (in cutting order).
    """
    changed = set()
    cut_edges = []
    edge_events = np.flatnonzero(ev_id[:, 0] == KS.EV_EDGE).tolist()
    followed = followed_in_step(cm, ev_id[edge_events, 1], ev_val[edge_events, 0], swept, tip)
    start = 0
    for k in edge_events + [ev_id.shape[0]]:
        if k > start:
            # the blade crosses these faces: moves their notch nodes F (crack front); only
            # positions change, the topology does not (a run between two edge events at once)
            cm.set_face_crossings(ev_id[start:k, 1], ev_val[start:k])
        start = k + 1
        if k == ev_id.shape[0]:
            break
        i = int(ev_id[k, 1])
        if np.isfinite(cm.edge_t[i]) or i in followed:  # cut already (an edge is cut once), or in a wound
            continue
        s = recrossed(cm, i, ev_val[k, 0], swept)  # an end moved away from the cut earlier in the step
        s = -1.0 if s < 0.0 or touches_only(cm, i, s, swept) else snap_away(cm, i, s, swept)
        ring = s >= 0.0 and cm.try_cut_edge(i, s)
        if ring:
            cut_edges.append(i)
            cut_edges.extend(cm.retried_edges)  # deferred edges this cut let through
            changed.update(ring)
        cm.retried_edges.clear()
    for i, s in new_crossings(cm, swept):  # edges of nodes moved away from the cut that cross now
        ring = not touches_only(cm, i, s, swept) and cm.try_cut_edge(i, s)
        if ring:
            cut_edges.append(i)
            cut_edges.extend(cm.retried_edges)
            changed.update(ring)
        cm.retried_edges.clear()
    return changed, cut_edges


def _follow_tip(cm: CutMesh, tip_tet: int, P1, changed: set) -> None:
    """Move the tip node T with the tip, and mark the tets the tip left or entered as ``changed``."""
    # tip node T follows the tip inside its tetrahedron (a move, unless the
    # tet's topology changes anyway)
    if tip_tet >= 0:
        tb = np.empty(4)
        KS.tet_bary(cm._x, cm.orig_tets[tip_tet], P1, tb)
        cm.tip_bary[tip_tet] = tb
        if tip_tet not in changed:
            cm.move_tip_node(tip_tet)
    # where the tip left a tet, its T node stays (freezes) and the tet may cone to a notch node
    # instead (resubdivision._face_apex_cone); a cut tet the tip enters is coned to T again
    if tip_tet != cm.tip_tet:
        changed.update(o for o in (cm.tip_tet, tip_tet) if o in cm.subtets and not cm.completely_split(o))
    cm.tip_tet = tip_tet


def _step_result(cm: CutMesh, n_nodes_before: int, cut_edges: list, tip_tet: int) -> StepResult:
    """Remove the step's crumbs and gather its net change into a :class:`StepResult`."""
    # a piece this step set loose below CRUMB_VOLUME_FRACTION of the model is removed (crumbs.py):
    # one around a new tet, or one a moved vertex shrank (smoothing keeps its star's volume, not
    # each piece's)
    made = np.array(cm.store.step_log.added_tets, np.int64)
    seeds = made[cm._alive[made]] if made.size else made
    vertices = [v for v in cm.store.step_log.moved_nodes if v < cm.n_orig_points]
    if vertices:
        stars = originals_holding(cm, vertices)
        seeds = np.concatenate([seeds, live_tets(cm, np.array(sorted(stars), np.int64))])
    remove_crumbs(cm, seeds)
    d = cm.store.step_log
    moved = np.unique(np.array(d.moved_nodes, np.int64))
    # net change: a tet made and unmade within the step (re-subdivided twice) is in neither
    added = np.array(d.added_tets, np.int64)
    removed = np.array(d.removed_tets, np.int64)
    if added.size and not cm._alive[added].all():
        transient = added[~cm._alive[added]]
        added, removed = added[cm._alive[added]], removed[~np.isin(removed, transient)]
    moved_from = np.array([d.moved_from[i] for i in moved.tolist()], np.float64).reshape(-1, 3)
    return StepResult(
        added_nodes=np.array(d.added_nodes, np.int64),
        moved_nodes=moved,
        moved_from=moved_from,
        removed_tets=removed,
        added_tets=added,
        cut_edges=np.array(cut_edges, np.int64),
        active_tets=cm.active_tets,
        tip_tet=int(tip_tet),
        delta=topology_delta(cm, n_nodes_before, moved, moved_from, removed, added),
    )


#: The node fields of a delta that adds and moves no node (read-only, shared).
_NO_NODES = tuple(np.zeros(shape, dtype) for shape, dtype in
                  (((0,), np.int64), ((0, 4), np.int64), ((0, 4), np.float64), ((0, 3), np.float64), ((0,), np.int64)))
for _a in _NO_NODES:
    _a.flags.writeable = False


def topology_delta(cm: CutMesh, n_nodes_before: int, moved, moved_from, removed, added) -> TopologyDelta:
    """The step's change as a :class:`~cutkit.tissue.TopologyDelta` (read off ``cm`` after the step).

    Parameters
    ----------
    cm : CutMesh
        After the step.
    n_nodes_before : int
        ``cm.n_points`` before the step.
    moved : (b,) int64
        Nodes re-interpolated in the step, ascending.
    moved_from : (b, 3) float64
        Their rest positions before the step.
    removed, added : (r,) int64, (c,) int64
        Tets alive before and not after, and after and not before.
    """
    if cm.n_points == n_nodes_before and moved.size == 0:  # most steps: no node made or moved
        new, parents, weights, rest, twin = _NO_NODES
        moved_parents, moved_weights, moved_to = _NO_NODES[1], _NO_NODES[2], _NO_NODES[3]
    else:
        new = np.arange(n_nodes_before, cm.n_points, dtype=np.int64)
        parents = cm.defining_nodes[new]
        weights = np.where(parents >= 0, cm.defining_weights[new], 0.0)
        rest, twin = cm.rest_points[new].copy(), twins_of(parents, weights)
        moved_parents = cm.defining_nodes[moved]
        moved_weights = np.where(moved_parents >= 0, cm.defining_weights[moved], 0.0)
        moved_to = cm.rest_points[moved].copy()
    tets, origin = cm.tet_corners, cm.tet_origins
    return TopologyDelta(
        n_nodes_before=int(n_nodes_before), n_nodes_after=int(cm.n_points),
        added_nodes=new, added_node_parents=parents, added_node_weights=weights,
        added_node_rest=rest, added_node_twin=twin,
        moved_nodes=moved, moved_rest_from=moved_from, moved_rest_to=moved_to,
        moved_node_parents=moved_parents, moved_node_weights=moved_weights,
        removed_tets=removed, removed_tet_corners=tets[removed],
        added_tets=added, added_tet_corners=tets[added], added_tet_origin=origin[added],
        n_tets_total=int(cm.n_tets_total))


def finish_stroke(cm: CutMesh, every_cut_tet: bool = True) -> StepResult | None:
    """The stroke has ended: look at the slivers the blade held once more, with nothing held, and at
    every cut-made tet.

    Fairing and vertex smoothing leave a sliver alone while the blade placed
    one of its nodes (``cm.fair_pending``, ``cm.smooth_pending``: the blade's
    next step may move it again).  When the blade has left the tissue, the
    trajectory ends with it inside or the hand holds still, no later step
    moves them: this looks at them
    with the same rules and nothing held (the moves stay off the stroke's
    swept surface, ``cm.stroke_swept``).  With ``every_cut_tet``, vertex
    smoothing also looks at every tet a cut made, in any stroke, once after
    each change to the cut
    (:func:`~cutkit.cutting.smoothing.pend_every_cut_made_tet`): a sliver
    whose original no later step re-subdivided is looked at too.  Call it
    before a rebase, which forgets what is pending.

    Parameters
    ----------
    cm : CutMesh
    every_cut_tet : bool
        Also look at every cut-made tet (False: only what was pending).

    Returns
    -------
    StepResult or None
        The nodes moved (``delta.moved_nodes``) and the sub-tets of a
        complete split re-made another way where that lifted a sliver
        (:func:`~cutkit.cutting.resubdivision.better_split`), or None when
        nothing changed.
    """
    fair = cm.fair_nodes and bool(cm.fair_pending)
    if every_cut_tet:
        pend_every_cut_made_tet(cm)
    if not fair and not (cm.smooth_vertices and cm.smooth_pending):
        return None
    cm.store.begin_step()
    n_nodes_before = cm.n_points
    if fair:
        fair_cut_nodes(cm, set(), set())
    cm.fair_pending = {}
    reshaped = originals_holding(cm, cm.store.step_log.moved_nodes)
    if cm.smooth_vertices and (cm.smooth_pending or reshaped):
        smooth_vertices_around(cm, reshaped, set())
    cm.smooth_pending = set()
    if not (len(cm.store.step_log.moved_nodes) or len(cm.store.step_log.added_tets)):
        return None
    return _step_result(cm, n_nodes_before, [], cm.tip_tet)


def blade_in_tissue(cm):
    """Whether the blade at its last pose meets one of the last step's active tets (current positions).

    The active tets are those the swept quad met, whose last edge is the
    blade at its new pose: a tet the blade is in now is among them, so the
    test is local.
    """
    from cutkit.mesh.geometry import segment_meets_any_tet

    if cm.prev_pose is None:
        return False
    if cm.tip_tet >= 0:
        return True
    tip, back = cm.prev_pose
    corners = np.ascontiguousarray(cm.orig_tets[cm.active_tets])
    return bool(segment_meets_any_tet(np.asarray(back, np.float64), np.asarray(tip, np.float64), cm._x, corners))


def rebase_if_left(cm):
    """End the stroke when the blade has left the tissue after it cut: rebase, keeping the blade's pose.

    Call it after each :func:`cut_step` of a kinematic
    cut (``cutkit cut``).  The next step then sweeps from the pose outside
    the tissue into it, and may cut the sub-tetrahedra of this stroke (a
    second stroke crossing the first).  The runtime decides the end of a
    stroke itself (the hand's tip leaving the entry plane) and calls
    :func:`~cutkit.cutting.rebase.rebase` through its session.  After the
    rebase every cut-made tet is looked at once more (:func:`finish_stroke`):
    the cut's nodes are vertices of original tets now, which vertex smoothing
    may move where a sliver needs it (it never moves a cut node of a
    subdivided original).

    Returns
    -------
    rebased : bool
    """
    if cm.prev_pose is None or blade_in_tissue(cm):
        return False
    if not cm.subtets and cm.n_points == cm.n_orig_points:
        return False  # the stroke cut nothing
    pose = cm.prev_pose
    finish_stroke(cm)  # what the blade held at its last steps, looked at once more
    cm.rebase()
    finish_stroke(cm)  # the look the rebase opens: the cut's nodes are vertices of original tets now
    cm.prev_pose = pose
    return True
