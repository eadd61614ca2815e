"""Only real contact cuts: a blade lying on the tissue's surface cuts nothing under it.

The edge test (:func:`cutkit.mesh.geometry.edge_triangle_crossing`) counts a
vertex on the swept surface's plane as lying just below it, so a blade
passing through an inner vertex makes one wall just above it (the edges
going up from the vertex are cut at the snap distance).  On the surface
the same rule would cut under a blade that only lies on the skin: with the
swept quad in a boundary face's plane and its normal pointing into the
tissue, every edge going in from the face's vertices would be cut, a crack
a quarter edge below the surface.  :func:`touches_only` tells that case:
the swept plane meets the edge only at a vertex and the tissue around that
vertex lies wholly on the edge's side of the plane (nothing strictly
below), so the plane only touches the tissue there and the edge is not
crossed.
"""

from __future__ import annotations

import numpy as np

from cutkit.cutting._kernels_step import tet_bary
from cutkit.mesh.geometry import EDGE_END_EPS, edge_triangle_crossing


#: A crossing with every barycentric coordinate in its swept triangle above this is inside the triangle.
BORDER_EPS = 1e-9
#: A crossing on a swept triangle's border cuts if the triangle, this fraction of the edge's length
#: from it, is inside the tissue.
SIDE_STEP = 1e-4
#: Directions in the triangle's plane sampled around a crossing on its border.
SIDE_SAMPLES = 16
#: ... and lifted this fraction of that step above the triangle's plane.
SIDE_LIFT = 0.1
#: Uncut edges named one by one in the warning line; more are counted.
NAMED_UNCUT_EDGES = 8


def uncut_edges_line(cm) -> str:
    """One warning line counting and naming (by rest midpoint, mm) the crossed edges left uncut; "" if none.

    The edges are :meth:`~cutkit.cutting.cutmesh.CutMesh.edges_left_uncut`'s:
    deferred where the stroke ended, or with a coincident copy along an
    earlier stroke's cut cut first at another point (docs/cutting.md).
    """
    places = cm.uncut_edge_places()
    k = len(places)
    if not k:
        return ""
    named = "; ".join("(" + ", ".join(f"{c:.2f}" for c in p) + ")" for p in places[:NAMED_UNCUT_EDGES].tolist())
    more = f" and {k - NAMED_UNCUT_EDGES} more" if k > NAMED_UNCUT_EDGES else ""
    one = k == 1
    return (f"{k} edge{'' if one else 's'} the blade met could not be cut (deferred where its stroke ended, or a "
            f"copy along an earlier cut cut elsewhere) and stay{'s' if one else ''} joined; "
            f"midpoint{'' if one else 's'} at {named}{more} mm; see docs/cutting.md")


def touches_only(cm, e: int, t: float, swept) -> bool:
    """Whether the crossing of original edge ``e`` at parameter ``t`` is a touch of the surface, not a cut.

    Two touches: the swept plane meets the edge only at a vertex around which
    the tissue lies wholly on one side (:func:`_touches_at_vertex`: a blade
    lying on the skin), or the swept surface meets the edge only on its own
    border and does not go into the tissue there (:func:`_meets_from_outside`:
    a tip sliding along the skin, whose path is the swept quad's border).

    Parameters
    ----------
    cm : CutMesh
    e : int  original edge
    t : float  the sweep's crossing parameter (only 0 or 1, an end on the plane, can be a touch)
    swept : (2, 3, 3) float64  the step's swept triangles

    Returns
    -------
    bool
    """
    return _touches_at_vertex(cm, e, t, swept) or _meets_from_outside(cm, e, t, swept)


