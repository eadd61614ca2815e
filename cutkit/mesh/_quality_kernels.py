"""Numba kernels of :mod:`cutkit.mesh.quality` (no input checks here).

Every kernel has a slow NumPy twin in ``tests/_twins_topology.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# For edge k = TET_EDGES[k] the two faces that contain it are the faces
# opposite the two other vertices.
_EDGE_OPP = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]], dtype=np.int64)
_CHUNK = 4096
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


@njit(cache=True, nogil=True, inline="always")
def tet_volume(points, tets, t):
    """Signed volume of tet t: det[p1-p0, p2-p0, p3-p0] / 6."""
    p0 = tets[t, 0]
    p1 = tets[t, 1]
    p2 = tets[t, 2]
    p3 = tets[t, 3]
    ax = points[p1, 0] - points[p0, 0]
    ay = points[p1, 1] - points[p0, 1]
    az = points[p1, 2] - points[p0, 2]
    bx = points[p2, 0] - points[p0, 0]
    by = points[p2, 1] - points[p0, 1]
    bz = points[p2, 2] - points[p0, 2]
    cx = points[p3, 0] - points[p0, 0]
    cy = points[p3, 1] - points[p0, 1]
    cz = points[p3, 2] - points[p0, 2]
    return (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)) / 6.0


@njit(cache=True, parallel=True)
def signed_volumes(points, tets):
    """(m,) float64 det[p1-p0, p2-p0, p3-p0] / 6."""
    m = tets.shape[0]
    out = np.empty(m, np.float64)
    for t in prange(m):
        out[t] = tet_volume(points, tets, t)
    return out


@njit(cache=True, nogil=True)
def signed_volumes_serial(points, tets):
    """:func:`signed_volumes` on one thread, for a handful of tets (no thread start-up per call)."""
    out = np.empty(tets.shape[0], np.float64)
    for t in range(tets.shape[0]):
        out[t] = tet_volume(points, tets, t)
    return out


@njit(cache=True, parallel=True)
def dihedral_angles(points, tets):
    """(m, 6) float64 interior dihedral angle in degrees at each local edge.

    The angle at an edge is pi minus the angle between the outward normals
    of its two faces, taken as atan2(|n1 x n2|, -n1 . n2): unlike acos this
    keeps full precision near 0 and 180 degrees (slivers).  A face of zero
    area has a zero normal and gives 0 degrees.
    """
    m = tets.shape[0]
    out = np.empty((m, 6), np.float64)
    n_chunks = (m + _CHUNK - 1) // _CHUNK
    for ch in prange(n_chunks):
        n = np.empty((4, 3), np.float64)  # one scratch array per chunk, not per tet
        for t in range(ch * _CHUNK, min(m, (ch + 1) * _CHUNK)):
            tet_dihedrals(points, tets, t, n, out)
    return out


@njit(cache=True, nogil=True)
def tet_dihedrals(points, tets, t, n, out):
    """The six dihedral angles of tet t into out[t] (n: (4, 3) scratch for the face normals)."""
    for f in range(4):
        a = tets[t, _FACES[f, 0]]
        b = tets[t, _FACES[f, 1]]
        c = tets[t, _FACES[f, 2]]
        ux = points[b, 0] - points[a, 0]
        uy = points[b, 1] - points[a, 1]
        uz = points[b, 2] - points[a, 2]
        vx = points[c, 0] - points[a, 0]
        vy = points[c, 1] - points[a, 1]
        vz = points[c, 2] - points[a, 2]
        n[f, 0] = uy * vz - uz * vy
        n[f, 1] = uz * vx - ux * vz
        n[f, 2] = ux * vy - uy * vx
    for k in range(6):
        f1 = _EDGE_OPP[k, 0]
        f2 = _EDGE_OPP[k, 1]
        cx = n[f1, 1] * n[f2, 2] - n[f1, 2] * n[f2, 1]
        cy = n[f1, 2] * n[f2, 0] - n[f1, 0] * n[f2, 2]
        cz = n[f1, 0] * n[f2, 1] - n[f1, 1] * n[f2, 0]
        dot = n[f1, 0] * n[f2, 0] + n[f1, 1] * n[f2, 1] + n[f1, 2] * n[f2, 2]
        out[t, k] = math.degrees(math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), -dot))


@njit(cache=True, nogil=True)
def dihedral_angles_serial(points, tets):
    """:func:`dihedral_angles` on one thread, for a handful of tets (no thread start-up per call)."""
    out = np.empty((tets.shape[0], 6), np.float64)
    n = np.empty((4, 3), np.float64)
    for t in range(tets.shape[0]):
        tet_dihedrals(points, tets, t, n, out)
    return out
