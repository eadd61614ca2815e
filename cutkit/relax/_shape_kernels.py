"""Numba kernels for tetrahedra's edge matrices: inverses, determinants, rest shapes.

A tet's edge matrix holds the edges from its first corner as columns,
``D = [X1 - X0, X2 - X0, X3 - X0]``; its determinant is six times the
signed volume, and ``D^-1`` gives the barycentric weights of a point and the
shape-function gradients.  A cut makes a few tets at a time, where NumPy's
batched ``det`` and ``inv`` cost more in calls than in arithmetic; these
kernels check nothing (:func:`cutkit.relax.elastic.rest_shape` does; the
NumPy twins are in ``tests/_twins_elastic.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, inline="always")
def _det_and_inverse(D, out):
    """det D of a (3, 3) matrix; ``out`` (3, 3) receives D^-1 when det D != 0 (the adjugate over det)."""
    c00 = D[1, 1] * D[2, 2] - D[1, 2] * D[2, 1]
    c01 = D[1, 2] * D[2, 0] - D[1, 0] * D[2, 2]
    c02 = D[1, 0] * D[2, 1] - D[1, 1] * D[2, 0]
    det = D[0, 0] * c00 + D[0, 1] * c01 + D[0, 2] * c02
    if det != 0.0:
        inv = 1.0 / det
        out[0, 0] = c00 * inv
        out[1, 0] = c01 * inv
        out[2, 0] = c02 * inv
        out[0, 1] = (D[0, 2] * D[2, 1] - D[0, 1] * D[2, 2]) * inv
        out[1, 1] = (D[0, 0] * D[2, 2] - D[0, 2] * D[2, 0]) * inv
        out[2, 1] = (D[0, 1] * D[2, 0] - D[0, 0] * D[2, 1]) * inv
        out[0, 2] = (D[0, 1] * D[1, 2] - D[0, 2] * D[1, 1]) * inv
        out[1, 2] = (D[0, 2] * D[1, 0] - D[0, 0] * D[1, 2]) * inv
        out[2, 2] = (D[0, 0] * D[1, 1] - D[0, 1] * D[1, 0]) * inv
    return det


@njit(cache=True, nogil=True)
def corner_edge_inverses(corners, Tinv):
    """Inverse edge matrices of tets given by their corners.

    Parameters
    ----------
    corners : (r, 4, 3) float64
    Tinv : (r, 3, 3) float64
        Out: D^-1 of each tet with det D != 0 (other rows untouched).

    Returns
    -------
    ok : (r,) bool
        det D != 0.
    """
    D = np.empty((3, 3))
    ok = np.empty(corners.shape[0], np.bool_)
    for r in range(corners.shape[0]):
        for i in range(3):
            for j in range(3):
                D[i, j] = corners[r, j + 1, i] - corners[r, 0, i]
        ok[r] = _det_and_inverse(D, Tinv[r]) != 0.0
    return ok


@njit(cache=True, nogil=True, inline="always")
def _rest_shape(X, tets, prestrain, fibre, quality_min, Dminv, volume, rest_volume, t):
    """Natural shape of tet ``t`` (the arguments of :func:`rest_shapes`)."""
    D = np.empty((3, 3))
    a = tets[t, 0]
    for j in range(3):
        b = tets[t, j + 1]
        for i in range(3):
            D[i, j] = X[b, i] - X[a, i]
    rest_volume[t] = (D[0, 0] * (D[1, 1] * D[2, 2] - D[1, 2] * D[2, 1])
                      + D[0, 1] * (D[1, 2] * D[2, 0] - D[1, 0] * D[2, 2])
                      + D[0, 2] * (D[1, 0] * D[2, 1] - D[1, 1] * D[2, 0])) / 6.0
    p = prestrain[t]
    f0, f1, f2 = fibre[t, 0], fibre[t, 1], fibre[t, 2]
    for j in range(3):
        along = p * (f0 * D[0, j] + f1 * D[1, j] + f2 * D[2, j])
        D[0, j] -= along * f0
        D[1, j] -= along * f1
        D[2, j] -= along * f2
    # rms edge length: the three edges from corner 0 and the three between the others
    s = 0.0
    for i in range(3):
        e0, e1, e2 = D[i, 0], D[i, 1], D[i, 2]
        s += e0 * e0 + e1 * e1 + e2 * e2 + (e1 - e0) ** 2 + (e2 - e1) ** 2 + (e0 - e2) ** 2
    l_rms = max(np.sqrt(s / 6.0), 1e-300)
    det = _det_and_inverse(D, Dminv[t])
    v = det / 6.0
    if 6.0 * np.sqrt(2.0) * v / (l_rms * l_rms * l_rms) >= quality_min:
        volume[t] = v
    else:
        volume[t] = 0.0
        Dminv[t, :, :] = 0.0


@njit(cache=True, nogil=True, parallel=True)
def rest_shapes(X, tets, prestrain, fibre, quality_min, Dminv, volume, rest_volume):
    """Natural shapes of tets with a prestrain along a fibre: ``D' = (I - p f f^T) D``.

    Parameters
    ----------
    X : (n, 3) float64
    tets : (m, 4) int64
    prestrain : (m,) float64
    fibre : (m, 3) float64
    quality_min : float
        Tets whose natural normalised volume 6 sqrt(2) V / l_rms^3 is below it
        get ``Dminv = 0`` and ``volume = 0``.
    Dminv : (m, 3, 3) float64
        Out: inverse natural edge matrices.
    volume, rest_volume : (m,) float64
        Out: natural and rest volumes, mm^3.
    """
    for t in prange(tets.shape[0]):
        _rest_shape(X, tets, prestrain, fibre, quality_min, Dminv, volume, rest_volume, t)


@njit(cache=True, nogil=True)
def rest_shapes_serial(X, tets, prestrain, fibre, quality_min, Dminv, volume, rest_volume):
    """:func:`rest_shapes` on the calling thread: a cut's few new tets, where waking the
    thread pool costs more than the arithmetic (about 0.3 ms a call on the knee's cut steps)."""
    for t in range(tets.shape[0]):
        _rest_shape(X, tets, prestrain, fibre, quality_min, Dminv, volume, rest_volume, t)
