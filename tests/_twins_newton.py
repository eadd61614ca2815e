"""Slow, obviously correct NumPy twins of cutkit.relax._newton_kernels."""

import numpy as np

from _twins_elastic import BARRIER_J, deformation_gradients

#: The Levi-Civita symbol eps_ijk.
EPS = np.zeros((3, 3, 3))
for _i, _j, _k in [(0, 1, 2), (1, 2, 0), (2, 0, 1)]:
    EPS[_i, _j, _k], EPS[_j, _i, _k] = 1.0, -1.0


def barrier_derivatives(J, k):
    """b'(J), b''(J) of b = -k (J - Jb)^2 ln(J / Jb) on 0 < J < Jb (0 outside), by hand."""
    if not 0.0 < J < BARRIER_J:
        return 0.0, 0.0
    d, ln = J - BARRIER_J, np.log(J / BARRIER_J)
    return -k * (2 * d * ln + d * d / J), -k * (2 * ln + 4 * d / J - d * d / J ** 2)


def stress_hessian(F, mu, lam, project):
    """P (3, 3) and d2psi/dF2 (9, 9), index 3 r + c; project: 0 exact, 1 clamp negative eigenvalues."""
    J = np.linalg.det(F)
    C = np.stack([np.cross(F[:, 1], F[:, 2]), np.cross(F[:, 2], F[:, 0]), np.cross(F[:, 0], F[:, 1])], axis=1)
    db, ddb = barrier_derivatives(J, lam + mu)
    s = (lam + mu) * (J - 1.0) - mu + db
    P = mu * F + s * C
    HJ = np.einsum("ijk,abc,kc->iajb", EPS, EPS, F).reshape(9, 9)
    H = mu * np.eye(9) + (lam + mu + ddb) * np.outer(C.ravel(), C.ravel()) + s * HJ
    if project:
        w, Q = np.linalg.eigh(H)
        H = (Q * np.maximum(w, 0.0)) @ Q.T
    return P, H


def gradient_operator(Dminv):
    """B (4, 3): rows b_0 .. b_3 with F = sum_j x_j b_j^T."""
    return np.concatenate([-Dminv.sum(axis=0, keepdims=True), Dminv], axis=0)


def element_terms(x, tets, Dminv, volume, mu, lam, project):
    """Gradients (m, 12) and Hessians (m, 12, 12) of each element's energy, through dF/dx (9, 12)."""
    F = deformation_gradients(x, tets, Dminv)
    m = tets.shape[0]
    g, H = np.zeros((m, 12)), np.zeros((m, 12, 12))
    for t in range(m):
        P, HF = stress_hessian(F[t], mu[t], lam[t], project)
        B = gradient_operator(Dminv[t])
        D = np.zeros((9, 12))  # d F_rc / d x_j,s = delta_rs b_j,c
        for r in range(3):
            for c in range(3):
                for j in range(4):
                    D[3 * r + c, 3 * j + r] = B[j, c]
        g[t] = volume[t] * D.T @ P.ravel()
        H[t] = volume[t] * D.T @ HF @ D
    return g, H


def assembled(x, tets, Dminv, volume, mu, lam, project, fixed, diagonal_add):
    """The dense (3n, 3n) system matrix: element Hessians summed, held dofs identity rows and columns."""
    n3 = x.size
    A = np.zeros((n3, n3))
    live = volume > 0
    _, H = element_terms(x, tets[live], Dminv[live], volume[live], mu[live], lam[live], project)
    for t, q in enumerate(tets[live]):
        dof = (3 * q[:, None] + np.arange(3)).ravel()
        A[np.ix_(dof, dof)] += H[t]
    A[np.diag_indices(n3)] += diagonal_add
    A[fixed, :] = 0.0
    A[:, fixed] = 0.0
    A[fixed, fixed] = 1.0
    return A


def step_bound(x, d, tets, volume, a_max):
    """Smallest a in (0, a_max] with det(Ds + a dDs) = 0 for an upright element (a_max + 1: none).

    det(A + a B) = det A det(I + a A^-1 B) vanishes at a = -1 / lambda for each real
    eigenvalue lambda of A^-1 B.
    """
    best = a_max + 1.0
    for t, q in enumerate(tets):
        if volume[t] <= 0:
            continue
        A = (x[q[1:]] - x[q[0]]).T
        Bm = (d[q[1:]] - d[q[0]]).T
        if np.linalg.det(A) <= 0:
            continue
        lam = np.linalg.eigvals(np.linalg.solve(A, Bm))
        for v in lam:
            if abs(v.imag) < 1e-12 * max(1.0, abs(v)) and v.real < 0:
                a = -1.0 / v.real
                if a <= a_max:
                    best = min(best, a)
    return best


def rotation_svd(F):
    """U, sigma, V with F = U diag(sigma) V^T, det U = det V = +1, sigma descending in magnitude,
    the last one carrying the sign of det F (LAPACK's SVD, signs moved by hand)."""
    U, sigma, Vt = np.linalg.svd(F)
    V = Vt.T.copy()
    if np.linalg.det(U) < 0:
        U[:, 2] *= -1
        sigma[2] *= -1
    if np.linalg.det(V) < 0:
        V[:, 2] *= -1
        sigma[2] *= -1
    return U, sigma, V


def clamp_negative(H, factor=1):
    """H with its negative eigenvalues clamped to 0 (factor 1) or reflected (2), by eigh."""
    w, Q = np.linalg.eigh(H)
    w = np.where(w < 0, w * (1 - factor), w)
    return (Q * w) @ Q.T
