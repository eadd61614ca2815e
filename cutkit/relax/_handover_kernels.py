"""Numba kernels that carry a cut over to the tissue (twins in ``tests/_twins_simulate.py``)."""

from __future__ import annotations

import numpy as np
from numba import njit

from cutkit.relax.kernels import corner_edge_inverses


@njit(cache=True, nogil=True)
def lookup_springs(adj_offsets, adj_nodes, adj_springs, a, b):
    """Spring joining ``a[i]`` and ``b[i]`` in a CSR spring graph, -1 where none.

    Parameters
    ----------
    adj_offsets : (n + 1,) int64
    adj_nodes : (2 s,) int32
        Other ends, ascending within each row.
    adj_springs : (2 s,) int32
    a, b : (k,) int64
        Node pairs; ``a`` or ``b`` >= n (a node the graph does not have yet) gives -1.

    Returns
    -------
    spring : (k,) int64
    """
    n = adj_offsets.shape[0] - 1
    out = np.full(a.shape[0], -1, np.int64)
    for i in range(a.shape[0]):
        u = a[i]
        w = b[i]
        if u >= n or w >= n:
            continue
        lo = adj_offsets[u]
        hi = adj_offsets[u + 1]
        while lo < hi:  # binary search in the ascending row
            mid = (lo + hi) // 2
            if adj_nodes[mid] < w:
                lo = mid + 1
            else:
                hi = mid
        if lo < adj_offsets[u + 1] and adj_nodes[lo] == w:
            out[i] = adj_springs[lo]
    return out


@njit(cache=True, nogil=True)
def place_through_old_shape(rest, X, x, Tinv, reach, out):
    """Current positions of nodes through the piecewise affine old shape of a few tets.

    Each node takes the affine map of the tet it lies in, or of the nearest
    one (the largest smallest barycentric weight, the first on a tie),
    extended outside it while that weight is at least ``-reach``; farther
    from every tet it keeps the position ``out`` holds on entry.

    Parameters
    ----------
    rest : (p, 3) float64
        The nodes' rest positions, mm.
    X, x : (r, 4, 3) float64
        The tets' rest and current corners, mm.
    Tinv : (r, 3, 3) float64
        Inverse rest edge matrices (columns X1 - X0, X2 - X0, X3 - X0).
    reach : float
    out : (p, 3) float64
        In: each node's position where no tet reaches it; out: its place.
    """
    b = np.empty(4)
    best_b = np.empty(4)
    for p in range(rest.shape[0]):
        best = -np.inf
        k = -1
        for r in range(X.shape[0]):
            d0 = rest[p, 0] - X[r, 0, 0]
            d1 = rest[p, 1] - X[r, 0, 1]
            d2 = rest[p, 2] - X[r, 0, 2]
            for i in range(3):
                b[i + 1] = Tinv[r, i, 0] * d0 + Tinv[r, i, 1] * d1 + Tinv[r, i, 2] * d2
            b[0] = 1.0 - (b[1] + b[2] + b[3])
            worst = min(min(b[0], b[1]), min(b[2], b[3]))
            if worst > best:
                best = worst
                k = r
                best_b[:] = b
        if k >= 0 and best >= -reach:
            for c in range(3):
                out[p, c] = (best_b[0] * x[k, 0, c] + best_b[1] * x[k, 1, c] + best_b[2] * x[k, 2, c]
                             + best_b[3] * x[k, 3, c])


@njit(cache=True, nogil=True)
def old_shape_corners(tets, X, x, n, moved, moved_from):
    """The tissue before a cut step, as corners of the tets it was made of.

    Parameters
    ----------
    tets : (r, 4) int64
        Corners of the tets (those with a corner >= ``n``, a node the tissue does not have yet, are left out).
    X, x : (N, 3) float64
        Rest and current positions (rows >= n unread).
    n : int
    moved : (b,) int64
        Nodes the step moved in the rest configuration, ascending.
    moved_from : (b, 3) float64
        Their rest positions before the step (taken in place of ``X``).

    Returns
    -------
    (Xc, xc, Tinv) : (q, 4, 3), (q, 4, 3), (q, 3, 3) float64
        Rest and current corners and inverse rest edge matrices of the tets
        with every corner < n and a non-zero rest volume, in input order.
    """
    r = tets.shape[0]
    Xc = np.empty((r, 4, 3))
    xc = np.empty((r, 4, 3))
    q = 0
    for t in range(r):
        if tets[t, 0] >= n or tets[t, 1] >= n or tets[t, 2] >= n or tets[t, 3] >= n:
            continue
        for c in range(4):
            a = tets[t, c]
            k = np.searchsorted(moved, a)
            src = moved_from[k] if k < moved.shape[0] and moved[k] == a else X[a]
            for d in range(3):
                Xc[q, c, d] = src[d]
                xc[q, c, d] = x[a, d]
        q += 1
    Tinv = np.empty((q, 3, 3))
    ok = corner_edge_inverses(Xc[:q], Tinv)
    keep = np.flatnonzero(ok)
    return Xc[keep], xc[keep], Tinv[keep]


@njit(cache=True, nogil=True)
def _minus(a, b):
    """Sorted unique ``a`` without the elements of sorted unique ``b``."""
    out = np.empty(a.shape[0], np.int64)
    k = 0
    j = 0
    for i in range(a.shape[0]):
        while j < b.shape[0] and b[j] < a[i]:
            j += 1
        if j == b.shape[0] or b[j] != a[i]:
            out[k] = a[i]
            k += 1
    return out[:k]


@njit(cache=True, nogil=True)
def _union(a, b):
    """Sorted unique union of sorted unique ``a`` and ``b``."""
    out = np.empty(a.shape[0] + b.shape[0], np.int64)
    i = j = k = 0
    while i < a.shape[0] or j < b.shape[0]:
        if j == b.shape[0] or (i < a.shape[0] and a[i] < b[j]):
            out[k] = a[i]
            i += 1
        elif i == a.shape[0] or b[j] < a[i]:
            out[k] = b[j]
            j += 1
        else:
            out[k] = a[i]
            i += 1
            j += 1
        k += 1
    return out[:k]


@njit(cache=True, nogil=True)
def step_tet_sets(added, removed, around):
    """The tet sets a cut step hands over, each sorted and unique.

    Parameters
    ----------
    added, removed : (a,), (r,) int64
        Tets the step made and unmade (a tet may be both: made and unmade
        within the step, never simulated).
    around : (b,) int64, sorted unique
        Tets around the nodes the step moved.

    Returns
    -------
    (added, removed, again, old) : int64 arrays
        Made and not unmade; unmade and not made; ``around`` neither made
        nor unmade (their rest shape is made again); unmade or around (the
        old shape's tets).
    """
    a, r = np.unique(added), np.unique(removed)
    added_only, removed_only = _minus(a, r), _minus(r, a)
    again = _minus(around, _union(added_only, removed_only))
    return added_only, removed_only, again, _union(removed_only, around)
