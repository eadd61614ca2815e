"""Numba driver of the progressive decimation: costs, collapses and the main loop."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from cutkit.decimate._state import Stars
from cutkit.decimate._candidates import cheapest_neighbours, half_edge_key2, volume_gradients, volume_precheck
from cutkit.decimate._legality import (
    P_H,
    P_VOL_EPS,
    _new_stamp,
    can_collapse,
    conforming_after,
    label_volume_change,
    surface_faces,
)
from cutkit.decimate._pool import (
    C_ALIVE_TETS,
    C_COLLAPSES,
    C_CHECKS,
    C_HEAP_SIZE,
    C_POPS,
    C_PRECHECK_REJECTS,
    C_TARGET,
    heap_build,
    heap_pop,
    heap_push,
    pool_append,
    pool_remove,
)
from cutkit.mesh.geometry import tet_max_cos

#: Status codes of :func:`run_collapses`.
STATUS_BUDGET = 0  # stopped after max_pops heap entries; call again
STATUS_TARGET = 1  # the tet count reached the target
STATUS_EMPTY = 2  # no collapse left in the heap

#: Cheapest half-edges of a vertex tried per pop; a vertex whose candidates all
#: fail waits until a collapse changes its neighbourhood (or the next round).
MAX_CANDIDATES = 4
#: Star size the per-pop scratch arrays are made for (larger stars get their own).
STAR_SCRATCH = 256


@njit(cache=True, parallel=True)
def all_tet_max_cos(points, tets):
    """Largest dihedral cosine of every tet: (m,) float64."""
    out = np.empty(tets.shape[0])
    for t in prange(tets.shape[0]):
        out[t] = tet_max_cos(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
    return out


@njit(cache=True, parallel=True)
def shortest_edges(points, tets, stride):
    """Shortest edge of every ``stride``-th tet: (ceil(m / stride),) float64."""
    k = (tets.shape[0] + stride - 1) // stride
    out = np.empty(k)
    for i in prange(k):
        t = i * stride
        best = np.inf
        for a in range(4):
            for b in range(a + 1, 4):
                pa = points[tets[t, a]]
                pb = points[tets[t, b]]
                d = (pa[0] - pb[0]) ** 2 + (pa[1] - pb[1]) ** 2 + (pa[2] - pb[2]) ** 2
                best = min(best, d)
        out[i] = math.sqrt(best)
    return out


@njit(cache=True)
def build_adjacency(tets, n, slack):
    """Per-vertex tet lists in one pool with room to grow.

    Each list gets ``4`` spare slots; the pool gets ``slack`` spare entries
    after the last list.  Returns ``(adj_start, adj_len, adj_cap, pool, pool_end)``.
    """
    m = tets.shape[0]
    counts = np.zeros(n, np.int64)
    for t in range(m):
        for k in range(4):
            counts[tets[t, k]] += 1
    start = np.empty(n, np.int64)
    cap = counts + 4
    end = 0
    for x in range(n):
        start[x] = end
        end += cap[x]
    pool = np.empty(end + slack, np.int64)
    length = np.zeros(n, np.int64)
    for t in range(m):
        for k in range(4):
            x = tets[t, k]
            pool[start[x] + length[x]] = t
            length[x] += 1
    return start, length, cap, pool, end


@njit(cache=True, parallel=True)
def classify_vertices(tets, labels, adj_start, adj_len, pool):
    """1 for a vertex on a boundary or tissue-interface face (S), else 0: (n,) int8."""
    n = adj_start.shape[0]
    out = np.zeros(n, np.int8)
    for x in prange(n):
        m = 3 * adj_len[x]
        if m == 0:
            continue
        fa = np.empty(m, np.int64)
        fb = np.empty(m, np.int64)
        f0 = np.empty(m, np.int64)
        f1 = np.empty(m, np.int64)
        if surface_faces(np.int64(x), Stars(tets, adj_start, adj_len, pool), labels, (fa, fb, f0, f1)) > 0:
            out[x] = 1
    return out


@njit(cache=True, parallel=True)
def surface_face_points(points, tets, labels, adj_start, adj_len, pool, vclass):
    """Centroids of the S-faces and the vertex each is attached to (its smallest id).

    Returns
    -------
    owner : (k,) int64
    centroids : (k, 3) float64
    """
    n = adj_start.shape[0]
    counts = np.zeros(n + 1, np.int64)
    for x in prange(n):
        if vclass[x] == 0:
            continue
        m = 3 * adj_len[x]
        fa = np.empty(m, np.int64)
        fb = np.empty(m, np.int64)
        f0 = np.empty(m, np.int64)
        f1 = np.empty(m, np.int64)
        nf = surface_faces(np.int64(x), Stars(tets, adj_start, adj_len, pool), labels, (fa, fb, f0, f1))
        c = 0
        for i in range(nf):
            if x < fa[i] and x < fb[i]:
                c += 1
        counts[x + 1] = c
    offsets = np.cumsum(counts)
    owner = np.empty(offsets[n], np.int64)
    cen = np.empty((offsets[n], 3))
    for x in prange(n):
        if counts[x + 1] == 0:
            continue
        m = 3 * adj_len[x]
        fa = np.empty(m, np.int64)
        fb = np.empty(m, np.int64)
        f0 = np.empty(m, np.int64)
        f1 = np.empty(m, np.int64)
        nf = surface_faces(np.int64(x), Stars(tets, adj_start, adj_len, pool), labels, (fa, fb, f0, f1))
        j = offsets[x]
        for i in range(nf):
            if x < fa[i] and x < fb[i]:
                owner[j] = x
                for c in range(3):
                    cen[j, c] = (points[x, c] + points[fa[i], c] + points[fb[i], c]) / 3.0
                j += 1
    return owner, cen


@njit(cache=True)
def link_owned_points(owner, n, own_tail, own_next):
    """Append extra point ``n + j`` to the list of vertex ``owner[j]``."""
    for j in range(owner.shape[0]):
        x = owner[j]
        own_next[own_tail[x]] = n + j
        own_tail[x] = n + j


@njit(cache=True, inline="always")
def edge_cost(w, n, points, vclass, params):
    """Weight of the half-edge collapse ``w -> n`` (the weighting function, docs/decimation.md).

    ``|w n| / h`` times a factor (:func:`cutkit.decimate._candidates.cost_factor`):
    1 for an interior vertex, ``1 + w_touch`` when it collapses onto the
    surface (boundary or interface), ``w_surface`` for a surface vertex, which
    may only move onto another surface vertex (inf otherwise).  Interior
    vertices thus go first, shortest edges first, and surface detail last.
    """
    key2 = half_edge_key2(w, n, points, vclass, params)
    if key2 == np.inf:
        return np.inf
    return math.sqrt(key2) / params[P_H]


@njit(cache=True)
def best_cost(w, points, tets, adj_start, adj_len, pool, vclass, params):
    """Smallest :func:`edge_cost` over the neighbours of ``w`` (inf if none)."""
    best2 = np.inf
    s0 = adj_start[w]
    for i in range(adj_len[w]):
        t = pool[s0 + i]
        for k in range(4):
            n = tets[t, k]
            if n != w:
                best2 = min(best2, half_edge_key2(w, n, points, vclass, params))
    if best2 == np.inf:
        return np.inf
    return math.sqrt(best2) / params[P_H]


@njit(cache=True, parallel=True)
def _all_best_costs(mesh, stars, params):
    n = stars.adj_start.shape[0]
    out = np.full(n, np.inf)
    for w in prange(n):
        if mesh.vert_alive[w] and not mesh.locked[w]:
            out[w] = best_cost(np.int64(w), mesh.points, stars.tets, stars.adj_start, stars.adj_len, stars.pool, mesh.vclass,
                               params)
    return out


@njit(cache=True)
def push_all(state, counters, params):
    """Rebuild the heap with every movable vertex at its current cost (``state`` a ``_state.Decimation``).

    ``qkey[w]`` is the key of w's live heap entry (inf: w is not queued), a
    lower bound of its cost; ``qlow[w]`` a lower bound of the cost of a vertex
    that is not queued.
    """
    ver, qkey, qlow, heap_key, heap_u, heap_stamp = state.queue
    costs = _all_best_costs(state.mesh, state.stars, params)
    size = np.int64(0)  # not the literal 0: heap_build compiles once
    for w in range(costs.shape[0]):
        ver[w] += 1
        qkey[w] = costs[w]
        qlow[w] = costs[w]
        if costs[w] < np.inf:
            heap_key[size] = costs[w]
            heap_u[size] = w
            heap_stamp[size] = ver[w]
            size += 1
    heap_build(heap_key, heap_u, heap_stamp, size)
    counters[C_HEAP_SIZE] = size


@njit(cache=True)
def collapse(u, v, state, counters, new_maxcos):
    """Apply the (legal) half-edge collapse ``u -> v``: local updates only (``state`` a ``_state.Decimation``).

    ``new_maxcos`` (>= adj_len[u],) float64: the largest dihedral cosine of
    each tet of ``u``'s list after the collapse, as computed by
    :func:`cutkit.decimate._legality.can_collapse` (in the same list order).
    """
    tets, adj_start, adj_len, pool = state.stars
    adj_cap = state.room
    tet_alive, tet_maxcos, vert_alive, vclass = (state.mesh.tet_alive, state.mesh.tet_maxcos, state.mesh.vert_alive,
                                                 state.mesh.vclass)
    own_tail, own_next = state.owners.own_tail, state.owners.own_next
    s0 = adj_start[u]
    n = adj_len[u]
    # Copy u's list first: appending to v's list may move lists inside the pool.
    star = pool[s0 : s0 + n].copy()
    for i in range(n):
        t = star[i]
        if tets[t, 0] == v or tets[t, 1] == v or tets[t, 2] == v or tets[t, 3] == v:
            tet_alive[t] = 0
            counters[C_ALIVE_TETS] -= 1
            for k in range(4):
                w = tets[t, k]
                if w != u:
                    pool_remove(w, t, adj_start, adj_len, pool)
    for i in range(n):
        t = star[i]
        if tet_alive[t] == 0:
            continue
        for k in range(4):
            if tets[t, k] == u:
                tets[t, k] = v
        tet_maxcos[t] = new_maxcos[i]
        pool_append(v, t, adj_start, adj_len, adj_cap, pool, counters)
    adj_len[u] = 0
    vert_alive[u] = 0
    if vclass[u] != 0:
        # v now represents the original surface points of u (own lists are linked lists).
        own_next[own_tail[v]] = u
        own_tail[v] = own_tail[u]


@njit(cache=True)
def _try_vertex(u, nc, cand, scratch, state, counters, params):
    """Collapse ``u`` onto the first legal of its ``nc`` cheapest neighbours ``cand``; False if none is legal.

    ``scratch`` = (``grad`` (k, 3) float64, ``gbase`` (k,) int64, ``newcos``
    (k,) float64): space for :func:`volume_gradients` and the new dihedral
    cosines (replaced locally when the star is larger than k).  ``state`` a
    ``_state.Decimation``.
    """
    grad, gbase, newcos = scratch
    points, tets, vclass = state.mesh.points, state.stars.tets, state.mesh.vclass
    adj_start, adj_len, pool = state.stars.adj_start, state.stars.adj_len, state.stars.pool
    mark = state.marks[0]
    vol_drift = state.budget.vol_drift
    s0 = adj_start[u]
    n = adj_len[u]
    if grad.shape[0] < n:
        grad = np.empty((2 * n, 3))
        gbase = np.empty(2 * n, np.int64)
        newcos = np.empty(2 * n)
    volume_gradients(u, points, tets, adj_start, adj_len, pool, grad, gbase)
    for idx in range(nc):
        v = cand[idx]
        if not volume_precheck(u, v, points, state.stars, (grad, gbase), params[P_VOL_EPS]):
            counters[C_PRECHECK_REJECTS] += 1
            continue
        counters[C_CHECKS] += 1
        ok, _err = can_collapse(u, v, state, counters, params, newcos)
        if not ok:
            continue
        if vclass[u] != 0 and state.boundary.bnd_keys.shape[0] and not conforming_after(u, v, state):
            continue
        if vclass[u] != 0:
            dvol = np.empty(vol_drift.shape[0])
            label_volume_change(u, v, points, tets, state.mesh.tet_lab, adj_start, adj_len, pool, dvol)
            vol_drift += dvol
        # The vertices whose star changes are those of u's tets; v's other
        # neighbours keep their stars (their collapses onto v are re-tested
        # when popped).
        st = _new_stamp(counters)
        touched = np.empty(4 * n, np.int64)
        nt = np.int64(0)  # not the literal 0: _requeue_touched compiles once
        for i in range(n):
            t = pool[s0 + i]
            for k in range(4):
                w = tets[t, k]
                if w != u and mark[w] != st:
                    mark[w] = st
                    touched[nt] = w
                    nt += 1
        collapse(u, v, state, counters, newcos)
        c = counters[C_COLLAPSES]
        state.log.collapse_u[c] = u
        state.log.collapse_v[c] = v
        state.log.tet_counts[c + 1] = counters[C_ALIVE_TETS]
        counters[C_COLLAPSES] = c + 1
        _requeue_touched(v, touched, nt, state, counters, params)
        return True
    return False


@njit(cache=True)
def _requeue_touched(v, touched, nt, state, counters, params):
    """Queue the touched vertices of a collapse ``u -> v`` whose cost may have gone down.

    Keys are lower bounds of the true costs (a popped vertex whose true cost
    is higher is requeued at it), so nothing is re-costed in full here.
    Between two touches a vertex only loses edges, which raises its cost;
    a collapse ``u -> v`` gives a touched ``w != v`` at most the new edge
    ``w v``, and ``v`` new edges to the other touched vertices.  A queued
    ``w`` (``qkey[w]`` finite, at most its true cost) is pushed again only if
    a new edge is cheaper than its key, and then that is its true cost.  A
    vertex that is not queued (``qkey[w]`` inf: its collapses failed when it
    was last popped at cost ``qlow[w]``, and the new neighbourhood may allow
    one) is pushed at ``min(qlow[w], new edges)``.
    """
    points, vclass, locked = state.mesh.points, state.mesh.vclass, state.mesh.locked
    ver, qkey, qlow, heap_key, heap_u, heap_stamp = state.queue
    inv_h = 1.0 / params[P_H]
    for i in range(nt):
        w = touched[i]
        if locked[w]:
            continue
        if w == v:
            new2 = np.inf
            for j in range(nt):
                x = touched[j]
                if x != v:
                    new2 = min(new2, half_edge_key2(v, x, points, vclass, params))
        else:
            new2 = half_edge_key2(w, v, points, vclass, params)
        c = np.inf if new2 == np.inf else math.sqrt(new2) * inv_h
        if qkey[w] == np.inf:
            c = min(c, qlow[w])
        if c < qkey[w]:
            ver[w] += 1
            qkey[w] = c
            heap_push(c, w, ver[w], heap_key, heap_u, heap_stamp, ver, counters)


@njit(cache=True)
def run_collapses(state, counters, params, max_pops):
    """Pop the heap until the target tet count, an empty heap, or ``max_pops`` pops (``state`` a
    ``_state.Decimation``).

    Returns one of ``STATUS_TARGET``, ``STATUS_EMPTY``, ``STATUS_BUDGET``.
    """
    points, vclass, vert_alive = state.mesh.points, state.mesh.vclass, state.mesh.vert_alive
    ver, qkey, qlow, heap_key, heap_u, heap_stamp = state.queue
    mark = state.marks[0]
    cand = np.empty(MAX_CANDIDATES, np.int64)
    cand_key2 = np.empty(MAX_CANDIDATES)
    grad = np.empty((STAR_SCRATCH, 3))
    gbase = np.empty(STAR_SCRATCH, np.int64)
    newcos = np.empty(STAR_SCRATCH)
    pops = 0
    while counters[C_ALIVE_TETS] > counters[C_TARGET]:
        if pops >= max_pops:
            return STATUS_BUDGET
        if counters[C_HEAP_SIZE] == 0:
            return STATUS_EMPTY
        key, u, stamp = heap_pop(heap_key, heap_u, heap_stamp, counters)
        pops += 1
        counters[C_POPS] += 1
        if vert_alive[u] == 0 or stamp != ver[u]:
            continue  # stale entry: u was pushed again since
        qkey[u] = np.inf
        nc = cheapest_neighbours(u, points, state.stars, vclass, mark, counters, params, (cand, cand_key2))
        cost = math.sqrt(cand_key2[0]) / params[P_H] if nc > 0 else np.inf
        if cost > key * (1.0 + 1e-12):
            # The neighbourhood changed since u was queued: requeue at its true cost.
            qlow[u] = cost
            if cost < np.inf:
                ver[u] += 1
                qkey[u] = cost
                heap_push(cost, u, ver[u], heap_key, heap_u, heap_stamp, ver, counters)
            continue
        if not _try_vertex(u, nc, cand, (grad, gbase, newcos), state, counters, params):
            qlow[u] = cost  # no legal collapse now; a lower bound once its star changes
    return STATUS_TARGET
