"""Numba kernels of the surface AABB hierarchy (paper section 4.1).

The kernels never check their inputs: :mod:`cutkit.collision.bvh` builds
and validates the arrays.  Tree layout (struct of arrays, node ids index
all of them): ``box_min``/``box_max`` (k, 3) float64, ``child`` (k, 2)
int64 (-1 for a leaf), ``parent`` (k,) int64 (-1 for the root),
``leaf_face`` (k,) int64 (-1 for an inner node).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from cutkit.mesh.geometry import segment_box, segment_triangle_hit

#: The hierarchy as its kernels read it (the module docstring's arrays) and its ``root`` node
#: (int, -1 when empty).
Tree = namedtuple("Tree", ["box_min", "box_max", "child", "parent", "leaf_face", "root"])
#: The boundary surface: ``faces`` (f, 3) int64, ``face_alive`` (f,) bool, and each face's leaf
#: node ``face_leaf`` (f,) int64.
Surface = namedtuple("Surface", ["faces", "face_alive", "face_leaf"])
#: The nodes' tolerance boxes (4.1): half size ``s_tol`` (float), ``tol_min`` / ``tol_max``
#: (n, 3) float64, and the faces around each node (CSR ``node_face_off`` (n_indexed_points + 1,)
#: int64, ``node_face_idx`` int64) among the first ``n_indexed_faces`` (int) faces.
Tolerances = namedtuple("Tolerances", ["s_tol", "tol_min", "tol_max", "node_face_off", "node_face_idx",
                                       "n_indexed_faces"])
#: Room for a segment's hits: ``face`` (cap,) int64, ``kind`` (cap,) int64 (see
#: :mod:`cutkit.mesh.geometry`), ``param`` (cap, 4) float64 (t, x, y, z).
HitRoom = namedtuple("HitRoom", ["face", "kind", "param"])


@njit(cache=True, nogil=True)
def pair_level(box_min, box_max, nodes, adj_off, adj_idx):
    """Greedy pairing of one level of boxes (Fig. 5b).

    The boxes of the level are visited in breadth-first order over their
    adjacency (one search per connected component, started at the lowest
    unvisited index); each box not yet paired is paired with its unpaired
    neighbour that minimises ``volume(parent) - volume(overlap)``
    (ties: the lower index).

    Parameters
    ----------
    box_min, box_max : (k, 3) float64
        Boxes of all nodes.
    nodes : (L,) int64
        Node ids of this level.
    adj_off : (L + 1,) int64, adj_idx : (nnz,) int64
        Adjacency between level positions (CSR, both directions).

    Returns
    -------
    first, second : (G,) int64
        Level positions of each group's members in order of creation
        (``second`` is -1 for a box that goes up alone).
    """
    n = nodes.shape[0]
    visited = np.zeros(n, dtype=np.bool_)
    paired = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    head = 0
    tail = 0
    for s in range(n):
        if visited[s]:
            continue
        visited[s] = True
        order[tail] = s
        tail += 1
        while head < tail:
            i = order[head]
            head += 1
            for k in range(adj_off[i], adj_off[i + 1]):
                j = adj_idx[k]
                if not visited[j]:
                    visited[j] = True
                    order[tail] = j
                    tail += 1
    first = np.empty(n, dtype=np.int64)
    second = np.empty(n, dtype=np.int64)
    g = 0
    for oi in range(n):
        i = order[oi]
        if paired[i]:
            continue
        paired[i] = True
        a = nodes[i]
        best = -1
        best_cost = np.inf
        for k in range(adj_off[i], adj_off[i + 1]):
            j = adj_idx[k]
            if paired[j]:
                continue
            b = nodes[j]
            vol_parent = 1.0
            vol_overlap = 1.0
            for ax in range(3):
                lo = min(box_min[a, ax], box_min[b, ax])
                hi = max(box_max[a, ax], box_max[b, ax])
                vol_parent *= hi - lo
                ilo = max(box_min[a, ax], box_min[b, ax])
                ihi = min(box_max[a, ax], box_max[b, ax])
                vol_overlap *= max(ihi - ilo, 0.0)
            cost = vol_parent - vol_overlap
            if cost < best_cost or (cost == best_cost and j < best):
                best_cost = cost
                best = j
        first[g] = i
        second[g] = best
        if best >= 0:
            paired[best] = True
        g += 1
    return first[:g], second[:g]


@njit(cache=True, nogil=True, inline="always")
def _refit_leaf(f, surface, tol, tree, counters):
    """Leaf box of face f from its corners' tolerance boxes, then its ancestors."""
    faces, tol_min, tol_max = surface.faces, tol.tol_min, tol.tol_max
    box_min, box_max, child = tree.box_min, tree.box_max, tree.child
    a = faces[f, 0]
    b = faces[f, 1]
    c = faces[f, 2]
    leaf = surface.face_leaf[f]
    for ax in range(3):
        box_min[leaf, ax] = min(tol_min[a, ax], tol_min[b, ax], tol_min[c, ax])
        box_max[leaf, ax] = max(tol_max[a, ax], tol_max[b, ax], tol_max[c, ax])
    counters[1] += 1
    node = tree.parent[leaf]
    while node >= 0:
        l = child[node, 0]
        r = child[node, 1]
        changed = False
        for ax in range(3):
            lo = min(box_min[l, ax], box_min[r, ax])
            hi = max(box_max[l, ax], box_max[r, ax])
            if lo != box_min[node, ax] or hi != box_max[node, ax]:
                changed = True
            box_min[node, ax] = lo
            box_max[node, ax] = hi
        counters[2] += 1
        if not changed:
            break
        node = tree.parent[node]


