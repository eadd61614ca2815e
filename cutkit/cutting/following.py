"""A blade drawn back into an earlier stroke's wound follows its walls instead of slicing them.

After a rebase an earlier stroke's cut is part of the mesh: its two walls
are boundary faces of the original tets (``cm.cut_faces_before``), their
nodes duplicated.  A blade drawn along that wound again (retracing an
incision) runs within a fraction of an edge of the walls
but never exactly in them: the old cut surface is not the new blade's plane
(its edge nodes were clamped at ``EDGE_SNAP``, fairing and vertex smoothing
moved them, and a hand's tremor bends both strokes), so the new blade
crosses the walls back and forth.  Cutting every such crossing slices thin
pieces off the walls: tetrahedra of 3-5 degrees next to the wound, and
crumbs.

The rule snaps the cut onto the wound, as node snapping moves a cut onto a
vertex it passes close to (Nienhuys & van der Stappen 2001) and hybrid
cutting lets a cut run along existing mesh faces (Steinemann, Harders, Gross
& Szekely 2006).  A step's crossings are *followed*, not cut, when every one
of them is followable and its tip, where inside the tissue, lies in the band
too (:func:`followed_in_step`: all or none, so that a step reaching past the
wound, a deeper pass, cuts and its cut joins the wound); the crossing of the
blade with edge ``e`` at point ``p`` is followable when

* ``p`` lies within ``FOLLOW_BAND`` x ``h`` of a wall face, ``h`` the
  model's mesh size there (:func:`_model_sizes`: the tets around the edge
  may be pieces of a model tet an earlier cut split), nearest to it away
  from the wound's front (where the two walls meet, the end of an incision
  inside the tissue: a deeper pass cuts past it to join the wound), and
* the blade runs along the wall there: the mean plane of the walls' faces
  within ``FOLLOW_RADIUS`` x ``h`` of ``p`` (the principal axis
  of their normals, weighted by area) lies within ``FOLLOW_ANGLE_DEG`` of
  the blade's plane.

The material the blade passes through there is already parted, at most
``FOLLOW_BAND`` x ``h`` away, by the wound itself; a followed edge stays
whole and is not a bridge across the wound, so it is counted apart from the
edges left uncut (``cm.followed_edges``, ``CutMesh.edges_followed``).  A
blade that crosses the wound at 45 degrees or more (a second incision
across the first) meets the walls' mean plane at more than the angle, and
cuts as before.  Measured (docs/cutting.md, "Following an earlier cut"):
the retraces that made the thousand paths' last slivers.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from cutkit.mesh.geometry import (cross_rows, edge_triangle_crossing, point_triangle_dist2, segment_dist2,
                                  tet_volumes6)

#: A crossing within this fraction of the model's mesh size of an earlier cut's wall may be followed
#: (the wall lies up to EDGE_SNAP = 0.25 of the model's edges off the blade that made it).
FOLLOW_BAND = 0.3
#: The walls' faces within this many mesh sizes of the crossing give the walls' mean plane there.
FOLLOW_RADIUS = 3.0
#: The blade follows where its normal and the walls' mean normal make at most this angle (degrees).
FOLLOW_ANGLE_DEG = 40.0

#: The nearest point of a wall is on its front when the front is as near, to this tolerance relative
#: to the coordinates' size (the two distances come from different primitives).
FRONT_TOL = 1e-12

#: The earlier cuts' walls of one cut state: ``faces`` (k, 3) int64 (sorted node ids), ``tree`` a
#: k-d tree of their centroids, ``reach`` float, mm: the largest distance from a face's centroid to
#: its corners, times two (a margin for the nodes vertex smoothing moves after the tree is built),
#: ``front`` (k, 3) bool: corners without a coincident copy, where the two walls meet (the crack's
#: front, where an incision ended inside the tissue).
WoundWalls = namedtuple("WoundWalls", "faces tree reach front")


def init_following(cm, enabled: bool) -> None:
    """Following state on a new CutMesh: ``follow_wounds`` (bool), ``followed_edges`` (set of edge ids)."""
    cm.follow_wounds = bool(enabled)
    cm.followed_edges = set()
    cm.followed_before = 0  # edges followed by the strokes before the last rebase
    cm.wound_walls = None  # WoundWalls, built on the first crossing near an earlier cut
    cm.wound_sizes = None  # (m0,) the model's mesh size at each original tet (_model_sizes)


def _walls(cm) -> WoundWalls:
    """The earlier cuts' walls of this cut state (built on first use; a rebase makes a fresh state)."""
    if cm.wound_walls is None:
        from scipy.spatial import cKDTree

        faces = np.array(sorted(cm.cut_faces_before), np.int64).reshape(-1, 3)
        corners = cm._x[faces]
        centroids = corners.mean(axis=1)
        reach = 2.0 * float(np.sqrt(((corners - centroids[:, None]) ** 2).sum(axis=2).max()))
        rep = cm.node_rep[:cm.n_orig_points]
        front = np.bincount(rep, minlength=rep.shape[0])[rep[faces]] == 1  # no copy: the walls meet there
        cm.wound_walls = WoundWalls(faces, cKDTree(centroids), reach, front)
    return cm.wound_walls


