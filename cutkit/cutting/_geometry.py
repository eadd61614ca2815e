"""Small geometry predicates for the volume collision (paper section 4.2).

Plain NumPy on a handful of points: the reference versions (twins) of the
numba kernels in :mod:`cutkit.cutting._kernels` and ``_kernels_step``.
"""

from __future__ import annotations

import numpy as np

#: Relative tolerance of the segment/triangle test (scaled by edge length).
SEG_TRI_EPS = 1e-12


def segment_triangle(p0, p1, a, b, c):
    """Parameter s in [0, 1] where segment p0-p1 crosses triangle abc, or -1.

    Moeller-Trumbore; a segment parallel to the triangle's plane misses.
    """
    d = p1 - p0
    e1 = b - a
    e2 = c - a
    h = np.cross(d, e2)
    det = float(e1 @ h)
    scale = float(np.linalg.norm(e1) * np.linalg.norm(e2) * np.linalg.norm(d)) + 1e-300
    if abs(det) <= SEG_TRI_EPS * scale:
        return -1.0
    inv = 1.0 / det
    s = p0 - a
    u = float(s @ h) * inv
    if u < 0.0 or u > 1.0:
        return -1.0
    q = np.cross(s, e1)
    v = float(d @ q) * inv
    if v < 0.0 or u + v > 1.0:
        return -1.0
    t = float(e2 @ q) * inv
    if t < 0.0 or t > 1.0:
        return -1.0
    return t


def barycentric(x, tet_points):
    """Barycentric coordinates (4,) of x in the tetrahedron (4, 3)."""
    p0 = tet_points[0]
    m = (tet_points[1:] - p0).T
    try:
        l123 = np.linalg.solve(m, x - p0)
    except np.linalg.LinAlgError:
        return np.full(4, -1.0)
    return np.array([1.0 - l123.sum(), l123[0], l123[1], l123[2]])


def segment_hits_tet(p0, p1, tet_points):
    """Whether segment p0-p1 meets the (positively oriented) tetrahedron.

    Clips the segment's parameter interval against the four face planes.
    """
    lo, hi = 0.0, 1.0
    d = p1 - p0
    for i, (a, b, c) in enumerate(((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))):
        n = np.cross(tet_points[b] - tet_points[a], tet_points[c] - tet_points[a])  # outward
        dist0 = float(n @ (p0 - tet_points[a]))
        dd = float(n @ d)
        if abs(dd) < 1e-300:
            if dist0 > 0.0:
                return False
            continue
        t = -dist0 / dd
        if dd > 0.0:
            hi = min(hi, t)
        else:
            lo = max(lo, t)
        if lo > hi:
            return False
    return True


def edge_crosses_triangle(p, q, tri, end_eps=1e-9, bary_eps=1e-12):
    """Twin of ``_kernels.edge_cross``: parameter where edge p-q crosses triangle tri (3, 3), or -1.

    An end within ``end_eps`` (relative to the edge's length) of the plane
    is on it and counts as just below it; the crossing point must lie in the
    closed triangle.
    """
    tri = np.asarray(tri, float)
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    if np.linalg.norm(n) <= SEG_TRI_EPS * np.linalg.norm(tri[1] - tri[0]) * np.linalg.norm(tri[2] - tri[0]):
        return -1.0  # flat triangle
    n = n / np.linalg.norm(n)
    dp, dq = float(n @ (p - tri[0])), float(n @ (q - tri[0]))
    tol = end_eps * float(np.linalg.norm(q - p))
    if (dp > tol) == (dq > tol):
        return -1.0
    dp = 0.0 if abs(dp) <= tol else dp
    dq = 0.0 if abs(dq) <= tol else dq
    t = dp / (dp - dq)
    x = p + t * (q - p)
    m = np.stack([tri[1] - tri[0], tri[2] - tri[0]], axis=1)
    b1, b2 = np.linalg.lstsq(m, x - tri[0], rcond=None)[0]
    if b1 < -bary_eps or b2 < -bary_eps or b1 + b2 > 1 + bary_eps:
        return -1.0
    return t
