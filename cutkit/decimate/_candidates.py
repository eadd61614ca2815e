"""Numba candidate selection of the decimator: the cheapest half-edges of a vertex and a volume pre-check.

Popping a vertex ``u`` from the heap picks its few cheapest half-edge
collapses ``u -> v`` (:func:`cheapest_neighbours`); most of them fail because
a surviving tet of ``u`` would turn flat or inside out.  That failure is
predicted cheaply: the volume of a tet of ``u`` with ``u`` replaced by a point
``x`` is affine in ``x``, ``6 V(x) = g . (x - a)``, so the gradients ``g`` of
the star are computed once per pop (:func:`volume_gradients`) and each
candidate costs one dot product per tet (:func:`volume_precheck`).  The
pre-check only skips candidates; the exact legality test
(:func:`cutkit.decimate._legality.can_collapse`) still runs on the others.

Every function here has a NumPy twin in ``tests/_twins_decimate.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cutkit.decimate._legality import P_W_SURFACE, P_W_TOUCH, _has, _new_stamp


@njit(cache=True, inline="always")
def cost_factor(w, x, vclass, params):
    """Factor of the weighting function for ``w -> x`` (inf: never).

    1 for an interior vertex, ``1 + w_touch`` when it collapses onto the
    surface, ``w_surface`` for a surface vertex onto a surface vertex.
    """
    if vclass[w] != 0:
        if vclass[x] == 0:
            return np.inf
        return params[P_W_SURFACE]
    if vclass[x] != 0:
        return 1.0 + params[P_W_TOUCH]
    return 1.0


@njit(cache=True, inline="always")
def half_edge_key2(w, x, points, vclass, params):
    """``(factor * |w x|)^2`` of the half-edge ``w -> x`` (inf: never); the cost is ``sqrt(key2) / h``."""
    f = cost_factor(w, x, vclass, params)
    if f == np.inf:
        return np.inf
    d0 = points[w, 0] - points[x, 0]
    d1 = points[w, 1] - points[x, 1]
    d2 = points[w, 2] - points[x, 2]
    return f * f * (d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True)
def cheapest_neighbours(u, points, stars, vclass, mark, counters, params, out):
    """The ``len(cand)`` cheapest allowed half-edges ``u -> v``, cheapest first.

    Parameters
    ----------
    u : int
    stars : _state.Stars
    out : tuple
        ``(cand, cand_key2)``:
    cand : (k,) int64
        Output: the neighbours ``v``; ties keep the order in which the star
        of ``u`` lists them (a stable sort).
    cand_key2 : (k,) float64
        Output: their :func:`half_edge_key2`.
    mark : (n,) int64
        Scratch stamps (see ``_new_stamp``); ``counters`` holds the stamp.

    Returns
    -------
    int
        How many entries of ``cand`` are filled (0: no allowed collapse).
    """
    cand, cand_key2 = out
    kmax = cand.shape[0]
    st = _new_stamp(counters)
    s0 = stars.adj_start[u]
    nc = 0
    for i in range(stars.adj_len[u]):
        t = stars.pool[s0 + i]
        for k in range(4):
            w = stars.tets[t, k]
            if w == u or mark[w] == st:
                continue
            mark[w] = st
            key2 = half_edge_key2(u, w, points, vclass, params)
            if key2 == np.inf or (nc == kmax and key2 >= cand_key2[kmax - 1]):
                continue
            # Insert after every entry with a key <= key2 (stable).
            j = nc if nc < kmax else kmax - 1
            while j > 0 and cand_key2[j - 1] > key2:
                cand[j] = cand[j - 1]
                cand_key2[j] = cand_key2[j - 1]
                j -= 1
            cand[j] = w
            cand_key2[j] = key2
            if nc < kmax:
                nc += 1
    return nc


@njit(cache=True)
def volume_gradients(u, points, tets, adj_start, adj_len, pool, grad, base):
    """Affine volume of each tet of ``u`` as a function of ``u``'s position.

    For the ``i``-th tet of ``u``'s list, six times the signed volume with
    ``u`` moved to ``x`` is ``grad[i] . (x - points[base[i]])``.

    Parameters
    ----------
    grad : (>= adj_len[u], 3) float64
        Output.
    base : (>= adj_len[u],) int64
        Output: a vertex of the face opposite ``u``.
    """
    s0 = adj_start[u]
    for i in range(adj_len[u]):
        t = pool[s0 + i]
        # The face opposite u, in tet order; moving u's slot to the end is an
        # even permutation for slots 1 and 3, odd for slots 0 and 2.
        a = -1
        b = -1
        c = -1
        sign = 1.0
        for k in range(4):
            w = tets[t, k]
            if w == u:
                sign = 1.0 if k % 2 == 1 else -1.0
            elif a < 0:
                a = w
            elif b < 0:
                b = w
            else:
                c = w
        ex = points[b, 0] - points[a, 0]
        ey = points[b, 1] - points[a, 1]
        ez = points[b, 2] - points[a, 2]
        fx = points[c, 0] - points[a, 0]
        fy = points[c, 1] - points[a, 1]
        fz = points[c, 2] - points[a, 2]
        grad[i, 0] = sign * (ey * fz - ez * fy)
        grad[i, 1] = sign * (ez * fx - ex * fz)
        grad[i, 2] = sign * (ex * fy - ey * fx)
        base[i] = a


@njit(cache=True)
def volume_precheck(u, v, points, stars, gradients, vol_eps):
    """Whether every tet of ``u`` without ``v`` keeps ``6 V > vol_eps`` after ``u -> v``.

    ``gradients`` = (``grad``, ``base``) come from :func:`volume_gradients` for ``u``.
    Rounding differs from :func:`cutkit.mesh.geometry.tet_volume6`, so this only
    skips candidates; the exact test decides.
    """
    tets, adj_start, adj_len, pool = stars.tets, stars.adj_start, stars.adj_len, stars.pool
    grad, base = gradients
    s0 = adj_start[u]
    px = points[v, 0]
    py = points[v, 1]
    pz = points[v, 2]
    for i in range(adj_len[u]):
        t = pool[s0 + i]
        if _has(tets, t, v):
            continue
        a = base[i]
        vol = grad[i, 0] * (px - points[a, 0]) + grad[i, 1] * (py - points[a, 1]) + grad[i, 2] * (pz - points[a, 2])
        if vol <= vol_eps:
            return False
    return True
