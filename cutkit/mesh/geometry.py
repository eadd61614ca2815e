"""Geometry of tetrahedra, triangles and segments: the local tables and numba-callable primitives.

Every package that needs a tet's faces or edges, its signed volume, its
dihedral angles, or a segment-triangle, segment-tet or point-segment test
imports it from here; no package keeps its own copy.  The primitives are
``@njit`` functions, callable from other numba kernels (those marked
``inline="always"`` are inlined into their callers) and from Python.

Each primitive performs its floating-point operations in one fixed order;
a kernel that calls it computes the same bits as the code it replaced.  The
signed volume exists in three orders of operations, each named and each
kept for the results computed with it: :func:`tet_volume6` (the cutter's
and the decimator's), :func:`tet_signed_volume` (:func:`cutkit.mesh.signed_volumes`
and the element model's fold test) and :func:`tet_volumes` (NumPy; the
springs' rest volumes).  They agree to rounding; making them one would move
simulated positions in the last bit.

Conventions (see docs/mesh-core.md): a tet ``(v0, v1, v2, v3)`` is
positively oriented when ``det[p1 - p0, p2 - p0, p3 - p0] > 0``; local face
``i`` is the face opposite local vertex ``i``.

Slow NumPy references of these primitives are in ``tests/_twins_*.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = [
    "TET_FACES",
    "clamp_bary",
    "TET_FACES_INWARD",
    "TET_EDGES",
    "EDGE_FACES",
    "cross",
    "triple_product",
    "tet_volume6",
    "tet_volumes6",
    "tet_signed_volume",
    "tet_volumes",
    "tet_volume_gradients",
    "signed_volumes_serial",
    "min_volume",
    "tet_dihedrals",
    "tet_max_cos",
    "point_triangle_dist2",
    "segment_dist2",
    "segment_box",
    "segment_triangle_hit",
    "segment_triangle_crossing",
    "edge_triangle_crossing",
    "segment_meets_tet",
    "segment_meets_any_tet",
    "HIT_FACE",
    "HIT_EDGE",
    "HIT_VERTEX",
    "HIT_COPLANAR",
]

# ---------------------------------------------------------------------------
# Local tables
# ---------------------------------------------------------------------------

#: (4, 3) int64: local vertices of face i (opposite vertex i), in the order
#: whose right-hand normal points OUT of a positively oriented tet.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)
TET_FACES.setflags(write=False)

#: (4, 3) int64: local vertices of face i (opposite vertex i), smallest first,
#: in the order whose right-hand normal points INTO a positively oriented tet
#: (towards vertex i).  The element model's gradient kernels use this order.
TET_FACES_INWARD = np.array([[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]], dtype=np.int64)
TET_FACES_INWARD.setflags(write=False)

#: (6, 2) int64: local vertices of the six edges.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
TET_EDGES.setflags(write=False)

#: (6, 2) int64: the two local faces meeting at local edge k (the faces
#: opposite the two vertices not on it).
EDGE_FACES = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]], dtype=np.int64)
EDGE_FACES.setflags(write=False)

# ---------------------------------------------------------------------------
# Signed volume
# ---------------------------------------------------------------------------


@njit(cache=True, nogil=True, inline="always")
def cross(ax, ay, az, bx, by, bz):
    """Cross product ``a x b`` of two 3-vectors given by their components (float64 scalars)."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, nogil=True, inline="always")
def triple_product(ax, ay, az, bx, by, bz, cx, cy, cz):
    """``(a x b) . c`` (float64), summed x, then y, then z."""
    nx, ny, nz = cross(ax, ay, az, bx, by, bz)
    return nx * cx + ny * cy + nz * cz


@njit(cache=True, nogil=True)
def tet_volume6(p0, p1, p2, p3):
    """Six times the signed volume, ``((p1 - p0) x (p2 - p0)) . (p3 - p0)``.

    Parameters
    ----------
    p0, p1, p2, p3 : (3,) float64

    Returns
    -------
    float
        Positive for a positively oriented tet.
    """
    return triple_product(p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2],
                          p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2],
                          p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2])


