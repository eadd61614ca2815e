"""Numba kernels of :mod:`cutkit.mesh.quality` (no input checks here).

The per-tet primitives are in :mod:`cutkit.mesh.geometry`.  Every kernel has
a slow NumPy twin in ``tests/_twins_topology.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cutkit.mesh.geometry import tet_dihedrals, tet_signed_volume

_CHUNK = 4096


@njit(cache=True, parallel=True)
def signed_volumes(points, tets):
    """(m,) float64 det[p1-p0, p2-p0, p3-p0] / 6 (:func:`cutkit.mesh.geometry.tet_signed_volume`)."""
    m = tets.shape[0]
    out = np.empty(m, np.float64)
    for t in prange(m):
        out[t] = tet_signed_volume(points, tets, t)
    return out


@njit(cache=True, parallel=True)
def dihedral_angles(points, tets):
    """(m, 6) float64 interior dihedral angle in degrees at each local edge (:func:`.geometry.tet_dihedrals`)."""
    m = tets.shape[0]
    out = np.empty((m, 6), np.float64)
    n_chunks = (m + _CHUNK - 1) // _CHUNK
    for ch in prange(n_chunks):
        n = np.empty((4, 3), np.float64)  # one scratch array per chunk, not per tet
        for t in range(ch * _CHUNK, min(m, (ch + 1) * _CHUNK)):
            tet_dihedrals(points, tets, t, n, out)
    return out


@njit(cache=True, nogil=True)
def dihedral_angles_serial(points, tets):
    """:func:`dihedral_angles` on one thread, for a handful of tets (no thread start-up per call)."""
    out = np.empty((tets.shape[0], 6), np.float64)
    n = np.empty((4, 3), np.float64)
    for t in range(tets.shape[0]):
        tet_dihedrals(points, tets, t, n, out)
    return out
