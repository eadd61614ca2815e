"""Slow, obviously correct NumPy twins of cutkit.relax._anp_kernels (the average nodal pressure tet)."""

import numpy as np

from _twins_elastic import barrier, deformation_gradients


def _nodal(x, tets, Dminv, volume, mu, lam, n):
    """Nodal rest volumes V_a, bulk weights kv_a = sum V K / 4 and volume ratios J_a (n,)."""
    F = deformation_gradients(x, tets, Dminv)
    J = np.linalg.det(F)
    K = lam + 2.0 * mu / 3.0
    V_a = np.zeros(n)
    v_a = np.zeros(n)
    kv_a = np.zeros(n)
    for a in range(4):
        np.add.at(V_a, tets[:, a], volume / 4)
        np.add.at(v_a, tets[:, a], volume * J / 4)
        np.add.at(kv_a, tets[:, a], volume * K / 4)
    J_a = np.divide(v_a, V_a, out=np.ones(n), where=V_a > 0)
    return F, J, V_a, kv_a, J_a


def energy(x, tets, Dminv, volume, mu, lam):
    """sum_e V [mu/2 (|F|^2 - 3) - mu (J - 1) + mu/6 (J - 1)^2 + b(J)] + sum_a kv_a/2 (J_a - 1)^2."""
    live = volume > 0
    tets, Dminv, volume, mu, lam = tets[live], Dminv[live], volume[live], mu[live], lam[live]
    F, J, V_a, kv_a, J_a = _nodal(x, tets, Dminv, volume, mu, lam, x.shape[0])
    ic = np.einsum("mij,mij->m", F, F)
    psi = 0.5 * mu * (ic - 3.0) - mu * (J - 1.0) + mu / 6.0 * (J - 1.0) ** 2 + barrier(J, lam + mu)[0]
    return float(np.sum(volume * psi) + np.sum(0.5 * kv_a * (J_a - 1.0) ** 2))


def forces(x, tets, Dminv, volume, mu, lam):
    """-dW/dx (n, 3): P = mu F + (mu/3 (J - 1) - mu + b'(J) + p_e) cof F, p_e the mean nodal pressure."""
    live = volume > 0
    tets, Dminv, volume, mu, lam = tets[live], Dminv[live], volume[live], mu[live], lam[live]
    n = x.shape[0]
    F, J, V_a, kv_a, J_a = _nodal(x, tets, Dminv, volume, mu, lam, n)
    pi = np.divide(kv_a * (J_a - 1.0), V_a, out=np.zeros(n), where=V_a > 0)
    p_e = pi[tets].mean(axis=1)
    cof = J[:, None, None] * np.transpose(np.linalg.inv(F), (0, 2, 1))
    s = mu / 3.0 * (J - 1.0) - mu + barrier(J, lam + mu)[1] + p_e
    P = mu[:, None, None] * F + s[:, None, None] * cof
    # dF/dx_j = e_r b_j^T with b_1..b_3 the rows of Dminv, b_0 = -their sum
    B = np.concatenate([-Dminv.sum(axis=1, keepdims=True), Dminv], axis=1)  # (m, 4, 3)
    g = volume[:, None, None] * np.einsum("mrc,mjc->mjr", P, B)
    out = np.zeros((n, 3))
    for j in range(4):
        np.add.at(out, tets[:, j], -g[:, j])
    return out
