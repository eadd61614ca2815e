"""Numba kernel of the crumb search: small pieces the cut has set loose.

:func:`loose_small_pieces` grows, from each seed tetrahedron, the set of
live tetrahedra joined to it through shared nodes (what the physics treats
as one body), summing rest volumes, and stops as soon as the sum passes the
limit or the growth meets a piece already found large.  A piece whose
growth ends below the limit is a crumb.  The work per step is bounded by
the limit, not by the mesh.

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
Incidence = namedtuple("Incidence", "node_tet_off node_tet_idx def_nodes n_orig sub_start sub_count neighbors")

#: States of a tet in one call, stored as ``mark[t] - base`` (below ``base``: not seen in this call).
_GROWING, _LARGE, _CRUMB = 1, 2, 3


@njit(cache=True, nogil=True)
def _rest_volume(X, tv):
    """Signed volume of the tet X[tv] (4,)."""
    o = tv[0]
    a0, a1, a2 = X[tv[1], 0] - X[o, 0], X[tv[1], 1] - X[o, 1], X[tv[1], 2] - X[o, 2]
    b0, b1, b2 = X[tv[2], 0] - X[o, 0], X[tv[2], 1] - X[o, 1], X[tv[2], 2] - X[o, 2]
    c0, c1, c2 = X[tv[3], 0] - X[o, 0], X[tv[3], 1] - X[o, 1], X[tv[3], 2] - X[o, 2]
    return (a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)) / 6.0


@njit(cache=True, nogil=True)
def _state(mark, base, t):
    """State of tet t in this call (0: not seen)."""
    v = mark[t] - base
    return v if v > 0 else 0


@njit(cache=True, nogil=True)
def _push(comp, n, c):
    """comp with c at position n (grown by doubling when full)."""
    if n == comp.shape[0]:
        bigger = np.empty(2 * n, np.int64)
        bigger[:n] = comp
        comp = bigger
    comp[n] = c
    return comp


@njit(cache=True, nogil=True)
def _visit_uncut(inc, alive, mark, base, t, q):
    """Face neighbours of uncut original tet t that are uncut too, onto ``q`` (queues) as growing.

    Returns (q, state): state 1 if a cut tet is next to t (its nodes' tets must be scanned),
    2 if a large piece was met, else 0.
    """
    near_cut = 0
    for f in range(4):
        nb = inc.neighbors[t, f]
        if nb < 0 or not alive[nb] and inc.sub_count[nb] == 0:
            continue
        if inc.sub_count[nb] > 0:
            near_cut = 1
            continue
        st = _state(mark, base, nb)
        if st == _LARGE:
            return q, 2
        if st == 0:
            mark[nb] = base + _GROWING
            q = _enqueue(q, nb, True)
    return q, near_cut


@njit(cache=True, nogil=True)
def _enqueue(q, c, cheap):
    """Put tet c on queue ``q`` (row 0 its members so far, row 1 uncut tets to visit, row 2 cut ones;
    column 0 of each row holds its length)."""
    for r in (0, 1 if cheap else 2):
        k = q[r, 0] + 1
        if k == q.shape[1]:
            bigger = np.zeros((3, 2 * q.shape[1]), np.int64)
            bigger[:, :q.shape[1]] = q
            q = bigger
        q[r, k] = c
        q[r, 0] = k
    return q


@njit(cache=True, nogil=True)
def _grow(X, tets, alive, inc, s, limit, mark, base, q):
    """Grow the piece of live tet ``s``; returns (q, large): its members are ``q[0, 1:q[0, 0] + 1]``.

    Uncut original tets are visited first, across faces (cheap): a large
    piece is usually found large before the cut's sub-tets are scanned.
    """
    m0 = inc.sub_count.shape[0]
    q[:, 0] = 0
    mark[s] = base + _GROWING
    q = _enqueue(q, s, s < m0)
    vol = 0.0
    while q[1, 0] > 0 or q[2, 0] > 0:
        r = 1 if q[1, 0] > 0 else 2
        t = q[r, q[r, 0]]
        q[r, 0] -= 1
        vol += _rest_volume(X, tets[t])
        if vol > limit:
            return q, True
        if t < m0:
            q, st = _visit_uncut(inc, alive, mark, base, t, q)
            if st == 2:
                return q, True
            if st == 0:
                continue
        for j in range(4):
            v = tets[t, j]
            sup = v if v < inc.n_orig else inc.def_nodes[v, 0]
            for k in range(inc.node_tet_off[sup], inc.node_tet_off[sup + 1]):
                o = inc.node_tet_idx[k]
                lo, hi = o, o + 1
                if inc.sub_count[o] > 0:
                    lo, hi = inc.sub_start[o], inc.sub_start[o] + inc.sub_count[o]
                for c in range(lo, hi):
                    if not alive[c] or _state(mark, base, c) == _GROWING:
                        continue
                    if tets[c, 0] != v and tets[c, 1] != v and tets[c, 2] != v and tets[c, 3] != v:
                        continue
                    if _state(mark, base, c) == _LARGE:
                        return q, True
                    mark[c] = base + _GROWING
                    q = _enqueue(q, c, c < m0)
    return q, False


@njit(cache=True, nogil=True)
def loose_small_pieces(X, tets, alive, inc, seeds, limit, mark, base):
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
    base : int  this call's stamp; leaves marks below ``base + 4``

    Returns
    -------
    crumbs : (c,) int64  the crumbs' tets, piece after piece
    n_pieces : int  crumbs found
    """
    q = np.zeros((3, 256), np.int64)
    out = np.empty(64, np.int64)
    n_out = 0
    n_pieces = 0
    for i in range(seeds.shape[0]):
        s = seeds[i]
        if not alive[s] or _state(mark, base, s) != 0:
            continue
        q, large = _grow(X, tets, alive, inc, s, limit, mark, base, q)
        flag = _LARGE if large else _CRUMB
        n = q[0, 0]
        for j in range(1, n + 1):
            mark[q[0, j]] = base + flag
        if not large:
            for j in range(1, n + 1):
                out = _push(out, n_out, q[0, j])
                n_out += 1
            n_pieces += 1
    return out[:n_out].copy(), n_pieces
