"""Numba geometry primitives of the decimator (tet shape, point-triangle distance).

Every function here has a NumPy twin in ``tests/_twins_decimate.py``.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True)
def tet_volume6(p0, p1, p2, p3):
    """Six times the signed volume, ``det[p1 - p0, p2 - p0, p3 - p0]``.

    Parameters
    ----------
    p0, p1, p2, p3 : (3,) float64
    """
    ax, ay, az = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
    bx, by, bz = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
    cx, cy, cz = p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2]
    nx, ny, nz = _cross(ax, ay, az, bx, by, bz)
    return nx * cx + ny * cy + nz * cz


@njit(cache=True)
def tet_max_cos(p0, p1, p2, p3):
    """Largest cosine of the six dihedral angles (1.0 for a degenerate tet).

    The smallest dihedral angle is ``arccos(tet_max_cos)``: comparing cosines
    avoids six ``acos`` per tet in the collapse test.  The dihedral angle
    between faces ``i`` and ``j`` is ``pi`` minus the angle between their
    outward normals, so ``cos(theta_ij) = -n_i . n_j / (|n_i| |n_j|)``.

    Parameters
    ----------
    p0, p1, p2, p3 : (3,) float64
    """
    # Face i is opposite vertex i; its normal is made to point away from vertex i
    # so that the result does not depend on the tet's orientation.
    n0 = _outward_unit(p1, p2, p3, p0)
    n1 = _outward_unit(p0, p2, p3, p1)
    n2 = _outward_unit(p0, p1, p3, p2)
    n3 = _outward_unit(p0, p1, p2, p3)
    if n0[3] == 0.0 or n1[3] == 0.0 or n2[3] == 0.0 or n3[3] == 0.0:
        return 1.0
    worst = -_dot3(n0, n1)
    worst = max(worst, -_dot3(n0, n2))
    worst = max(worst, -_dot3(n0, n3))
    worst = max(worst, -_dot3(n1, n2))
    worst = max(worst, -_dot3(n1, n3))
    worst = max(worst, -_dot3(n2, n3))
    return worst


@njit(cache=True, inline="always")
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def _outward_unit(a, b, c, o):
    """Unit normal of triangle abc pointing away from o, and its length (0: degenerate)."""
    nx, ny, nz = _cross(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1], c[2] - a[2])
    if nx * (o[0] - a[0]) + ny * (o[1] - a[1]) + nz * (o[2] - a[2]) > 0.0:
        nx, ny, nz = -nx, -ny, -nz
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln == 0.0:
        return (0.0, 0.0, 0.0, 0.0)
    return (nx / ln, ny / ln, nz / ln, ln)


@njit(cache=True)
def point_triangle_dist2(p, a, b, c):
    """Squared distance from point ``p`` to the triangle ``abc`` (all (3,) float64).

    Closest-point by Voronoi regions of the triangle (vertices, edges, face);
    a degenerate triangle falls through to its edges.
    """
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        qx, qy, qz = a[0], a[1], a[2]
    else:
        bpx, bpy, bpz = p[0] - b[0], p[1] - b[1], p[2] - b[2]
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            qx, qy, qz = b[0], b[1], b[2]
        elif d6 >= 0.0 and d5 <= d6:
            qx, qy, qz = c[0], c[1], c[2]
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0 and d1 - d3 > 0.0:
            t = d1 / (d1 - d3)
            qx, qy, qz = a[0] + t * abx, a[1] + t * aby, a[2] + t * abz
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0 and d2 - d6 > 0.0:
            t = d2 / (d2 - d6)
            qx, qy, qz = a[0] + t * acx, a[1] + t * acy, a[2] + t * acz
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0 and (d4 - d3) + (d5 - d6) > 0.0:
            t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            qx, qy, qz = b[0] + t * (c[0] - b[0]), b[1] + t * (c[1] - b[1]), b[2] + t * (c[2] - b[2])
        else:
            den = va + vb + vc
            if den > 0.0:
                v = vb / den
                w = vc / den
                qx = a[0] + abx * v + acx * w
                qy = a[1] + aby * v + acy * w
                qz = a[2] + abz * v + acz * w
            else:
                # Degenerate triangle: nearest of its three edges.
                return min(segment_dist2(p, a, b), segment_dist2(p, b, c), segment_dist2(p, a, c))
    dx, dy, dz = p[0] - qx, p[1] - qy, p[2] - qz
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, nogil=True)
def segment_dist2(p, a, b):
    """Squared distance from point ``p`` (3,) to the segment from ``a`` (3,) to ``b`` (3,) (a point if a == b)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    den = abx * abx + aby * aby + abz * abz
    t = 0.0
    if den > 0.0:
        t = ((p[0] - a[0]) * abx + (p[1] - a[1]) * aby + (p[2] - a[2]) * abz) / den
        t = min(1.0, max(0.0, t))
    dx = p[0] - (a[0] + t * abx)
    dy = p[1] - (a[1] + t * aby)
    dz = p[2] - (a[2] + t * abz)
    return dx * dx + dy * dy + dz * dz
