"""Numba kernels that carry the Newton matrix's sparsity pattern over a topology change.

A cut removes elements, adds elements and appends nodes; it leaves the rest
of the model as it was.  A node row of the pattern (the sorted nodes that
share an active element with the node, itself included) changes only where
an element around the node changed: an element switched on or off, or one
whose corners were rewritten.  Every corner of such an element, and every
new node, is *touched*; the other rows are the old ones, shifted.  So the
update builds only the touched rows (as ``_newton_kernels.node_neighbours``
and ``gather_rows`` build every row), copies the others, and finds an element's blocks afresh
only in touched rows (an untouched row's blocks move with the row's start).
The result is the pattern a full build makes, array for array
(``tests/test_newton_pattern.py`` compares them, and both with a NumPy
twin), at about a quarter of a full build's time on the knee
(:mod:`cutkit.relax.hessian_pattern`).

The kernels check nothing (:meth:`cutkit.relax.hessian_pattern.HessianPattern.get`
does); ``halt`` ((1,) int64) is read every ``STOP_EVERY`` elements and
non-zero ends a kernel early, its last result False.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cutkit.relax._elastic_kernels import STOP_EVERY
from cutkit.relax._newton_kernels import gather_rows, sort_unique
from cutkit.relax._stop_flag import flag_up


@njit(cache=True, nogil=True)
def touched_nodes(tets, volume, old_tets, old_active, n_old, n, halt):
    """Nodes whose row may have changed since the pattern of ``old_tets`` (m_old, 4) int64 with
    ``old_active`` (m_old,) bool on ``n_old`` nodes was built: the corners, before and after, of
    every element (``tets`` (m, 4) int64, active where ``volume`` (m,) float64 > 0, m >= m_old)
    switched on, off or rewritten, and the nodes from ``n_old`` to ``n``.  Returns the (n,) bool
    mask, the elements changed and whether the scan was whole."""
    m, m_old = tets.shape[0], old_tets.shape[0]
    touched = np.zeros(n, np.bool_)
    touched[n_old:] = True
    changed = 0
    for t in range(m):
        if t % STOP_EVERY == 0 and flag_up(halt):
            return touched, changed, False
        active = volume[t] > 0.0
        was = t < m_old and old_active[t]
        same = active == was
        if same and active:
            for a in range(4):
                if tets[t, a] != old_tets[t, a]:
                    same = False
        if same:
            continue
        changed += 1
        if was:
            for a in range(4):
                touched[old_tets[t, a]] = True
        if active:
            for a in range(4):
                touched[tets[t, a]] = True
    return touched, changed, True


@njit(cache=True, nogil=True, parallel=True)
def update_node_rows(tets, volume, touched, old_ptr, old_idx, halt):
    """The node rows after the change: built afresh for ``touched`` (n,) bool nodes (the appended
    ones among them), copied from ``old_ptr`` (n_old + 1,) / ``old_idx`` for the others.  Returns ``node_ptr`` (n + 1,), ``node_idx`` and whether whole."""
    n = touched.shape[0]
    start, raw, whole = gather_rows(tets, volume, touched, halt)
    if not whole:
        return start, raw, False
    length = np.empty(n, np.int64)
    for i in prange(n):  # a touched row: sort and drop repeats in place; the others keep their length
        if not touched[i]:
            length[i] = old_ptr[i + 1] - old_ptr[i]
            continue
        length[i] = sort_unique(raw[start[i]:start[i + 1]])
    ptr = np.zeros(n + 1, np.int64)
    for i in range(n):
        ptr[i + 1] = ptr[i] + length[i]
    idx = np.empty(ptr[n], np.int64)
    for i in prange(n):
        if touched[i]:
            idx[ptr[i]:ptr[i + 1]] = raw[start[i]:start[i] + length[i]]
        else:
            idx[ptr[i]:ptr[i + 1]] = old_idx[old_ptr[i]:old_ptr[i + 1]]
    return ptr, idx, not flag_up(halt)


@njit(cache=True, nogil=True, parallel=True)
def update_element_blocks(tets, volume, touched, ptr, idx, old_ptr, old_blocks, halt):
    """(m, 4, 4) int64 element blocks on the rows ``ptr`` / ``idx`` of :func:`update_node_rows`:
    looked up in a touched row, the old position (``old_blocks`` (m_old, 4, 4)) moved with its
    row's start (``old_ptr``) in an untouched one (an element with an untouched corner is one
    that did not change).  Returns them and whether whole."""
    m = tets.shape[0]
    out = np.full((m, 4, 4), -1, np.int64)
    for t in prange(m):
        if volume[t] <= 0.0 or flag_up(halt):
            continue
        for a in range(4):
            i = tets[t, a]
            if touched[i]:
                row = idx[ptr[i]:ptr[i + 1]]
                for b in range(4):
                    out[t, a, b] = ptr[i] + np.searchsorted(row, tets[t, b])
            else:
                shift = ptr[i] - old_ptr[i]
                for b in range(4):
                    out[t, a, b] = old_blocks[t, a, b] + shift
    return out, not flag_up(halt)
