"""Numba kernel of the crumb search: small pieces the cut has set loose.

:func:`loose_small_pieces` grows, from each seed tetrahedron, the set of
live tetrahedra joined to it through shared nodes (what the physics treats
as one body), summing rest volumes, and stops as soon as the sum passes the
limit or the growth meets a piece already found large.  A piece whose
growth ends below the limit is a crumb.

The main body is proven large in a few steps by blocks (:func:`make_blocks`):
face-connected groups of original tets, each a small share of the limit, made
with their rest volumes when the cut state is.  A block none of whose tets a
step has subdivided, removed or moved since ("clean") lies whole in one piece
(its tets are live, uncut and joined by their faces), so where the growth
meets it, its volume and that of every clean block joined to it count at
once; its tets count nothing when the growth meets them one by one, so a
crumb's volume stays exact.  The work per step is then about the blocks
near the cut, not a share of the mesh.

Slow, obviously correct NumPy twin: ``tests/_twins_cut.py::loose_small_pieces_twin``.
"""

from collections import namedtuple

import numpy as np
from numba import njit

#: Live-tet incidence of a :class:`~cutkit.cutting.cutmesh.CutMesh` as flat arrays.
#: ``node_tet_off`` (n0 + 1,), ``node_tet_idx`` (4 m0,) int64: original tets of each original
#: node (CSR); ``def_nodes`` (n, 4) int64 and ``n_orig`` (int): a cut node i >= n_orig lies in
#: original tets that all hold its first defining node ``def_nodes[i, 0]`` (an original node
#: lies in its own); ``sub_start``, ``sub_count`` (m0,) int64: the contiguous range of sub-tet
#: ids of each original tet (count 0: the original tet itself); ``neighbors`` (m0, 4) int64: the
#: original tets across each face (-1: boundary).
#: Blocks (:func:`make_blocks`): ``block_of`` (m0,) int64 the block of each original tet,
#: ``block_volume`` (B,) float64 its rest volume as made, ``block_ptr`` (B + 1,), ``block_adj`` (k,)
#: int64 the blocks next to each across a face (CSR), ``block_dirty`` (B,) bool: a tet of it
#: subdivided, removed or moved since (the caller marks them).
Incidence = namedtuple("Incidence", "node_tet_off node_tet_idx def_nodes n_orig sub_start sub_count neighbors "
                                    "block_of block_volume block_ptr block_adj block_dirty")

#: States of a tet in one call, stored as ``mark[t] - base`` (below ``base``: not seen in this call).
_GROWING, _LARGE, _CRUMB = 1, 2, 3
# (passed as np.int64(_GROWING): a constant argument is typed as its literal, and numba would compile
# _set_state and _set_block once for it and once for the states read from the marks)


@njit(cache=True, nogil=True)
def _rest_volume(X, tv):
    """Signed volume of the tet X[tv] (4,)."""
    o = tv[0]
    a0, a1, a2 = X[tv[1], 0] - X[o, 0], X[tv[1], 1] - X[o, 1], X[tv[1], 2] - X[o, 2]
    b0, b1, b2 = X[tv[2], 0] - X[o, 0], X[tv[2], 1] - X[o, 1], X[tv[2], 2] - X[o, 2]
    c0, c1, c2 = X[tv[3], 0] - X[o, 0], X[tv[3], 1] - X[o, 1], X[tv[3], 2] - X[o, 2]
    return (a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)) / 6.0


@njit(cache=True, nogil=True)
def _state(marks, t):
    """State of tet t in this call (0: not seen); ``marks`` is (mark, base, block_mark, block
    scratch), as :func:`loose_small_pieces` makes it."""
    v = marks[0][t] - marks[1]
    return v if v > 0 else 0


@njit(cache=True, nogil=True)
def _set_state(marks, t, state):
    """Tet t takes ``state`` in this call."""
    marks[0][t] = marks[1] + state


@njit(cache=True, nogil=True)
def _block_state(marks, b):
    """State of block b in this call (0: not counted); ``marks[2]`` (B,) int64 the blocks' marks."""
    v = marks[2][b] - marks[1]
    return v if v > 0 else 0


