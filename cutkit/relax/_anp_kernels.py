"""Numba kernels of the average nodal pressure (ANP) tetrahedron (:mod:`cutkit.relax.anp`).

The stored energy is split into a part per element and a volumetric part per node
(Bonet & Burton 1998; Bonet, Marriott & Hassan 2001; Joldes, Wittek & Miller 2009):

    W = sum_e V_e (psi_dev(F_e) + b(J_e)) + sum_a kv_a / 2 (J_a - 1)^2
    psi_dev = mu/2 (tr F^T F - 3) - mu (J - 1) + mu/6 (J - 1)^2

with J_a = v_a / V_a the nodal volume ratio of patch a, a node's tets of one material (v_a,
V_a: the shares w_ea of the current and natural volumes of the patch's tets summed; w_ea = 1/4, or 1/k over a tet's k corners
not held and 0 on held ones, ``NodalTerms.share``), kv_a the sum over them of w_ea V_e K_e
(K = lam + 2 mu / 3, the bulk modulus) and b the element barrier of
:mod:`cutkit.relax._elastic_kernels` (modulus lam + mu, as there).  psi_dev is the stable
neo-Hookean energy (Smith et al. 2018) with lam replaced by -2 mu / 3: its rest-stability
term -mu (J - 1) stays, and its small-strain limit is mu |dev eps|^2, so the sum has
the small-strain limit mu |dev eps|^2 + K / 2 (tr eps)^2: linear elasticity with the
material's E and nu, the volumetric part carried by the nodes.

With the nodal pressure pi_a = dU_a / dv_a = kv_a (J_a - 1) / V_a and the element's
average p_e = sum_{a in e} w_ea pi_a (the "average nodal pressure"),

    dW/dx = sum_e V_e [ mu F + (mu/3 (J - 1) - mu + b'(J) + p_e) cof F ] : dF/dx
    d2W/dx2 = sum_e V_e dF^T [ mu I + (mu/3 + b'') cof (x) cof + (...) d2J/dF2 ] dF
              + sum_a (kv_a / V_a^2) g_a g_a^T,   g_a = dv_a/dx = sum_{e ni a} w_ea V_e cof(F_e) b_j

The nodal terms couple every pair of nodes of a node's patch: the wider stencil.  The
element term is projected (negative eigenvalues clamped) where asked; the nodal terms
are positive semi-definite as they stand.  The kernels check nothing.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from cutkit.relax._elastic_kernels import barrier
from cutkit.relax._eigen_kernels import _cofactor
from cutkit.relax._newton_kernels import _deformation, add_det_hessian, project_hf

#: Per patch (a node's tets of one material; P >= n patches, patch a < n is node a's first
#: material's, ``cutkit.relax.anp.material_patches``): natural volume V_a (P,), bulk weight kv_a
#: (P,) (N mm: sum V_e K_e / 4), the tets of the patch ``node_ptr`` (P + 1,) int64 / ``node_tets``
#: (4m,) int64 with the patch's corner in each ``node_corner`` (4m,) int64, the shear weight (P,)
#: (N mm: sum V_e mu_e / 4) and the share alpha (float, 0..1) of the deviatoric energy carried by
#: the patches' smoothed deformation, ``share`` (m, 4): the share of each element's volume its
#: corner's nodal volume takes in the volumetric term (1/4, or 1/k over its k free corners where
#: some are held, 0 on held corners), ``pressure_volume`` (P,) = sum share V_e, the V_a of the
#: volumetric term (``bulk`` uses the same shares), and ``patch`` (m, 4) int64, the patch of each
#: element's corner.  ``volume`` stays the quarter sums: the smoothed deformation's weights.
NodalTerms = namedtuple("NodalTerms", ["volume", "bulk", "node_ptr", "node_tets", "node_corner", "shear",
                                       "smoothing", "share", "pressure_volume", "patch"])


@njit(cache=True, nogil=True)
def volume_ratios(x, el, J):
    """J (m,) = det F of every element (0 where inactive)."""
    B = np.empty((4, 3))
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    for t in range(el.tets.shape[0]):
        if el.volume[t] <= 0.0:
            J[t] = 0.0
            continue
        _deformation(x, el, t, B, F)
        J[t] = _cofactor(F, C)


@njit(cache=True, nogil=True)
def nodal_pressures(el, J, nodal, pi):
    """Nodal volume ratios J_a and pressures pi_a = kv_a (J_a - 1) / V_a into pi (n,);
    returns the nodal energy sum_a kv_a / 2 (J_a - 1)^2."""
    n = nodal.volume.shape[0]
    v = np.zeros(n)
    for t in range(el.tets.shape[0]):
        q = el.volume[t] * J[t]
        for a in range(4):
            v[nodal.patch[t, a]] += nodal.share[t, a] * q
    energy = 0.0
    for a in range(n):
        Va = nodal.pressure_volume[a]
        if Va <= 0.0:
            pi[a] = 0.0
            continue
        d = v[a] / Va - 1.0
        pi[a] = nodal.bulk[a] * d / Va
        energy += 0.5 * nodal.bulk[a] * d * d
    return energy


@njit(cache=True, nogil=True)
def energy(x, el, nodal):
    """W (N mm): the elements' deviatoric energy and barrier plus the nodal volumetric energy."""
    m = el.tets.shape[0]
    J = np.zeros(m)
    B = np.empty((4, 3))
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    total = 0.0
    for t in range(m):
        V = el.volume[t]
        if V <= 0.0:
            continue
        _deformation(x, el, t, B, F)
        Jt = _cofactor(F, C)
        J[t] = Jt
        mu = el.mu[t]
        ic = 0.0
        for r in range(3):
            for c in range(3):
                ic += F[r, c] * F[r, c]
        keep = 1.0 - nodal.smoothing
        total += V * (keep * (0.5 * mu * (ic - 3.0) - mu * (Jt - 1.0) + mu / 6.0 * (Jt - 1.0) ** 2)
                      + barrier(Jt, el.lam[t] + mu)[0])
    pi = np.empty(nodal.volume.shape[0])
    total += nodal_pressures(el, J, nodal, pi)
    if nodal.smoothing > 0.0:
        total += smoothed_energy(x, el, nodal)
    return total