@njit(cache=True, nogil=True)
def refit(points, surface, tol, tree, counters):
    """Tolerance-box test of every node and local bottom-up refit (4.1).

    A node that left its tolerance box gets a new one centred on its
    position (half size ``s_tol``); the leaf boxes of the live faces around
    it are recomputed as the union of their corners' tolerance boxes
    (Fig. 5a) and each ancestor is recomputed from its two children, going
    up until a box does not change (the boxes above are then already
    consistent with it).

    Parameters
    ----------
    points : (n, 3) float64
    surface : Surface
        The faces in use (faces from ``tol.n_indexed_faces`` on, added by
        cuts since the index was made, are scanned one by one).
    tol : Tolerances
        Its boxes updated in place; nodes beyond the index have no faces
        there.
    tree : Tree
        Node boxes updated in place.
    counters : (3,) int64
        Incremented in place: nodes that left their tolerance box, leaf
        refits, inner-node refits.
    """
    faces, face_alive, tol_min, tol_max = surface.faces, surface.face_alive, tol.tol_min, tol.tol_max
    n = points.shape[0]
    moved = np.zeros(n, dtype=np.bool_)
    moved_ids = np.empty(n, dtype=np.int64)
    n_moved = 0
    for i in range(n):
        out = False
        for ax in range(3):
            x = points[i, ax]
            if x < tol_min[i, ax] or x > tol_max[i, ax]:
                out = True
        if out:
            moved[i] = True
            moved_ids[n_moved] = i
            n_moved += 1
            for ax in range(3):
                tol_min[i, ax] = points[i, ax] - tol.s_tol
                tol_max[i, ax] = points[i, ax] + tol.s_tol
    counters[0] += n_moved
    if n_moved == 0:
        return
    n_indexed_points = tol.node_face_off.shape[0] - 1
    for q in range(n_moved):
        i = moved_ids[q]
        if i >= n_indexed_points:
            continue
        for k in range(tol.node_face_off[i], tol.node_face_off[i + 1]):
            f = tol.node_face_idx[k]
            if not face_alive[f]:
                continue
            # refit a face once: from its lowest-numbered moved corner
            first = True
            for c in range(3):
                v = faces[f, c]
                if v < i and moved[v]:
                    first = False
            if first:
                _refit_leaf(f, surface, tol, tree, counters)
    for f in range(tol.n_indexed_faces, faces.shape[0]):
        if face_alive[f] and (moved[faces[f, 0]] or moved[faces[f, 1]] or moved[faces[f, 2]]):
            _refit_leaf(f, surface, tol, tree, counters)


