"""Numba legality test of one half-edge collapse ``u -> v`` (u removed, v kept).

The rules (documented in docs/decimation.md) in the order they are tried,
cheapest and most often failing first:

1. shape: every tet of ``u`` that survives (does not contain ``v``) stays
   positively oriented with ``6 V > vol_eps`` and its smallest dihedral angle
   at least ``min(min_dihedral, smallest dihedral now in the star of u)``:
   a collapse never creates an angle below the threshold and never makes the
   local minimum worse;
2. link condition of Edelsbrunner/Dey et al. for the tet complex: the common
   neighbours of ``u`` and ``v`` are exactly the vertices of the tets around
   the edge, every triangle ``u w x`` with a twin ``v w x`` spans a tet
   ``u v w x``, and no face has ``u`` on one side and ``v`` on the other;
   no other vertex loses its last tet;
3. surface (boundary and tissue interfaces, "S-faces"), when ``u`` lies on S:
   ``v`` lies on every sheet (label pair) that ``u`` lies on, the link
   condition again with a virtual vertex coned to S, no S-face turns by more
   than the normal limit, and the original surface points that ``u``
   represents, plus samples of the new S-faces, stay within the surface
   tolerance of the new/old S-faces.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cutkit.decimate._pool import C_STAMP
from cutkit.mesh.geometry import point_on_triangle, point_triangle_dist2, tet_max_cos, tet_volume6

#: Slots of the ``params`` (float64) array.
P_H = 0  # reference edge length, mm
P_COS_MIN = 1  # cos(min_dihedral)
P_TOL = 2  # surface tolerance, mm
P_NORMAL_COS = 3  # cos of the largest turn of an S-face normal
P_W_SURFACE = 4  # cost factor of a surface vertex
P_W_TOUCH = 5  # cost factor of an interior vertex collapsing onto S
P_VOL_EPS = 6  # smallest 6*volume of a tet, mm^3
P_SURF_SAFETY = 7  # fraction of the tolerance one collapse may use
N_PARAMS = 8


@njit(cache=True, inline="always")
def _has(tets, t, x):
    return tets[t, 0] == x or tets[t, 1] == x or tets[t, 2] == x or tets[t, 3] == x


@njit(cache=True, inline="always")
def _swap(x, u, v):
    return v if x == u else x


@njit(cache=True)
def surface_faces(x, stars, labels, faces):
    """S-faces (boundary or tissue interface) around vertex ``x`` (``stars`` a ``_state.Stars``;
    ``faces`` the outputs ``(fa, fb, fs0, fs1)``).

    Each S-face ``(x, fa[i], fb[i])`` is written once, with its sheet
    ``(fs0[i], fs1[i])``: the two labels on its sides, sorted, ``-1`` for the
    outside.  Returns the number of S-faces; the outputs need room for
    ``3 * adj_len[x]`` entries.  ``(fa, fb)`` follow the order of the vertices
    in the tet the face came from, so that ``cross(fa - x, fb - x)`` keeps its
    sense when ``x`` is replaced by another point.
    """
    tets, adj_start, adj_len, pool = stars.tets, stars.adj_start, stars.adj_len, stars.pool
    fa, fb, fs0, fs1 = faces
    s0 = adj_start[x]
    n = adj_len[x]
    # Every tet of x has three faces through x, named by their other two
    # vertices; a face inside the mesh shows up twice.  Sorting the names
    # pairs the twins up in O(k log k) instead of searching the star.
    k = 3 * n
    key = np.empty(k, np.int64)
    ea = np.empty(k, np.int64)
    eb = np.empty(k, np.int64)
    et = np.empty(k, np.int64)
    big = adj_start.shape[0]
    j = 0
    for i in range(n):
        t = pool[s0 + i]
        o0 = -1
        o1 = -1
        o2 = -1
        for c in range(4):
            w = tets[t, c]
            if w != x:
                if o0 < 0:
                    o0 = w
                elif o1 < 0:
                    o1 = w
                else:
                    o2 = w
        for pair in range(3):
            if pair == 0:
                a, b = o0, o1
            elif pair == 1:
                a, b = o1, o2
            else:
                a, b = o0, o2
            ea[j] = a
            eb[j] = b
            et[j] = t
            key[j] = min(a, b) * big + max(a, b)
            j += 1
    order = np.argsort(key)
    count = 0
    i = 0
    while i < k:
        p = order[i]
        lab = labels[et[p]]
        if i + 1 < k and key[order[i + 1]] == key[p]:
            lab2 = labels[et[order[i + 1]]]
            if lab != lab2:  # interface: written once, from the lower label's side
                q = p if lab < lab2 else order[i + 1]
                fa[count] = ea[q]
                fb[count] = eb[q]
                fs0[count] = min(lab, lab2)
                fs1[count] = max(lab, lab2)
                count += 1
            i += 2
        else:
            fa[count] = ea[p]
            fb[count] = eb[p]
            fs0[count] = -1
            fs1[count] = lab
            count += 1
            i += 1
    return count


@njit(cache=True)
def _new_stamp(counters):
    counters[C_STAMP] += 1
    return counters[C_STAMP]


@njit(cache=True)
def label_volume_change(u, v, points, tets, tet_lab, adj_start, adj_len, pool, dvol):
    """Change of each label's volume (mm^3) by the collapse ``u -> v``, written to ``dvol``."""
    dvol[:] = 0.0
    s0 = adj_start[u]
    for i in range(adj_len[u]):
        t = pool[s0 + i]
        a, b, c, d = tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3]
        before = tet_volume6(points[a], points[b], points[c], points[d])
        after = 0.0
        if not _has(tets, t, v):
            a, b, c, d = _swap(a, u, v), _swap(b, u, v), _swap(c, u, v), _swap(d, u, v)
            after = tet_volume6(points[a], points[b], points[c], points[d])
        dvol[tet_lab[t]] += (after - before) / 6.0


