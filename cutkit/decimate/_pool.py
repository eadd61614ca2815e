"""Numba flat-array containers of the decimator: per-vertex tet lists and the collapse heap.

Node -> tet adjacency is kept as one dynamic list per vertex inside a single
pool array (``adj_start``, ``adj_len``, ``adj_cap`` index into ``pool``), so a
collapse updates only the lists it touches.  A list that outgrows its slot is
moved to the end of the pool; when the pool's end is reached the lists are
packed to the front (in place, in start order).

The heap is a binary min-heap of ``(key, vertex, stamp)`` with lazy
invalidation: an entry is stale when its stamp differs from the vertex's
current version (``ver``), which is bumped whenever the vertex's neighbourhood
changes.  A full heap drops its stale entries and is rebuilt.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Slots of the ``counters`` (int64) state array shared by the kernels.
C_HEAP_SIZE = 0
C_POOL_END = 1
C_ALIVE_TETS = 2
C_COLLAPSES = 3
C_STAMP = 4
C_TARGET = 5
C_POPS = 6  # statistics: heap entries popped
C_CHECKS = 7  # statistics: legality tests run
C_PRECHECK_REJECTS = 8  # statistics: candidates skipped by the volume pre-check
N_COUNTERS = 9


@njit(cache=True)
def pool_compact(adj_start, adj_len, adj_cap, pool, counters):
    """Pack every list to the front of the pool, in order of its start."""
    order = np.argsort(adj_start, kind="mergesort")
    end = 0
    for idx in range(order.shape[0]):
        x = order[idx]
        s = adj_start[x]
        n = adj_len[x]
        # Lists are disjoint and visited by increasing start, so end <= s: moving left is safe.
        for k in range(n):
            pool[end + k] = pool[s + k]
        adj_start[x] = end
        adj_cap[x] = n
        end += n
    counters[C_POOL_END] = end


@njit(cache=True)
def pool_append(x, t, adj_start, adj_len, adj_cap, pool, counters):
    """Append tet ``t`` to the list of vertex ``x`` (moving the list if its slot is full).

    The pool must hold all lists with room to spare: the decimator gives it
    twice the initial node-tet incidences, whose number only shrinks.
    """
    n = adj_len[x]
    if n == adj_cap[x]:
        cap = 2 * n + 4
        if counters[C_POOL_END] + cap > pool.shape[0]:
            pool_compact(adj_start, adj_len, adj_cap, pool, counters)
        end = counters[C_POOL_END]
        s = adj_start[x]
        for k in range(n):
            pool[end + k] = pool[s + k]
        adj_start[x] = end
        adj_cap[x] = cap
        counters[C_POOL_END] = end + cap
    pool[adj_start[x] + n] = t
    adj_len[x] = n + 1


@njit(cache=True)
def pool_remove(x, t, adj_start, adj_len, pool):
    """Remove tet ``t`` from the list of vertex ``x`` (swap with the last entry)."""
    s = adj_start[x]
    n = adj_len[x]
    for k in range(n):
        if pool[s + k] == t:
            pool[s + k] = pool[s + n - 1]
            adj_len[x] = n - 1
            return


@njit(cache=True, inline="always")
def _less(key, u, i, j):
    # Ties are broken by vertex id so that the order is reproducible.
    return key[i] < key[j] or (key[i] == key[j] and u[i] < u[j])


@njit(cache=True)
def _sift_down(key, u, stamp, i, size):
    while True:
        left = 2 * i + 1
        if left >= size:
            return
        best = left
        right = left + 1
        if right < size and _less(key, u, right, left):
            best = right
        if not _less(key, u, best, i):
            return
        key[i], key[best] = key[best], key[i]
        u[i], u[best] = u[best], u[i]
        stamp[i], stamp[best] = stamp[best], stamp[i]
        i = best


@njit(cache=True)
def heap_build(key, u, stamp, size):
    """Turn the first ``size`` entries into a heap (Floyd's bottom-up build)."""
    for i in range(size // 2 - 1, -1, -1):
        _sift_down(key, u, stamp, i, size)


@njit(cache=True)
def heap_push(k, x, st, key, u, stamp, ver, counters):
    """Push ``(k, x, st)``; a full heap is first purged of stale entries."""
    size = counters[C_HEAP_SIZE]
    if size == key.shape[0]:
        kept = np.int64(0)  # not the literal 0: heap_build compiles once
        for i in range(size):
            if stamp[i] == ver[u[i]]:
                key[kept] = key[i]
                u[kept] = u[i]
                stamp[kept] = stamp[i]
                kept += 1
        heap_build(key, u, stamp, kept)
        size = kept
    i = size
    key[i] = k
    u[i] = x
    stamp[i] = st
    while i > 0:
        parent = (i - 1) // 2
        if not _less(key, u, i, parent):
            break
        key[i], key[parent] = key[parent], key[i]
        u[i], u[parent] = u[parent], u[i]
        stamp[i], stamp[parent] = stamp[parent], stamp[i]
        i = parent
    counters[C_HEAP_SIZE] = size + 1


@njit(cache=True)
def heap_pop(key, u, stamp, counters):
    """Remove the smallest entry and return ``(key, vertex, stamp)``; the heap must not be empty."""
    size = counters[C_HEAP_SIZE]
    k0, x0, s0 = key[0], u[0], stamp[0]
    size -= 1
    key[0] = key[size]
    u[0] = u[size]
    stamp[0] = stamp[size]
    counters[C_HEAP_SIZE] = size
    _sift_down(key, u, stamp, np.int64(0), size)  # one compile, not one for the literal
    return k0, x0, s0
