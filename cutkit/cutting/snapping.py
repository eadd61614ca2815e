"""Snapping: move a vertex away from the cut before its edges are cut, instead of slicing a sliver off it.

An edge crossed within ``EDGE_SNAP`` of a vertex is cut at the snap limit
(:meth:`~cutkit.cutting.cutmesh.CutMesh._cut_edge` clamps the parameter), so
the corner cut off near that vertex has edges a quarter and three quarters
along: the slivers of docs/cutting.md ("Angles").  Nienhuys & van der
Stappen (2001, "A surgery simulation supporting cuts and finite element
deformation") move the mesh vertex *onto* the cut surface; a cut through a
vertex needs per-side copies of it, which the one-node-pair-per-edge
representation cannot express.  The dual move keeps the representation:
the vertex moves *away* from the swept surface, along the surface's normal,
until every edge from it to the other side is crossed at least
``SNAP_TARGET`` of its length from it.  The crossing then needs no clamp
and the cut surface follows the blade.

The move is made only where it is harmless (:func:`snap_away`; the
outcome of every crossing near a vertex is counted in ``cm.snap_counts``):

* the vertex is an original node of the cut state, not moved before, not
  on the cut surface of an earlier stroke, and no earlier step of this
  stroke visited a tetrahedron around it (the move keeps the region of its
  star, so no crossing with an earlier swept triangle changes);
* it moves at most ``SNAP_MOVE_MAX`` of its shortest edge;
* the tetrahedra around it and their sub-tetrahedra stay positive and
  their worst dihedral angle stays >= ``min(worst before, SNAP_KEEP_DEG)``;
  the move is halved up to ``SNAP_TRIES - 1`` times until this holds, else
  not made.  Cut nodes defined on the vertex (edge, face and tip nodes)
  follow it by their weights: inside each original tetrahedron the move is
  affine, so the subdivisions stay conforming;
* an interior vertex moves inside its star (whose boundary does not move):
  the model's volume is kept exactly.  A boundary vertex moves only within
  its flat surface: along its one face plane, or along the crease line of
  two (a box edge); on a curved surface or at a corner it stays.  The
  surface and the volume do not move.

After the moves of a step, the edges of a moved vertex are crossed again
(:func:`recrossed`, :func:`new_crossings`): the sweep's events were found
before the moves.

Rest and current positions move together (the current move is carried to
the rest configuration through the inverse deformation of one tetrahedron
around the vertex; the texture coordinates likewise).  The step reports the
vertex in ``StepResult.moved_nodes`` with its rest position before the
move in ``moved_from``, as for cut nodes that moved: the element tissue
places it through the old shape of the tetrahedra around it and re-makes
their rest data.  The spring tissue re-interpolates moved nodes from their
defining nodes, which an original vertex lacks: it cannot take a snapped
vertex (``simulate`` does not turn snapping on).
"""

from __future__ import annotations

import numpy as np

from cutkit.mesh.geometry import EDGE_END_EPS, TET_FACES, cross_rows, edge_triangle_crossing
from cutkit.mesh.quality import min_dihedral_angles

#: Only a crossing within this fraction of its edge's length from a vertex moves the vertex
#: (the cut's clamp, cutmesh.EDGE_SNAP: closer crossings would be clamped).
SNAP_NEAR = 0.25
#: After the move, every edge from the vertex to the other side of the swept plane is crossed
#: at least this fraction of its length from the vertex.
SNAP_TARGET = 0.3
#: A vertex moves at most this fraction of its shortest edge.
SNAP_MOVE_MAX = 0.3
#: No tet around a moved vertex gets a smallest dihedral angle below min(its own, SNAP_KEEP_DEG).
SNAP_KEEP_DEG = 10.0
#: A boundary node moves only if its allowed direction gains at least this much per unit of move
#: away from the swept plane.
SNAP_ALONG_MIN = 0.3
#: The move is tried at full length, then halved this many times less one.
SNAP_TRIES = 3
#: Boundary faces of a vertex count as coplanar when their unit normals agree to this.
COPLANAR_TOL = 1e-9


