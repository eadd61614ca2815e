"""Numba kernels of the cut-node fairing (:mod:`cutkit.cutting.fairing`).

* :func:`poor_tets`: the live sub-tets of some original tets with a
  dihedral angle below a limit;
* :func:`fair_place`: the best place of one cut node (and its copies) in
  its simplex, by a compass search;
* :func:`vertex_place`: the best move of one mesh vertex (the cut nodes
  defined on it following), by a compass search in space
  (:mod:`cutkit.cutting.smoothing`).

Slow, obviously correct NumPy twins: ``tests/_twins_cut.py::fair_place_twin``,
``tests/_twins_cut.py::vertex_place_twin``,
and ``min_dihedral_angles`` over the sub-tets for :func:`poor_tets`
(``tests/test_cut_kernels.py``).
"""

from collections import namedtuple

import numpy as np
from numba import njit

from cutkit.mesh.geometry import edge_triangle_crossing, tet_dihedrals, tet_signed_volume

#: A pattern-search move is taken only when it raises the smallest angle by more than this (degrees):
#: equal candidates keep the earlier one, whatever the rounding.
_GAIN_EPS_DEG = 1e-9


@njit(cache=True, nogil=True)
def _worst_angle(x, tets, floor, normals, angles):
    """Smallest dihedral angle (degrees) of ``tets``, or -1 as soon as a tet is not positive or has an
    angle at or below ``floor`` (the candidate cannot win)."""
    worst = np.inf
    for j in range(tets.shape[0]):
        if tet_signed_volume(x, tets, j) <= 0.0:
            return -1.0
        tet_dihedrals(x, tets, j, normals, angles)
        for e in range(6):
            a = angles[j, e]
            if a <= floor:
                return -1.0
            if a < worst:
                worst = a
    return worst


@njit(cache=True, nogil=True)
def _put(x, copies, corners, w):
    for c in range(3):
        s = 0.0
        for q in range(corners.shape[0]):
            s += w[q] * x[corners[q], c]
        for i in range(copies.shape[0]):
            x[copies[i], c] = s


#: The cut state :func:`fair_place` reads: node positions x (n, 3) float64 (rows of the node and
#: its copies written during the search, then restored); the store's tet corners (cap, 4) int64
#: and alive flags (cap,) bool; each original tet's contiguous range of sub-tets, sub_start and
#: sub_count (m0,) int64.
FairMesh = namedtuple("FairMesh", ["x", "tets", "alive", "sub_start", "sub_count"])
#: The search's limits, (3,) float64: smallest weight, largest change of a weight from where the cut
#: put the node, and the smallest angle (degrees) at or above which the node is left alone.
LIM_LO, LIM_MOVE, LIM_BELOW = 0, 1, 2


@njit(cache=True, nogil=True)
def poor_tets(mesh, originals, below):
    """The live sub-tets of ``originals`` (q,) int64 with a dihedral angle below ``below`` (degrees).

    Returns
    -------
    (tets, owner) : (p,) int64 each
        The tets and their original tets.
    """
    n = 0
    for o in originals:
        n += mesh.sub_count[o]
    tets = np.empty(n, np.int64)
    owner = np.empty(n, np.int64)
    one = np.empty((1, 4), np.int64)
    normals = np.empty((4, 3))
    angles = np.empty((1, 6))
    p = 0
    for o in originals:
        for t in range(mesh.sub_start[o], mesh.sub_start[o] + mesh.sub_count[o]):
            if not mesh.alive[t]:
                continue
            one[0] = mesh.tets[t]
            tet_dihedrals(mesh.x, one, np.int64(0), normals, angles)  # one compile
            if angles[0].min() < below:
                tets[p] = t
                owner[p] = o
                p += 1
    return tets[:p], owner[:p]


@njit(cache=True, nogil=True)
def _tets_around(mesh, around, copies):
    """(r, 4) int64 the live sub-tets of the originals ``around`` that hold one of ``copies``."""
    n = 0
    for o in around:
        n += mesh.sub_count[o]
    out = np.empty((n, 4), np.int64)
    r = 0
    for o in around:
        for t in range(mesh.sub_start[o], mesh.sub_start[o] + mesh.sub_count[o]):
            if not mesh.alive[t]:
                continue
            hit = False
            for c in range(4):
                for i in range(copies.shape[0]):
                    hit |= mesh.tets[t, c] == copies[i]
            if hit:
                out[r] = mesh.tets[t]
                r += 1
    return out[:r]


