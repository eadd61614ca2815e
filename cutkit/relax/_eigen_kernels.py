"""The analytic eigensystem of the stable neo-Hookean stress Hessian, for projected Newton.

The stress Hessian of :mod:`cutkit.relax._newton_kernels` (and of every
energy of the same family, barrier included) has the form

    H = mu I_9 + w vec(cof F) vec(cof F)^T + s d2J/dF2

with scalars mu, w = lam + mu + b''(J), s = (lam + mu)(J - 1) - mu + b'(J)
that depend on F through J only.  With the rotation-variant SVD
``F = U diag(sigma) V^T`` (det U = det V = +1, sigma_3 < 0 for an inverted
element) and a direction ``D = U M V^T`` (an orthogonal change of basis),
``cof F = U diag(sigma_2 sigma_3, sigma_1 sigma_3, sigma_1 sigma_2) V^T``
and ``d2J/dF2 : D : D = 2 sum_{i<j} sigma_k (M_ii M_jj - M_ij M_ji)`` (the
second-order term of det(diag(sigma) + t M)), so H splits into

* for each pair (i, j), k the third index, a *twist* mode
  ``D = U (E_ij - E_ji) V^T / sqrt 2`` with eigenvalue ``mu + s sigma_k`` and
  a *flip* mode ``D = U (E_ij + E_ji) V^T / sqrt 2`` with ``mu - s sigma_k``;
* three *scaling* modes ``D = U diag(a) V^T``, a the eigenvectors of the
  3x3 ``A = mu I + w c c^T + s K``, ``c = (sigma_2 sigma_3, sigma_1 sigma_3,
  sigma_1 sigma_2)``, ``K_ij = sigma_k`` off the diagonal.

This is the eigensystem of Smith, de Goes & Kim, *Stable Neo-Hookean Flesh
Simulation* (ACM TOG 2018, section 4.2) and *Analytic Eigensystems for
Isotropic Distortion Energies* (ACM TOG 2019): twist and flip are in closed
form for any isotropic psi.  The barrier b(J) changes only w and s, not the
structure, so the same modes hold for cutkit's energy; the scaling block's
eigenvalues are the roots of a cubic, which loses accuracy where two are
close, so the 3x3 symmetric eigenproblem is solved by cyclic Jacobi instead,
to rounding.

The kernels check nothing (:mod:`cutkit.relax.newton` does).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Sweeps of the Jacobi iterations at most (each converges quadratically: 4-6 sweeps suffice).
JACOBI_SWEEPS = 30
#: A pair of columns (SVD) or an off-diagonal entry (3x3 eigenproblem) counts as zero below this
#: fraction of its scale: the rounding of double precision.
JACOBI_TOLERANCE = 1e-16
#: A rotation angle's tangent is 1 / (2 zeta) past this |zeta| (zeta^2 would overflow).
LARGE_ZETA = 1e100
#: Orthogonalised column norms at or below this are zero: the singular vector is then any unit
#: vector orthogonal to the ones before it.
TINY = 1e-290
INV_SQRT2 = 1.0 / np.sqrt(2.0)


@njit(cache=True, nogil=True, inline="always")
def _tangent(zeta):
    """The smaller root t of t^2 + 2 zeta t - 1 = 0 (the Jacobi rotation of Rutishauser, |t| <= 1)."""
    if abs(zeta) > LARGE_ZETA:
        return 0.5 / zeta
    return (1.0 if zeta >= 0.0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))


@njit(cache=True, nogil=True)
def _orthogonal_columns(B, V):
    """One-sided Jacobi (Hestenes): rotate the columns of B (3, 3) in place until they are
    orthogonal, applying the same rotations to V (set to the identity here): then F V = B."""
    V[:] = 0.0
    for i in range(3):
        V[i, i] = 1.0
    for _ in range(JACOBI_SWEEPS):
        rotated = False
        for p, q in ((0, 1), (0, 2), (1, 2)):
            a = B[0, p] * B[0, p] + B[1, p] * B[1, p] + B[2, p] * B[2, p]
            b = B[0, q] * B[0, q] + B[1, q] * B[1, q] + B[2, q] * B[2, q]
            g = B[0, p] * B[0, q] + B[1, p] * B[1, q] + B[2, p] * B[2, q]
            if abs(g) <= JACOBI_TOLERANCE * np.sqrt(a * b):
                continue
            t = _tangent((b - a) / (2.0 * g))
            c = 1.0 / np.sqrt(1.0 + t * t)
            sn = c * t
            rotated = True
            for M in (B, V):
                for r in range(3):
                    mp, mq = M[r, p], M[r, q]
                    M[r, p] = c * mp - sn * mq
                    M[r, q] = sn * mp + c * mq
        if not rotated:
            return


@njit(cache=True, nogil=True, inline="always")
def _swap_columns(M, p, q):
    for r in range(3):
        M[r, p], M[r, q] = M[r, q], M[r, p]


@njit(cache=True, nogil=True)
def _unit_orthogonal(u, out):
    """Some unit vector orthogonal to the unit vector u, into out (3,)."""
    e = 0
    for i in range(1, 3):
        if abs(u[i]) < abs(u[e]):
            e = i
    nrm2 = 0.0
    for r in range(3):
        out[r] = (1.0 if r == e else 0.0) - u[e] * u[r]
        nrm2 += out[r] * out[r]
    nrm = np.sqrt(nrm2)
    for r in range(3):
        out[r] /= nrm


@njit(cache=True, nogil=True)
def rotation_svd(F, U, sigma, V):
    """The rotation-variant SVD F (3, 3) = U diag(sigma) V^T: U, V (3, 3) rotations (det +1),
    sigma (3,) with sigma_1 >= sigma_2 >= |sigma_3| and sigma_3 of the sign of det F.

    One-sided Jacobi gives V and the orthogonal columns b_i = sigma_i u_i of F V; the columns
    are sorted by length, V made a rotation, and U = (u_1, u_2, u_1 x u_2) with
    sigma_3 = u_3 . b_3, which carries the sign of det F and needs no division by a small
    singular value (a flat or inverted element).
    """
    B = F.copy()
    _orthogonal_columns(B, V)
    nrm = np.empty(3)
    for i in range(3):
        nrm[i] = B[0, i] * B[0, i] + B[1, i] * B[1, i] + B[2, i] * B[2, i]
    for p, q in ((0, 1), (0, 2), (1, 2)):  # sort by length, longest first
        if nrm[q] > nrm[p]:
            nrm[p], nrm[q] = nrm[q], nrm[p]
            _swap_columns(B, p, q)
            _swap_columns(V, p, q)
    detV = (V[0, 0] * (V[1, 1] * V[2, 2] - V[2, 1] * V[1, 2]) - V[0, 1] * (V[1, 0] * V[2, 2] - V[2, 0] * V[1, 2])
            + V[0, 2] * (V[1, 0] * V[2, 1] - V[2, 0] * V[1, 1]))
    if detV < 0.0:
        for r in range(3):
            V[r, 2] = -V[r, 2]
            B[r, 2] = -B[r, 2]
    u = np.empty(3)
    sigma[0] = np.sqrt(nrm[0])
    if sigma[0] <= TINY:
        for r in range(3):
            u[r] = 1.0 if r == 0 else 0.0
    else:
        for r in range(3):
            u[r] = B[r, 0] / sigma[0]
    U[:, 0] = u
    w = B[:, 1].copy()
    for _ in range(2):  # Gram-Schmidt, twice (to rounding)
        d = u[0] * w[0] + u[1] * w[1] + u[2] * w[2]
        for r in range(3):
            w[r] -= d * u[r]
    wn = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if wn <= TINY:
        _unit_orthogonal(u, w)
    else:
        for r in range(3):
            w[r] /= wn
    U[:, 1] = w
    U[0, 2] = u[1] * w[2] - u[2] * w[1]
    U[1, 2] = u[2] * w[0] - u[0] * w[2]
    U[2, 2] = u[0] * w[1] - u[1] * w[0]
    sigma[1] = U[0, 1] * B[0, 1] + U[1, 1] * B[1, 1] + U[2, 1] * B[2, 1]
    sigma[2] = U[0, 2] * B[0, 2] + U[1, 2] * B[1, 2] + U[2, 2] * B[2, 2]


@njit(cache=True, nogil=True)
def symmetric_eigen3(A, lam, Q):
    """Eigenvalues lam (3,) and orthonormal eigenvectors Q (3, 3) (columns) of the symmetric
    A (3, 3), by cyclic Jacobi rotations (to rounding; A is overwritten)."""
    Q[:] = 0.0
    for i in range(3):
        Q[i, i] = 1.0
    for _ in range(JACOBI_SWEEPS):
        off = A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2] + A[1, 2] * A[1, 2]
        scale = A[0, 0] * A[0, 0] + A[1, 1] * A[1, 1] + A[2, 2] * A[2, 2] + 2.0 * off
        if off <= JACOBI_TOLERANCE * JACOBI_TOLERANCE * scale:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if A[p, q] == 0.0:
                continue
            t = _tangent((A[q, q] - A[p, p]) / (2.0 * A[p, q]))
            c = 1.0 / np.sqrt(1.0 + t * t)
            sn = c * t
            for r in range(3):  # A <- A R, Q <- Q R, R the rotation in the plane (p, q)
                ap, aq = A[r, p], A[r, q]
                A[r, p] = c * ap - sn * aq
                A[r, q] = sn * ap + c * aq
                qp, qq = Q[r, p], Q[r, q]
                Q[r, p] = c * qp - sn * qq
                Q[r, q] = sn * qp + c * qq
            for r in range(3):  # A <- R^T A
                ap, aq = A[p, r], A[q, r]
                A[p, r] = c * ap - sn * aq
                A[q, r] = sn * ap + c * aq
            A[p, q] = A[q, p] = 0.0  # zero by construction of t
    for i in range(3):
        lam[i] = A[i, i]


@njit(cache=True, nogil=True)
def _cofactor(F, C):
    """C = cof F = dJ/dF (3, 3): its columns are cross products of F's columns; returns J = det F.
    (The one copy: the Newton and ANP kernels import it.)"""
    for c in range(3):
        c1, c2 = (c + 1) % 3, (c + 2) % 3
        C[0, c] = F[1, c1] * F[2, c2] - F[2, c1] * F[1, c2]
        C[1, c] = F[2, c1] * F[0, c2] - F[0, c1] * F[2, c2]
        C[2, c] = F[0, c1] * F[1, c2] - F[1, c1] * F[0, c2]
    return F[0, 0] * C[0, 0] + F[1, 0] * C[1, 0] + F[2, 0] * C[2, 0]


@njit(cache=True, nogil=True, inline="always")
def _remove_mode(HF, D, lam, factor):
    """HF -= factor lam vec(D) vec(D)^T (D (3, 3), vec index 3 r + c)."""
    g = factor * lam
    for p in range(9):
        dp = g * D[p // 3, p % 3]
        for q in range(9):
            HF[p, q] -= dp * D[q // 3, q % 3]


@njit(cache=True, nogil=True)
def project_stress_hessian(F, mu, w, s, factor, HF):
    """Make HF = mu I + w vec(cof F) vec(cof F)^T + s d2J/dF2 (9, 9) positive semi-definite in
    place: each mode with eigenvalue lam < 0 (module docstring) is removed ``factor`` times
    (1: clamped to 0, projected Newton, Smith et al. 2018 section 4.3; 2: reflected to |lam|).
    A HF without a negative eigenvalue is left as it is.  Returns the smallest eigenvalue."""
    U = np.empty((3, 3))
    V = np.empty((3, 3))
    sig = np.empty(3)
    rotation_svd(F, U, sig, V)
    D = np.empty((3, 3))
    smallest = np.inf
    for k in range(3):  # twist (sign +1) and flip (-1) modes of the pair (i, j)
        i, j = (k + 1) % 3, (k + 2) % 3
        for sign in (1.0, -1.0):
            lam = mu + sign * s * sig[k]
            smallest = min(smallest, lam)
            if lam < 0.0:
                for r in range(3):
                    for c in range(3):
                        D[r, c] = INV_SQRT2 * (U[r, i] * V[c, j] - sign * U[r, j] * V[c, i])
                _remove_mode(HF, D, lam, factor)
    c3 = np.empty(3)  # cof F in the SVD's frame: u_i . C v_i (= sigma_j sigma_k)
    C = np.empty((3, 3))
    _cofactor(F, C)
    for i in range(3):
        acc = 0.0
        for r in range(3):
            for c in range(3):
                acc += U[r, i] * C[r, c] * V[c, i]
        c3[i] = acc
    A = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            A[i, j] = w * c3[i] * c3[j] + (mu if i == j else s * sig[3 - i - j])
    lam3 = np.empty(3)
    Q = np.empty((3, 3))
    symmetric_eigen3(A, lam3, Q)
    for e in range(3):  # the scaling modes
        smallest = min(smallest, lam3[e])
        if lam3[e] < 0.0:
            for r in range(3):
                for c in range(3):
                    D[r, c] = Q[0, e] * U[r, 0] * V[c, 0] + Q[1, e] * U[r, 1] * V[c, 1] + Q[2, e] * U[r, 2] * V[c, 2]
            _remove_mode(HF, D, lam3[e], factor)
    return smallest
