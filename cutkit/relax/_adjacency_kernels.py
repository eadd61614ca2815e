"""Numba kernels that keep the element model's node table: adjacency rows, colour classes, masses.

A node's adjacency row (:class:`~cutkit.relax._elastic_kernels.Adjacency`)
holds, for each tet around it, the tet, the node's corner, the three other
corners and the node's part of the tet's node-term row; the sweep kernels of
:mod:`cutkit.relax._elastic_kernels` read nothing else.  Colour classes group
nodes that share no tet, so a sweep updates each class in parallel.  The
kernels check nothing (:mod:`cutkit.relax.elastic` does).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

from cutkit.relax._elastic_kernels import EDGE_COLUMN, OPPOSITE

#: What :func:`step_seeds` reads of each node (n,): ``masses`` float64, ``fixed`` (n, 3) bool
#: (held directions) and ``degree`` int64 (its tets).
NodeKinds = namedtuple("NodeKinds", ["masses", "fixed", "degree"])


@njit(cache=True, nogil=True)
def colour_nodes_greedy(adj, tets, colour, nodes):
    """Give each node of ``nodes`` the smallest colour no node sharing a tet with it has.

    Only ``nodes`` change; the others keep theirs (-1 = none yet).
    """
    for q in range(nodes.shape[0]):
        i = nodes[q]
        used = np.zeros(256, np.bool_)
        for k in range(adj.degree[i]):
            t = adj.tets[adj.start[i] + k]
            for j in range(4):
                a = tets[t, j]
                if a != i and colour[a] >= 0 and colour[a] < 256:
                    used[colour[a]] = True
        c = 0
        while c < 255 and used[c]:
            c += 1
        colour[i] = c


@njit(cache=True, nogil=True)
def colour_classes(colour, movable, n_colours):
    """Counting sort of the movable nodes by colour: ``offsets`` (n_colours + 1,), ``nodes``."""
    counts = np.zeros(n_colours + 1, np.int64)
    for i in range(colour.shape[0]):
        if movable[i]:
            counts[colour[i] + 1] += 1
    for c in range(n_colours):
        counts[c + 1] += counts[c]
    nodes = np.empty(counts[n_colours], np.int64)
    fill = counts[:-1].copy()
    for i in range(colour.shape[0]):
        if movable[i]:
            nodes[fill[colour[i]]] = i
            fill[colour[i]] += 1
    return counts, nodes


@njit(cache=True, nogil=True)
def add_mass_shares(masses, tets, share):
    """``masses[tets[k, j]] += share[k]`` for every tet k and corner j, in that order (the sums of
    ``np.add.at(masses, tets.ravel(), np.repeat(share, 4))`` to the bit, without its dispatch).

    Parameters
    ----------
    masses : (n,) float64
        Changed in place.
    tets : (k, 4) int64
    share : (k,) float64
        Each tet's mass share per corner (negative to take it out).
    """
    for k in range(tets.shape[0]):
        for j in range(4):
            masses[tets[k, j]] += share[k]


@njit(cache=True, nogil=True)
def add_to_adjacency(adj, tets, rows, ids):
    """Append tets ``ids`` to the rows of their nodes (row capacity made by the caller), each with
    its corner's part of the tet's node-term row (``rows`` (len(ids), NODE_TERMS), :func:`node_term_rows`)."""
    for q in range(ids.shape[0]):
        t = ids[q]
        for c in range(4):
            i = tets[t, c]
            r = adj.start[i] + adj.degree[i]
            adj.tets[r] = t
            adj.corner[r] = c
            for m in range(3):
                j = OPPOSITE[c, m]
                adj.opposite[r, m] = tets[t, j]
                adj.terms[r, m] = rows[q, EDGE_COLUMN[c, j]]
            adj.terms[r, 3] = rows[q, 6]
            adj.terms[r, 4] = rows[q, 7]
            adj.terms[r, 5] = rows[q, 8]
            adj.degree[i] += 1


@njit(cache=True, nogil=True, inline="always")
def _copy_slot(adj, a, b):
    """Slot b of the pool into slot a, element by element (a row slice copy costs more than its reads)."""
    adj.tets[a] = adj.tets[b]
    adj.corner[a] = adj.corner[b]
    for m in range(3):
        adj.opposite[a, m] = adj.opposite[b, m]
    for m in range(adj.terms.shape[1]):
        adj.terms[a, m] = adj.terms[b, m]


@njit(cache=True, nogil=True)
def copy_rows(adj, pool, nodes, start):
    """The row of each node ``nodes[i]`` of ``adj``'s pool into ``pool``'s slots from ``start[i]``.

    ``pool`` is an :class:`~cutkit.relax._elastic_kernels.Adjacency` over other arrays than
    ``adj``'s (its ``start`` and ``degree`` are not read): a copy slot by slot, without the
    index arrays and gathered temporaries a NumPy fancy-index copy makes.
    """
    for i in range(nodes.shape[0]):
        v = nodes[i]
        a, b = adj.start[v], start[i]
        for k in range(adj.degree[v]):
            pool.tets[b + k] = adj.tets[a + k]
            pool.corner[b + k] = adj.corner[a + k]
            for m in range(3):
                pool.opposite[b + k, m] = adj.opposite[a + k, m]
            for m in range(adj.terms.shape[1]):
                pool.terms[b + k, m] = adj.terms[a + k, m]


@njit(cache=True, nogil=True)
def _runs(a):
    """The distinct values of sorted ``a`` (k,) and how often each occurs: (u,), (u,) int64."""
    values = np.empty(a.shape[0], np.int64)
    counts = np.zeros(a.shape[0], np.int64)
    u = -1
    for q in range(a.shape[0]):
        if q == 0 or a[q] != a[q - 1]:
            u += 1
            values[u] = a[q]
        counts[u] += 1
    return values[:u + 1], counts[:u + 1]


@njit(cache=True, nogil=True)
def make_room(adj, capacity, corners, used, slack, pool_size):
    """Give the row of every node in ``corners`` room for as many more slots as it occurs there.

    A row too small moves to the pool's end (slots ``used`` onwards) with room
    ``max(2 capacity, need + slack)``, its slots carried over; rows are moved
    in ascending node order.  Nothing changes when the pool (``pool_size``
    slots) is too small: the caller grows it and calls again.

    Parameters
    ----------
    adj : Adjacency
    capacity : (n,) int64
        Room of each row; updated.
    corners : (k,) int64
        Corners of the tets to be added (a node once per tet).
    used, slack, pool_size : int

    Returns
    -------
    end : int
        The pool's slots in use afterwards; ``-end - 1`` when ``end > pool_size`` (nothing moved).
    """
    nodes, counts = _runs(np.sort(corners))
    end = used
    for q in range(nodes.shape[0]):
        need = adj.degree[nodes[q]] + counts[q]
        if need > capacity[nodes[q]]:
            end += max(2 * capacity[nodes[q]], need + slack)
    if end > pool_size:
        return -end - 1
    pos = used
    for q in range(nodes.shape[0]):
        i = nodes[q]
        need = adj.degree[i] + counts[q]
        if need <= capacity[i]:
            continue
        s0 = adj.start[i]
        for k in range(adj.degree[i]):
            _copy_slot(adj, pos + k, s0 + k)
        adj.start[i] = pos
        capacity[i] = max(2 * capacity[i], need + slack)
        pos += capacity[i]
    return end


@njit(cache=True, nogil=True)
def remove_from_adjacency(adj, tets, ids, mark):
    """Remove tets ``ids`` from the rows of their nodes (the order of the rest kept).

    Each node's row is compacted once, however many of its tets go: the
    tets are marked in ``mark`` (one flag per tet id, all False on entry and
    on return) and every slot is kept or dropped by its mark.
    """
    corners = np.empty(4 * ids.shape[0], np.int64)
    for q in range(ids.shape[0]):
        mark[ids[q]] = True
        for c in range(4):
            corners[4 * q + c] = tets[ids[q], c]
    for i in np.unique(corners):
        s0 = adj.start[i]
        k_out = 0
        for r in range(adj.degree[i]):
            if mark[adj.tets[s0 + r]]:
                continue
            if k_out != r:
                _copy_slot(adj, s0 + k_out, s0 + r)
            k_out += 1
        adj.degree[i] = k_out
    for q in range(ids.shape[0]):
        mark[ids[q]] = False


@njit(cache=True, nogil=True)
def colour_classes_of(colour, nodes, n_colours):
    """Counting sort of ``nodes`` by colour: ``offsets`` (n_colours + 1,), ``sorted`` (k,) int64."""
    counts = np.zeros(n_colours + 1, np.int64)
    for q in range(nodes.shape[0]):
        counts[colour[nodes[q]] + 1] += 1
    for c in range(n_colours):
        counts[c + 1] += counts[c]
    out = np.empty(nodes.shape[0], np.int64)
    fill = counts[:-1].copy()
    for q in range(nodes.shape[0]):
        c = colour[nodes[q]]
        out[fill[c]] = nodes[q]
        fill[c] += 1
    return counts, out


@njit(cache=True, nogil=True)
def _collect(mark):
    """The indices of ``mark`` (n,) bool that are True, ascending; clears them."""
    k = 0
    for i in range(mark.shape[0]):
        if mark[i]:
            k += 1
    out = np.empty(k, np.int64)
    k = 0
    for i in range(mark.shape[0]):
        if mark[i]:
            out[k] = i
            k += 1
            mark[i] = False
    return out


@njit(cache=True, nogil=True)
def tets_around(adj, nodes):
    """The tets around any of ``nodes`` (k,) int64, ascending and each once: (t,) int64."""
    total = 0
    for q in range(nodes.shape[0]):
        total += adj.degree[nodes[q]]
    found = np.empty(total, np.int64)
    k = 0
    for q in range(nodes.shape[0]):
        s0 = adj.start[nodes[q]]
        for r in range(s0, s0 + adj.degree[nodes[q]]):
            found[k] = adj.tets[r]
            k += 1
    return np.unique(found)


@njit(cache=True, nogil=True)
def node_rings(adj, nodes, rings, n):
    """``nodes`` (k,) int64 grown by ``rings`` rings of tets (each ring: every node sharing a tet
    with one found so far, read from the adjacency rows' ``opposite`` corners), ascending and each
    once: (j,) int64.  ``n`` is the node count."""
    mark = np.zeros(n, np.bool_)
    found = np.empty(n, np.int64)
    k = 0
    for q in range(nodes.shape[0]):
        if not mark[nodes[q]]:
            mark[nodes[q]] = True
            found[k] = nodes[q]
            k += 1
    lo = 0
    for _ in range(rings):
        hi = k
        for f in range(lo, hi):
            i = found[f]
            for r in range(adj.start[i], adj.start[i] + adj.degree[i]):
                for c in range(3):
                    j = adj.opposite[r, c]
                    if not mark[j]:
                        mark[j] = True
                        found[k] = j
                        k += 1
        lo = hi
    return np.sort(found[:k])


@njit(cache=True, nogil=True)
def loose_nodes(adj, nodes, fixed, budget, n):
    """Which of ``nodes`` (k,) int64 lie in a loose piece: a component of the tets with no node held
    in any direction by ``fixed`` (n, 3) bool, found whole within ``budget`` nodes by a breadth-first
    search over the adjacency rows' ``opposite`` corners.  A component the search leaves before it
    meets a held node or its end counts as held.  Returns (k,) bool; ``n`` is the node count."""
    seen = np.zeros(n, np.int64)  # 0 unseen, else the search that saw it (1-based)
    queue = np.empty(min(n, budget) + 1, np.int64)
    verdict = np.zeros(nodes.shape[0] + 1, np.bool_)  # per search: loose
    loose = np.zeros(nodes.shape[0], np.bool_)
    searches = 0
    for q in range(nodes.shape[0]):
        if seen[nodes[q]] == 0:
            searches += 1
            seen[nodes[q]] = searches
            queue[0] = nodes[q]
            i = nodes[q]
            head, tail, open_end = 0, 1, fixed[i, 0] or fixed[i, 1] or fixed[i, 2]
            while head < tail and not open_end:
                i = queue[head]
                head += 1
                for r in range(adj.start[i], adj.start[i] + adj.degree[i]):
                    for c in range(3):
                        j = adj.opposite[r, c]
                        if seen[j] == searches:
                            continue
                        if seen[j] != 0 or fixed[j, 0] or fixed[j, 1] or fixed[j, 2] or tail >= budget:
                            open_end = True  # an earlier search's (held), a held node, or past the budget
                        else:
                            seen[j] = searches
                            queue[tail] = j
                            tail += 1
                    if open_end:
                        break
            verdict[searches] = not open_end
        loose[q] = verdict[seen[nodes[q]]]
    return loose


#: Blocks the nodes of :func:`awake_after_sweep` are split into for its threads.
AWAKE_BLOCKS = 16


@njit(cache=True, nogil=True, parallel=True)
def awake_after_sweep(adj, movable, r2, tau2, nodes, mark):
    """The nodes the next sweep moves, in ascending order: those of ``nodes`` still out of
    balance by more than sqrt(tau2), and every movable node sharing a tet with one of them
    (read from the nodes' own adjacency rows, ``adj.opposite``).

    Marks first, then one pass over ``mark`` (n,) bool collects and clears them
    (all False on entry and on return): a third of the time of collecting
    while marking, whose branch on every visit cost more than the pass.  The
    blocks of ``nodes`` mark in parallel: two threads may both write True to
    one node, and the set marked is the same for any thread count.  Unsigned
    indices spare each read numba's negative-index test (15 % on the knee).
    """
    n = nodes.shape[0]
    for b in prange(AWAKE_BLOCKS):
        for q in range(b * n // AWAKE_BLOCKS, (b + 1) * n // AWAKE_BLOCKS):
            i = np.uint64(nodes[q])
            if r2[i] <= tau2:
                continue
            if movable[i]:
                mark[i] = True
            s0 = np.uint64(adj.start[i])
            for r in range(s0, s0 + np.uint64(adj.degree[i])):
                for m in range(3):
                    a = np.uint64(adj.opposite[r, m])
                    if movable[a]:
                        mark[a] = True
    return _collect(mark)


@njit(cache=True, nogil=True)
def step_seeds(kinds, velocities, r2, h, tau2, seeds, work):
    """The start of a local step (:func:`cutkit.relax.vbd.local_step`) in one pass over the nodes.

    ``work`` is (``movable``, ``mark``), both (n,) bool.  Fills ``movable``
    (not held in all three directions, in some tet; ``kinds`` a
    :class:`NodeKinds`), zeroes ``r2`` of the others, and returns in
    ascending order the nodes to wake first: ``seeds``, and the movable nodes
    that move (inertial force ``m |v| / h`` above ``sqrt(tau2)``) or are out
    of balance (``r2 > tau2``).  ``mark`` is all False on entry and on return.
    """
    masses, fixed, degree = kinds.masses, kinds.fixed, kinds.degree
    movable, mark = work
    tau = np.sqrt(tau2)
    for i in range(movable.shape[0]):
        mov = degree[i] > 0 and not (fixed[i, 0] and fixed[i, 1] and fixed[i, 2])
        movable[i] = mov
        if not mov:
            r2[i] = 0.0
            continue
        v = velocities[i]
        speed = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if masses[i] * speed / h > tau or r2[i] > tau2:
            mark[i] = True
    for q in range(seeds.shape[0]):
        mark[seeds[q]] = True
    return _collect(mark)


@njit(cache=True, nogil=True)
def step_velocities(x, x0, fixed, h, velocities):
    """Backward Euler's velocities ``(x - x0) / h``, 0 in held directions: (n, 3) float64, in place."""
    for i in range(x.shape[0]):
        for c in range(3):
            velocities[i, c] = 0.0 if fixed[i, c] else (x[i, c] - x0[i, c]) / h


@njit(cache=True, nogil=True)
def loaded_nodes(forces):
    """The nodes with a non-zero force, ascending: (k,) int64 of ``forces`` (n, 3) float64."""
    k = 0
    for i in range(forces.shape[0]):
        if forces[i, 0] != 0.0 or forces[i, 1] != 0.0 or forces[i, 2] != 0.0:
            k += 1
    out = np.empty(k, np.int64)
    k = 0
    for i in range(forces.shape[0]):
        if forces[i, 0] != 0.0 or forces[i, 1] != 0.0 or forces[i, 2] != 0.0:
            out[k] = i
            k += 1
    return out
