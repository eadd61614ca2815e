"""Numba kernels of one cut step (paper section 4.2) and of the cut nodes.

* :func:`tet_bary` / :func:`walk`: barycentric coordinates (Cramer's rule)
  and the paper's findTrajectoryTetra walk across faces;
* :func:`sweep`: the markSwapFace-style local traversal; it tests the
  tetrahedra around the blade and returns the *events* of the step (edges
  met by the swept surface, faces crossed by the blade) in visit order, so
  the cut state machine (Python, :mod:`cutkit.cutting.cutmesh`) replays
  them exactly as a per-tet Python loop would;
* :func:`tet_mask`, :func:`cut_nodes_centroid`,
  :func:`best_cone_apex`: the small per-node / per-candidate work of the
  subdivision (the face patterns and compact splits are in
  :mod:`cutkit.cutting._kernels_split`).

Slow, obviously correct NumPy twins: ``tests/_twins_cut.py``.
"""

from collections import namedtuple

import numpy as np
from numba import njit

from cutkit.cutting._kernels import tet_sweep
from cutkit.mesh.geometry import TET_EDGES, clamp_bary, segment_meets_tet, tet_dihedrals

#: The walk stops in a tet whose barycentric coordinates of the target are all >= -WALK_EPS.
WALK_EPS = 1e-12
#: Event kinds returned by :func:`sweep`.
EV_EDGE, EV_FACE = 0, 1
#: The mesh tables :func:`sweep` walks: the original tets' (m, 4) corners and neighbours, (m, 6) edges and
#: (m, 4) faces; the global (ne, 2) edges and (nf, 3) faces (int64); each edge's cut parameter (ne,) float64.
SweepMesh = namedtuple("SweepMesh", ["tets", "neighbors", "tet_edges", "tet_faces", "edges", "faces", "edge_t"])
#: One step's blade for :func:`sweep`: the two swept triangles (2, 3, 3), the blade segment (2, 3) (back
#: Q1, tip P1) and the previous tip P0 (3,), float64.
SweepBlade = namedtuple("SweepBlade", ["swept", "blade", "p0"])
#: The caller's buffers of :func:`sweep` (see its parameters).
SweepBuffers = namedtuple("SweepBuffers", ["stack", "active", "ev_id", "ev_val", "counts"])


@njit(cache=True, nogil=True)
def tet_bary(x, tv, p, out):
    """Barycentric coordinates of ``p`` in the tet ``x[tv]`` (Cramer's rule).

    Parameters
    ----------
    x : (n, 3) float64  node positions
    tv : (4,) int64  the tet's vertices
    p : (3,) float64  the point
    out : (4,) float64  written: (1 - l1 - l2 - l3, l1, l2, l3); all -1 if the tet is flat

    Returns
    -------
    bool  False when the tet is flat (zero determinant)
    """
    a = x[tv[0]]
    b1x, b1y, b1z = x[tv[1], 0] - a[0], x[tv[1], 1] - a[1], x[tv[1], 2] - a[2]
    b2x, b2y, b2z = x[tv[2], 0] - a[0], x[tv[2], 1] - a[1], x[tv[2], 2] - a[2]
    b3x, b3y, b3z = x[tv[3], 0] - a[0], x[tv[3], 1] - a[1], x[tv[3], 2] - a[2]
    rx, ry, rz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    # c23 = b2 x b3, det = b1 . c23
    cx, cy, cz = b2y * b3z - b2z * b3y, b2z * b3x - b2x * b3z, b2x * b3y - b2y * b3x
    det = b1x * cx + b1y * cy + b1z * cz
    if det == 0.0:
        out[:] = -1.0
        return False
    l1 = (rx * cx + ry * cy + rz * cz) / det
    # l2 = b1 . (r x b3) / det, l3 = b1 . (b2 x r) / det
    l2 = (b1x * (ry * b3z - rz * b3y) + b1y * (rz * b3x - rx * b3z) + b1z * (rx * b3y - ry * b3x)) / det
    l3 = (b1x * (b2y * rz - b2z * ry) + b1y * (b2z * rx - b2x * rz) + b1z * (b2x * ry - b2y * rx)) / det
    out[0] = 1.0 - (l1 + l2 + l3)
    out[1] = l1
    out[2] = l2
    out[3] = l3
    return True


