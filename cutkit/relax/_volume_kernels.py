"""Numba kernels of the volume term (no checks; NumPy twins in ``tests/_twins_relax.py``).

Energy of tet t: ``W_t = bulk_t (V_t - V0_t)^2 / (2 V0_t)``; the force on its
corner i is ``-bulk_t (V_t - V0_t) / V0_t * dV_t/dx_i``.  Each node sums the
terms of its own tets (node -> tet CSR), so a ``prange`` over nodes gives the
same result for every thread count.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, inline="always")
def _grad(p, a, b, c, d, corner):
    """dV/dx of ``corner`` (0..3) of tet (a, b, c, d), V = det[b - a, c - a, d - a] / 6, as a 3-tuple."""
    # The gradient of corner i is (1/6) times the cross product of two edges
    # of the opposite face, ordered so that it points towards corner i for a
    # positive tet.
    if corner == 0:
        i, j, k = b, d, c
    elif corner == 1:
        i, j, k = a, c, d
    elif corner == 2:
        i, j, k = a, d, b
    else:
        i, j, k = a, b, c
    e0 = p[j, 0] - p[i, 0]
    e1 = p[j, 1] - p[i, 1]
    e2 = p[j, 2] - p[i, 2]
    g0 = p[k, 0] - p[i, 0]
    g1 = p[k, 1] - p[i, 1]
    g2 = p[k, 2] - p[i, 2]
    return (e1 * g2 - e2 * g1) / 6.0, (e2 * g0 - e0 * g2) / 6.0, (e0 * g1 - e1 * g0) / 6.0


@njit(cache=True, nogil=True, inline="always")
def _volume(p, a, b, c, d):
    x0 = p[b, 0] - p[a, 0]
    x1 = p[b, 1] - p[a, 1]
    x2 = p[b, 2] - p[a, 2]
    y0 = p[c, 0] - p[a, 0]
    y1 = p[c, 1] - p[a, 1]
    y2 = p[c, 2] - p[a, 2]
    z0 = p[d, 0] - p[a, 0]
    z1 = p[d, 1] - p[a, 1]
    z2 = p[d, 2] - p[a, 2]
    return (x0 * (y1 * z2 - y2 * z1) - x1 * (y0 * z2 - y2 * z0) + x2 * (y0 * z1 - y1 * z0)) / 6.0


@njit(cache=True, parallel=True, nogil=True)
def add_volume_forces(nodes, p, tets, tet_offsets, node_tets, node_corner, rest_volume, bulk, f_in, k_in, f_out, k_out):
    """Volume forces and stiffnesses of each node of ``nodes`` at positions ``p``, added to given ones.

    ``f_out[k] = f_in[k] + sum over k's tets of -bulk (V - V0) / V0 dV/dx_k``
    (N) and ``k_out[k] = k_in[k] + sum of bulk |dV/dx_k|^2 / V0`` (N/mm),
    for the listed nodes only (other rows are left alone): the force and the
    diagonal stiffness along the gradient at the current shape, which the
    semi-implicit step of eq. (6) adds to the node's spring stiffness sum.

    p : (n, 3) float64 positions (the eq. (7) predictions); tets : (m, 4)
    int64; tet_offsets : (n + 1,) int64, node_tets, node_corner : (4 m,)
    int64 (tet and corner of each incidence); rest_volume : (m,) mm^3;
    bulk : (m,) N/mm^2; f_in, f_out : (n, 3) float64; k_in, k_out : (n,) float64.
    """
    for ii in prange(nodes.shape[0]):
        k = nodes[ii]
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        kk = 0.0
        for r in range(tet_offsets[k], tet_offsets[k + 1]):
            t = node_tets[r]
            a = tets[t, 0]
            b = tets[t, 1]
            c = tets[t, 2]
            d = tets[t, 3]
            v0 = rest_volume[t]
            s = -bulk[t] * (_volume(p, a, b, c, d) - v0) / v0
            g0, g1, g2 = _grad(p, a, b, c, d, node_corner[r])
            f0 += s * g0
            f1 += s * g1
            f2 += s * g2
            kk += bulk[t] * (g0 * g0 + g1 * g1 + g2 * g2) / v0
        f_out[k, 0] = f_in[k, 0] + f0
        f_out[k, 1] = f_in[k, 1] + f1
        f_out[k, 2] = f_in[k, 2] + f2
        k_out[k] = k_in[k] + kk


@njit(cache=True, nogil=True)
def tet_incidence(tets, n_nodes):
    """Node -> tet CSR by counting sort: ``(offsets (n + 1,), node_tets (4 m,), node_corner (4 m,))``, int64.

    The tets of node k, ascending, are ``node_tets[offsets[k]:offsets[k + 1]]``
    and ``node_corner`` says which corner of each tet k is.
    """
    m = tets.shape[0]
    offsets = np.zeros(n_nodes + 1, np.int64)
    for t in range(m):
        for c in range(4):
            offsets[tets[t, c] + 1] += 1
    for k in range(n_nodes):
        offsets[k + 1] += offsets[k]
    fill = offsets[:-1].copy()
    node_tets = np.empty(4 * m, np.int64)
    node_corner = np.empty(4 * m, np.int64)
    for t in range(m):
        for c in range(4):
            k = tets[t, c]
            node_tets[fill[k]] = t
            node_corner[fill[k]] = c
            fill[k] += 1
    return offsets, node_tets, node_corner
