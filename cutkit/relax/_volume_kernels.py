"""Numba kernels of the volume term (no checks; NumPy twins in ``tests/_twins_relax.py``).

Energy of tet t: ``W_t = bulk_t (V_t - V0_t)^2 / (2 V0_t)``; the force on its
corner i is ``-bulk_t (V_t - V0_t) / V0_t * dV_t/dx_i``.  Each node sums the
terms of its own tets (node -> tet CSR), so a ``prange`` over nodes gives the
same result for every thread count.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

#: The volume term's tets as the kernel reads them: ``tets`` (m, 4) int64, the node -> tet CSR
#: ``tet_offsets`` (n + 1,) int64 and ``node_tets`` (4 m,) int64
#: (:func:`cutkit.mesh.topology.node_to_tets`), ``rest_volume`` (m,) mm^3, ``bulk`` (m,) N/mm^2.
VolumeTets = namedtuple("VolumeTets", ["tets", "tet_offsets", "node_tets", "rest_volume", "bulk"])
#: Per-node sums: ``force`` (n, 3) float64 N and ``stiffness`` (n,) float64 N/mm.
NodeSums = namedtuple("NodeSums", ["force", "stiffness"])


@njit(cache=True, nogil=True, inline="always")
def _grad_volume(p, a, b, c, d, corner):
    """dV/dx of ``corner`` (0..3) of tet (a, b, c, d) and V itself, as a 4-tuple.

    V = det[b - a, c - a, d - a] / 6.  The gradient of corner i is (1/6)
    times the cross product of two edges of the opposite face, ordered so
    that it points towards corner i for a positive tet; V is linear in the
    corner's position and vanishes on that face, so V = grad . (x_i - x_f)
    for a face node f: one dot product instead of a determinant.
    """
    if corner == 0:
        x, i, j, k = a, b, d, c
    elif corner == 1:
        x, i, j, k = b, a, c, d
    elif corner == 2:
        x, i, j, k = c, a, d, b
    else:
        x, i, j, k = d, a, b, c
    e0 = p[j, 0] - p[i, 0]
    e1 = p[j, 1] - p[i, 1]
    e2 = p[j, 2] - p[i, 2]
    h0 = p[k, 0] - p[i, 0]
    h1 = p[k, 1] - p[i, 1]
    h2 = p[k, 2] - p[i, 2]
    g0 = (e1 * h2 - e2 * h1) / 6.0
    g1 = (e2 * h0 - e0 * h2) / 6.0
    g2 = (e0 * h1 - e1 * h0) / 6.0
    vol = g0 * (p[x, 0] - p[i, 0]) + g1 * (p[x, 1] - p[i, 1]) + g2 * (p[x, 2] - p[i, 2])
    return g0, g1, g2, vol


@njit(cache=True, parallel=True, nogil=True)
def add_volume_forces(nodes, p, volume, given, out):
    """Volume forces and stiffnesses of each node of ``nodes`` at positions ``p``, added to given ones.

    ``out.force[k] = given.force[k] + sum over k's tets of -bulk (V - V0) / V0 dV/dx_k``
    (N) and ``out.stiffness[k] = given.stiffness[k] + sum of bulk |dV/dx_k|^2 / V0`` (N/mm),
    for the listed nodes only (other rows are left alone): the force and the
    diagonal stiffness along the gradient at the current shape, which the
    semi-implicit step of eq. (6) adds to the node's spring stiffness sum.

    nodes : (k,) int64; p : (n, 3) float64 positions (the eq. (7) predictions); volume :
    VolumeTets; given, out : NodeSums (``out`` written at ``nodes``).
    """
    tets, tet_offsets, node_tets = volume.tets, volume.tet_offsets, volume.node_tets
    rest_volume, bulk = volume.rest_volume, volume.bulk
    f_in, k_in, f_out, k_out = given.force, given.stiffness, out.force, out.stiffness
    for ii in prange(nodes.shape[0]):
        k = nodes[ii]
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        kk = 0.0
        for r in range(tet_offsets[k], tet_offsets[k + 1]):
            t = node_tets[r]
            v0 = rest_volume[t]
            corner = 0
            while tets[t, corner] != k:
                corner += 1
            g0, g1, g2, vol = _grad_volume(p, tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3], corner)
            s = -bulk[t] * (vol - v0) / v0
            f0 += s * g0
            f1 += s * g1
            f2 += s * g2
            kk += bulk[t] * (g0 * g0 + g1 * g1 + g2 * g2) / v0
        f_out[k, 0] = f_in[k, 0] + f0
        f_out[k, 1] = f_in[k, 1] + f1
        f_out[k, 2] = f_in[k, 2] + f2
        k_out[k] = k_in[k] + kk