@njit(cache=True, nogil=True)
def walk(x, tets, neighbors, start, target, max_walk):
    """The paper's findTrajectoryTetra: original tet containing ``target``, or -1.

    From ``start``, cross the face opposite the most negative barycentric
    coordinate (not back into the tet we came from) until every coordinate
    is >= -WALK_EPS.

    Parameters
    ----------
    x : (n, 3) float64
    tets : (m, 4) int64  original tets
    neighbors : (m, 4) int64  tet across local face i, -1 on the boundary
    start : int  start tet
    target : (3,) float64
    max_walk : int  maximum number of face crossings

    Returns
    -------
    int  tet containing ``target``; -1 when the walk leaves the mesh
    """
    b = np.empty(4)
    order = np.empty(4, np.int64)
    t = start
    prev = -1
    for _ in range(max_walk):
        tet_bary(x, tets[t], target, b)
        if min(b[0], b[1], b[2], b[3]) >= -WALK_EPS:
            return t
        # ascending coordinates (insertion sort: stable, like argsort on 4 items)
        for i in range(4):
            order[i] = i
        for i in range(1, 4):
            j = i
            while j > 0 and b[order[j - 1]] > b[order[j]]:
                order[j - 1], order[j] = order[j], order[j - 1]
                j -= 1
        moved = False
        for q in range(4):
            i = order[q]
            if b[i] >= 0.0:
                break
            nb = neighbors[t, i]
            if nb >= 0 and nb != prev:
                prev = t
                t = nb
                moved = True
                break
        if not moved:
            return -1
    return -1


@njit(cache=True, nogil=True)
def locate(x, tets, target):
    """First tet (in index order) containing ``target`` within ``WALK_EPS``, or -1: an O(m) scan.

    Where no walk can start (the blade's first pose, with no tip tet and no
    boundary face met), this finds the tip.  A tet whose bounding box misses
    the point is skipped before its barycentric coordinates are computed.

    Parameters
    ----------
    x : (n, 3) float64
    tets : (m, 4) int64
    target : (3,) float64

    Returns
    -------
    int
    """
    b = np.empty(4)
    for t in range(tets.shape[0]):
        inside = True
        for c in range(3):
            lo = min(x[tets[t, 0], c], x[tets[t, 1], c], x[tets[t, 2], c], x[tets[t, 3], c])
            hi = max(x[tets[t, 0], c], x[tets[t, 1], c], x[tets[t, 2], c], x[tets[t, 3], c])
            span = hi - lo
            if target[c] < lo - WALK_EPS * span or target[c] > hi + WALK_EPS * span:
                inside = False
                break
        if not inside:
            continue
        if tet_bary(x, tets[t], target, b) and min(b[0], b[1], b[2], b[3]) >= -WALK_EPS:
            return t
    return -1


@njit(cache=True, nogil=True)
def _face_bary(x, fv, px, py, pz, out, row):
    """Barycentric coordinates (3,) of a point in the plane of triangle x[fv].

    Closed-form 2x2 normal equations of the least-squares fit
    ``p - x0 = u (x1 - x0) + v (x2 - x0)``, written to ``out[row]``.
    """
    x0 = x[fv[0]]
    e1x, e1y, e1z = x[fv[1], 0] - x0[0], x[fv[1], 1] - x0[1], x[fv[1], 2] - x0[2]
    e2x, e2y, e2z = x[fv[2], 0] - x0[0], x[fv[2], 1] - x0[1], x[fv[2], 2] - x0[2]
    dx, dy, dz = px - x0[0], py - x0[1], pz - x0[2]
    g11 = e1x * e1x + e1y * e1y + e1z * e1z
    g12 = e1x * e2x + e1y * e2y + e1z * e2z
    g22 = e2x * e2x + e2y * e2y + e2z * e2z
    r1 = e1x * dx + e1y * dy + e1z * dz
    r2 = e2x * dx + e2y * dy + e2z * dz
    det = g11 * g22 - g12 * g12
    if det > 0.0:
        u = (g22 * r1 - g12 * r2) / det
        v = (g11 * r2 - g12 * r1) / det
    else:  # flat face: cannot be crossed (segment_triangle_crossing refuses it); keep a valid value
        u = v = 1.0 / 3.0
    out[row, 0] = 1.0 - (u + v)
    out[row, 1] = u
    out[row, 2] = v