@njit(cache=True, nogil=True)
def _element_pressure(el, nodal, t, pi):
    """p_e = sum_a share_ea pi_a: the mean of the four nodal pressures where no corner is held."""
    p = 0.0
    for a in range(4):
        p += nodal.share[t, a] * pi[nodal.patch[t, a]]
    return p


@njit(cache=True, nogil=True)
def forces(x, el, nodal, out):
    """-dW/dx (N) into out (n, 3) (zeroed here)."""
    m = el.tets.shape[0]
    J = np.zeros(m)
    volume_ratios(x, el, J)
    pi = np.empty(nodal.volume.shape[0])
    nodal_pressures(el, J, nodal, pi)
    out[:] = 0.0
    B = np.empty((4, 3))
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    for t in range(m):
        V = el.volume[t]
        if V <= 0.0:
            continue
        _deformation(x, el, t, B, F)
        Jt = _cofactor(F, C)
        mu = (1.0 - nodal.smoothing) * el.mu[t]
        s = mu / 3.0 * (Jt - 1.0) - mu + barrier(Jt, el.lam[t] + el.mu[t])[1] + _element_pressure(el, nodal, t, pi)
        for j in range(4):
            i = el.tets[t, j]
            for r in range(3):
                acc = 0.0
                for c in range(3):
                    acc += (mu * F[r, c] + s * C[r, c]) * B[j, c]
                out[i, r] -= V * acc
    if nodal.smoothing > 0.0:
        smoothed_forces(x, el, nodal, out)


