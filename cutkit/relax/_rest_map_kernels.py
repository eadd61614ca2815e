"""Numba kernel of :mod:`cutkit.relax.rest_map`: the nodes near the blade (twin in
``tests/_twins_simulate.py``)."""

from __future__ import annotations

from collections import namedtuple

from numba import njit

from cutkit.mesh.geometry import segment_dist2

#: The flood fill's visit marks and work space, kept between calls: ``tet_stamp`` (m,) int64 and
#: ``node_stamp`` (n,) int64 (never reset: visited when equal to ``mark``, an int no entry has
#: yet), ``stack`` (m,) int64, and the results ``out`` (n,) int64 (the nodes) and ``out_d2`` (n,)
#: float64 (their squared distances to the blade), ``[:count]``.
FloodFill = namedtuple("FloodFill", ["tet_stamp", "node_stamp", "mark", "stack", "out", "out_d2"])


@njit(cache=True, nogil=True)
def nodes_near_blade(x, tets, neighbors, seeds, blade, radius, fill):
    """The corners of tets within ``radius`` of the blade segment, found by a flood fill from ``seeds``.

    Tets are visited over face neighbours while one of their corners lies
    within ``radius`` of the blade: the blade's neighbourhood (a capsule) is
    face-connected, so no node inside it that is linked to the seeds
    through it is missed.

    Parameters
    ----------
    x : (n, 3) float64  node positions (deformed)
    tets : (m, 4) int64
    neighbors : (m, 4) int64  face neighbours, -1 on the boundary
    seeds : (k,) int64  tets to start from (always visited)
    blade : (2, 3) float64  its back end and its tip
    radius : float
    fill : FloodFill  its marks and results written

    Returns
    -------
    count : int
    """
    tet_stamp, node_stamp, mark, stack = fill.tet_stamp, fill.node_stamp, fill.mark, fill.stack
    out, out_d2 = fill.out, fill.out_d2
    back, tip = blade[0], blade[1]
    r2 = radius * radius
    n = 0
    for j in range(seeds.shape[0]):
        t = seeds[j]
        if tet_stamp[t] != mark:
            tet_stamp[t] = mark
            stack[n] = t
            n += 1
    head = 0
    count = 0
    while head < n:
        t = stack[head]
        head += 1
        for c in range(4):
            i = tets[t, c]
            if node_stamp[i] != mark:
                node_stamp[i] = mark
                d2 = segment_dist2(x[i], back, tip)
                if d2 < r2:
                    out[count] = i
                    out_d2[count] = d2
                    count += 1
        for f in range(4):
            nb = neighbors[t, f]
            if nb < 0 or tet_stamp[nb] == mark:
                continue
            tet_stamp[nb] = mark
            for c in range(4):
                if segment_dist2(x[tets[nb, c]], back, tip) < r2:
                    stack[n] = nb
                    n += 1
                    break
    return count