@njit(cache=True, nogil=True)
def _edge_events(o, tv, edge_par, tet_edges, edges, edge_t, ev_id, ev_val, n_ev):
    """EV_EDGE events of tet ``o``: each of its uncut edges (``edge_t`` NaN) that the swept
    surface meets (``edge_par >= 0``, along the local edge), from ``n_ev`` on.

    Returns
    -------
    (touched, n_ev) : (bool, int)
        Whether the swept surface meets any of its edges (cut or not), and the new event count.
    """
    touched = False
    k = 0
    for i in range(4):
        for j in range(i + 1, 4):
            if edge_par[k] >= 0.0:
                touched = True
                e = tet_edges[o, k]
                if np.isnan(edge_t[e]):
                    ev_id[n_ev, 0] = EV_EDGE
                    ev_id[n_ev, 1] = e
                    ev_val[n_ev, 0] = edge_par[k] if tv[i] == edges[e, 0] else 1.0 - edge_par[k]
                    ev_val[n_ev, 1] = 0.0
                    ev_val[n_ev, 2] = 0.0
                    n_ev += 1
            k += 1
    return touched, n_ev


@njit(cache=True, nogil=True)
def _face_events(x, o, face_par, tet_faces, faces, blade, ev_id, ev_val, n_ev):
    """EV_FACE events of active tet ``o``: each face the blade crosses (``face_par >= 0``, along
    the blade from its back), with the crossing's barycentric coordinates on the face; the
    crossings move the crack front (notch nodes F).  Returns the new event count."""
    q0, p1 = blade[0], blade[1]
    for lf in range(4):
        fp = face_par[lf]
        if fp < 0.0:
            continue
        f = tet_faces[o, lf]
        ev_id[n_ev, 0] = EV_FACE
        ev_id[n_ev, 1] = f
        _face_bary(x, faces[f], q0[0] + fp * (p1[0] - q0[0]), q0[1] + fp * (p1[1] - q0[1]),
                   q0[2] + fp * (p1[2] - q0[2]), ev_val, n_ev)
        n_ev += 1
    return n_ev