@njit(cache=True, nogil=True)
def element_hessian(x, el, t, p_e, keep, project, H):
    """The element part of d2W/dx2 of element t (12, 12) (dof 3 j + s), its pressure p_e included;
    ``keep`` (1 - alpha) scales its deviatoric energy."""
    B = np.empty((4, 3))
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    HF = np.empty((9, 9))
    _deformation(x, el, t, B, F)
    J = _cofactor(F, C)
    mu = keep * el.mu[t]
    _, db, ddb = barrier(J, el.lam[t] + el.mu[t])
    s = mu / 3.0 * (J - 1.0) - mu + db + p_e
    w = mu / 3.0 + ddb
    for p in range(9):
        for q in range(9):
            HF[p, q] = w * C[p // 3, p % 3] * C[q // 3, q % 3]
        HF[p, p] += mu
    add_det_hessian(F, s, HF)  # s d2J/dF2 = s eps_ijk eps_abc F_kc
    project_hf(F, mu, w, s, project, HF)  # the analytic eigensystem: the same structure as nh's
    V = el.volume[t]
    for j in range(4):
        for s_ in range(3):
            for k in range(4):
                for t_ in range(3):
                    acc = 0.0
                    for c in range(3):
                        for q in range(3):
                            acc += B[j, c] * HF[3 * s_ + c, 3 * t_ + q] * B[k, q]
                    H[3 * j + s_, 3 * k + t_] = V * acc


@njit(cache=True, nogil=True)
def _add_block(pattern, i, j, H, data):
    """data += the 3x3 H into the block (i, j) of the pattern (which must hold it)."""
    ptr = pattern.node_ptr
    lo = ptr[i]
    deg = ptr[i + 1] - lo
    k = lo + np.searchsorted(pattern.node_idx[lo:ptr[i + 1]], j)
    base = 9 * lo + 3 * (k - lo)
    for r in range(3):
        for c in range(3):
            data[base + 3 * r * deg + c] += H[r, c]


@njit(cache=True, nogil=True, inline="always")
def _patch_slot(local, patch, rows, i, k):
    """Give node i of a patch its local slot if it has none: ``local[i] = k``, ``patch[k] = i`` and
    ``rows[k]`` zeroed.  Returns the patch size (k, or k + 1 when i is new)."""
    if local[i] < 0:
        local[i] = k
        patch[k] = i
        rows[k, :] = 0.0
        k += 1
    return k


@njit(cache=True, nogil=True, inline="always")
def _clear_slots(local, patch, k):
    """Reset ``local`` to -1 on the patch's k nodes."""
    for q in range(k):
        local[patch[q]] = -1


@njit(cache=True, nogil=True)
def _nodal_gradients(x, el, nodal, a, local, patch, g):
    """g_a = dv_a/dx over a's patch: fills patch (k,) and g (k, 3); returns k.
    ``local`` (n,) is -1 on entry and on exit."""
    B = np.empty((4, 3))
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    k = 0
    for q in range(nodal.node_ptr[a], nodal.node_ptr[a + 1]):
        t = nodal.node_tets[q]
        _deformation(x, el, t, B, F)
        _cofactor(F, C)
        w = nodal.share[t, nodal.node_corner[q]] * el.volume[t]
        for j in range(4):
            i = el.tets[t, j]
            k = _patch_slot(local, patch, g, i, k)
            for r in range(3):
                acc = 0.0
                for c in range(3):
                    acc += C[r, c] * B[j, c]
                g[local[i], r] += w * acc
    _clear_slots(local, patch, k)
    return k


@njit(cache=True, nogil=True)
def assemble_hessian(x, el, nodal, pattern, project, data):
    """The ANP Hessian (element parts, projected where ``project``, and nodal rank-one parts)
    into the CSR ``data`` (zeroed here) of a pattern that holds every patch pair."""
    data[:] = 0.0
    m = el.tets.shape[0]
    n = nodal.volume.shape[0]
    J = np.zeros(m)
    volume_ratios(x, el, J)
    pi = np.empty(n)
    nodal_pressures(el, J, nodal, pi)
    H = np.empty((12, 12))
    Hb = np.empty((3, 3))
    for t in range(m):
        if el.volume[t] <= 0.0:
            continue
        element_hessian(x, el, t, _element_pressure(el, nodal, t, pi), 1.0 - nodal.smoothing, project, H)
        for a in range(4):
            for b in range(4):
                Hb[:, :] = H[3 * a:3 * a + 3, 3 * b:3 * b + 3]
                _add_block(pattern, el.tets[t, a], el.tets[t, b], Hb, data)
    most = 0
    for a in range(n):
        most = max(most, nodal.node_ptr[a + 1] - nodal.node_ptr[a])
    local = np.full(n, -1, np.int64)
    patch = np.empty(4 * most, np.int64)
    g = np.empty((4 * most, 3))
    for a in range(n):
        Va = nodal.pressure_volume[a]
        if Va <= 0.0:
            continue
        c = nodal.bulk[a] / (Va * Va)
        k = _nodal_gradients(x, el, nodal, a, local, patch, g)
        for p in range(k):
            for q in range(k):
                for r in range(3):
                    for s in range(3):
                        Hb[r, s] = c * g[p, r] * g[q, s]
                _add_block(pattern, patch[p], patch[q], Hb, data)
    if nodal.smoothing > 0.0:
        smoothed_hessian(x, el, nodal, pattern, project, data)


# ---------------------------------------------------------------- the nodes' smoothed deviatoric part
# With alpha = nodal.smoothing > 0 a share alpha of the deviatoric energy is carried by the nodes
# (the alpha-FEM of Liu, Nguyen-Thoi & Lam 2008 / the selective smoothed FEM of Nguyen-Thoi,
# Liu et al. 2009 with node-based smoothing): linear tets are too stiff in bending (they lock in
# shear), node-based smoothed strain is too soft, and the blend is close to exact
# (benchmarks/anp_deviatoric_blend.py):
#
#     W_s = alpha sum_a G_a psi(Fs_a),  Fs_a = sum_{e ni a} (V_e / 4) F_e / V_a,
#     psi(F) = (|F|^2 - 3) / 2 - (J - 1) + (J - 1)^2 / 6,  G_a = sum_{e ni a} V_e mu_e / 4
#
# Fs_a is linear in x: dFs_a/dx_i = e_r w_i^T with w_i = sum_{e ni a, i} (V_e / 4 V_a) b_e,i,
# so W_s has ANP's two-ring stencil.


@njit(cache=True, nogil=True)
def _smoothed_deformation(x, el, nodal, a, local, patch, w, F):
    """Fs_a into F (3, 3), a's patch into patch (k,) and w (k, 3); returns k.
    ``local`` (n,) is -1 on entry and on exit."""
    B = np.empty((4, 3))
    Fe = np.empty((3, 3))
    F[:, :] = 0.0
    k = 0
    Va = nodal.volume[a]
    for q in range(nodal.node_ptr[a], nodal.node_ptr[a + 1]):
        t = nodal.node_tets[q]
        _deformation(x, el, t, B, Fe)
        c = 0.25 * el.volume[t] / Va
        for r in range(3):
            for cc in range(3):
                F[r, cc] += c * Fe[r, cc]
        for j in range(4):
            i = el.tets[t, j]
            k = _patch_slot(local, patch, w, i, k)
            for cc in range(3):
                w[local[i], cc] += c * B[j, cc]
    _clear_slots(local, patch, k)
    return k


@njit(cache=True, nogil=True)
def _unit_deviatoric(F, C):
    """psi(F) and the factor s of its stress dpsi/dF = F + s cof F (C: cof F, filled here)."""
    J = _cofactor(F, C)
    ic = 0.0
    for r in range(3):
        for c in range(3):
            ic += F[r, c] * F[r, c]
    return 0.5 * (ic - 3.0) - (J - 1.0) + (J - 1.0) ** 2 / 6.0, (J - 1.0) / 3.0 - 1.0


@njit(cache=True, nogil=True)
def _scratch(nodal):
    most = 0
    for a in range(nodal.volume.shape[0]):
        most = max(most, nodal.node_ptr[a + 1] - nodal.node_ptr[a])
    return np.full(nodal.volume.shape[0], -1, np.int64), np.empty(4 * most, np.int64), np.empty((4 * most, 3))


@njit(cache=True, nogil=True)
def smoothed_energy(x, el, nodal):
    """W_s (N mm)."""
    local, patch, w = _scratch(nodal)
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    total = 0.0
    for a in range(nodal.volume.shape[0]):
        if nodal.volume[a] <= 0.0:
            continue
        _smoothed_deformation(x, el, nodal, a, local, patch, w, F)
        total += nodal.shear[a] * _unit_deviatoric(F, C)[0]
    return nodal.smoothing * total


@njit(cache=True, nogil=True)
def smoothed_forces(x, el, nodal, out):
    """out (n, 3) -= dW_s/dx."""
    local, patch, w = _scratch(nodal)
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    for a in range(nodal.volume.shape[0]):
        if nodal.volume[a] <= 0.0:
            continue
        k = _smoothed_deformation(x, el, nodal, a, local, patch, w, F)
        s = _unit_deviatoric(F, C)[1]
        g = nodal.smoothing * nodal.shear[a]
        for p in range(k):
            for r in range(3):
                acc = 0.0
                for c in range(3):
                    acc += (F[r, c] + s * C[r, c]) * w[p, c]
                out[patch[p], r] -= g * acc


@njit(cache=True, nogil=True)
def _unit_stress_hessian(F, C, s, HF):
    """d2psi/dF2 (9, 9) (index 3 r + c): I + cof (x) cof / 3 + s d2J/dF2."""
    for p in range(9):
        for q in range(9):
            HF[p, q] = C[p // 3, p % 3] * C[q // 3, q % 3] / 3.0
        HF[p, p] += 1.0
    add_det_hessian(F, s, HF)


@njit(cache=True, nogil=True)
def smoothed_hessian(x, el, nodal, pattern, project, data):
    """data += d2W_s/dx2 into the CSR values of the two-ring pattern; each node's 9x9 d2psi/dF2
    projected to positive semi-definite where ``project``."""
    local, patch, w = _scratch(nodal)
    F = np.empty((3, 3))
    C = np.empty((3, 3))
    HF = np.empty((9, 9))
    Hb = np.empty((3, 3))
    for a in range(nodal.volume.shape[0]):
        if nodal.volume[a] <= 0.0:
            continue
        k = _smoothed_deformation(x, el, nodal, a, local, patch, w, F)
        s = _unit_deviatoric(F, C)[1]
        _unit_stress_hessian(F, C, s, HF)
        project_hf(F, 1.0, 1.0 / 3.0, s, project, HF)
        g = nodal.smoothing * nodal.shear[a]
        for p in range(k):
            for q in range(k):
                for r in range(3):
                    for t_ in range(3):
                        acc = 0.0
                        for c in range(3):
                            for d in range(3):
                                acc += w[p, c] * HF[3 * r + c, 3 * t_ + d] * w[q, d]
                        Hb[r, t_] = g * acc
                _add_block(pattern, patch[p], patch[q], Hb, data)