# ---------------------------------------------------------------------------
# The rules, one function each (numbered as in the module docstring).  Each
# returns whether the collapse passes it; the distance rules also carry the
# largest squared distance found so far.
# ---------------------------------------------------------------------------


@njit(cache=True)
def shape_rule(u, v, points, stars, tet_maxcos, params, new_maxcos):
    """Rule 1: the surviving tets of ``u`` keep ``6 V > vol_eps`` and no worse a dihedral angle.

    Also refuses a collapse that kills no tet (``u v`` is not an edge).
    Writes the new largest dihedral cosine of each surviving tet of ``u``'s
    list to ``new_maxcos``.
    """
    tets, adj_start, adj_len, pool = stars.tets, stars.adj_start, stars.adj_len, stars.pool
    su0 = adj_start[u]
    nsu = adj_len[u]
    old_worst = -1.0
    for i in range(nsu):
        old_worst = max(old_worst, tet_maxcos[pool[su0 + i]])
    thr = max(params[P_COS_MIN], old_worst)
    # Volumes first (cheap; a flat or inverted tet is the usual failure),
    # dihedral angles only if every volume passes.
    n_dying = 0
    for i in range(nsu):
        t = pool[su0 + i]
        if _has(tets, t, v):
            n_dying += 1
            continue
        a, b, c, d = _swap(tets[t, 0], u, v), _swap(tets[t, 1], u, v), _swap(tets[t, 2], u, v), _swap(tets[t, 3], u, v)
        if tet_volume6(points[a], points[b], points[c], points[d]) <= params[P_VOL_EPS]:
            return False
    if n_dying == 0:
        return False
    for i in range(nsu):
        t = pool[su0 + i]
        if _has(tets, t, v):
            continue
        a, b, c, d = _swap(tets[t, 0], u, v), _swap(tets[t, 1], u, v), _swap(tets[t, 2], u, v), _swap(tets[t, 3], u, v)
        mc = tet_max_cos(points[a], points[b], points[c], points[d])
        if mc > thr:
            return False
        new_maxcos[i] = mc
    return True