def init_snapping(cm, enabled: bool):
    """Snapping state on a new CutMesh: ``snap_vertices`` (bool) and ``snapped_nodes`` (set of moved vertices)."""
    cm.snap_vertices = bool(enabled)
    cm.snapped_nodes = set()
    cm.snap_counts = {}  # outcome of each crossing near a vertex (snap_away)
    cm.crack_nodes = None  # nodes on an earlier stroke's cut surface (built on first use)


def _star(cm, v):
    """(k,) int64 original tets around original node ``v``."""
    return cm.node_tet_idx[cm.node_tet_off[v]:cm.node_tet_off[v + 1]]


def _why_fixed(cm, v):
    """Why ``v`` may not move ("" if it may): an original node, not moved before, not on an earlier
    stroke's cut, its star not visited by an earlier step of this stroke."""
    if v in cm.snapped_nodes:
        return "moved before"
    if v >= cm.n_orig_points:
        return "cut node"
    if v in crack_nodes(cm):
        return "on an earlier cut"
    # no earlier step of this stroke visited its star: no swept triangle of the stroke but this step's
    # met it, so the move (inside the star, whose region it keeps) changes no earlier crossing
    st = cm.stamp[_star(cm, v)]
    if not ((st == 0) | (st == cm.step_count)).all():
        return "met before"
    return ""


def _dependants(cm, v):
    """(k,) int64 cut nodes defined by weights on ``v`` (they follow it)."""
    d = cm._def_nodes[cm.n_orig_points:cm.n_points]
    return cm.n_orig_points + np.flatnonzero((d == v).any(axis=1))


def _sub_tets(cm, star):
    """(k,) int64 live sub-tets of the tets of ``star``."""
    ids = [t for o in star.tolist() for t in cm.subtets.get(o, ())]
    ids = np.array(ids, np.int64)
    return ids[cm._alive[ids]] if ids.size else ids


def boundary_faces(cm, v, star) -> np.ndarray:
    """(k, 3) int64 the boundary faces that hold ``v`` of the original tets ``star``, outward (one per
    face, repeats and all; k = 0 for an interior node)."""
    t = cm.orig_tets[star]
    on = (cm.neighbors[star] < 0) & (t != v)  # the face opposite local vertex i is on the boundary, holds v
    return t[:, TET_FACES][on]