@njit(cache=True, nogil=True)
def _poorest_first(tets, angles):
    """``tets`` (m, 4) in ascending order of their smallest angle (``angles`` (m, 6), stable)."""
    worst_of = np.empty(tets.shape[0])
    for j in range(tets.shape[0]):
        worst_of[j] = angles[j].min()
    return tets[np.argsort(worst_of, kind="mergesort")]


@njit(cache=True, nogil=True)
def fair_place(mesh, around, copies, corners, w0, w_cut, limits, steps, directions):
    """Weights of a cut node (and its coincident copies) that maximise the smallest dihedral angle of
    the tets around it, by a compass search over its defining simplex.

    The node is ``w . x[corners]``; a move adds ``s d`` to its weights, for
    each direction ``d`` of ``directions`` and each step ``s`` of ``steps`` in
    turn, as long as the best move raises the smallest angle; every weight
    stays ``>= limits[LIM_LO]`` and within ``limits[LIM_MOVE]`` of ``w_cut``
    (where the cut put the node), and every tet stays positive.  Nothing is
    searched when the smallest angle is already at least
    ``limits[LIM_BELOW]``.  ``mesh.x`` is left as it was.

    Parameters
    ----------
    mesh : FairMesh
    around : (a,) int64
        The original tets whose sub-tets may hold the node or a copy.
    copies : (c,) int64
        The node and its coincident copies (both sides of a cut).
    corners : (k,) int64
        Its defining original nodes, k = 2 (edge), 3 (face) or 4 (tet).
    w0 : (k,) float64
        Its weights now (the search starts there).
    w_cut : (k,) float64
        Its weights where the cut put it (the centre of the box).
    limits : (3,) float64
        ``LIM_LO``, ``LIM_MOVE``, ``LIM_BELOW`` (above).
    steps : (q,) float64
        Step lengths, largest first.
    directions : (r, k) float64
        Moves of the weights, each summing to zero (largest entry 1).

    Returns
    -------
    (w, angle, start) : (k,) float64, float, float
        The best weights found (``w0`` when nothing is better), their
        smallest angle, and the smallest angle at ``w0`` (degrees; -1 when
        a tet around is not positive; inf when no live tet holds the node).
    """
    x = mesh.x
    tets = _tets_around(mesh, around, copies)
    k = corners.shape[0]
    normals = np.empty((4, 3))
    angles = np.zeros((tets.shape[0], 6))  # rows past a non-positive tet stay 0 (the order below only)
    keep = x[copies[0]].copy()
    w = w0.copy()
    best_w = w.copy()
    start = _worst_angle(x, tets, -np.inf, normals, angles)
    best = start
    if start >= limits[LIM_BELOW]:
        return best_w, best, start
    tets = _poorest_first(tets, angles)  # a candidate that cannot win is then left at its first tet
    cand = np.empty(k)
    for si in range(steps.shape[0]):
        for _ in range(64):  # each move gains; the box bounds the moves
            moved = False
            for r in range(directions.shape[0]):
                inside = True
                for q in range(k):
                    cand[q] = w[q] + steps[si] * directions[r, q]
                    inside &= cand[q] >= limits[LIM_LO] and abs(cand[q] - w_cut[q]) <= limits[LIM_MOVE]
                if not inside:
                    continue
                _put(x, copies, corners, cand)
                a = _worst_angle(x, tets, best + _GAIN_EPS_DEG, normals, angles)
                if a > best + _GAIN_EPS_DEG:
                    best = a
                    best_w[:] = cand
                    moved = True
            if not moved:
                break
            w[:] = best_w
    for i in range(copies.shape[0]):
        x[copies[i], 0] = keep[0]
        x[copies[i], 1] = keep[1]
        x[copies[i], 2] = keep[2]
    return best_w, best, start


