"""Numba kernels of :mod:`cutkit.mesh.topology` (no input checks here).

Every kernel has a slow NumPy twin in ``tests/_twins_topology.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, parallel=True)
def sorted_tuples(tets, local):
    """(len(local) * m, w) int64: for each tet t and local tuple i (row ``k*t + i``),
    the node ids ``tets[t, local[i]]`` in ascending order."""
    m = tets.shape[0]
    k = local.shape[0]
    w = local.shape[1]
    out = np.empty((k * m, w), np.int64)
    for t in prange(m):
        for i in range(k):
            r = k * t + i
            for j in range(w):  # insertion sort of w <= 3 values
                v = tets[t, local[i, j]]
                q = j
                while q > 0 and out[r, q - 1] > v:
                    out[r, q] = out[r, q - 1]
                    q -= 1
                out[r, q] = v
    return out


@njit(cache=True, nogil=True, parallel=True)
def unique_rows(rows, n):
    """Unique rows of a (k, w) array of ascending rows with entries in [0, n), w in {2, 3}.

    Rows are bucketed by their first (smallest) node with a counting sort,
    then each bucket, a few dozen rows for a tet mesh, is insertion-sorted
    by the rest of the row; this is linear in k apart from the small
    bucket sorts, and the buckets run in parallel.

    Returns ``unique`` (u, w) int64 in lexicographic order and ``inverse``
    (k,) int64 with ``unique[inverse[r]] == rows[r]``.
    """
    k = rows.shape[0]
    w = rows.shape[1]
    offsets = np.zeros(n + 1, np.int64)
    for r in range(k):
        offsets[rows[r, 0] + 1] += 1
    for v in range(n):
        offsets[v + 1] += offsets[v]
    fill = offsets[:-1].copy()
    order = np.empty(k, np.int64)
    sub = np.empty(k, np.int64)  # the rest of the row as one key, bucket-sorted alongside
    for r in range(k):
        a = rows[r, 0]
        s = fill[a]
        fill[a] = s + 1
        order[s] = r
        key = rows[r, 1]
        if w == 3:
            key = key * n + rows[r, 2]
        sub[s] = key
    ucount = np.zeros(n + 1, np.int64)
    for a in prange(n):
        lo = offsets[a]
        hi = offsets[a + 1]
        for s in range(lo + 1, hi):
            key = sub[s]
            r = order[s]
            q = s
            while q > lo and sub[q - 1] > key:
                sub[q] = sub[q - 1]
                order[q] = order[q - 1]
                q -= 1
            sub[q] = key
            order[q] = r
        u = 0
        for s in range(lo, hi):
            if s == lo or sub[s] != sub[s - 1]:
                u += 1
        ucount[a + 1] = u
    for a in range(n):
        ucount[a + 1] += ucount[a]
    unique = np.empty((ucount[n], w), np.int64)
    inverse = np.empty(k, np.int64)
    for a in prange(n):
        u = ucount[a] - 1
        for s in range(offsets[a], offsets[a + 1]):
            r = order[s]
            if s == offsets[a] or sub[s] != sub[s - 1]:
                u += 1
                for j in range(w):
                    unique[u, j] = rows[r, j]
            inverse[r] = u
    return unique, inverse


@njit(cache=True, nogil=True)
def face_tets_from_inverse(inverse, n_faces):
    """(f, 2) int64 tets on each side of each face (-1 = none) and a (f,) count of users.

    A face used by more than two tets keeps its first two (the count tells).
    """
    face_tets = np.full((n_faces, 2), -1, np.int64)
    count = np.zeros(n_faces, np.int64)
    for r in range(inverse.shape[0]):
        f = inverse[r]
        t = r // 4
        c = count[f]
        if c < 2:
            face_tets[f, c] = t
        count[f] = c + 1
    return face_tets, count


@njit(cache=True, nogil=True, parallel=True)
def neighbors_from_faces(tet_faces, face_tets):
    """(m, 4) int64 neighbour across face i (-1 on the boundary)."""
    m = tet_faces.shape[0]
    out = np.empty((m, 4), np.int64)
    for t in prange(m):
        for i in range(4):
            f = tet_faces[t, i]
            a = face_tets[f, 0]
            b = face_tets[f, 1]
            out[t, i] = b if a == t else a
    return out


@njit(cache=True, nogil=True)
def csr_counts(tets, n_points):
    """Offsets (n+1,) int64 and indices of the node -> row incidence of a (m, w) table (rows ascending per node)."""
    m, w = tets.shape
    offsets = np.zeros(n_points + 1, np.int64)
    for t in range(m):
        for j in range(w):
            offsets[tets[t, j] + 1] += 1
    for v in range(n_points):
        offsets[v + 1] += offsets[v]
    fill = offsets[:-1].copy()
    indices = np.empty(w * m, np.int64)
    for t in range(m):
        for j in range(w):
            v = tets[t, j]
            indices[fill[v]] = t
            fill[v] += 1
    return offsets, indices
