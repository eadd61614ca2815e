"""Numba kernels of the volume collision (twins: cutkit.cutting._geometry)."""

import numpy as np
from numba import njit

#: Relative tolerance of the segment/triangle test (scaled by the lengths).
SEG_TRI_EPS = 1e-12
#: A vertex within this distance (relative to its edge's length) of the
#: swept surface's plane lies on it, and counts as lying just below it (a
#: symbolic perturbation): only its edges to vertices above the surface are
#: cut.  A blade through a vertex, along an edge or in a face plane then makes
#: one wall, not one on each side (which would free a slab between them).
EDGE_END_EPS = 1e-9
#: Closed-triangle slack of the edge crossing's barycentric coordinates, so an
#: edge crossing the swept quad on its diagonal is found by one of its halves.
EDGE_BARY_EPS = 1e-12


@njit(cache=True, nogil=True)
def seg_tri(p0, p1, a, b, c):
    """Parameter in [0, 1] where segment p0-p1 crosses triangle abc, or -1."""
    dx, dy, dz = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
    e1x, e1y, e1z = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    e2x, e2y, e2z = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    hx, hy, hz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * hx + e1y * hy + e1z * hz
    scale = (np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z) * np.sqrt(e2x * e2x + e2y * e2y + e2z * e2z)
             * np.sqrt(dx * dx + dy * dy + dz * dz)) + 1e-300
    if abs(det) <= SEG_TRI_EPS * scale:
        return -1.0
    inv = 1.0 / det
    sx, sy, sz = p0[0] - a[0], p0[1] - a[1], p0[2] - a[2]
    u = (sx * hx + sy * hy + sz * hz) * inv
    if u < 0.0 or u > 1.0:
        return -1.0
    qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return -1.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t < 0.0 or t > 1.0:
        return -1.0
    return t


@njit(cache=True, nogil=True)
def edge_cross(p, q, tri):
    """Parameter in [0, 1] where the edge p-q crosses triangle ``tri`` (3, 3), or -1.

    The edge crosses when one end lies above the triangle's plane and the
    other does not, an end within EDGE_END_EPS (relative to the edge's
    length) of the plane counting as on it, i.e. just below (a symbolic
    perturbation); then the crossing point must lie in the closed triangle
    (barycentric coordinates >= -EDGE_BARY_EPS).  An edge in the plane never
    crosses; an edge from a vertex on the plane crosses at that vertex only
    if it goes up.  The result depends on the edge's ends, not their order.
    """
    ux, uy, uz = tri[1, 0] - tri[0, 0], tri[1, 1] - tri[0, 1], tri[1, 2] - tri[0, 2]
    vx, vy, vz = tri[2, 0] - tri[0, 0], tri[2, 1] - tri[0, 1], tri[2, 2] - tri[0, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    if nn <= SEG_TRI_EPS * np.sqrt((ux * ux + uy * uy + uz * uz) * (vx * vx + vy * vy + vz * vz)):
        return -1.0  # a flat triangle (e.g. the blade pushed along its own axis) sweeps nothing
    dp = (nx * (p[0] - tri[0, 0]) + ny * (p[1] - tri[0, 1]) + nz * (p[2] - tri[0, 2])) / nn
    dq = (nx * (q[0] - tri[0, 0]) + ny * (q[1] - tri[0, 1]) + nz * (q[2] - tri[0, 2])) / nn
    tol = EDGE_END_EPS * np.sqrt((q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2 + (q[2] - p[2]) ** 2)
    if (dp > tol) == (dq > tol):
        return -1.0
    if abs(dp) <= tol:
        dp = 0.0
    if abs(dq) <= tol:
        dq = 0.0
    t = dp / (dp - dq)
    # barycentric coordinates of the crossing point (closed-form 2x2 normal equations)
    wx = p[0] + t * (q[0] - p[0]) - tri[0, 0]
    wy = p[1] + t * (q[1] - p[1]) - tri[0, 1]
    wz = p[2] + t * (q[2] - p[2]) - tri[0, 2]
    g11, g12, g22 = ux * ux + uy * uy + uz * uz, ux * vx + uy * vy + uz * vz, vx * vx + vy * vy + vz * vz
    r1, r2 = ux * wx + uy * wy + uz * wz, vx * wx + vy * wy + vz * wz
    det = g11 * g22 - g12 * g12
    if not det > 0.0:
        return -1.0
    b1 = (g22 * r1 - g12 * r2) / det
    b2 = (g11 * r2 - g12 * r1) / det
    if b1 < -EDGE_BARY_EPS or b2 < -EDGE_BARY_EPS or b1 + b2 > 1.0 + EDGE_BARY_EPS:
        return -1.0
    return t


@njit(cache=True, nogil=True)
def tet_sweep(x, tv, swept, blade, out_edge, out_face):
    """Edges of one tet met by the swept surface and faces met by the blade.

    Parameters
    ----------
    x : (n, 3) float64  node positions
    tv : (4,) int64  the tet's vertices
    swept : (2, 3, 3) float64  the two swept triangles
    blade : (2, 3) float64  blade segment (back, tip)
    out_edge : (6,) float64  parameter along local edge (TET_EDGES order, from
        the lower local vertex) or -1
    out_face : (4,) float64  blade parameter where it crosses local face i or -1
    """
    k = 0
    for i in range(4):
        for j in range(i + 1, 4):
            out_edge[k] = -1.0
            for s in range(2):
                t = edge_cross(x[tv[i]], x[tv[j]], swept[s])
                if t >= 0.0:
                    out_edge[k] = t
                    break
            k += 1
    for f in range(4):
        ia, ib, ic = (f + 1) % 4, (f + 2) % 4, (f + 3) % 4
        out_face[f] = seg_tri(blade[0], blade[1], x[tv[ia]], x[tv[ib]], x[tv[ic]])


@njit(cache=True, nogil=True)
def seg_tet(p0, p1, x, tv):
    """Whether segment p0-p1 meets the positively oriented tet ``tv``."""
    lo, hi = 0.0, 1.0
    for f in range(4):
        # face opposite vertex f; the inward direction points to vertex f
        a, b, c = x[tv[(f + 1) % 4]], x[tv[(f + 2) % 4]], x[tv[(f + 3) % 4]]
        nx = (b[1] - a[1]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[1] - a[1])
        ny = (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2])
        nz = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        p = x[tv[f]]
        if nx * (p[0] - a[0]) + ny * (p[1] - a[1]) + nz * (p[2] - a[2]) > 0:
            nx, ny, nz = -nx, -ny, -nz  # make it outward
        d0 = nx * (p0[0] - a[0]) + ny * (p0[1] - a[1]) + nz * (p0[2] - a[2])
        dd = nx * (p1[0] - p0[0]) + ny * (p1[1] - p0[1]) + nz * (p1[2] - p0[2])
        if abs(dd) < 1e-300:
            if d0 > 0.0:
                return False
            continue
        t = -d0 / dd
        if dd > 0.0:
            hi = min(hi, t)
        else:
            lo = max(lo, t)
        if lo > hi:
            return False
    return True


@njit(cache=True, nogil=True)
def seg_meets_any_tet(p0, p1, x, tets):
    """Whether segment p0-p1 meets one of ``tets`` (k, 4) over ``x`` (either orientation: :func:`seg_tet`)."""
    for t in range(tets.shape[0]):
        if seg_tet(p0, p1, x, tets[t]):
            return True
    return False