@njit(cache=True)
def vertex_link_rule(u, v, tets, adj_start, adj_len, pool, mark, mark2, counters):
    """Rule 2a: the common neighbours of ``u`` and ``v`` are the vertices of the tets around the edge.

    Returns ``(ok, ring_stamp)``: the vertices of the tets around the edge
    carry ``mark2 == ring_stamp`` afterwards (for :func:`edge_triangle_link_rule`).
    """
    su0 = adj_start[u]
    nsu = adj_len[u]
    sv0 = adj_start[v]
    nsv = adj_len[v]
    st1 = _new_stamp(counters)
    for i in range(nsu):
        t = pool[su0 + i]
        for k in range(4):
            mark[tets[t, k]] = st1
    st2 = _new_stamp(counters)
    for i in range(nsu):
        t = pool[su0 + i]
        if _has(tets, t, v):
            for k in range(4):
                mark2[tets[t, k]] = st2
    for i in range(nsv):
        t = pool[sv0 + i]
        for k in range(4):
            w = tets[t, k]
            if w != u and w != v and mark[w] == st1 and mark2[w] != st2:
                return False, st2
    return True, st2


@njit(cache=True)
def no_orphan_rule(u, v, tets, adj_start, adj_len, pool):
    """Rule 2b: no vertex of a dying tet loses its last tet.

    Every vertex w of a dying tet needs a tet without u or without v
    (usually its first one).
    """
    su0 = adj_start[u]
    for i in range(adj_len[u]):
        t = pool[su0 + i]
        if not _has(tets, t, v):
            continue
        for k in range(4):
            w = tets[t, k]
            if w == u or w == v:
                continue
            keeps = False
            sw0 = adj_start[w]
            for i2 in range(adj_len[w]):
                t2 = pool[sw0 + i2]
                if not (_has(tets, t2, u) and _has(tets, t2, v)):
                    keeps = True
                    break
            if not keeps:
                return False
    return True


@njit(cache=True)
def edge_triangle_link_rule(u, v, tets, adj_start, adj_len, pool, mark2, ring_stamp):
    """Rule 2c: the edge and triangle links.

    A link edge w x (or triangle) shared by u and v has all its vertices in
    N(u) & N(v), which :func:`vertex_link_rule` showed to be the ring of the
    edge (``mark2 == ring_stamp``): only those few candidates are looked at.
    Every triangle ``u w x`` with a twin ``v w x`` must span a tet
    ``u v w x``, and no face may have ``u`` on one side and ``v`` on the other.
    """
    su0 = adj_start[u]
    nsu = adj_len[u]
    sv0 = adj_start[v]
    nsv = adj_len[v]
    for i in range(nsu):
        t = pool[su0 + i]
        if _has(tets, t, v):
            continue
        o0 = -1
        o1 = -1
        o2 = -1
        for k in range(4):
            w = tets[t, k]
            if w != u:
                if o0 < 0:
                    o0 = w
                elif o1 < 0:
                    o1 = w
                else:
                    o2 = w
        r0 = mark2[o0] == ring_stamp
        r1 = mark2[o1] == ring_stamp
        r2 = mark2[o2] == ring_stamp
        if r0 and r1 and r2:
            for i2 in range(nsv):
                s = pool[sv0 + i2]
                if _has(tets, s, o0) and _has(tets, s, o1) and _has(tets, s, o2):
                    return False  # face o has u on one side and v on the other
        for pair in range(3):
            if pair == 0:
                w, x, ok_pair = o0, o1, r0 and r1
            elif pair == 1:
                w, x, ok_pair = o1, o2, r1 and r2
            else:
                w, x, ok_pair = o0, o2, r0 and r2
            if not ok_pair:
                continue
            twin = False
            for i2 in range(nsv):
                s = pool[sv0 + i2]
                if _has(tets, s, w) and _has(tets, s, x):
                    twin = True
                    break
            if twin:
                spans = False
                for i2 in range(nsu):
                    s = pool[su0 + i2]
                    if _has(tets, s, v) and _has(tets, s, w) and _has(tets, s, x):
                        spans = True
                        break
                if not spans:
                    return False
    return True