def _on_front(p, corners, front, d) -> bool:
    """Whether the nearest point to p (3,) of the wall triangle ``corners`` (3, 3), at distance ``d``,
    lies on its front (its corners with ``front`` (3,) bool and the sides between two of them): the
    crossing is past the wound's end, where a deeper pass must cut."""
    near = np.inf
    for i in range(3):
        if front[i]:
            near = min(near, float(((p - corners[i]) ** 2).sum()))
            j = (i + 1) % 3
            if front[j]:
                near = min(near, segment_dist2(p, corners[i], corners[j]))
    return bool(np.sqrt(near) <= d + FRONT_TOL * float(np.abs(corners).max()))


def _blade_normal(p, q, swept) -> np.ndarray:
    """Unit normal (3,) of the swept triangle the edge p-q crosses (the first of the step's two if neither)."""
    tri = swept[0]
    for k in range(swept.shape[0]):
        if edge_triangle_crossing(p, q, swept[k]) >= 0.0:
            tri = swept[k]
            break
    n = cross_rows(tri[1] - tri[0], tri[2] - tri[0])
    return n / max(float(np.linalg.norm(n)), 1e-300)


def _distances(p, corners) -> np.ndarray:
    """(k,) float64 distance from point p (3,) to each triangle of ``corners`` (k, 3, 3)."""
    return np.sqrt(np.array([point_triangle_dist2(p, c[0], c[1], c[2]) for c in corners]))


