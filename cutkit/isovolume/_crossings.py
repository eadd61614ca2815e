"""Where each crossing of a label map lies on its grid edge (numba, no checks).

Crossing node ``eoff[g] + r - n_v`` (the r-th crossing edge of vertex g, in
direction order) gets its parameter ``s`` in (0, 1) from ``g`` towards the
edge's far end.  Every other pass reads ``s`` from this one table, so a
crossing is computed once and every tet that shares the edge sees the same
point.
"""

from __future__ import annotations

from numba import njit, prange

from cutkit.isovolume._clip import POPCOUNT, label_crossing


@njit(cache=True, nogil=True, inline="always")
def crossing_node(g, d, mask, eoff):
    """Node id of the crossing on the forward edge ``d`` (0..6) of grid vertex ``g``."""
    return eoff[g] + POPCOUNT[mask[g] & ((1 << d) - 1)]


@njit(cache=True, parallel=True)
def label_crossing_params(lab, mask, eoff, n_v, nx, ny, nz, out):
    """``out[node - n_v]``: the :func:`label_crossing` parameter of every crossing (the midpoint rule).

    out : (n_e,) float64, written.
    """
    for i in prange(nx):
        for j in range(ny):
            for k in range(nz):
                g = (i * ny + j) * nz + k
                m = mask[g]
                if m == 0:
                    continue
                r = 0
                for d in range(7):
                    if (m >> d) & 1:
                        out[eoff[g] + r - n_v] = label_crossing(lab, g, d + 1, ny, nz)
                        r += 1