def face_normals(cm, faces) -> np.ndarray:
    """(k, 3) float64 the unit normals of ``faces`` (k, 3) int64 (right-handed order) at ``cm._x``."""
    x = cm._x
    n = cross_rows(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def boundary_face_normals(cm, v, star) -> np.ndarray:
    """(k, 3) float64 the outward unit normals of :func:`boundary_faces`."""
    return face_normals(cm, boundary_faces(cm, v, star))


def _boundary_normals(cm, v, star):
    """(k, 3) float64 the distinct outward unit normals of ``v``'s boundary faces (k = 0 for an interior
    node)."""
    normals = []
    for n in boundary_face_normals(cm, v, star):
        if all(abs(float(n @ m) - 1.0) > COPLANAR_TOL for m in normals):
            normals.append(n)
    return np.array(normals).reshape(-1, 3)


def crack_nodes(cm) -> set:
    """The nodes on an earlier stroke's cut surface (``cm.cut_faces_before``), built on first use."""
    if cm.crack_nodes is None:
        cm.crack_nodes = {i for f in cm.cut_faces_before for i in f}
    return cm.crack_nodes


def _surface_direction(normals, direction):
    """``direction`` (3,) restricted to the flat surface around a boundary node, or None.

    One distinct face normal (a flat patch): the component along it is
    removed; two (a straight crease, e.g. a box edge): the direction is
    projected onto the crease line.  Either keeps the surface and the
    volume.  More (a corner, or a curved surface): None, the node stays.
    """
    if len(normals) == 1:
        return direction - (direction @ normals[0]) * normals[0]
    if len(normals) == 2:
        line = cross_rows(normals[0], normals[1])
        if line @ line < COPLANAR_TOL:  # opposite faces (a sheet one tet thick)
            return None
        return (direction @ line) / (line @ line) * line
    return None


def _plane(cm, e, swept):
    """(point (3,), unit normal (3,)) of the swept triangle edge ``e`` crosses, or None."""
    x = cm._x
    p, q = (int(i) for i in cm.edges[e])
    for tri in swept:
        if edge_triangle_crossing(x[p], x[q], tri) >= 0.0:
            n = cross_rows(tri[1] - tri[0], tri[2] - tri[0])
            return tri[0], n / np.linalg.norm(n)
    return None


def _needed_move(cm, v, star, origin, n):
    """(direction (3,), length) that puts every crossing of ``v``'s edges >= SNAP_TARGET from it.

    ``v`` lies above the plane (origin, n) or, within EDGE_END_EPS of it,
    just below (the edge test's perturbation); it moves away from the plane.
    """
    x = cm._x
    around = np.unique(cm.orig_tets[star])
    around = around[around != v]
    h = (x[around] - origin) @ n
    hv = float((x[v] - origin) @ n)
    length = np.linalg.norm(x[around] - x[v], axis=1)
    tol = EDGE_END_EPS * length
    above = hv > EDGE_END_EPS * float(length.min())
    other = ~(h > tol) if above else h > tol  # ends across the plane from v
    if not other.any():
        return n, 0.0
    side = 1.0 if above else -1.0
    need = SNAP_TARGET / (1.0 - SNAP_TARGET) * float(np.abs(h[other]).max())
    return side * n, max(need - side * hv, 0.0)


def _shape_ok(x, tets, before):
    """Whether the tets (k, 4) over ``x`` (n, 3) are positive and their worst dihedral angle is
    >= min(``before``, SNAP_KEEP_DEG)."""
    vol = np.einsum("ij,ij->i", x[tets[:, 1]] - x[tets[:, 0]],
                    cross_rows(x[tets[:, 2]] - x[tets[:, 0]], x[tets[:, 3]] - x[tets[:, 0]]))
    if not (vol > 0).all():
        return False
    return bool(min_dihedral_angles(x, tets).min() >= min(before, SNAP_KEEP_DEG))


def _trial_ok(cm, tets, v, dependants, dx, before):
    """Whether moving ``v`` by ``dx`` (its ``dependants`` following) keeps ``tets`` (k, 4) acceptable
    (:func:`_shape_ok`); evaluated on a copy, nothing moves."""
    nodes, local = np.unique(tets, return_inverse=True)
    x = cm._x[nodes].copy()
    x[np.searchsorted(nodes, v)] += dx
    for i in dependants.tolist():
        if i in nodes:
            k = cm._def_nodes[i] >= 0
            d = cm._def_nodes[i, k]
            pos = cm._x[d].copy()
            pos[d == v] += dx
            x[np.searchsorted(nodes, i)] = cm._def_w[i, k] @ pos
    return _shape_ok(x, local.reshape(-1, 4), before)


def _rest_move(cm, o, dx):
    """The rest move (3,) and texture move (3,) or None for current move ``dx`` (3,) inside original tet ``o``."""
    t = cm.orig_tets[o]
    Ds = (cm._x[t[1:]] - cm._x[t[0]]).T
    Dm = (cm._X[t[1:]] - cm._X[t[0]]).T
    g = np.linalg.solve(Ds, dx)  # the move in the tet's reference coordinates
    uvw = None if cm._uvw is None else (cm._uvw[t[1:]] - cm._uvw[t[0]]).T @ g
    return Dm @ g, uvw


def _move(cm, v, star, dx, dependants):
    """Move original node ``v`` by ``dx`` (3,) (current), its rest and texture positions alike, and the
    cut nodes defined on it (``dependants``, re-interpolated); all recorded as moved."""
    dX, duvw = _rest_move(cm, int(star[0]), dx)
    cm.move_original_node(v, dx, dX, duvw)
    cm.snapped_nodes.add(v)
    for i in dependants.tolist():
        k = cm._def_nodes[i] >= 0
        cm.reinterpolate_node(i, cm._def_nodes[i, k], cm._def_w[i, k])


def _move_for(cm, v, plane):
    """(direction (3,), length) of the move of ``v`` away from ``plane`` (point, unit normal), or a reason (str)."""
    star = _star(cm, v)
    direction, dist = _needed_move(cm, v, star, *plane)
    normals = _boundary_normals(cm, v, star)
    if len(normals):  # within the flat surface around it only
        direction = _surface_direction(normals, direction)
        along = 0.0 if direction is None else abs(float(direction @ plane[1]))
        if along < SNAP_ALONG_MIN:
            return "curved or cornered surface"
        dist /= along
    edges = np.linalg.norm(cm._x[np.unique(cm.orig_tets[star])] - cm._x[v], axis=1)
    dist = min(dist, SNAP_MOVE_MAX * float(edges[edges > 0].min()))
    if dist <= 0.0:
        return "no move needed"
    return direction, dist


def _snap(cm, e, s, swept):
    """(new parameter, outcome) of :func:`snap_away`."""
    a, b = (int(i) for i in cm.edges[e])
    v = a if s < 0.5 else b
    plane = _plane(cm, e, swept)
    why = "no swept plane" if plane is None else _why_fixed(cm, v)
    if why:
        return s, why
    move = _move_for(cm, v, plane)
    if isinstance(move, str):
        return s, move
    direction, dist = move
    star = _star(cm, v)
    dep = _dependants(cm, v)
    tets = np.vstack([cm.orig_tets[star], cm._tets[_sub_tets(cm, star)]])
    before = float(min_dihedral_angles(cm._x, tets).min())
    for k in range(SNAP_TRIES):
        dx = dist * 0.5 ** k * direction
        if _trial_ok(cm, tets, v, dep, dx, before):
            _move(cm, v, star, dx, dep)
            return recrossed(cm, e, s, swept), "moved" if k == 0 else "moved part way"
    return s, "shape"


def snap_away(cm, e: int, s: float, swept) -> float:
    """Move the vertex a crossing of edge ``e`` at parameter ``s`` lies near away from the cut; the new parameter.

    Outcomes are counted in ``cm.snap_counts`` (why a vertex stayed, or "moved").

    Parameters
    ----------
    cm : CutMesh
    e : int  original edge, crossed by the swept surface
    s : float  the crossing's parameter along ``edges[e]`` (from its first end)
    swept : (2, 3, 3) float64  the step's swept triangles

    Returns
    -------
    float
        The crossing's parameter after the move (``s`` when nothing moved; -1 when the edge, moved,
        no longer crosses the swept surface: it is not cut in this step).
    """
    if not cm.snap_vertices or SNAP_NEAR <= s <= 1.0 - SNAP_NEAR or np.isfinite(cm.edge_t[e]):
        return s
    s, outcome = _snap(cm, e, s, swept)
    cm.snap_counts[outcome] = cm.snap_counts.get(outcome, 0) + 1
    return s


def recrossed(cm, e: int, s: float, swept) -> float:
    """The parameter of the crossing of edge ``e`` now, if an end moved in this step; else ``s``.

    The sweep's events are computed before any move, so an edge of a
    vertex moved earlier in the step is crossed elsewhere now (or not at
    all: -1).
    """
    a, b = (int(i) for i in cm.edges[e])
    moved = cm.store.step_log.moved_from
    if not cm.snapped_nodes or (a not in moved and b not in moved):
        return s
    for tri in swept:
        t = edge_triangle_crossing(cm._x[a], cm._x[b], np.asarray(tri))
        if t >= 0.0:
            return float(t)
    return -1.0


def new_crossings(cm, swept):
    """Edges of the nodes moved in this step that the swept surface crosses now and that are neither cut
    nor deferred: list of (edge, parameter).  The sweep's events were found before the moves."""
    if not cm.snapped_nodes:
        return []
    moved = [v for v in cm.store.step_log.moved_from if v < cm.n_orig_points and v in cm.snapped_nodes]
    out = []
    for v in moved:
        for o in _star(cm, v).tolist():
            for e in cm.tet_edges[o].tolist():
                if v not in cm.edges[e] or np.isfinite(cm.edge_t[e]) or e in cm.pending_edges:
                    continue
                t = recrossed(cm, e, 0.5, swept)
                if t >= 0.0 and all(e != k for k, _ in out):
                    out.append((e, t))
    return out