@njit(cache=True)
def sheet_rule(v, nu, fa, fb, fs0, fs1):
    """Rule 3a: ``v`` lies on every sheet of ``u``, along an S-edge of that sheet (u's S-faces given)."""
    for i in range(nu):
        found = False
        for j in range(nu):
            if fs0[j] == fs0[i] and fs1[j] == fs1[i] and (fa[j] == v or fb[j] == v):
                found = True
                break
        if not found:
            return False
    return True


@njit(cache=True)
def surface_link_rule(v, nu, fa, fb, nv, ga, gb, mark, counters):
    """Rule 3b: the link condition with a virtual vertex coned to S.

    A common S-neighbour w of u and v needs the S-face u v w; no S-face pair
    u w x / v w x.  ``fa, fb`` (``nu``) and ``ga, gb`` (``nv``) are the
    S-faces of u and of v.
    """
    st3 = _new_stamp(counters)
    for j in range(nv):
        mark[ga[j]] = st3
        mark[gb[j]] = st3
    for i in range(nu):
        for w in (fa[i], fb[i]):
            if w == v or mark[w] != st3:
                continue
            spans = False
            for j in range(nu):
                if (fa[j] == v and fb[j] == w) or (fa[j] == w and fb[j] == v):
                    spans = True
                    break
            if not spans:
                return False
        if fa[i] != v and fb[i] != v:
            for j in range(nv):
                if (ga[j] == fa[i] and gb[j] == fb[i]) or (ga[j] == fb[i] and gb[j] == fa[i]):
                    return False
    return True


@njit(cache=True)
def normal_rule(u, v, points, nu, fa, fb, params):
    """Rule 3c: no S-face of ``u`` turns by more than the normal limit (a local fold test)."""
    pu = points[u]
    pv = points[v]
    for i in range(nu):
        if fa[i] == v or fb[i] == v:
            continue
        a = points[fa[i]]
        b = points[fb[i]]
        n0x = (a[1] - pu[1]) * (b[2] - pu[2]) - (a[2] - pu[2]) * (b[1] - pu[1])
        n0y = (a[2] - pu[2]) * (b[0] - pu[0]) - (a[0] - pu[0]) * (b[2] - pu[2])
        n0z = (a[0] - pu[0]) * (b[1] - pu[1]) - (a[1] - pu[1]) * (b[0] - pu[0])
        n1x = (a[1] - pv[1]) * (b[2] - pv[2]) - (a[2] - pv[2]) * (b[1] - pv[1])
        n1y = (a[2] - pv[2]) * (b[0] - pv[0]) - (a[0] - pv[0]) * (b[2] - pv[2])
        n1z = (a[0] - pv[0]) * (b[1] - pv[1]) - (a[1] - pv[1]) * (b[0] - pv[0])
        l0 = math.sqrt(n0x * n0x + n0y * n0y + n0z * n0z)
        l1 = math.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
        if l1 == 0.0 or n0x * n1x + n0y * n1y + n0z * n1z < params[P_NORMAL_COS] * l0 * l1:
            return False
    return True


