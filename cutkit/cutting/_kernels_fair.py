"""Numba kernel of the cut-node fairing (:mod:`cutkit.cutting.fairing`): the best place of one cut node.

Slow, obviously correct NumPy twin: ``tests/_twins_cut.py::fair_place``.
"""

import numpy as np
from numba import njit

from cutkit.mesh.geometry import tet_dihedrals, tet_signed_volume

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


@njit(cache=True, nogil=True)
def fair_place(x, tets, copies, corners, w0, w_cut, lo, move_max, steps):
    """Weights of a cut node (and its coincident copies) that maximise the smallest dihedral angle of
    the tets around it, by a compass search over its defining simplex.

    The node is ``w . x[corners]``; a move adds ``s`` to one weight and takes
    it from another, for each step ``s`` of ``steps`` in turn, as long as the
    best move raises the smallest angle; every weight stays ``>= lo`` and
    within ``move_max`` of ``w_cut`` (where the cut put the node), and every
    tet stays positive.  ``x`` is
    left as it was.

    Parameters
    ----------
    x : (n, 3) float64
        Node positions (rows ``copies`` written during the search, then restored).
    tets : (m, 4) int64
        The live tets that hold one of ``copies``.
    copies : (c,) int64
        The node and its coincident copies (both sides of a cut).
    corners : (k,) int64
        Its defining original nodes, k = 2 (edge), 3 (face) or 4 (tet).
    w0 : (k,) float64
        Its weights now (the search starts there).
    w_cut : (k,) float64
        Its weights where the cut put it (the centre of the box).
    lo, move_max : float
        Smallest weight; largest change of any weight from ``w0``.
    steps : (q,) float64
        Step lengths, largest first.

    Returns
    -------
    (w, angle) : (k,) float64 and float
        The best weights found (``w0`` when nothing is better) and their
        smallest angle, degrees (-1 when ``w0`` itself leaves a tet not
        positive).
    """
    k = corners.shape[0]
    m = tets.shape[0]
    normals = np.empty((4, 3))
    angles = np.empty((m, 6))
    keep = x[copies[0]].copy()
    w = w0.copy()
    best = _worst_angle(x, tets, -np.inf, normals, angles)
    cand = np.empty(k)
    best_w = w.copy()
    for si in range(steps.shape[0]):
        s = steps[si]
        for _ in range(64):  # each move gains; the box bounds the moves
            moved = False
            for i in range(k):
                for j in range(k):
                    if i == j or w[j] - s < lo or abs(w[i] + s - w_cut[i]) > move_max or abs(w[j] - s - w_cut[j]) > move_max:
                        continue
                    for q in range(k):
                        cand[q] = w[q]
                    cand[i] += s
                    cand[j] -= s
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
    return best_w, best