@njit(cache=True, nogil=True)
def sweep(x, mesh, stamp, step, cut, buf):
    """Local traversal of one step (markSwapFace, paper 4.2) and its events.

    Tets are popped from ``stack`` (last-in first-out; the caller pushes
    the seeds) and marked ``stamp[o] = step``.  A tet is *active* when the
    swept surface meets one of its edges, or the blade ``blade`` or the tip
    path ``p0 - blade[1]`` meets it; the unvisited neighbours of an active
    tet are pushed.  Per visited tet, in order: an EV_EDGE event for each
    uncut edge (``edge_t`` NaN) met by the swept surface; then, if active, an
    EV_FACE event for each face crossed by the blade.

    The buffers are the caller's (no allocation here).  When one might
    overflow, the kernel returns False *before* visiting the next tet with
    its progress in ``counts``; the caller enlarges the buffers and calls
    again to resume.

    Parameters
    ----------
    x : (n, 3) float64  node positions
    mesh : SweepMesh
        tets, neighbors, tet_edges, tet_faces : (m, 4|6) int64  original mesh tables;
        edges : (ne, 2) int64;  faces : (nf, 3) int64  global edges and faces;
        edge_t : (ne,) float64  cut parameter, NaN when uncut
    stamp : (m,) int64  visit stamps (modified)
    step : int  this step's stamp
    cut : SweepBlade
        swept : (2, 3, 3) float64  the two swept triangles;
        blade : (2, 3) float64  blade segment (back Q1, tip P1);
        p0 : (3,) float64  previous tip P0
    buf : SweepBuffers, the arrays below
    stack : (cs,) int64  tets to visit, ``stack[:counts[0]]``
    active : (ca,) int64  written: active tets in visit order, ``active[:counts[1]]``
    ev_id : (ce, 2) int64  written: (kind EV_EDGE | EV_FACE, global edge | face), ``[:counts[2]]``
    ev_val : (ce, 3) float64  written: EV_EDGE: [s, 0, 0], s along the edge from
        edges[e, 0]; EV_FACE: barycentric coordinates (on faces[f]) of the blade crossing
    counts : (3,) int64  (stack size, active count, event count), read and written

    Returns
    -------
    bool  True when done; False when a buffer must grow (then call again)
    """
    tets, neighbors, tet_edges, tet_faces = mesh.tets, mesh.neighbors, mesh.tet_edges, mesh.tet_faces
    edges, faces, edge_t = mesh.edges, mesh.faces, mesh.edge_t
    blade, p0 = cut.blade, cut.p0
    stack, active, ev_id, ev_val, counts = buf.stack, buf.active, buf.ev_id, buf.ev_val, buf.counts
    n_stack, n_active, n_ev = counts[0], counts[1], counts[2]
    edge_par = np.empty(6)
    face_par = np.empty(4)
    q0, p1 = blade[0], blade[1]
    done = True
    while n_stack > 0:
        if n_stack + 4 > stack.size or n_active >= active.size or n_ev + 10 > ev_id.shape[0]:
            done = False
            break
        n_stack -= 1
        o = stack[n_stack]
        if stamp[o] == step:
            continue
        stamp[o] = step
        tv = tets[o]
        tet_sweep(x, tv, cut.swept, blade, edge_par, face_par)
        touched, n_ev = _edge_events(o, tv, edge_par, tet_edges, edges, edge_t, ev_id, ev_val, n_ev)
        if not touched:
            touched = segment_meets_tet(q0, p1, x, tv) or segment_meets_tet(p0, p1, x, tv)
        if not touched:
            continue
        active[n_active] = o
        n_active += 1
        # blade crossings of this tet's faces move the crack front (notch nodes F)
        n_ev = _face_events(x, o, face_par, tet_faces, faces, blade, ev_id, ev_val, n_ev)
        for lf in range(4):
            nb = neighbors[o, lf]
            if nb >= 0 and stamp[nb] != step:
                stack[n_stack] = nb
                n_stack += 1
    counts[0] = n_stack
    counts[1] = n_active
    counts[2] = n_ev
    return done


@njit(cache=True, nogil=True)
def best_cone_apex(x, corners, tb, blends, tris, bary_min, spare):
    """The apex T of a cone over triangles with the largest smallest dihedral angle.

    Each candidate is ``clamp_bary((1 - w) tb + w / 4, bary_min)`` over the
    tet's ``corners`` for w in ``blends`` (from the cut nodes' centroid
    towards the tet's centroid); its cone is the tets ``(t0, t2, t1, T)`` of
    the triangles.  The first best candidate wins a tie.

    Parameters
    ----------
    x : (n, 3) float64
        Node positions; row ``spare`` (no node's) holds each candidate in turn.
    corners : (4,) int64
    tb : (4,) float64
    blends : (q,) float64
    tris : (k, 3) int64
    bary_min : float
    spare : int

    Returns
    -------
    (bary, angle) : (4,) float64 and float
        The best candidate's weights and the smallest dihedral angle of its cone, degrees.
    """
    k = tris.shape[0]
    cone = np.empty((k, 4), np.int64)
    for j in range(k):
        cone[j, 0], cone[j, 1], cone[j, 2], cone[j, 3] = tris[j, 0], tris[j, 2], tris[j, 1], spare
    normals = np.empty((4, 3))
    angles = np.empty((k, 6))
    best = -1.0
    best_b = np.zeros(4)
    for q in range(blends.shape[0]):
        b = clamp_bary((1.0 - blends[q]) * tb + 0.25 * blends[q], bary_min)
        for c in range(3):
            x[spare, c] = (b[0] * x[corners[0], c] + b[1] * x[corners[1], c] + b[2] * x[corners[2], c]
                           + b[3] * x[corners[3], c])
        worst = np.inf
        for j in range(k):
            tet_dihedrals(x, cone, j, normals, angles)
            for e in range(6):
                worst = min(worst, angles[j, e])
        if worst > best:
            best = worst
            best_b[:] = b
    return best_b, best


