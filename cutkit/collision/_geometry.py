"""Segment-triangle and segment-box tests (numba, no input checks).

All tolerances are module constants; they are relative to the sizes of
the segment and the triangle so that the tests behave the same in mm or
in m.
"""

from __future__ import annotations

import math

from numba import njit

#: Relative tolerance on the barycentric coordinates: a segment passing
#: within this of an edge or a vertex hits it, so a segment through a
#: shared edge or vertex hits every triangle around it (no gap between
#: neighbours through which it could slip).
EPS_BARY = 1e-10
#: Segment parameter tolerance: hits at t in [-EPS_T, 1 + EPS_T] count
#: (clamped to [0, 1]), so a segment ending on the surface hits it.
EPS_T = 1e-10
#: |sin| of the angle between the segment and the triangle's plane below
#: which the two are parallel; then the segment hits only if it lies in the
#: plane (coplanar case).
EPS_PARALLEL = 1e-12
#: Distance of a parallel segment from the plane, relative to the size of
#: the triangle, below which it lies in the plane.
EPS_COPLANAR = 1e-10
#: Slab test padding, relative to the box size: boxes are closed sets.
EPS_BOX = 1e-12

#: Kinds of hit: through the inside of the triangle, through (or within
#: EPS_BARY of) an edge, through a vertex, or lying in the triangle's plane.
HIT_FACE = 0
HIT_EDGE = 1
HIT_VERTEX = 2
HIT_COPLANAR = 3


@njit(cache=True, nogil=True)
def segment_box(p0x, p0y, p0z, dx, dy, dz, bmin, bmax):
    """True if the segment p0 + t d, t in [0, 1], meets the closed box."""
    if bmin[0] > bmax[0]:  # empty box (dead leaf)
        return False
    t0 = 0.0
    t1 = 1.0
    for ax in range(3):
        if ax == 0:
            p, d = p0x, dx
        elif ax == 1:
            p, d = p0y, dy
        else:
            p, d = p0z, dz
        pad = EPS_BOX * (abs(bmax[ax]) + abs(bmin[ax]) + 1.0)
        lo = bmin[ax] - pad
        hi = bmax[ax] + pad
        if d == 0.0:
            if p < lo or p > hi:
                return False
        else:
            inv = 1.0 / d
            ta = (lo - p) * inv
            tb = (hi - p) * inv
            if ta > tb:
                ta, tb = tb, ta
            if ta > t0:
                t0 = ta
            if tb < t1:
                t1 = tb
            if t0 > t1:
                return False
    return True


@njit(cache=True, nogil=True)
def segment_triangle(p0, p1, v0, v1, v2, out):
    """Möller–Trumbore segment-triangle test with degenerate cases.

    Parameters
    ----------
    p0, p1 : (3,) float64
        Segment end points; the segment is p0 + t (p1 - p0), t in [0, 1].
    v0, v1, v2 : (3,) float64
        Triangle corners.
    out : (4,) float64
        Receives t and the hit point (x, y, z).

    Returns
    -------
    int
        -1 for no hit, else one of HIT_FACE, HIT_EDGE, HIT_VERTEX,
        HIT_COPLANAR.  For a coplanar segment ``t`` is where it enters
        the (closed) triangle.
    """
    dx = p1[0] - p0[0]
    dy = p1[1] - p0[1]
    dz = p1[2] - p0[2]
    e1x = v1[0] - v0[0]
    e1y = v1[1] - v0[1]
    e1z = v1[2] - v0[2]
    e2x = v2[0] - v0[0]
    e2y = v2[1] - v0[1]
    e2z = v2[2] - v0[2]
    # plane normal (not normalised) and its length
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    nlen = math.sqrt(nx * nx + ny * ny + nz * nz)
    dlen = math.sqrt(dx * dx + dy * dy + dz * dz)
    if nlen == 0.0 or dlen == 0.0:
        return -1  # degenerate triangle or segment: no well-defined crossing
    sx = p0[0] - v0[0]
    sy = p0[1] - v0[1]
    sz = p0[2] - v0[2]
    # det = -(d . n): Möller–Trumbore's determinant
    dn = dx * nx + dy * ny + dz * nz
    if abs(dn) <= EPS_PARALLEL * nlen * dlen:
        # parallel: a hit only if the segment lies in the plane
        size = math.sqrt(max(e1x * e1x + e1y * e1y + e1z * e1z, e2x * e2x + e2y * e2y + e2z * e2z))
        dist = abs(sx * nx + sy * ny + sz * nz) / nlen
        if dist > EPS_COPLANAR * size:
            return -1
        return _coplanar(p0, dx, dy, dz, v0, v1, v2, nx, ny, nz, nlen, out)
    # Cramer's rule on p0 + t d = v0 + u e1 + v e2 (Möller–Trumbore form)
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return -1  # a nearly flat triangle: d.n passed the parallel test, rounding made det 0
    inv = 1.0 / det
    u = (sx * px + sy * py + sz * pz) * inv
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    w = 1.0 - u - v
    if u < -EPS_BARY or v < -EPS_BARY or w < -EPS_BARY:
        return -1
    if t < -EPS_T or t > 1.0 + EPS_T:
        return -1
    t = min(max(t, 0.0), 1.0)
    out[0] = t
    out[1] = p0[0] + t * dx
    out[2] = p0[1] + t * dy
    out[3] = p0[2] + t * dz
    n_on = 0
    if abs(u) <= EPS_BARY:
        n_on += 1
    if abs(v) <= EPS_BARY:
        n_on += 1
    if abs(w) <= EPS_BARY:
        n_on += 1
    if n_on >= 2:
        return HIT_VERTEX
    if n_on == 1:
        return HIT_EDGE
    return HIT_FACE


@njit(cache=True, nogil=True)
def _coplanar(p0, dx, dy, dz, v0, v1, v2, nx, ny, nz, nlen, out):
    """Clip a segment lying in the triangle's plane to the triangle (Cyrus–Beck)."""
    t0 = 0.0
    t1 = 1.0
    for k in range(3):
        if k == 0:
            a, b = v0, v1
        elif k == 1:
            a, b = v1, v2
        else:
            a, b = v2, v0
        ex = b[0] - a[0]
        ey = b[1] - a[1]
        ez = b[2] - a[2]
        # inward edge normal within the plane: n x e (the triangle is
        # counter-clockwise seen from n)
        mx = ny * ez - nz * ey
        my = nz * ex - nx * ez
        mz = nx * ey - ny * ex
        # f = (p - a) . m is the barycentric coordinate of the opposite
        # corner times |n|^2, so EPS_BARY means the same here as in the
        # crossing test
        f0 = (p0[0] - a[0]) * mx + (p0[1] - a[1]) * my + (p0[2] - a[2]) * mz
        fd = dx * mx + dy * my + dz * mz
        tol = EPS_BARY * nlen * nlen
        # f(t) = f0 + t fd >= -tol
        if fd == 0.0:
            if f0 < -tol:
                return -1
        else:
            tt = (-tol - f0) / fd
            if fd > 0.0:
                if tt > t0:
                    t0 = tt
            else:
                if tt < t1:
                    t1 = tt
        if t0 > t1:
            return -1
    out[0] = t0
    out[1] = p0[0] + t0 * dx
    out[2] = p0[1] + t0 * dy
    out[3] = p0[2] + t0 * dz
    return HIT_COPLANAR