def _touches_at_vertex(cm, e, t, swept):
    """Whether the swept plane meets edge ``e`` only at an end on it with no tissue beyond the plane there."""
    if t not in (0.0, 1.0):
        return False
    x = cm._x
    p, q = (int(i) for i in cm.edges[e])
    for tri in swept:
        if edge_triangle_crossing(x[p], x[q], tri) < 0.0:
            continue
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        n /= np.linalg.norm(n)
        dp, dq = float((x[p] - tri[0]) @ n), float((x[q] - tri[0]) @ n)
        u, up = (p, dq) if abs(dp) <= abs(dq) else (q, dp)  # u on the plane, the other end off it
        around = np.unique(cm.orig_tets[cm.node_tet_idx[cm.node_tet_off[u]:cm.node_tet_off[u + 1]]])
        d = (x[around] - tri[0]) @ n * np.sign(up)
        tol = EDGE_END_EPS * float(np.linalg.norm(x[p] - x[q]))
        return not bool((d < -tol).any())
    return False


def _in_tets(x, tets, q) -> bool:
    """Whether the point ``q`` (3,) lies strictly inside one of ``tets`` (k, 4) over ``x`` (n, 3)."""
    b = np.empty(4)
    for tv in tets:
        if tet_bary(x, tv, q, b) and b.min() > 0.0:
            return True
    return False


def _tri_bary(g, ru, rv):
    """The coordinates (l1, l2) along a triangle's edges u, v of a point w, from the Gram matrix ``g``
    (2, 2) of u, v and ``ru`` = w.u, ``rv`` = w.v (the 2 x 2 normal equations, Cramer's rule)."""
    det = g[0, 0] * g[1, 1] - g[0, 1] * g[0, 1]
    return (g[1, 1] * ru - g[0, 1] * rv) / det, (g[0, 0] * rv - g[0, 1] * ru) / det


def _meets_from_outside(cm, e, t, swept):
    """Whether the swept surface meets edge ``e`` (at parameter ``t``) only on its border, from outside.

    A tip dragged along the skin sweeps a quad whose border (the tip's
    path) lies in the surface: the surface edges under that path are met
    on the quad's border, in the closed triangle, and would be cut though
    the blade never enters.  The crossing counts as a cut only if, for some
    swept triangle the edge crosses, the crossing point lies inside the
    triangle (barycentric coordinates all > ``BORDER_EPS``), or a point of
    the triangle near it lies inside the tissue around the crossing (the
    edge's tets, or an end's tets for a crossing at an end): the points
    ``SIDE_STEP`` of the edge's length from it in ``SIDE_SAMPLES``
    directions of the triangle's plane that fall in the triangle, lifted
    ``SIDE_LIFT`` of that above the plane (the side the edge test's
    perturbation puts the swept surface on).
    """
    x = cm._x
    p, q = (int(i) for i in cm.edges[e])
    c = x[p] + t * (x[q] - x[p])
    if t in (0.0, 1.0):
        u = p if t == 0.0 else q
        around = cm.orig_tets[cm.node_tet_idx[cm.node_tet_off[u]:cm.node_tet_off[u + 1]]]
    else:
        around = cm.orig_tets[cm.edge_ring(e)]
    step = SIDE_STEP * float(np.linalg.norm(x[q] - x[p]))
    met = False
    for tri in swept:
        if edge_triangle_crossing(x[p], x[q], tri) < 0.0:
            continue
        met = True
        u, v, w = tri[1] - tri[0], tri[2] - tri[0], c - tri[0]
        g = np.array([[u @ u, u @ v], [u @ v, v @ v]])
        l1, l2 = _tri_bary(g, w @ u, w @ v)
        if min(1.0 - l1 - l2, l1, l2) > BORDER_EPS:
            return False
        n = np.cross(u, v)
        n /= np.linalg.norm(n)
        e1 = u / np.linalg.norm(u)
        e2 = np.cross(n, e1)
        # the triangle near c (a wedge, sampled at SIDE_SAMPLES directions in its plane), each point
        # lifted a little above the plane (the edge test's perturbation: a vertex on the plane lies
        # just below it, so the swept surface lies just above)
        for th in np.linspace(0.0, 2 * np.pi, SIDE_SAMPLES, endpoint=False):
            d = np.cos(th) * e1 + np.sin(th) * e2
            b1, b2 = _tri_bary(g, (w + step * d) @ u, (w + step * d) @ v)
            if min(1.0 - b1 - b2, b1, b2) >= 0.0 and _in_tets(x, around, c + step * (d + SIDE_LIFT * n)):
                return False
    return met