def _along(corners, blade) -> bool:
    """Whether the walls' mean plane through the triangles ``corners`` (k, 3, 3) lies within
    ``FOLLOW_ANGLE_DEG`` of the plane of unit normal ``blade`` (3,).

    The mean plane's normal is the principal axis of the faces' normals weighted by area (the
    eigenvector of the largest eigenvalue of sum(area n n^T)): it takes no side of the wound, so the
    two walls' opposite normals count alike, and a bumpy wall gives its overall plane.
    """
    normals = cross_rows(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # twice the area
    size = np.sqrt((normals * normals).sum(axis=1))
    keep = size > 0.0
    if not keep.any():
        return False
    normals = normals[keep]
    scatter = (normals / size[keep][:, None]).T @ normals  # sum of 2 area n n^T
    axis = np.linalg.eigh(scatter)[1][:, -1]
    return abs(float(axis @ blade)) >= np.cos(np.radians(FOLLOW_ANGLE_DEG))


def _model_sizes(cm) -> np.ndarray:
    """(m0,) float64 the length scale of each original tet's model tet, mm (built once per cut state).

    The edge of the regular tetrahedron of the model tet's volume (summed over its live pieces: a
    crumb removed from it is left out): earlier cuts split a model tet into smaller tets, but the wound's
    distance from a new blade follows the model's mesh size (its cut nodes were clamped at
    ``EDGE_SNAP`` of the model's edges), not the pieces' edges.
    """
    if cm.wound_sizes is None:
        volumes = np.abs(tet_volumes6(np.ascontiguousarray(cm._X[:cm.n_orig_points]), cm.orig_tets)) / 6.0
        model = np.bincount(cm.model_tet, weights=volumes, minlength=cm.n_model_tets)
        cm.wound_sizes = np.cbrt(6.0 * np.sqrt(2.0) * model[cm.model_tet])
    return cm.wound_sizes


def followable(cm, e: int, s: float, swept) -> bool:
    """Whether the blade's crossing of original edge ``e`` at parameter ``s`` lies in an earlier cut's
    wound, with the blade running along it (module doc).

    Parameters
    ----------
    cm : CutMesh
    e : int  original edge
    s : float  the crossing's parameter from ``cm.edges[e, 0]``, in [0, 1]
    swept : (2, 3, 3) float64  the step's swept triangles

    Returns
    -------
    bool
    """
    a, b = (int(v) for v in cm.edges[e])
    x = cm._x
    ring = cm.edge_tet_idx[cm.edge_tet_off[e]:cm.edge_tet_off[e + 1]]
    h = float(_model_sizes(cm)[ring].max())
    corners = _walls_in_band(cm, x[a] + float(s) * (x[b] - x[a]), h)
    return corners is not None and _along(corners, _blade_normal(x[a], x[b], np.asarray(swept, np.float64)))


def _walls_in_band(cm, p, h):
    """The wall triangles (k, 3, 3) within ``FOLLOW_RADIUS`` x h of point p (3,), where p lies within
    ``FOLLOW_BAND`` x h of a wall with its nearest wall point off the wound's front; else None."""
    x = cm._x
    walls = _walls(cm)
    nearest, _ = walls.tree.query(p)
    if nearest > FOLLOW_BAND * h + walls.reach:  # no wall face within the band
        return None
    ids = np.asarray(walls.tree.query_ball_point(p, FOLLOW_RADIUS * h + walls.reach), np.int64)
    corners = x[walls.faces[ids]]
    d = _distances(p, corners)
    k = int(np.argmin(d))
    if d[k] > FOLLOW_BAND * h or _on_front(p, corners[k], walls.front[ids[k]], d[k]):
        return None
    return corners[d <= FOLLOW_RADIUS * h]


def _in_band(cm, tip, edges) -> bool:
    """Whether the blade's tip (3,) lies in the wound's band, off its front (h: the largest model mesh
    size around the step's ``edges``)."""
    h = max(float(_model_sizes(cm)[cm.edge_tet_idx[cm.edge_tet_off[e]:cm.edge_tet_off[e + 1]]].max())
            for e in edges)
    return _walls_in_band(cm, tip, h) is not None


def followed_in_step(cm, edges, params, swept, tip=None) -> set:
    """The edges a step follows instead of cutting: all its crossings, or none.

    A step follows the wound only where every crossing it makes, of an uncut edge or of one cut
    already (by the steps before it, which it overlaps), is :func:`followable`; a step that crosses
    anything outside the wound's band (a deeper pass going
    past the wound's end, a stroke leaving it) cuts all its crossings as before, so the cut it makes
    there joins the wound rather than stopping beside it (a new cut ending a fraction of an edge
    beside an old wall would leave the material between them joining the wound's two sides).

    Parameters
    ----------
    cm : CutMesh
    edges : (k,) int64  the original edges of the step's crossing events, in visit order
    params : (k,) float64  each crossing's parameter from ``cm.edges[e, 0]``
    swept : (2, 3, 3) float64  the step's swept triangles
    tip : (3,) float64 or None  the blade's tip where it is inside the tissue: it must lie in the band
        too (the deepest point the step sweeps: past the wound's front, the edges there may all have
        been cut by the steps before, and give no crossing)

    Returns
    -------
    set of int  the followed edges (recorded in ``cm.followed_edges``); empty where the step cuts
    """
    if not (cm.follow_wounds and cm.cut_faces_before) or not len(edges):
        return set()
    first = {}
    for e, s in zip(edges.tolist(), params.tolist()):  # an edge's first crossing is the one cut
        first.setdefault(e, s)
    uncut = {e for e in first if not np.isfinite(cm.edge_t[e])}
    # the edges cut already count too: a step reaching past the wound (its edges there cut by the
    # steps before it, which it overlaps) must cut its crossings in the band as well, or its cut would
    # stop beside the wound's wall instead of joining it
    if not uncut or (tip is not None and not _in_band(cm, np.asarray(tip, np.float64), uncut)):
        return set()
    if not all(followable(cm, e, s, swept) for e, s in first.items()):
        return set()
    cm.followed_edges.update(uncut)
    return uncut
