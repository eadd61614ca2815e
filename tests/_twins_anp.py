"""Slow, obviously correct NumPy twins of cutkit.relax._anp_kernels (the average nodal pressure tet)."""

import numpy as np

from _twins_elastic import barrier, deformation_gradients


def shares(tets, held):
    """Each corner's share of its tet's volume: 1/4, or 1/k over the k corners not held (0 held)."""
    w = np.zeros(tets.shape)
    for e in range(tets.shape[0]):
        free = [a for a in range(4) if not held[tets[e, a]]]
        for a in free:
            w[e, a] = 1.0 / len(free)
    return w


def patches(tets, mu, lam, n):
    """Each corner's patch (m, 4): node * kinds + its tet's material, the materials the distinct
    (mu, lam) pairs; and the number of possible patches, n * kinds (most of them empty)."""
    _, material = np.unique(np.stack([mu, lam], axis=1), axis=0, return_inverse=True)
    kinds = int(material.max()) + 1
    return tets * kinds + material.ravel()[:, None], n * kinds


def material_patches(tets, volume, mu, lam, n):
    """Twin of cutkit.relax.anp.material_patches, by sorting (node, material) keys: a node's
    first material (smallest (mu, lam)) keeps the node's id, its others get n, n + 1, ... in the
    order of (node, material); inactive rows keep their nodes."""
    live = np.flatnonzero(volume > 0.0)
    patch = np.array(tets, np.int64)
    if live.size == 0:
        return patch, n
    _, material = np.unique(np.stack([mu[live], lam[live]], axis=1), axis=0, return_inverse=True)
    kinds = int(material.max()) + 1
    pairs, inverse = np.unique((patch[live] * kinds + material.ravel()[:, None]).ravel(), return_inverse=True)
    node = pairs // kinds
    first = np.r_[True, node[1:] != node[:-1]]
    ids = np.where(first, node, n + np.cumsum(~first) - 1)
    patch[live] = ids[inverse.ravel()].reshape(-1, 4)
    return patch, n + int(np.count_nonzero(~first))


def _nodal(x, tets, Dminv, volume, mu, lam, n, held=None):
    """Per patch: rest volumes V_a, bulk weights kv_a = sum w V K and volume ratios J_a, w the shares;
    and the corners' patches (m, 4)."""
    F = deformation_gradients(x, tets, Dminv)
    J = np.linalg.det(F)
    K = lam + 2.0 * mu / 3.0
    w = shares(tets, np.zeros(n, bool) if held is None else held)
    key, count = patches(tets, mu, lam, n)
    V_a = np.zeros(count)
    v_a = np.zeros(count)
    kv_a = np.zeros(count)
    for a in range(4):
        np.add.at(V_a, key[:, a], w[:, a] * volume)
        np.add.at(v_a, key[:, a], w[:, a] * volume * J)
        np.add.at(kv_a, key[:, a], w[:, a] * volume * K)
    J_a = np.divide(v_a, V_a, out=np.ones(count), where=V_a > 0)
    return F, J, V_a, kv_a, J_a, w, key


def _unit_deviatoric(F):
    """psi(F) = (|F|^2 - 3)/2 - (J - 1) + (J - 1)^2/6 and dpsi/dF, for F (k, 3, 3)."""
    J = np.linalg.det(F)
    cof = J[:, None, None] * np.transpose(np.linalg.inv(F), (0, 2, 1))
    psi = 0.5 * (np.einsum("kij,kij->k", F, F) - 3.0) - (J - 1.0) + (J - 1.0) ** 2 / 6.0
    return psi, F + ((J - 1.0) / 3.0 - 1.0)[:, None, None] * cof


def _smoothed(F, key, count, volume, mu):
    """Per patch (key (m, 4): the corners' patches): smoothed F_a = sum (V/4) F_e / V_a (count, 3, 3),
    shear weights G_a = sum V mu / 4, V_a."""
    V_a = np.zeros(count)
    G_a = np.zeros(count)
    Fs = np.zeros((count, 3, 3))
    for a in range(4):
        np.add.at(V_a, key[:, a], volume / 4)
        np.add.at(G_a, key[:, a], volume * mu / 4)
        np.add.at(Fs, key[:, a], (volume / 4)[:, None, None] * F)
    used = V_a > 0
    Fs[used] /= V_a[used, None, None]
    Fs[~used] = np.eye(3)
    return Fs, G_a, V_a


def energy(x, tets, Dminv, volume, mu, lam, smoothing=0.0, held=None):
    """sum_e V [(1 - alpha) mu (|F|^2 - 3)/2 - ... + b(J)] + sum_a kv_a/2 (J_a - 1)^2 + alpha sum_a G_a psi(Fs_a)."""
    live = volume > 0
    tets, Dminv, volume, mu, lam = tets[live], Dminv[live], volume[live], mu[live], lam[live]
    F, J, V_a, kv_a, J_a, _, key = _nodal(x, tets, Dminv, volume, mu, lam, x.shape[0], held)
    ic = np.einsum("mij,mij->m", F, F)
    keep = (1.0 - smoothing) * mu
    psi = 0.5 * keep * (ic - 3.0) - keep * (J - 1.0) + keep / 6.0 * (J - 1.0) ** 2 + barrier(J, lam + mu)[0]
    Fs, G_a, _ = _smoothed(F, key, V_a.shape[0], volume, mu)
    return float(np.sum(volume * psi) + np.sum(0.5 * kv_a * (J_a - 1.0) ** 2)
                 + smoothing * np.sum(G_a * _unit_deviatoric(Fs)[0]))


def forces(x, tets, Dminv, volume, mu, lam, smoothing=0.0, held=None):
    """-dW/dx (n, 3): P = mu F + (mu/3 (J - 1) - mu + b'(J) + p_e) cof F, p_e the mean nodal pressure."""
    live = volume > 0
    tets, Dminv, volume, mu, lam = tets[live], Dminv[live], volume[live], mu[live], lam[live]
    n = x.shape[0]
    F, J, V_a, kv_a, J_a, w, key = _nodal(x, tets, Dminv, volume, mu, lam, n, held)
    pi = np.divide(kv_a * (J_a - 1.0), V_a, out=np.zeros(V_a.shape[0]), where=V_a > 0)
    p_e = (w * pi[key]).sum(axis=1)
    cof = J[:, None, None] * np.transpose(np.linalg.inv(F), (0, 2, 1))
    keep = (1.0 - smoothing) * mu
    s = keep / 3.0 * (J - 1.0) - keep + barrier(J, lam + mu)[1] + p_e
    P = keep[:, None, None] * F + s[:, None, None] * cof
    # the nodes' share: dW_s/dF_e = sum_{a in e} alpha G_a (V_e / 4 V_a) dpsi/dF(Fs_a) / V_e
    Fs, G_a, V_s = _smoothed(F, key, V_a.shape[0], volume, mu)
    dpsi = _unit_deviatoric(Fs)[1]
    for a in range(4):
        c = smoothing * G_a[key[:, a]] / (4.0 * V_s[key[:, a]])
        P = P + c[:, None, None] * dpsi[key[:, a]]
    # dF/dx_j = e_r b_j^T with b_1..b_3 the rows of Dminv, b_0 = -their sum
    B = np.concatenate([-Dminv.sum(axis=1, keepdims=True), Dminv], axis=1)  # (m, 4, 3)
    g = volume[:, None, None] * np.einsum("mrc,mjc->mjr", P, B)
    out = np.zeros((n, 3))
    for j in range(4):
        np.add.at(out, tets[:, j], -g[:, j])
    return out
