"""Numba kernels of the swept-blade surface query (twins: ``tests/_twins_aabb.py``).

Two triangles meet when an edge of one crosses the other
(``cutkit.mesh.geometry.segment_triangle_hit``, closed, with its degenerate cases); the
hierarchy is descended while a node's box overlaps the query triangle's
box.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cutkit.collision._kernels import HitRoom, query_segment
from cutkit.mesh.geometry import EPS_BOX, segment_triangle_hit


@njit(cache=True, nogil=True)
def tri_tri(a, b, c, u, v, w, out):
    """Whether triangles abc and uvw meet; ``out[1:4]`` receives a common point.

    An edge of either triangle crossing the other is found for every pair
    of triangles that meet (coplanar overlaps included, through the
    coplanar case of ``segment_triangle_hit``).
    """
    if segment_triangle_hit(u, v, a, b, c, out) >= 0 or segment_triangle_hit(v, w, a, b, c, out) >= 0 \
            or segment_triangle_hit(w, u, a, b, c, out) >= 0:
        return True
    return segment_triangle_hit(a, b, u, v, w, out) >= 0 or segment_triangle_hit(b, c, u, v, w, out) >= 0 \
        or segment_triangle_hit(c, a, u, v, w, out) >= 0


@njit(cache=True, nogil=True)
def _box_overlap(lo, hi, bmin, bmax):
    for d in range(3):
        pad = EPS_BOX * (bmax[d] - bmin[d] + hi[d] - lo[d]) + 1e-300
        if hi[d] < bmin[d] - pad or lo[d] > bmax[d] + pad:
            return False
    return True


@njit(cache=True, nogil=True)
def query_triangle(points, surface, tree, tri, hit_face, hit_point):
    """Every live face the triangle ``tri`` (3, 3) meets, by top-down traversal.

    Parameters
    ----------
    points : (n, 3) float64
    surface : _kernels.Surface;  tree : _kernels.Tree
    tri : (3, 3) float64
    hit_face : (cap,) int64;  hit_point : (cap, 3) float64  filled with the first min(count, cap) hits

    Returns
    -------
    int  number of hits (may exceed cap: call again with more room)
    """
    faces, face_alive, box_min, box_max = surface.faces, surface.face_alive, tree.box_min, tree.box_max
    cap = hit_face.shape[0]
    count = 0
    if tree.root < 0:
        return 0
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = min(tri[0, d], tri[1, d], tri[2, d])
        hi[d] = max(tri[0, d], tri[1, d], tri[2, d])
    out = np.empty(4)
    stack = np.empty(128, np.int64)
    stack[0] = tree.root
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if not _box_overlap(lo, hi, box_min[node], box_max[node]):
            continue
        f = tree.leaf_face[node]
        if f >= 0:
            if face_alive[f] and tri_tri(points[faces[f, 0]], points[faces[f, 1]], points[faces[f, 2]],
                                         tri[0], tri[1], tri[2], out):
                if count < cap:
                    hit_face[count] = f
                    for d in range(3):
                        hit_point[count, d] = out[1 + d]
                count += 1
            continue
        if top + 2 > stack.shape[0]:
            grown = np.empty(2 * stack.shape[0], np.int64)
            grown[:top] = stack[:top]
            stack = grown
        stack[top] = tree.child[node, 1]
        stack[top + 1] = tree.child[node, 0]
        top += 2
    return count


#: :func:`blade_entry`'s codes for how the blade entered (the order the tests are made in).
ENTRY_NONE, ENTRY_TIP_PATH, ENTRY_BLADE, ENTRY_SWEPT = -1, 0, 1, 2


@njit(cache=True, nogil=True, inline="always")
def _against(points, faces, f, d0, d1, d2):
    """Whether face ``f``'s outward normal (its corners' order) points against the motion d: n · d < 0."""
    a, b, c = points[faces[f, 0]], points[faces[f, 1]], points[faces[f, 2]]
    u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    v0, v1, v2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    return n0 * d0 + n1 * d1 + n2 * d2 < 0.0


@njit(cache=True, nogil=True)
def _segment_hits(points, surface, tree, a, b):
    """Every live face the segment a-b meets: (HitRoom, count)."""
    cap = 16
    while True:
        hits = HitRoom(np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty((cap, 4)))
        count, _ = query_segment(points, surface, tree, a, b, hits)
        if count <= cap:
            return hits, count
        cap = count


@njit(cache=True, nogil=True)
def _first_inward(points, faces, hits, count, a, b, point):
    """Of the ``count`` hits of the segment a-b, the face it crosses inwards first (least parameter,
    then least face id), its point in ``point``; -1 where it crosses none inwards."""
    best, best_t = -1, np.inf
    for i in range(count):
        f, t = hits.face[i], hits.param[i, 0]
        if (t < best_t or (t == best_t and f < best)) and \
                _against(points, faces, f, b[0] - a[0], b[1] - a[1], b[2] - a[2]):
            best, best_t = f, t
            for d in range(3):
                point[d] = hits.param[i, 1 + d]
    return best


@njit(cache=True, nogil=True)
def _swept_triangle(points, surface, tree, tri, flat_eps, faces, pts, n):
    """Append to (faces, pts)[n:] the faces triangle ``tri`` (3, 3) meets, unless it is flat
    (|u x v| at most ``flat_eps`` |u| |v|); returns (faces, pts, n), grown where the room was short."""
    u0, u1, u2 = tri[1, 0] - tri[0, 0], tri[1, 1] - tri[0, 1], tri[1, 2] - tri[0, 2]
    v0, v1, v2 = tri[2, 0] - tri[0, 0], tri[2, 1] - tri[0, 1], tri[2, 2] - tri[0, 2]
    w0, w1, w2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    if not np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) > flat_eps * np.sqrt(u0 * u0 + u1 * u1 + u2 * u2) \
            * np.sqrt(v0 * v0 + v1 * v1 + v2 * v2):
        return faces, pts, n
    while True:
        got = query_triangle(points, surface, tree, tri, faces[n:], pts[n:])
        if n + got <= faces.shape[0]:
            return faces, pts, n + got
        grown_f, grown_p = np.empty(2 * (n + got), np.int64), np.empty((2 * (n + got), 3))
        grown_f[:n], grown_p[:n] = faces[:n], pts[:n]
        faces, pts = grown_f, grown_p


@njit(cache=True, nogil=True)
def _nearest_swept(points, surface, faces, pts, n, p0, q0, motion, point):
    """Of the first ``n`` (face, point) rows (a face's first row counts), the face whose normal points
    against ``motion`` with its point nearest the blade's previous pose q0-p0 (ties: the least face
    id); its point in ``point``; -1 where none."""
    e0, e1, e2 = p0[0] - q0[0], p0[1] - q0[1], p0[2] - q0[2]
    ee = e0 * e0 + e1 * e1 + e2 * e2
    best, best_d = -1, np.inf
    for i in range(n):
        f = faces[i]
        seen = False
        for j in range(i):
            if faces[j] == f:
                seen = True
                break
        if seen or not _against(points, surface.faces, f, motion[0], motion[1], motion[2]):
            continue
        r0, r1, r2 = pts[i, 0] - q0[0], pts[i, 1] - q0[1], pts[i, 2] - q0[2]
        s = 0.0 if ee == 0.0 else min(max((r0 * e0 + r1 * e1 + r2 * e2) / ee, 0.0), 1.0)
        g0, g1, g2 = pts[i, 0] - (q0[0] + s * e0), pts[i, 1] - (q0[1] + s * e1), pts[i, 2] - (q0[2] + s * e2)
        dist = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        if dist < best_d or (dist == best_d and f < best):
            best, best_d = f, dist
            for d in range(3):
                point[d] = pts[i, d]
    return best


@njit(cache=True, nogil=True)
def blade_entry(points, surface, tree, p0, q0, p1, q1, flat_eps, point):
    """Where the blade moving from (tip p0, back q0) to (p1, q1) enters the surface, in one call.

    In order: the tip's path crossing a face inwards; the blade at its new pose crossing one inwards
    from back to tip; the face the swept quad (p0, q0, q1) + (p0, q1, p1) or the blade now meets
    whose normal points against the mean motion, nearest the previous blade (section 4.1, extended).

    Parameters
    ----------
    points : (n, 3) float64
    surface : _kernels.Surface;  tree : _kernels.Tree
    p0, q0, p1, q1 : (3,) float64
    flat_eps : float
        A swept triangle with |u x v| at most this times |u| |v| is flat, not queried.
    point : (3,) float64
        Receives the contact's point.

    Returns
    -------
    code : int  ENTRY_NONE, ENTRY_TIP_PATH, ENTRY_BLADE or ENTRY_SWEPT
    face : int  the face met (-1 with ENTRY_NONE)
    """
    if p0[0] != p1[0] or p0[1] != p1[1] or p0[2] != p1[2]:
        hits, count = _segment_hits(points, surface, tree, p0, p1)
        f = _first_inward(points, surface.faces, hits, count, p0, p1, point)
        if f >= 0:
            return ENTRY_TIP_PATH, f
    # the blade now (q1-p1): its hits serve its own test and the swept faces below, queried once
    blade, n_blade = HitRoom(np.empty(0, np.int64), np.empty(0, np.int64), np.empty((0, 4))), 0
    if q1[0] != p1[0] or q1[1] != p1[1] or q1[2] != p1[2]:
        blade, n_blade = _segment_hits(points, surface, tree, q1, p1)
        f = _first_inward(points, surface.faces, blade, n_blade, q1, p1, point)
        if f >= 0:
            return ENTRY_BLADE, f
    quad = np.empty((2, 3, 3))  # the swept quad as the triangles (p0, q0, q1) and (p0, q1, p1)
    for d in range(3):
        quad[0, 0, d], quad[0, 1, d], quad[0, 2, d] = p0[d], q0[d], q1[d]
        quad[1, 0, d], quad[1, 1, d], quad[1, 2, d] = p0[d], q1[d], p1[d]
    faces, pts = np.empty(64, np.int64), np.empty((64, 3))
    faces, pts, n = _swept_triangle(points, surface, tree, quad[0], flat_eps, faces, pts, np.int64(0))  # one compile
    faces, pts, n = _swept_triangle(points, surface, tree, quad[1], flat_eps, faces, pts, n)
    if n + n_blade > faces.shape[0]:
        grown_f, grown_p = np.empty(n + n_blade, np.int64), np.empty((n + n_blade, 3))
        grown_f[:n], grown_p[:n] = faces[:n], pts[:n]
        faces, pts = grown_f, grown_p
    for i in range(n_blade):
        faces[n + i] = blade.face[i]
        for d in range(3):
            pts[n + i, d] = blade.param[i, 1 + d]
    n += n_blade
    motion = 0.5 * ((p1 - p0) + (q1 - q0))
    f = _nearest_swept(points, surface, faces, pts, n, p0, q0, motion, point)
    return (ENTRY_SWEPT, f) if f >= 0 else (ENTRY_NONE, -1)
