"""Numba kernels of :mod:`cutkit.mesh.check` (no input checks here).

Twin: ``tests/_twins_topology.py::hanging_nodes``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from cutkit.mesh.geometry import point_on_triangle


@njit(cache=True, parallel=True)
def hanging_nodes(points, tri, cand, cell_keys, cell_order, lo, h, dims, rel_tol):
    """For each node, a triangle it lies on without being one of its corners.

    ``cand`` are node ids, binned in a uniform grid (cell size ``h``, first
    corner ``lo``, ``dims`` cells per axis); ``cell_keys`` are their sorted
    linear cell keys and ``cell_order[s]`` the position in ``cand`` of the
    s-th sorted one.  A node x lies on triangle (a, b, c) of longest edge L
    when its distance to the plane is <= rel_tol * L and its barycentric
    coordinates are all >= -rel_tol, and it is farther than rel_tol * L from
    each corner.  Returns (n_points,) int64: a triangle index per node, -1
    where none (threads that find the same node on two triangles may
    write either index: both are right).
    """
    nt = tri.shape[0]
    out = np.full(points.shape[0], -1, np.int64)
    for t in prange(nt):
        a = tri[t, 0]
        b = tri[t, 1]
        c = tri[t, 2]
        ux = points[b, 0] - points[a, 0]
        uy = points[b, 1] - points[a, 1]
        uz = points[b, 2] - points[a, 2]
        vx = points[c, 0] - points[a, 0]
        vy = points[c, 1] - points[a, 1]
        vz = points[c, 2] - points[a, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        nn = nx * nx + ny * ny + nz * nz
        if nn == 0.0:
            continue  # a degenerate triangle: the orientation check reports it
        wx = points[c, 0] - points[b, 0]
        wy = points[c, 1] - points[b, 1]
        wz = points[c, 2] - points[b, 2]
        L = math.sqrt(max(ux * ux + uy * uy + uz * uz, vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz))
        tol = rel_tol * L
        i0 = np.empty(3, np.int64)
        i1 = np.empty(3, np.int64)
        for d in range(3):
            mn = min(points[a, d], points[b, d], points[c, d]) - tol
            mx = max(points[a, d], points[b, d], points[c, d]) + tol
            i0[d] = max(0, int(math.floor((mn - lo[d]) / h)))
            i1[d] = min(dims[d] - 1, int(math.floor((mx - lo[d]) / h)))
        for ci in range(i0[0], i1[0] + 1):
            for cj in range(i0[1], i1[1] + 1):
                for ck in range(i0[2], i1[2] + 1):
                    key = (ci * dims[1] + cj) * dims[2] + ck
                    s = np.searchsorted(cell_keys, key)  # the first candidate of the cell
                    while s < cell_keys.shape[0] and cell_keys[s] == key:
                        x = cand[cell_order[s]]
                        s += 1
                        if x == a or x == b or x == c:
                            continue
                        if point_on_triangle(points[x], points[a], points[b], points[c], rel_tol):
                            out[x] = t
    return out