#: A vertex's local problem for :func:`vertex_place`: ``x`` (k, 3) float64 the positions of the nodes
#: of the tets around the vertex, ``tets`` (m, 4) int64 those tets over them (local rows), ``share``
#: (k,) float64 each node's weight on the vertex (1 for the vertex, a cut node's weight for one
#: defined on it, else 0: a move dx of the vertex moves node i by share[i] dx, affine inside every
#: original tet), ``vertex`` int its row, ``ends`` (g, 3) float64 the far ends of its uncut edges
#: and ``swept`` (h, 3, 3) float64 the stroke's swept triangles near it: no move may make one of
#: those edges cross one of those triangles.
VertexStar = namedtuple("VertexStar", ["x", "tets", "share", "vertex", "ends", "swept"])


@njit(cache=True, nogil=True)
def _shifted(x0, share, dx, y):
    """y = x0 + share dx (each row by its weight)."""
    for i in range(x0.shape[0]):
        for c in range(3):
            y[i, c] = x0[i, c] + share[i] * dx[c]


@njit(cache=True, nogil=True)
def _edges_crossing(p, ends, swept, out):
    """out[j]: whether the edge from p to ends[j] crosses one of the triangles ``swept`` strictly
    between its ends.  A crossing at an end (p on the triangle's plane, the edge going up: s = 0)
    does not count: the cut leaves such an edge whole, so a move that turns it into a crossing
    inside the edge would leave a crossed edge uncut (a vertex on an earlier cut that a stroke
    retraces lies in the swept plane)."""
    for j in range(ends.shape[0]):
        out[j] = False
        for t in range(swept.shape[0]):
            s = edge_triangle_crossing(p, ends[j], swept[t])
            if 0.0 < s < 1.0:
                out[j] = True
                break


@njit(cache=True, nogil=True)
def vertex_place(star, directions, steps, move_max):
    """The move of a vertex that maximises the smallest dihedral angle of the tets around it.

    A compass search: from dx = 0, for each step length of ``steps`` in turn
    (largest first), the best of the moves dx + s d over ``directions`` is
    taken while it raises the smallest angle by more than a rounding margin;
    a trial is refused where a tet would not be positive, where |dx| would
    exceed ``move_max``, or where an uncut edge of the vertex that does not
    cross a swept triangle now would cross one.  ``star.x`` is not changed.

    Parameters
    ----------
    star : VertexStar
    directions : (d, 3) float64
        Unit directions the vertex may move along.
    steps : (s,) float64
        Step lengths, mm, largest first.
    move_max : float
        mm, the longest move.

    Returns
    -------
    dx : (3,) float64
        The move (zero where nothing gains).
    best : float
        The smallest angle after it, degrees.
    start : float
        The smallest angle before it, degrees.
    """
    x0 = star.x
    y = x0.copy()
    normals = np.empty((4, 3))
    angles = np.zeros((star.tets.shape[0], 6))  # rows past a non-positive tet stay 0 (the order below only)
    start = _worst_angle(y, star.tets, -np.inf, normals, angles)
    # a trial that cannot win is then refused at its first tet (the smallest angle is the same in any
    # order; often the poorest tet holds no moved node, and every trial ends there)
    tets = _poorest_first(star.tets, angles)
    now = np.empty(star.ends.shape[0], np.bool_)
    _edges_crossing(x0[star.vertex], star.ends, star.swept, now)
    after = np.empty_like(now)
    best = start
    dx = np.zeros(3)
    trial = np.empty(3)
    for s in steps:
        while True:
            pick = -1
            for d in range(directions.shape[0]):
                for c in range(3):
                    trial[c] = dx[c] + s * directions[d, c]
                if trial[0] * trial[0] + trial[1] * trial[1] + trial[2] * trial[2] > move_max * move_max:
                    continue
                _shifted(x0, star.share, trial, y)
                a = _worst_angle(y, tets, best + _GAIN_EPS_DEG, normals, angles)
                if not a > best + _GAIN_EPS_DEG:
                    continue
                _edges_crossing(y[star.vertex], star.ends, star.swept, after)
                if (after & ~now).any():
                    continue
                best, pick = a, d
            if pick < 0:
                break
            for c in range(3):
                dx[c] += s * directions[pick, c]
    return dx, best, start
