"""Numba kernels of the swept-blade surface query (twins: ``tests/_twins_aabb.py``).

Two triangles meet when an edge of one crosses the other
(``cutkit.mesh.geometry.segment_triangle_hit``, closed, with its degenerate cases); the
hierarchy is descended while a node's box overlaps the query triangle's
box.
"""

from __future__ import annotations

import numpy as np
from numba import njit

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