@njit(cache=True)
def volume_balance_rule(u, v, points, stars, tet_lab, budget):
    """Rule 3d: no label's volume drift goes beyond its budget, unless the collapse brings it back towards zero."""
    vol_drift, vol_budget = budget.vol_drift, budget.vol_budget
    dvol = np.empty(vol_drift.shape[0])
    label_volume_change(u, v, points, stars.tets, tet_lab, stars.adj_start, stars.adj_len, stars.pool, dvol)
    for lab in range(dvol.shape[0]):
        after = vol_drift[lab] + dvol[lab]
        if abs(after) > vol_budget[lab] and abs(after) > abs(vol_drift[lab]):
            return False
    return True


@njit(cache=True)
def own_points_distance_rule(u, v, points, owners, faces_u, faces_v, tol2, worst):
    """Rule 3e, the points ``u`` and ``v`` represent: within the tolerance of the S-faces after the collapse.

    The points of u go to the new S-faces; those of v to the new S-faces and
    v's S-faces that stay (``faces_u`` = (nu, fa, fb), ``faces_v`` = (nv, ga, gb):
    :func:`surface_faces` of u and of v).  Returns ``(ok, worst)``, ``worst`` the
    largest squared distance so far (in: from the rules before).
    """
    own_pts, own_next = owners.own_pts, owners.own_next
    nu, fa, fb = faces_u
    nv, ga, gb = faces_v
    pv = points[v]
    r = u
    while r >= 0:
        pr = own_pts[r]
        best = np.inf
        for i in range(nu):
            if fa[i] == v or fb[i] == v:
                continue
            best = min(best, point_triangle_dist2(pr, pv, points[fa[i]], points[fb[i]]))
        worst = max(worst, best)
        if worst > tol2:
            return False, worst
        r = own_next[r]
    r = own_next[v]
    while r >= 0:
        pr = own_pts[r]
        best = np.inf
        for i in range(nu):
            if fa[i] == v or fb[i] == v:
                continue
            best = min(best, point_triangle_dist2(pr, pv, points[fa[i]], points[fb[i]]))
        for j in range(nv):
            if ga[j] == u or gb[j] == u:
                continue
            best = min(best, point_triangle_dist2(pr, pv, points[ga[j]], points[gb[j]]))
        worst = max(worst, best)
        if worst > tol2:
            return False, worst
        r = own_next[r]
    return True, worst


@njit(cache=True)
def neighbour_points_distance_rule(u, v, state, faces_u, counters, tol2, worst):
    """Rule 3e, the points the other S-neighbours w of ``u`` represent.

    Each goes to the S-faces around w after the collapse (u replaced by v,
    faces holding both gone).  ``state`` a ``_state.Decimation``, ``faces_u``
    as for :func:`own_points_distance_rule`.  Returns ``(ok, worst)`` as
    :func:`own_points_distance_rule`.
    """
    points, labels, stars = state.mesh.points, state.mesh.labels, state.stars
    own_pts, own_next, mark = state.owners.own_pts, state.owners.own_next, state.marks[0]
    nu, fa, fb = faces_u
    pv = points[v]
    st4 = _new_stamp(counters)
    for i in range(nu):
        for w in (fa[i], fb[i]):
            if w == v or mark[w] == st4:
                continue
            mark[w] = st4
            if own_next[w] < 0:
                continue
            nw = 3 * stars.adj_len[w]
            ha = np.empty(nw, np.int64)
            hb = np.empty(nw, np.int64)
            hs0 = np.empty(nw, np.int64)
            hs1 = np.empty(nw, np.int64)
            nfw = surface_faces(w, stars, labels, (ha, hb, hs0, hs1))
            r = own_next[w]
            while r >= 0:
                pr = own_pts[r]
                best = np.inf
                for j in range(nfw):
                    a = ha[j]
                    b = hb[j]
                    if (a == u and b == v) or (a == v and b == u):
                        continue
                    pa = pv if a == u else points[a]
                    pb = pv if b == u else points[b]
                    best = min(best, point_triangle_dist2(pr, points[w], pa, pb))
                worst = max(worst, best)
                if worst > tol2:
                    return False, worst
                r = own_next[r]
    return True, worst


