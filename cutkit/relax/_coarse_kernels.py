"""Numba kernels of the two-level preconditioner of the Newton solver's conjugate gradients.

The coarse space is the rigid motions of aggregates: the nodes of one cell of
a coarse grid that are joined through the matrix's blocks (so a crack that
crosses the cell splits it: the tissue on its two sides moves apart), three
translations and three rotations about the aggregate's centroid each
(Brezina, Vanek et al.'s smoothed-aggregation null space, unsmoothed here).
The correction is additive, ``z = D^-1 r + W E^-1 W^T r`` with ``E = W^T A
W`` (Toselli & Widlund, *Domain Decomposition Methods*, 2005, section 2.2):
symmetric positive definite wherever A is.  The kernels check nothing
(:mod:`cutkit.relax.newton` does); the NumPy twin is in
``tests/test_newton_two_level.py``.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from cutkit.relax._stop_flag import flag_up

#: One node's part of the coarse basis: ``agg`` (n,) int64 its aggregate (-1: none, a held node);
#: ``rel`` (n, 3) float64 its position less its aggregate's centroid (mm); ``free`` (n, 3) float64
#: 1.0 at a free dof, 0.0 at a held one; ``turns`` (n,) float64 1.0 where its aggregate has enough
#: nodes to turn (rotations in the basis), else 0.0; ``inv`` (6k, 6k) float64 E's inverse (k
#: aggregates), or (0, 0) for no coarse correction.
Coarse = namedtuple("Coarse", ["agg", "rel", "free", "turns", "inv"])


@njit(cache=True, nogil=True, inline="always")
def _basis(c, i, B):
    """Node i's 3 x 6 rows of the coarse basis W into B: the translations, then the rotations
    ``e_m x rel`` (zero where its aggregate does not turn), each row zero at a held dof."""
    x, y, z = c.rel[i, 0], c.rel[i, 1], c.rel[i, 2]
    t = c.turns[i]
    for a in range(3):
        for m in range(6):
            B[a, m] = 0.0
        B[a, a] = 1.0
    B[1, 3], B[2, 3] = -z * t, y * t
    B[0, 4], B[2, 4] = z * t, -x * t
    B[0, 5], B[1, 5] = -y * t, x * t
    for a in range(3):
        for m in range(6):
            B[a, m] *= c.free[i, a]


@njit(cache=True, nogil=True, inline="always")
def _product(Bi, M, Bj, transposed, S):
    """S (6, 6) = Bi^T M Bj (M^T with ``transposed``), through M Bj (3 x 6) first."""
    MB = np.empty((3, 6))
    for a in range(3):
        for q in range(6):
            s = 0.0
            for b in range(3):
                s += (M[b, a] if transposed else M[a, b]) * Bj[b, q]
            MB[a, q] = s
    for m in range(6):
        for q in range(6):
            S[m, q] = Bi[0, m] * MB[0, q] + Bi[1, m] * MB[1, q] + Bi[2, m] * MB[2, q]


@njit(cache=True, nogil=True, inline="always")
def _add(E, ai, aj, S, both):
    """E[ai, aj] += S; with ``both`` also E[aj, ai] += S^T (the transposed block's share)."""
    for m in range(6):
        for q in range(6):
            E[6 * ai + m, 6 * aj + q] += S[m, q]
            if both:
                E[6 * aj + q, 6 * ai + m] += S[m, q]


#: :func:`galerkin` reads its halt flag every this many nodes.
HALT_EVERY = 1024


@njit(cache=True, nogil=True)
def galerkin(A, c, n_agg, halt):
    """(6k, 6k) float64 E = W^T A W for the symmetric block matrix A (a BlockMatrix) and the
    basis of ``c`` (its ``inv`` unused); a coarse dof no node carries gets 1 on the diagonal.
    ``halt`` ((1,) int64, a waiting cut's flag) is read every :data:`HALT_EVERY` nodes: set, E is
    left unfinished (the caller reads the flag)."""
    E = np.zeros((6 * n_agg, 6 * n_agg))
    Bi = np.empty((3, 6))
    Bj = np.empty((3, 6))
    S = np.empty((6, 6))
    n = A.diag.shape[0]
    for i in range(n):
        if i % HALT_EVERY == 0 and flag_up(halt):
            return E
        ai = c.agg[i]
        if ai < 0:
            continue
        _basis(c, i, Bi)
        _product(Bi, A.diag[i], Bi, False, S)
        _add(E, ai, ai, S, False)
        for q in range(A.ptr[i], A.ptr[i + 1]):
            aj = c.agg[A.col[q]]
            if aj < 0:
                continue
            _basis(c, A.col[q], Bj)
            _product(Bi, A.off[q], Bj, False, S)  # the block above the diagonal; below it, its transpose
            _add(E, ai, aj, S, True)
    for k in range(E.shape[0]):
        if E[k, k] == 0.0:
            E[k, k] = 1.0
    return E


@njit(cache=True, nogil=True)
def add_correction(c, r, z):
    """z (n, 3) += W E^-1 W^T r (r (n, 3)); nothing where ``c.inv`` is empty.  W's rows written out
    (:func:`_basis`): node i's translation part is f r_i, its rotation part t (rel_i x f r_i), and
    W w adds f (u + t (omega x rel_i)) (f its free dofs, t whether its aggregate turns)."""
    k = c.inv.shape[0]
    if k == 0:
        return
    y = np.zeros(k)
    n = r.shape[0]
    for i in range(n):
        a = c.agg[i]
        if a < 0:
            continue
        g0, g1, g2 = c.free[i, 0] * r[i, 0], c.free[i, 1] * r[i, 1], c.free[i, 2] * r[i, 2]
        x0, x1, x2, t = c.rel[i, 0], c.rel[i, 1], c.rel[i, 2], c.turns[i]
        o = 6 * a
        y[o] += g0
        y[o + 1] += g1
        y[o + 2] += g2
        y[o + 3] += t * (x1 * g2 - x2 * g1)
        y[o + 4] += t * (x2 * g0 - x0 * g2)
        y[o + 5] += t * (x0 * g1 - x1 * g0)
    w = c.inv @ y
    for i in range(n):
        a = c.agg[i]
        if a < 0:
            continue
        o = 6 * a
        x0, x1, x2, t = c.rel[i, 0], c.rel[i, 1], c.rel[i, 2], c.turns[i]
        u0, u1, u2 = w[o + 3], w[o + 4], w[o + 5]
        z[i, 0] += c.free[i, 0] * (w[o] + t * (u1 * x2 - u2 * x1))
        z[i, 1] += c.free[i, 1] * (w[o + 1] + t * (u2 * x0 - u0 * x2))
        z[i, 2] += c.free[i, 2] * (w[o + 2] + t * (u0 * x1 - u1 * x0))