#: The cut state a kernel reads of one original tet's edges and faces: orig_tets (m, 4),
#: tet_edges (m, 6), tet_faces (m, 4), edges (E, 2) int64; edge_t (E,) float64 (NaN: uncut);
#: edge_node (E, 2) (the cut node's copy at either end), face_node (F, 3), face_ncut (F,) int64;
#: def_nodes (N, 4) int64, def_w (N, 4) float64 (each node's defining original nodes and weights);
#: face_diag (F,) int64 (a split face's fixed quad diagonal vertex, or -1); node_rep (n0,) int64
#: (each original node's representative among its coincident copies along earlier cuts).
CutTables = namedtuple("CutTables", ["orig_tets", "tet_edges", "tet_faces", "edges", "edge_t", "edge_node",
                                     "face_node", "face_ncut", "def_nodes", "def_w", "face_diag", "node_rep"])



@njit(cache=True, nogil=True)
def tet_mask(tet_edges, edge_t, o):
    """6-bit mask of the cut edges of original tet ``o`` (bit k: local edge k; cut = edge_t not NaN)."""
    mask = 0
    for k in range(6):
        t = edge_t[tet_edges[o, k]]
        if t == t:
            mask |= 1 << k
    return mask

@njit(cache=True, nogil=True)
def cut_nodes_centroid(ct, o, mask):
    """Barycentric weights (4,) over original tet ``o``'s corners of the mean of its cut nodes:
    the edge nodes of the edges in ``mask`` (6-bit) and the node of every notched face
    (the tip node T of a tet no tip is in, :meth:`CutMesh.resubdivide`)."""
    acc = np.zeros(4)
    n = 0
    for k in range(6):
        if mask >> k & 1:
            e = ct.tet_edges[o, k]
            i, j = TET_EDGES[k, 0], TET_EDGES[k, 1]
            s = ct.edge_t[e]
            if ct.edges[e, 0] == ct.orig_tets[o, i]:
                acc[i] += 1.0 - s
                acc[j] += s
            else:
                acc[i] += s
                acc[j] += 1.0 - s
            n += 1
    for lf in range(4):
        f = ct.tet_faces[o, lf]
        fn = ct.face_node[f, 0]
        if fn >= 0 and ct.face_ncut[f] >= 1:
            for q in range(3):
                a = ct.def_nodes[fn, q]
                for c in range(4):
                    if ct.orig_tets[o, c] == a:
                        acc[c] += ct.def_w[fn, q]
                        break
            n += 1
    return acc / n


@njit(cache=True, nogil=True)
def originals_holding(node_tet_off, node_tet_idx, tets, parents, out):
    """The original tets that hold each node's defining simplex; returns how many were written.

    Parameters
    ----------
    node_tet_off, node_tet_idx : (n + 1,) int64, (s,) int64
        The original tets around each original node (CSR).
    tets : (m, 4) int64
        The original tets' corners.
    parents : (q, 4) int64
        Each node's defining original nodes, -1 padded (an original node: itself, then -1).
    out : (r,) int64
        Room for the tets (at most the stars of the first parents together), repeats and all.
    """
    k = 0
    for i in range(parents.shape[0]):
        p0 = parents[i, 0]
        for j in range(node_tet_off[p0], node_tet_off[p0 + 1]):
            o = node_tet_idx[j]
            holds = True
            for c in range(1, 4):
                q = parents[i, c]
                if q >= 0 and tets[o, 0] != q and tets[o, 1] != q and tets[o, 2] != q and tets[o, 3] != q:
                    holds = False
                    break
            if holds:
                out[k] = o
                k += 1
    return k