@njit(cache=True)
def sample_distance_rule(u, v, points, nu, fa, fb, tol2, worst):
    """Rule 3e, samples of the new S-faces (centroid, two edge midpoints): to the S-faces of ``u`` now.

    Returns ``(ok, worst)`` as :func:`own_points_distance_rule`.
    """
    pu = points[u]
    pv = points[v]
    sample = np.empty(3)
    for i in range(nu):
        if fa[i] == v or fb[i] == v:
            continue
        a = points[fa[i]]
        b = points[fb[i]]
        for m in range(3):
            if m == 0:
                for c in range(3):
                    sample[c] = (pv[c] + a[c] + b[c]) / 3.0
            elif m == 1:
                for c in range(3):
                    sample[c] = 0.5 * (pv[c] + a[c])
            else:
                for c in range(3):
                    sample[c] = 0.5 * (pv[c] + b[c])
            best = np.inf
            for j in range(nu):
                best = min(best, point_triangle_dist2(sample, pu, points[fa[j]], points[fb[j]]))
            worst = max(worst, best)
        if worst > tol2:
            return False, worst
    return True, worst


@njit(cache=True)
def can_collapse(u, v, state, counters, params, new_maxcos):
    """Whether the half-edge collapse ``u -> v`` is legal; returns ``(ok, surface_error_mm)``.

    The rules of the module docstring, in order (the ``*_rule`` functions
    above); the surface rules only when ``u`` lies on S (``vclass[u] != 0``).

    ``new_maxcos`` (>= adj_len[u],) float64 receives, when the collapse is
    legal, the largest dihedral cosine of each tet of ``u``'s list after the
    collapse (entries of the tets that die are left alone), for
    :func:`cutkit.decimate._kernels.collapse`.

    ``state`` is the ``_state.Decimation``: its owners' ``own_pts`` (n + k, 3)
    hold the original surface points (the n nodes, then the centroids of the
    original S-faces), ``own_next`` links the ones each vertex represents (a
    list that starts at the vertex itself and ends with -1); its budget the
    volume each label has gained so far and the drift allowed.
    """
    mesh, stars = state.mesh, state.stars
    points, labels, vclass = mesh.points, mesh.labels, mesh.vclass
    tets, adj_start, adj_len, pool = stars.tets, stars.adj_start, stars.adj_len, stars.pool
    mark, mark2 = state.marks
    # 1. shape; 2. link conditions of the tet complex
    if not shape_rule(u, v, points, stars, mesh.tet_maxcos, params, new_maxcos):
        return False, 0.0
    ok, ring = vertex_link_rule(u, v, tets, adj_start, adj_len, pool, mark, mark2, counters)
    if not ok:
        return False, 0.0
    if not no_orphan_rule(u, v, tets, adj_start, adj_len, pool):
        return False, 0.0
    if not edge_triangle_link_rule(u, v, tets, adj_start, adj_len, pool, mark2, ring):
        return False, 0.0
    if vclass[u] == 0:
        return True, 0.0

    # 3. surface rules, over the S-faces of u and of v
    nsu = adj_len[u]
    nsv = adj_len[v]
    fa = np.empty(3 * nsu, np.int64)
    fb = np.empty(3 * nsu, np.int64)
    fs0 = np.empty(3 * nsu, np.int64)
    fs1 = np.empty(3 * nsu, np.int64)
    nu = surface_faces(u, stars, labels, (fa, fb, fs0, fs1))
    if not sheet_rule(v, nu, fa, fb, fs0, fs1):
        return False, 0.0
    ga = np.empty(3 * nsv, np.int64)
    gb = np.empty(3 * nsv, np.int64)
    gs0 = np.empty(3 * nsv, np.int64)
    gs1 = np.empty(3 * nsv, np.int64)
    nv = surface_faces(v, stars, labels, (ga, gb, gs0, gs1))
    if not surface_link_rule(v, nu, fa, fb, nv, ga, gb, mark, counters):
        return False, 0.0
    if not normal_rule(u, v, points, nu, fa, fb, params):
        return False, 0.0
    if not volume_balance_rule(u, v, points, stars, mesh.tet_lab, state.budget):
        return False, 0.0
    # 3e. distance, both ways: original points -> new S-faces, samples of the new S-faces -> S now
    tol = params[P_TOL] * params[P_SURF_SAFETY]
    tol2 = tol * tol
    ok, worst = own_points_distance_rule(u, v, points, state.owners, (nu, fa, fb), (nv, ga, gb), tol2, 0.0)
    if ok:
        ok, worst = neighbour_points_distance_rule(u, v, state, (nu, fa, fb), counters, tol2, worst)
    if ok:
        ok, worst = sample_distance_rule(u, v, points, nu, fa, fb, tol2, worst)
    return ok, math.sqrt(worst)


