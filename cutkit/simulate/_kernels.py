"""Numba kernels of the cut-to-spring coupling (twins in ``tests/_twins_simulate.py``)."""

from __future__ import annotations

import numpy as np
from numba import njit


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
