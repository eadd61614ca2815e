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

#: Buffers :func:`append_rows` made, by id: only a prefix view of one of these grows in
#: place (a view of anything else, such as the cut mesh's own node arrays, is copied first).
_BUFFERS: "weakref.WeakValueDictionary[int, np.ndarray]" = weakref.WeakValueDictionary()
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
        rows when ``a`` is such a view with room after it; otherwise the
        rows are copied once into a buffer of twice the size.  Call it on
        the newest array only: appending to an older view of the same
        buffer would write over rows appended since.
    """
    rows = np.asarray(rows, a.dtype).reshape((-1,) + a.shape[1:])
    n, p = a.shape[0], rows.shape[0]
    buf = a.base
    fits = (buf is not None and _BUFFERS.get(id(buf)) is buf and buf.shape[0] >= n + p
            and a.ctypes.data == buf.ctypes.data)
    if not fits:
        buf = np.empty((max(n + p, 2 * n, MIN_ROWS),) + a.shape[1:], a.dtype)
        buf[:n] = a
        _BUFFERS[id(buf)] = buf
    buf[n:n + p] = rows
    return buf[:n + p]
