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
#: node (CSR); ``support`` (n,) int64: an original node every tet holding node i also holds
#: (i itself for an original node, its first defining node for a cut node);
#: ``sub_start``, ``sub_count`` (m0,) int64: the contiguous range of sub-tet ids of each
#: original tet (count 0: the original tet itself).
Incidence = namedtuple("Incidence", "node_tet_off node_tet_idx support sub_start sub_count")

_UNSEEN, _GROWING, _LARGE, _CRUMB = 0, 1, 2, 3


@njit(cache=True, nogil=True)
def _rest_volume(X, tv):
    """Signed volume of the tet X[tv] (4,)."""
    o = tv[0]
    a0, a1, a2 = X[tv[1], 0] - X[o, 0], X[tv[1], 1] - X[o, 1], X[tv[1], 2] - X[o, 2]
    b0, b1, b2 = X[tv[2], 0] - X[o, 0], X[tv[2], 1] - X[o, 1], X[tv[2], 2] - X[o, 2]
    c0, c1, c2 = X[tv[3], 0] - X[o, 0], X[tv[3], 1] - X[o, 1], X[tv[3], 2] - X[o, 2]
    return (a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)) / 6.0


@njit(cache=True, nogil=True)
def _grow(X, tets, alive, inc, s, limit, state, comp):
    """Grow the piece of live tet ``s`` into ``comp``; returns (size, volume, large)."""
    n = 1
    comp[0] = s
    state[s] = _GROWING
    head = 0
    vol = 0.0
    while head < n:
        t = comp[head]
        head += 1
        vol += _rest_volume(X, tets[t])
        if vol > limit:
            return n, vol, True
        for j in range(4):
            v = tets[t, j]
            sup = inc.support[v]
            for k in range(inc.node_tet_off[sup], inc.node_tet_off[sup + 1]):
                o = inc.node_tet_idx[k]
                lo, hi = o, o + 1
                if inc.sub_count[o] > 0:
                    lo, hi = inc.sub_start[o], inc.sub_start[o] + inc.sub_count[o]
                for c in range(lo, hi):
                    if not alive[c] or state[c] == _GROWING:
                        continue
                    if tets[c, 0] != v and tets[c, 1] != v and tets[c, 2] != v and tets[c, 3] != v:
                        continue
                    if state[c] == _LARGE:
                        return n, vol, True
                    state[c] = _GROWING
                    comp[n] = c
                    n += 1
    return n, vol, False


@njit(cache=True, nogil=True)
def loose_small_pieces(X, tets, alive, inc, seeds, limit, state, out):
    """Live tets of the pieces through ``seeds`` whose rest volume is at most ``limit``.

    Parameters
    ----------
    X : (n, 3) float64  rest positions
    tets : (T, 4) int64  every tet made so far (``alive`` says which are live)
    alive : (T,) bool
    inc : Incidence
    seeds : (s,) int64  live tet ids to start from
    limit : float  largest crumb volume, mm^3
    state : (T,) int8  zeros on entry (scratch)
    out : (T,) int64  receives the crumbs' tets, piece after piece

    Returns
    -------
    n_out : int  tets written to ``out``
    n_pieces : int  crumbs found
    """
    comp = np.empty(tets.shape[0], np.int64)
    n_out = 0
    n_pieces = 0
    for i in range(seeds.shape[0]):
        s = seeds[i]
        if not alive[s] or state[s] != _UNSEEN:
            continue
        n, vol, large = _grow(X, tets, alive, inc, s, limit, state, comp)
        mark = _LARGE if large else _CRUMB
        for q in range(n):
            state[comp[q]] = mark
        if not large:
            out[n_out:n_out + n] = comp[:n]
            n_out += n
            n_pieces += 1
    return n_out, n_pieces