@njit(cache=True, nogil=True)
def query_segment(points, surface, tree, p0, p1, hits):
    """Top-down traversal: every live face the segment p0-p1 meets.

    Parameters
    ----------
    points : (n, 3) float64
    surface : Surface
    tree : Tree
    p0, p1 : (3,) float64
    hits : HitRoom
        Filled with the first ``min(count, cap)`` hits.

    Returns
    -------
    count : int
        Number of hits (may exceed ``cap``: call again with more room).
    n_box_tests : int
        Boxes tested, for statistics.
    """
    faces, face_alive, box_min, box_max = surface.faces, surface.face_alive, tree.box_min, tree.box_max
    cap = hits.face.shape[0]
    count = 0
    n_box = 0
    if tree.root < 0:
        return 0, 0
    dx = p1[0] - p0[0]
    dy = p1[1] - p0[1]
    dz = p1[2] - p0[2]
    stack = np.empty(128, dtype=np.int64)
    out = np.empty(4, dtype=np.float64)
    stack[0] = tree.root
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        n_box += 1
        if not segment_box(p0[0], p0[1], p0[2], dx, dy, dz, box_min[node], box_max[node]):
            continue
        f = tree.leaf_face[node]
        if f >= 0:
            if not face_alive[f]:
                continue
            kind = segment_triangle_hit(p0, p1, points[faces[f, 0]], points[faces[f, 1]],
                                    points[faces[f, 2]], out)
            if kind >= 0:
                if count < cap:
                    hits.face[count] = f
                    hits.kind[count] = kind
                    for q in range(4):
                        hits.param[count, q] = out[q]
                count += 1
            continue
        if top + 2 > stack.shape[0]:
            grown = np.empty(2 * stack.shape[0], dtype=np.int64)
            grown[:top] = stack[:top]
            stack = grown
        stack[top] = tree.child[node, 1]
        stack[top + 1] = tree.child[node, 0]
        top += 2
    return count, n_box


@njit(cache=True, nogil=True)
def brute_segment(points, surface, p0, p1, hits):
    """Every live face the segment meets, testing all faces (no hierarchy).

    Same outputs as :func:`query_segment`; the reference the hierarchy is
    benchmarked against.
    """
    faces, face_alive = surface.faces, surface.face_alive
    cap = hits.face.shape[0]
    count = 0
    out = np.empty(4, dtype=np.float64)
    for f in range(faces.shape[0]):
        if not face_alive[f]:
            continue
        kind = segment_triangle_hit(p0, p1, points[faces[f, 0]], points[faces[f, 1]],
                                points[faces[f, 2]], out)
        if kind >= 0:
            if count < cap:
                hits.face[count] = f
                hits.kind[count] = kind
                for q in range(4):
                    hits.param[count, q] = out[q]
            count += 1
    return count


@njit(cache=True, nogil=True)
def adjacency_csr(pairs, n):
    """Symmetric, de-duplicated adjacency (CSR) from undirected pairs.

    Parameters
    ----------
    pairs : (e, 2) int64
        Adjacent positions; order, duplicates and self pairs allowed.
    n : int
        Number of positions.

    Returns
    -------
    off : (n + 1,) int64
    idx : (nnz,) int64
        Neighbours of i in ``idx[off[i]:off[i + 1]]``, increasing.
    """
    deg = np.zeros(n + 1, dtype=np.int64)
    for k in range(pairs.shape[0]):
        a = pairs[k, 0]
        b = pairs[k, 1]
        if a != b:
            deg[a + 1] += 1
            deg[b + 1] += 1
    for i in range(n):
        deg[i + 1] += deg[i]
    fill = deg[:n].copy()
    raw = np.empty(deg[n], dtype=np.int64)
    for k in range(pairs.shape[0]):
        a = pairs[k, 0]
        b = pairs[k, 1]
        if a != b:
            raw[fill[a]] = b
            fill[a] += 1
            raw[fill[b]] = a
            fill[b] += 1
    off = np.zeros(n + 1, dtype=np.int64)
    idx = np.empty(deg[n], dtype=np.int64)
    m = 0
    for i in range(n):
        lo = deg[i]
        hi = deg[i + 1]
        # insertion sort: rows are short (a face has three neighbours)
        for k in range(lo + 1, hi):
            x = raw[k]
            j = k - 1
            while j >= lo and raw[j] > x:
                raw[j + 1] = raw[j]
                j -= 1
            raw[j + 1] = x
        for k in range(lo, hi):
            if k == lo or raw[k] != raw[k - 1]:
                idx[m] = raw[k]
                m += 1
        off[i + 1] = m
    return off, idx[:m]