@njit(cache=True)
def conforming_after(u, v, state):
    """Rule 4: no boundary node lies on an outer boundary face the collapse ``u -> v`` makes.

    Such a node hangs (``cutkit check`` refuses the mesh): thin structures
    whose two sides touch put nodes of one side on the plane of the other's
    faces.  Nodes never move in a half-edge collapse, so the boundary nodes
    are binned once: ``bnd_keys`` their sorted linear cell keys,
    ``bnd_nodes`` the node of each, ``grid`` = (lo x, y, z, cell size,
    cells along x, y, z, relative tolerance): ``state.boundary``.  Run after :func:`can_collapse`
    found the collapse legal (``u`` on the surface).
    """
    points, labels, vert_alive, stars = state.mesh.points, state.mesh.labels, state.mesh.vert_alive, state.stars
    bnd_keys, bnd_nodes, grid = state.boundary
    nsu = stars.adj_len[u]
    fa = np.empty(3 * nsu, np.int64)
    fb = np.empty(3 * nsu, np.int64)
    fs0 = np.empty(3 * nsu, np.int64)
    fs1 = np.empty(3 * nsu, np.int64)
    nu = surface_faces(u, stars, labels, (fa, fb, fs0, fs1))
    h = grid[3]
    rel_tol = grid[7]
    dims = np.empty(3, np.int64)
    for d in range(3):
        dims[d] = int(grid[4 + d])
    pv = points[v]
    i0 = np.empty(3, np.int64)
    i1 = np.empty(3, np.int64)
    for i in range(nu):
        if fs0[i] != -1 or fa[i] == v or fb[i] == v:
            continue  # an interface face, or one that dies with the edge
        a = fa[i]
        b = fb[i]
        pa = points[a]
        pb = points[b]
        big = 0.0
        for d in range(3):
            big = max(big, abs(pa[d] - pv[d]), abs(pb[d] - pv[d]), abs(pa[d] - pb[d]))
        tol = rel_tol * 2.0 * big
        for d in range(3):
            mn = min(pv[d], pa[d], pb[d]) - tol
            mx = max(pv[d], pa[d], pb[d]) + tol
            i0[d] = max(0, int(math.floor((mn - grid[d]) / h)))
            i1[d] = min(dims[d] - 1, int(math.floor((mx - grid[d]) / h)))
        for ci in range(i0[0], i1[0] + 1):
            for cj in range(i0[1], i1[1] + 1):
                for ck in range(i0[2], i1[2] + 1):
                    key = (ci * dims[1] + cj) * dims[2] + ck
                    s = np.searchsorted(bnd_keys, key)  # the first node of the cell
                    while s < bnd_keys.shape[0] and bnd_keys[s] == key:
                        x = bnd_nodes[s]
                        s += 1
                        if x == u or x == v or x == a or x == b or vert_alive[x] == 0:
                            continue
                        if point_on_triangle(points[x], pv, pa, pb, rel_tol):
                            return False
    return True
