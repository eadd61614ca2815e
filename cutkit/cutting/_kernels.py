"""Numba kernel of the volume collision: what one tet meets of a cut step.

The segment and edge tests are :mod:`cutkit.mesh.geometry`'s (twins:
``tests/_twins_cut.py``).
"""

from numba import njit

from cutkit.mesh.geometry import edge_triangle_crossing, segment_triangle_crossing


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
                t = edge_triangle_crossing(x[tv[i]], x[tv[j]], swept[s])
                if t >= 0.0:
                    out_edge[k] = t
                    break
            k += 1
    for f in range(4):
        ia, ib, ic = (f + 1) % 4, (f + 2) % 4, (f + 3) % 4
        out_face[f] = segment_triangle_crossing(blade[0], blade[1], x[tv[ia]], x[tv[ib]], x[tv[ic]])
