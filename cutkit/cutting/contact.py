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

from cutkit.mesh.geometry import EDGE_END_EPS, edge_triangle_crossing


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
    return (f"{k} edge{'s' * (k != 1)} the blade met could not be cut (deferred where its stroke ended, or a "
            f"copy along an earlier cut cut elsewhere) and stay joined; midpoints at {named}{more} mm; "
            "see docs/cutting.md")


def touches_only(cm, e: int, t: float, swept) -> bool:
    """Whether the crossing of original edge ``e`` at parameter ``t`` is a touch of the surface, not a cut.

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
