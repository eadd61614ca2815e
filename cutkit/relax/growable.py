"""Arrays that grow by rows at amortised constant cost per row.

A cut adds a few nodes at a time, and every per-node array of the tissue
(masses, damping, held flags, adjacency degrees, colours, positions,
velocities) grows with them.  Concatenating copies the whole array: work
proportional to the model on every cut step.  :func:`append_rows` instead
returns a prefix view of a buffer with room to spare, doubled when full,
so the arrays keep their plain NumPy type and length for every reader.
"""

from __future__ import annotations

import weakref

import numpy as np

#: The view :func:`append_rows` last returned of each buffer it made, by the buffer's id: only that
#: view grows in place (a view holds its buffer, so the id is the buffer's while the entry lives).
#: Any other array, an older view of the same buffer or a view of someone else's (the tissue store's
#: own node arrays), is copied first.
_LATEST: "weakref.WeakValueDictionary[int, np.ndarray]" = weakref.WeakValueDictionary()
#: Rows a new buffer holds at least.
MIN_ROWS = 16


def append_rows(a: np.ndarray, rows) -> np.ndarray:
    """``a`` with ``rows`` appended along the first axis.

    Parameters
    ----------
    a : (n, ...) array
        The array as it is; its rows are not changed.
    rows : (p, ...) array_like
        Cast to ``a``'s dtype.

    Returns
    -------
    out : (n + p, ...) array
        A view of a buffer this function owns, sharing ``a``'s first ``n``
        rows when ``a`` is the view it last returned of that buffer and
        there is room after it; otherwise the rows are copied once into a
        buffer of twice the size (so an older view is never written over).
    """
    rows = np.asarray(rows, a.dtype).reshape((-1,) + a.shape[1:])
    n, p = a.shape[0], rows.shape[0]
    buf = a.base
    if buf is None or _LATEST.get(id(buf)) is not a or buf.shape[0] < n + p:
        buf = np.empty((max(n + p, 2 * n, MIN_ROWS),) + a.shape[1:], a.dtype)
        buf[:n] = a
    buf[n:n + p] = rows
    out = buf[:n + p]
    _LATEST[id(buf)] = out
    return out