@njit(cache=True, parallel=True)
def tet_volumes6(points, tets):
    """Six times the signed volume of every tet, as :func:`tet_volume6`.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64

    Returns
    -------
    (m,) float64
    """
    out = np.empty(tets.shape[0])
    for t in prange(tets.shape[0]):
        out[t] = tet_volume6(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
    return out


@njit(cache=True, nogil=True, inline="always")
def tet_signed_volume(points, tets, t):
    """Signed volume of tet ``t``, ``det[p1 - p0, p2 - p0, p3 - p0] / 6``, by cofactors of ``p1 - p0``.

    The determinant is expanded along its first row, ``a . (b x c)`` with
    ``a = p1 - p0``; :func:`tet_volume6` takes ``(a x b) . c``.  The two can
    differ in the last bit (and in the sign of an exact zero); each is kept
    for the results computed with it (see the module docstring).

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64
    t : int

    Returns
    -------
    float
    """
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


def tet_volumes(points, tets):
    """Signed volume of every tet, in NumPy (no compilation: for build steps and one-off checks).

    ``((p1 - p0) x (p2 - p0)) . (p3 - p0) / 6`` with :func:`numpy.cross` and
    :func:`numpy.einsum`; einsum sums the three products in its own order
    (which may depend on the NumPy build), so this can differ from
    :func:`tet_volume6` / 6 in the last bit.  The springs' rest volumes and
    masses are computed with it.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int

    Returns
    -------
    (m,) float64
    """
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


def cross_rows(a, b):
    """``a x b`` of (..., 3) float64 arrays (broadcast), in NumPy.

    The same products and differences as :func:`numpy.cross` (so the same
    bits) without its argument handling, which costs tens of microseconds a
    call: the cut's per-vertex look (:mod:`cutkit.cutting.smoothing`) makes
    tens of thousands of calls on a handful of rows each.

    Parameters
    ----------
    a, b : (..., 3) float64

    Returns
    -------
    (..., 3) float64
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def tet_volume_gradients(points, tets):
    """The gradient of every tet's signed volume with respect to each of its corners, in NumPy.

    ``6 V = (p1 - p0) . ((p2 - p0) x (p3 - p0))`` is linear in each corner:
    its gradient at p1 is ``(p2 - p0) x (p3 - p0) / 6``, at p2
    ``(p3 - p0) x (p1 - p0) / 6``, at p3 ``(p1 - p0) x (p2 - p0) / 6`` and at
    p0 minus their sum.  Corners moved along one vector change V by exactly
    the sum of their moves dotted with these (the terms with two moved
    columns are determinants with two parallel columns).

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int

    Returns
    -------
    (m, 4, 3) float64
    """
    p = points[tets]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    g = np.empty((len(tets), 4, 3))
    g[:, 1] = cross_rows(b, c) / 6.0
    g[:, 2] = cross_rows(c, a) / 6.0
    g[:, 3] = cross_rows(a, b) / 6.0
    g[:, 0] = -(g[:, 1] + g[:, 2] + g[:, 3])
    return g


@njit(cache=True, nogil=True)
def signed_volumes_serial(points, tets):
    """:func:`tet_signed_volume` of a handful of tets, on one thread (no thread start-up per call).

    Parameters
    ----------
    points : (n, 3) float64
    tets : (k, 4) int64

    Returns
    -------
    (k,) float64
        The values of :func:`cutkit.mesh.signed_volumes`, to the bit.
    """
    out = np.empty(tets.shape[0], np.float64)
    for t in range(tets.shape[0]):
        out[t] = tet_signed_volume(points, tets, t)
    return out


@njit(cache=True, nogil=True)
def min_volume(x, tets):
    """Smallest signed volume (:func:`tet_volume6` / 6) of a few tets.

    Parameters
    ----------
    x : (n, 3) float64
    tets : (k, 4) int64

    Returns
    -------
    float
        +inf if ``k == 0``.
    """
    m = np.inf
    for r in range(tets.shape[0]):
        m = min(m, tet_volume6(x[tets[r, 0]], x[tets[r, 1]], x[tets[r, 2]], x[tets[r, 3]]) / 6.0)
    return m


# ---------------------------------------------------------------------------
# Dihedral angles
# ---------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def tet_dihedrals(points, tets, t, n, out):
    """The six interior dihedral angles of tet ``t``, in degrees, into ``out[t]``.

    The angle at an edge is pi minus the angle between the outward normals
    of its two faces, taken as atan2(|n1 x n2|, -n1 . n2): unlike acos this
    keeps full precision near 0 and 180 degrees (slivers).  A face of zero
    area has a zero normal and gives 0 degrees.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64
    t : int
    n : (4, 3) float64
        Scratch for the face normals.
    out : (m, 6) float64
        Column k is the angle at local edge ``TET_EDGES[k]``.
    """
    for f in range(4):
        a = tets[t, TET_FACES[f, 0]]
        b = tets[t, TET_FACES[f, 1]]
        c = tets[t, TET_FACES[f, 2]]
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
        f1 = EDGE_FACES[k, 0]
        f2 = EDGE_FACES[k, 1]
        cx = n[f1, 1] * n[f2, 2] - n[f1, 2] * n[f2, 1]
        cy = n[f1, 2] * n[f2, 0] - n[f1, 0] * n[f2, 2]
        cz = n[f1, 0] * n[f2, 1] - n[f1, 1] * n[f2, 0]
        dot = n[f1, 0] * n[f2, 0] + n[f1, 1] * n[f2, 1] + n[f1, 2] * n[f2, 2]
        out[t, k] = math.degrees(math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), -dot))


@njit(cache=True, nogil=True, inline="always")
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True, inline="always")
def _outward_unit(a, b, c, o):
    """Unit normal of triangle abc pointing away from o, and its length (0: degenerate)."""
    nx, ny, nz = cross(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1], c[2] - a[2])
    if nx * (o[0] - a[0]) + ny * (o[1] - a[1]) + nz * (o[2] - a[2]) > 0.0:
        nx, ny, nz = -nx, -ny, -nz
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln == 0.0:
        return (0.0, 0.0, 0.0, 0.0)
    return (nx / ln, ny / ln, nz / ln, ln)


@njit(cache=True, nogil=True)
def tet_max_cos(p0, p1, p2, p3):
    """Largest cosine of the six dihedral angles (1.0 for a degenerate tet).

    The smallest dihedral angle is ``arccos(tet_max_cos)``: comparing cosines
    avoids six ``acos`` per tet where only a threshold matters.  The dihedral
    angle between faces ``i`` and ``j`` is ``pi`` minus the angle between
    their outward normals, so ``cos(theta_ij) = -n_i . n_j / (|n_i| |n_j|)``.
    The result does not depend on the tet's orientation.

    Parameters
    ----------
    p0, p1, p2, p3 : (3,) float64

    Returns
    -------
    float
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


# ---------------------------------------------------------------------------
# Distances
# ---------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def segment_dist2(p, a, b):
    """Squared distance from a point to a segment (a point if ``a == b``).

    Parameters
    ----------
    p, a, b : (3,) float64
        The point and the segment's ends.

    Returns
    -------
    float
    """
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


@njit(cache=True, nogil=True)
def point_triangle_dist2(p, a, b, c):
    """Squared distance from a point to a triangle.

    Closest point by the Voronoi regions of the triangle (vertices, edges,
    face); a degenerate triangle falls through to its edges.

    Parameters
    ----------
    p : (3,) float64
    a, b, c : (3,) float64
        The triangle's corners.

    Returns
    -------
    float
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


# ---------------------------------------------------------------------------
# Segment against box, triangle and tet
# ---------------------------------------------------------------------------

#: Tolerances of :func:`segment_triangle_hit` and :func:`segment_box`; they
#: are relative to the sizes of the segment and the triangle so that the
#: tests behave the same in mm or in m.
#:
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

#: Kinds of hit of :func:`segment_triangle_hit`: through the inside of the
#: triangle, through (or within EPS_BARY of) an edge, through a vertex, or
#: lying in the triangle's plane.
HIT_FACE = 0
HIT_EDGE = 1
HIT_VERTEX = 2
HIT_COPLANAR = 3

#: Relative tolerance of :func:`segment_triangle_crossing` and of the flat
#: triangle test of :func:`edge_triangle_crossing` (scaled by the lengths).
SEG_TRI_EPS = 1e-12
#: A vertex within this distance (relative to its edge's length) of the
#: triangle's plane lies on it, and counts as lying just below it (a
#: symbolic perturbation): only its edges to vertices above the plane cross.
#: A blade through a vertex, along an edge or in a face plane then makes one
#: wall, not one on each side (which would free a slab between them).
EDGE_END_EPS = 1e-9
#: Closed-triangle slack of the edge crossing's barycentric coordinates, so an
#: edge crossing a quad (two triangles) on its diagonal is found by one half.
EDGE_BARY_EPS = 1e-12


@njit(cache=True, nogil=True)
def segment_box(p0x, p0y, p0z, dx, dy, dz, bmin, bmax):
    """Whether the segment ``p0 + t d``, t in [0, 1], meets a closed box.

    Parameters
    ----------
    p0x, p0y, p0z, dx, dy, dz : float
        Start and direction (end minus start) of the segment.
    bmin, bmax : (3,) float64
        The box's corners; ``bmin[0] > bmax[0]`` is an empty box.

    Returns
    -------
    bool
    """
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


@njit(cache=True, nogil=True, inline="always")
def _direction_and_normal(p0, p1, v0, v1, v2):
    """(dx, dy, dz) = p1 - p0, (e1x..e2z) = v1 - v0, v2 - v0, the plane normal (nx, ny, nz) =
    e1 x e2 (not normalised) and its length: the numbers both segment-triangle tests start from."""
    dx = p1[0] - p0[0]
    dy = p1[1] - p0[1]
    dz = p1[2] - p0[2]
    e1x = v1[0] - v0[0]
    e1y = v1[1] - v0[1]
    e1z = v1[2] - v0[2]
    e2x = v2[0] - v0[0]
    e2y = v2[1] - v0[1]
    e2z = v2[2] - v0[2]
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    nlen = math.sqrt(nx * nx + ny * ny + nz * nz)
    return dx, dy, dz, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, nlen


@njit(cache=True, nogil=True)
def segment_triangle_hit(p0, p1, v0, v1, v2, out):
    """Möller–Trumbore segment-triangle test of a closed triangle, with its degenerate cases.

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
    # the segment's direction, the triangle's edges, its plane normal (not normalised) and length
    dx, dy, dz, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, nlen = _direction_and_normal(p0, p1, v0, v1, v2)
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
        return _coplanar(p0, p1, v0, v1, v2, out)
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
    return _hit_kind(u, v, w)


@njit(cache=True, nogil=True, inline="always")
def _hit_kind(u, v, w):
    """HIT_VERTEX, HIT_EDGE or HIT_FACE: two, one or none of the barycentric coordinates within EPS_BARY of 0."""
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
def _coplanar(p0, p1, v0, v1, v2, out):
    """Clip a segment lying in the triangle's plane to the triangle (Cyrus–Beck); its direction and
    the plane's normal computed as :func:`segment_triangle_hit` computes them (the same numbers)."""
    dx, dy, dz, _, _, _, _, _, _, nx, ny, nz, nlen = _direction_and_normal(p0, p1, v0, v1, v2)
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


@njit(cache=True, nogil=True)
def segment_triangle_crossing(p0, p1, a, b, c):
    """Parameter in [0, 1] where the segment p0-p1 crosses the open triangle abc, or -1.

    Möller–Trumbore; a segment parallel to the triangle's plane (within
    SEG_TRI_EPS relative to the lengths) misses.

    Parameters
    ----------
    p0, p1, a, b, c : (3,) float64

    Returns
    -------
    float
    """
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
def edge_triangle_crossing(p, q, tri):
    """Parameter in [0, 1] where the edge p-q crosses a triangle, or -1.

    The edge crosses when one end lies above the triangle's plane and the
    other does not, an end within EDGE_END_EPS (relative to the edge's
    length) of the plane counting as on it, i.e. just below (a symbolic
    perturbation); then the crossing point must lie in the closed triangle
    (barycentric coordinates >= -EDGE_BARY_EPS).  An edge in the plane never
    crosses; an edge from a vertex on the plane crosses at that vertex only
    if it goes up.  The result depends on the edge's ends, not their order.

    Parameters
    ----------
    p, q : (3,) float64
        The edge's ends.
    tri : (3, 3) float64
        The triangle's corners (rows).

    Returns
    -------
    float
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
def segment_meets_tet(p0, p1, x, tv):
    """Whether the segment p0-p1 meets a tet (either orientation).

    Clips the segment's parameter interval against the four face planes,
    each normal turned away from the opposite vertex.

    Parameters
    ----------
    p0, p1 : (3,) float64
    x : (n, 3) float64
        Node positions.
    tv : (4,) int64
        The tet's nodes.

    Returns
    -------
    bool
    """
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
def segment_meets_any_tet(p0, p1, x, tets):
    """Whether the segment p0-p1 meets one of a few tets (:func:`segment_meets_tet`).

    Parameters
    ----------
    p0, p1 : (3,) float64
    x : (n, 3) float64
    tets : (k, 4) int64

    Returns
    -------
    bool
    """
    for t in range(tets.shape[0]):
        if segment_meets_tet(p0, p1, x, tets[t]):
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def point_on_triangle(x, pa, pb, pc, rel_tol):
    """Whether the point ``x`` lies on the triangle (pa, pb, pc) without being at one of its corners.

    With L the triangle's longest edge: its distance to the triangle's plane
    is at most ``rel_tol * L``, its barycentric coordinates (Cramer's rule on
    the sub-triangle normals) are all >= -``rel_tol``, and it is farther than
    ``rel_tol * L`` from each corner.  A degenerate (zero-area) triangle holds
    no point.  This is the one hanging-node predicate: ``cutkit check``
    (:func:`cutkit.mesh.check.check_mesh`) and decimation's rule that keeps
    boundary nodes off new boundary faces both ask it.

    Parameters
    ----------
    x, pa, pb, pc : (3,) float64

    Returns
    -------
    bool
    """
    ux, uy, uz = pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]
    vx, vy, vz = pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    nn = nx * nx + ny * ny + nz * nz
    if nn == 0.0:
        return False
    wx, wy, wz = pc[0] - pb[0], pc[1] - pb[1], pc[2] - pb[2]
    L = math.sqrt(max(ux * ux + uy * uy + uz * uz, vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz))
    tol = rel_tol * L
    px, py, pz = x[0] - pa[0], x[1] - pa[1], x[2] - pa[2]
    if abs((px * nx + py * ny + pz * nz) / math.sqrt(nn)) > tol:
        return False
    # x - a = beta u + gamma v  =>  beta = (p x v).n / |n|^2, gamma = (u x p).n / |n|^2
    beta = ((py * vz - pz * vy) * nx + (pz * vx - px * vz) * ny + (px * vy - py * vx) * nz) / nn
    gamma = ((uy * pz - uz * py) * nx + (uz * px - ux * pz) * ny + (ux * py - uy * px) * nz) / nn
    if 1.0 - beta - gamma < -rel_tol or beta < -rel_tol or gamma < -rel_tol:
        return False
    for q in (pa, pb, pc):
        dx, dy, dz = x[0] - q[0], x[1] - q[1], x[2] - q[2]
        if dx * dx + dy * dy + dz * dz <= tol * tol:
            return False
    return True


@njit(cache=True, nogil=True)
def clamp_bary(b, lo):
    """Barycentric weights made valid and kept >= ``lo``.

    Negative weights are set to 0 and the rest normalised (all equal if
    none is positive); then the weights are mixed with the centroid just
    enough that the smallest is ``lo``.

    Parameters
    ----------
    b : (k,) float64
    lo : float  smallest weight allowed, < 1 / k

    Returns
    -------
    (k,) float64  new array
    """
    k = b.size
    out = np.empty(k)
    s = 0.0
    for i in range(k):
        out[i] = max(b[i], 0.0)
        s += out[i]
    m = np.inf
    for i in range(k):
        out[i] = out[i] / s if s > 0.0 else 1.0 / k
        m = min(m, out[i])
    if m < lo:
        c = 1.0 / k
        w = (lo - m) / (c - m)
        for i in range(k):
            out[i] = (1.0 - w) * out[i] + w * c
    return out