@njit(cache=True, nogil=True)
def make_blocks(X, tets, neighbors, target):
    """Blocks of face-connected tets of about ``target`` rest volume each, grown breadth first.

    Parameters
    ----------
    X : (n, 3) float64  rest positions
    tets : (m, 4) int64  original tets
    neighbors : (m, 4) int64  the tet across each face (-1: none)
    target : float  a block stops growing once its volume reaches it, mm^3

    Returns
    -------
    block_of : (m,) int64
    block_volume : (B,) float64
    block_ptr : (B + 1,) int64
    block_adj : (k,) int64  the blocks next to each block across a face (CSR, no repeats)
    """
    m = tets.shape[0]
    block_of = np.full(m, -1, np.int64)
    order = np.empty(m, np.int64)  # the members of each block, block after block
    start = np.empty(m + 1, np.int64)
    volume = np.empty(m, np.float64)
    n_blocks, n = 0, 0
    for s in range(m):
        if block_of[s] >= 0:
            continue
        start[n_blocks] = n
        block_of[s], order[n] = n_blocks, s
        head, n = n, n + 1
        v = _rest_volume(X, tets[s])
        while head < n and v < target:
            t = order[head]
            head += 1
            for f in range(4):
                c = neighbors[t, f]
                if c >= 0 and block_of[c] < 0 and v < target:
                    block_of[c], order[n] = n_blocks, c
                    n += 1
                    v += _rest_volume(X, tets[c])
        volume[n_blocks] = v
        n_blocks += 1
    start[n_blocks] = n
    seen = np.full(n_blocks, -1, np.int64)
    ptr = np.zeros(n_blocks + 1, np.int64)
    adj = np.empty(4 * m, np.int64)
    k = 0
    for b in range(n_blocks):
        ptr[b] = k
        for i in range(start[b], start[b + 1]):
            for f in range(4):
                c = neighbors[order[i], f]
                if c >= 0 and block_of[c] != b and seen[block_of[c]] != b:
                    seen[block_of[c]] = b
                    adj[k] = block_of[c]
                    k += 1
    ptr[n_blocks] = k
    return block_of, volume[:n_blocks].copy(), ptr, adj[:k].copy()


@njit(cache=True, nogil=True)
def _count_blocks(inc, marks, b, room):
    """Count clean block b and the clean blocks joined to it into the growing piece, until their
    volume passes ``room``.  Returns (volume, large): ``large`` if one of them was found large before."""
    stack = marks[3]  # (B + 1,) int64 scratch: entry 0 how many blocks this growth counted, then they
    top = stack[0]
    _set_block(marks, b, np.int64(_GROWING))
    stack[0] += 1
    stack[stack[0]] = b
    volume = 0.0
    while top < stack[0] and volume <= room:
        top += 1
        c = stack[top]
        volume += inc.block_volume[c]
        for k in range(inc.block_ptr[c], inc.block_ptr[c + 1]):
            d = inc.block_adj[k]
            if inc.block_dirty[d]:
                continue
            st = _block_state(marks, d)
            if st == _LARGE:
                return volume, True
            if st == 0:
                _set_block(marks, d, np.int64(_GROWING))
                stack[0] += 1
                stack[stack[0]] = d
    return volume, False


@njit(cache=True, nogil=True)
def _set_block(marks, b, state):
    """Block b takes ``state`` in this call."""
    marks[2][b] = marks[1] + state


@njit(cache=True, nogil=True)
def _join_volume(inc, marks, c, own, room):
    """The rest volume tet c brings as it joins the growing piece: its own ``own`` (a cut tet, or
    one of a block a step changed), nothing (its block counted already), or its clean block's with
    the clean blocks joined to it (:func:`_count_blocks`).  Returns (volume, large)."""
    if c >= inc.sub_count.shape[0] or inc.block_dirty[inc.block_of[c]]:
        return own, False
    b = inc.block_of[c]
    st = _block_state(marks, b)
    if st == _LARGE:
        return 0.0, True
    if st != 0:
        return 0.0, False
    return _count_blocks(inc, marks, b, room)


@njit(cache=True, nogil=True)
def _push(comp, n, c):
    """comp with c at position n (grown by doubling when full)."""
    if n == comp.shape[0]:
        bigger = np.empty(2 * n, np.int64)
        bigger[:n] = comp
        comp = bigger
    comp[n] = c
    return comp


# The queues of one growth: ``q`` (3, k) int64 and ``hk`` (k,) float64.  Row 0 lists the piece's
# tets found so far; row 1 is a binary max-heap (1-based, keys ``hk``) of uncut original tets to grow
# from across their faces, the largest first; row 2 a stack of tets whose nodes' tets are to be
# scanned (cut tets, and uncut ones next to a cut, deferred until the heap is empty).  Column 0 of
# each row holds its length.


@njit(cache=True, nogil=True)
def _room(q, hk):
    """(q, hk) with room for one more entry in every row (doubled when full)."""
    if max(q[0, 0], q[1, 0], q[2, 0]) + 1 < q.shape[1]:
        return q, hk
    bigger = np.zeros((3, 2 * q.shape[1]), np.int64)
    bigger[:, :q.shape[1]] = q
    bk = np.zeros(2 * hk.shape[0])
    bk[:hk.shape[0]] = hk
    return bigger, bk


@njit(cache=True, nogil=True)
def _push_nodes(q, hk, t):
    """Tet t onto the node-scan stack (row 2)."""
    q, hk = _room(q, hk)
    q[2, 0] += 1
    q[2, q[2, 0]] = t
    return q, hk


@njit(cache=True, nogil=True)
def _enqueue(q, hk, c, cheap, vol):
    """Tet c (rest volume ``vol``) joins the piece: onto row 0, and onto the heap (row 1, an uncut
    original tet: ``cheap``) or the node-scan stack (row 2).  Returns (q, hk)."""
    q, hk = _room(q, hk)
    q[0, 0] += 1
    q[0, q[0, 0]] = c
    if not cheap:
        return _push_nodes(q, hk, c)
    i = q[1, 0] + 1  # sift up: the heap keeps its largest tet at position 1
    q[1, 0] = i
    while i > 1 and hk[i // 2] < vol:
        q[1, i], hk[i] = q[1, i // 2], hk[i // 2]
        i //= 2
    q[1, i], hk[i] = c, vol
    return q, hk


@njit(cache=True, nogil=True)
def _pop_largest(q, hk):
    """The uncut tet of largest rest volume off the heap (row 1 of ``q``)."""
    top = q[1, 1]
    n = q[1, 0]
    c, vol = q[1, n], hk[n]
    n -= 1
    q[1, 0] = n
    i = 1
    while 2 * i <= n:  # sift the last entry down from the root
        j = 2 * i
        if j + 1 <= n and hk[j + 1] > hk[j]:
            j += 1
        if hk[j] <= vol:
            break
        q[1, i], hk[i] = q[1, j], hk[j]
        i = j
    q[1, i], hk[i] = c, vol
    return top


@njit(cache=True, nogil=True)
def _visit_uncut(X, tets, inc, alive, marks, t, q, hk, room):
    """Face neighbours of uncut original tet t that are uncut too join the piece (``q``).

    Returns (q, hk, state, added): state 1 if a cut tet is next to t (its
    nodes' tets must be scanned), 2 if a large piece was met, else 0;
    ``added`` the rest volume that joined (:func:`_join_volume`; ``room``: what the piece may
    still take before it is large).
    """
    near_cut, added = 0, 0.0
    for f in range(4):
        nb = inc.neighbors[t, f]
        if nb < 0 or not alive[nb] and inc.sub_count[nb] == 0:
            continue
        if inc.sub_count[nb] > 0:
            near_cut = 1
            continue
        st = _state(marks, nb)
        if st == _LARGE:
            return q, hk, 2, added
        if st == 0:
            _set_state(marks, nb, np.int64(_GROWING))
            own = _rest_volume(X, tets[nb])
            q, hk = _enqueue(q, hk, nb, np.bool_(True), own)  # np.bool_: one compile
            v, large = _join_volume(inc, marks, nb, own, room - added)
            added += v
            if large:
                return q, hk, 2, added
    return q, hk, near_cut, added


@njit(cache=True, nogil=True)
def _scan_nodes(X, tets, alive, inc, t, marks, q, hk, room):
    """Live tets sharing a node with tet t join the piece.  Returns (q, hk, large, added): ``large``
    if a tet of a piece already found large shares one; ``added`` the rest volume that joined
    (:func:`_join_volume`, ``room`` as there)."""
    m0 = inc.sub_count.shape[0]
    added = 0.0
    for j in range(4):
        v = tets[t, j]
        sup = v if v < inc.n_orig else inc.def_nodes[v, 0]
        for k in range(inc.node_tet_off[sup], inc.node_tet_off[sup + 1]):
            o = inc.node_tet_idx[k]
            lo, hi = o, o + 1
            if inc.sub_count[o] > 0:
                lo, hi = inc.sub_start[o], inc.sub_start[o] + inc.sub_count[o]
            for c in range(lo, hi):
                if not alive[c] or _state(marks, c) == _GROWING:
                    continue
                if tets[c, 0] != v and tets[c, 1] != v and tets[c, 2] != v and tets[c, 3] != v:
                    continue
                if _state(marks, c) == _LARGE:
                    return q, hk, True, added
                _set_state(marks, c, np.int64(_GROWING))
                own = _rest_volume(X, tets[c])
                q, hk = _enqueue(q, hk, c, c < m0, own)
                w, large = _join_volume(inc, marks, c, own, room - added)
                added += w
                if large:
                    return q, hk, True, added
    return q, hk, False, added


@njit(cache=True, nogil=True)
def _grow(X, tets, alive, inc, s, limit, marks, q, hk):
    """Grow the piece of live tet ``s``; returns (q, hk, large): its members are ``q[0, 1:q[0, 0] + 1]``.

    A tet's volume counts when it joins.  Uncut original tets grow across
    their faces (cheap), the largest first, and the scans of nodes' tets (a
    cut tet's, or an uncut tet's next to a cut) wait until no uncut tet is
    left to grow from: a large piece is usually found large after a few of
    them (the cut runs through the skin's small tets; larger ones lie deeper).
    A piece is a crumb only when both queues ran dry below the limit.
    """
    q[:, 0] = 0
    marks[3][0] = 0  # no block counted yet
    _set_state(marks, s, np.int64(_GROWING))
    own = _rest_volume(X, tets[s])
    q, hk = _enqueue(q, hk, s, s < inc.sub_count.shape[0], own)
    vol, large = _join_volume(inc, marks, s, own, limit)
    if large:
        return q, hk, True
    while vol <= limit and (q[1, 0] > 0 or q[2, 0] > 0):
        if q[1, 0] > 0:
            t = _pop_largest(q, hk)
            q, hk, st, added = _visit_uncut(X, tets, inc, alive, marks, t, q, hk, limit - vol)
            if st == 1:
                q, hk = _push_nodes(q, hk, t)
        else:
            t = q[2, q[2, 0]]
            q[2, 0] -= 1
            q, hk, large, added = _scan_nodes(X, tets, alive, inc, t, marks, q, hk, limit - vol)
            st = 2 if large else 0
        if st == 2:
            return q, hk, True
        vol += added
    return q, hk, vol > limit


@njit(cache=True, nogil=True)
def loose_small_pieces(X, tets, alive, inc, seeds, limit, mark, block_mark, base):
    """Live tets of the pieces through ``seeds`` whose rest volume is at most ``limit``.

    Parameters
    ----------
    X : (n, 3) float64  rest positions
    tets : (T, 4) int64  every tet made so far (``alive`` says which are live)
    alive : (T,) bool
    inc : Incidence
    seeds : (s,) int64  live tet ids to start from
    limit : float  largest crumb volume, mm^3
    mark : (>= T,) int64  per-tet marks kept between calls, every entry below ``base`` (no reset)
    block_mark : (B,) int64  per-block marks, the same way
    base : int  this call's stamp; leaves marks below ``base + 4``

    Returns
    -------
    crumbs : (c,) int64  the crumbs' tets, piece after piece
    n_pieces : int  crumbs found
    """
    marks = (mark, base, block_mark, np.zeros(block_mark.shape[0] + 1, np.int64))
    q = np.zeros((3, 256), np.int64)
    hk = np.zeros(256)
    out = np.empty(64, np.int64)
    n_out = np.int64(0)  # not the literal 0: _push compiles once
    n_pieces = 0
    for i in range(seeds.shape[0]):
        s = seeds[i]
        if not alive[s] or _state(marks, s) != 0:
            continue
        q, hk, large = _grow(X, tets, alive, inc, s, limit, marks, q, hk)
        flag = _LARGE if large else _CRUMB
        n = q[0, 0]
        for j in range(1, n + 1):
            _set_state(marks, q[0, j], flag)
        for j in range(1, marks[3][0] + 1):
            _set_block(marks, marks[3][j], flag)
        if not large:
            for j in range(1, n + 1):
                out = _push(out, n_out, q[0, j])
                n_out += 1
            n_pieces += 1
    return out[:n_out].copy(), n_pieces
