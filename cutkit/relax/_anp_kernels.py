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
from numba import njit, prange

from cutkit.relax._elastic_kernels import barrier
from cutkit.relax._eigen_kernels import _cofactor
from cutkit.relax._newton_kernels import (ASSEMBLY_CHUNK, _deformation, add_det_hessian, add_element_blocks,
                                          gradient_operator, project_hf)

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
#: The patches' members (:func:`patch_members`): ``member_ptr`` (P + 1,) int64 into
#: ``member_node`` (S,) int64, the distinct nodes of each patch in the order its tets meet them,
#: ``member_patch`` (S,) int64, ``tet_slot`` (4m, 4) int64, the member (from ``member_ptr[a]``) of
#: each corner of each of the patch's tets (as ``node_tets``), and ``row_ptr`` (n + 1,) int64 into
#: ``row_member`` (S,) int64, the members that are node i, by patch: what node i's row gathers.
NodalTerms = namedtuple("NodalTerms", ["volume", "bulk", "node_ptr", "node_tets", "node_corner", "shear",
                                       "smoothing", "share", "pressure_volume", "patch", "member_ptr",
                                       "member_node", "member_patch", "tet_slot", "row_ptr", "row_member"])

#: Fixed count of parallel blocks of the patch and row kernels: every sum is made by one block in
#: a fixed order, so no result depends on the number of threads.
PATCH_BLOCKS = 64


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


def energy(x, el, nodal):
    """W (N mm): the elements' deviatoric energy and barrier, the nodal volumetric energy and the
    smoothed deviatoric energy."""
    total = element_energy(x, el, nodal)
    if nodal.smoothing > 0.0:
        total += smoothed_energy(x, el, nodal)
    return total


@njit(cache=True, nogil=True)
def element_energy(x, el, nodal):
    """The elements' deviatoric energy and barrier plus the nodal volumetric energy (N mm)."""
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
    return total


@njit(cache=True, nogil=True)
def _element_pressure(el, nodal, t, pi):
    """p_e = sum_a share_ea pi_a: the mean of the four nodal pressures where no corner is held."""
    p = 0.0
    for a in range(4):
        p += nodal.share[t, a] * pi[nodal.patch[t, a]]
    return p


def forces(x, el, nodal, out):
    """-dW/dx (N) into out (n, 3) (zeroed here)."""
    element_forces(x, el, nodal, out)
    if nodal.smoothing > 0.0:
        smoothed_forces(x, el, nodal, out)


@njit(cache=True, nogil=True)
def element_forces(x, el, nodal, out):
    """-dW/dx (N) of the elements' and the nodal volumetric part into out (n, 3) (zeroed here)."""
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


# ---------------------------------------------------------------- the patches and their members
@njit(cache=True, nogil=True)
def _corner_ptr(table, live, count):
    """(count + 1,) int64: where each key's corners start when the corners of the live elements
    ``live`` (k,) are sorted by their key in ``table`` (m, 4) int64 (keys below ``count``)."""
    ptr = np.zeros(count + 1, np.int64)
    for q in range(live.shape[0]):
        for j in range(4):
            ptr[table[live[q], j] + 1] += 1
    for a in range(count):
        ptr[a + 1] += ptr[a]
    return ptr


@njit(cache=True, nogil=True)
def corner_patches(tets, live, material, n):
    """The patch of every live element corner (see ``cutkit.relax.anp.material_patches``).

    ``live`` (k,) int64: the active elements; ``material`` (k,) int64 their materials, numbered in
    the order of (mu, lam).  Returns patch (m, 4) int64 (inactive rows: their nodes) and the count
    of patches."""
    patch = tets.copy()
    ptr = _corner_ptr(tets, live, n)
    fill = ptr[:n].copy()
    kinds = np.empty(ptr[n], np.int64)  # each node's corners' materials, then its distinct ones
    for q in range(live.shape[0]):
        for j in range(4):
            i = tets[live[q], j]
            kinds[fill[i]] = material[q]
            fill[i] += 1
    ids = np.empty(ptr[n], np.int64)
    count = n
    for i in range(n):
        lo, k = ptr[i], 0
        for e in range(ptr[i], ptr[i + 1]):  # distinct materials, ascending (insertion)
            mat = kinds[e]
            pos = lo + k
            while pos > lo and kinds[pos - 1] > mat:
                pos -= 1
            if pos > lo and kinds[pos - 1] == mat:
                continue
            for f in range(lo + k, pos, -1):
                kinds[f] = kinds[f - 1]
            kinds[pos] = mat
            k += 1
        fill[i] = k
        for f in range(k):
            ids[lo + f] = i if f == 0 else count + f - 1
        count += max(k - 1, 0)
    for q in range(live.shape[0]):
        for j in range(4):
            i = tets[live[q], j]
            for f in range(ptr[i], ptr[i] + fill[i]):
                if kinds[f] == material[q]:
                    patch[live[q], j] = ids[f]
                    break
    return patch, count


@njit(cache=True, nogil=True)
def patch_tets(patch, live, count):
    """Each patch's tets: ptr (count + 1,) int64 into node_tets (4k,) int64 with the patch's corner
    in node_corner (4k,) int64, in the order of the live elements (a stable counting sort)."""
    ptr = _corner_ptr(patch, live, count)
    fill = ptr[:count].copy()
    node_tets = np.empty(ptr[count], np.int64)
    node_corner = np.empty(ptr[count], np.int64)
    for q in range(live.shape[0]):
        for j in range(4):
            a = patch[live[q], j]
            node_tets[fill[a]] = live[q]
            node_corner[fill[a]] = j
            fill[a] += 1
    return ptr, node_tets, node_corner


# ---------------------------------------------------------------- the patches' members
@njit(cache=True, nogil=True)
def patch_members(tets, node_ptr, node_tets, n):
    """The members of every patch and the rows that gather them (the layout ``NodalTerms`` keeps).

    Returns member_ptr (P + 1,), member_node (S,), member_patch (S,), tet_slot (4m, 4),
    row_ptr (n + 1,), row_member (S,), all int64 (see :data:`NodalTerms`)."""
    P = node_ptr.shape[0] - 1
    local = np.full(n, -1, np.int64)
    member_ptr = np.zeros(P + 1, np.int64)
    nodes = np.empty(4 * node_tets.shape[0], np.int64)
    tet_slot = np.empty((node_tets.shape[0], 4), np.int64)
    S = 0
    for a in range(P):
        k = 0
        for q in range(node_ptr[a], node_ptr[a + 1]):
            for j in range(4):
                i = tets[node_tets[q], j]
                if local[i] < 0:
                    local[i] = k
                    nodes[S + k] = i
                    k += 1
                tet_slot[q, j] = local[i]
        for p in range(S, S + k):
            local[nodes[p]] = -1
        S += k
        member_ptr[a + 1] = S
    member_node = nodes[:S].copy()
    member_patch = np.empty(S, np.int64)
    row_ptr = np.zeros(n + 1, np.int64)
    for a in range(P):
        for s in range(member_ptr[a], member_ptr[a + 1]):
            member_patch[s] = a
            row_ptr[member_node[s] + 1] += 1
    for i in range(n):
        row_ptr[i + 1] += row_ptr[i]
    fill = row_ptr[:n].copy()
    row_member = np.empty(S, np.int64)
    for s in range(S):  # by member, so each row's members are in patch order
        i = member_node[s]
        row_member[fill[i]] = s
        fill[i] += 1
    return member_ptr, member_node, member_patch, tet_slot, row_ptr, row_member


@njit(cache=True, nogil=True, parallel=True)
def tet_deformations(x, el, Fe):
    """Fe (m, 3, 3) = F of every active element (inactive ones are not written)."""
    m = el.tets.shape[0]
    for b in prange(PATCH_BLOCKS):
        B = np.empty((4, 3))
        for t in range(m * b // PATCH_BLOCKS, m * (b + 1) // PATCH_BLOCKS):
            if el.volume[t] > 0.0:
                _deformation(x, el, t, B, Fe[t])


@njit(cache=True, nogil=True)
def _nodal_gradient(el, nodal, Fe, a, B, C, g):
    """g (S, 3) at patch a's members: g_a = dv_a/dx = sum_{e ni a} share_ea V_e cof(F_e) b_j, from
    Fe (m, 3, 3) (:func:`tet_deformations`); zero without pressure volume."""
    first = nodal.member_ptr[a]
    g[first:nodal.member_ptr[a + 1]] = 0.0
    if nodal.pressure_volume[a] <= 0.0:
        return
    for q in range(nodal.node_ptr[a], nodal.node_ptr[a + 1]):
        t = nodal.node_tets[q]
        gradient_operator(el, t, B)
        _cofactor(Fe[t], C)
        w = nodal.share[t, nodal.node_corner[q]] * el.volume[t]
        for j in range(4):
            s = first + nodal.tet_slot[q, j]
            for r in range(3):
                acc = 0.0
                for c in range(3):
                    acc += C[r, c] * B[j, c]
                g[s, r] += w * acc


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
# so W_s has ANP's two-ring stencil.  Each patch's Fs_a and w are made by one block, and each
# node's force and Hessian row gather its patches in patch order: the sums are those of a
# serial loop over the patches, whatever the thread count.


@njit(cache=True, nogil=True, parallel=True)
def smoothed_deformations(el, nodal, Fe, Fs, w):
    """Fs (P, 3, 3) = Fs_a and w (S, 3) the weights of its members, from Fe (m, 3, 3)
    (:func:`tet_deformations`); patches without volume get zeros."""
    P = nodal.volume.shape[0]
    for b in prange(PATCH_BLOCKS):
        B = np.empty((4, 3))
        for a in range(P * b // PATCH_BLOCKS, P * (b + 1) // PATCH_BLOCKS):
            first = nodal.member_ptr[a]
            Fs[a] = 0.0
            w[first:nodal.member_ptr[a + 1]] = 0.0
            Va = nodal.volume[a]
            if Va <= 0.0:
                continue
            for q in range(nodal.node_ptr[a], nodal.node_ptr[a + 1]):
                t = nodal.node_tets[q]
                c = 0.25 * el.volume[t] / Va
                for r in range(3):
                    for cc in range(3):
                        Fs[a, r, cc] += c * Fe[t, r, cc]
                gradient_operator(el, t, B)
                for j in range(4):
                    s = first + nodal.tet_slot[q, j]
                    for cc in range(3):
                        w[s, cc] += c * B[j, cc]


@njit(cache=True, nogil=True)
def _unit_deviatoric(F, C):
    """psi(F) and the factor s of its stress dpsi/dF = F + s cof F (C: cof F, filled here)."""
    J = _cofactor(F, C)
    ic = 0.0
    for r in range(3):
        for c in range(3):
            ic += F[r, c] * F[r, c]
    return 0.5 * (ic - 3.0) - (J - 1.0) + (J - 1.0) ** 2 / 6.0, (J - 1.0) / 3.0 - 1.0


def _smoothed_state(x, el, nodal):
    """(Fs (P, 3, 3), w (S, 3)) at x."""
    Fe = np.empty((el.tets.shape[0], 3, 3))
    tet_deformations(x, el, Fe)
    Fs = np.empty((nodal.volume.shape[0], 3, 3))
    w = np.empty((nodal.member_node.shape[0], 3))
    smoothed_deformations(el, nodal, Fe, Fs, w)
    return Fs, w


@njit(cache=True, nogil=True)
def _smoothed_energy_sum(nodal, Fs):
    """alpha sum_a G_a psi(Fs_a), over the patches in order."""
    C = np.empty((3, 3))
    total = 0.0
    for a in range(nodal.volume.shape[0]):
        if nodal.volume[a] > 0.0:
            total += nodal.shear[a] * _unit_deviatoric(Fs[a], C)[0]
    return nodal.smoothing * total


def smoothed_energy(x, el, nodal):
    """W_s (N mm)."""
    return _smoothed_energy_sum(nodal, _smoothed_state(x, el, nodal)[0])


@njit(cache=True, nogil=True)
def _patch_stress(nodal, Fs):
    """Fs (P, 3, 3) overwritten with the unit stress dpsi/dF = Fs + s cof Fs of each patch."""
    C = np.empty((3, 3))
    for a in range(nodal.volume.shape[0]):
        if nodal.volume[a] <= 0.0:
            continue
        s = _unit_deviatoric(Fs[a], C)[1]
        for r in range(3):
            for c in range(3):
                Fs[a, r, c] = Fs[a, r, c] + s * C[r, c]


@njit(cache=True, nogil=True, parallel=True)
def _gather_smoothed_forces(nodal, stress, w, out):
    """out (n, 3) -= dW_s/dx, each node gathering its patches in order."""
    n = out.shape[0]
    for b in prange(PATCH_BLOCKS):
        for i in range(n * b // PATCH_BLOCKS, n * (b + 1) // PATCH_BLOCKS):
            for e in range(nodal.row_ptr[i], nodal.row_ptr[i + 1]):
                s = nodal.row_member[e]
                a = nodal.member_patch[s]
                if nodal.volume[a] <= 0.0:
                    continue
                g = nodal.smoothing * nodal.shear[a]
                for r in range(3):
                    acc = 0.0
                    for c in range(3):
                        acc += stress[a, r, c] * w[s, c]
                    out[i, r] -= g * acc


def smoothed_forces(x, el, nodal, out):
    """out (n, 3) -= dW_s/dx."""
    Fs, w = _smoothed_state(x, el, nodal)
    _patch_stress(nodal, Fs)
    _gather_smoothed_forces(nodal, Fs, w, out)


@njit(cache=True, nogil=True)
def _unit_stress_hessian(F, C, s, HF):
    """d2psi/dF2 (9, 9) (index 3 r + c): I + cof (x) cof / 3 + s d2J/dF2."""
    for p in range(9):
        for q in range(9):
            HF[p, q] = C[p // 3, p % 3] * C[q // 3, q % 3] / 3.0
        HF[p, p] += 1.0
    add_det_hessian(F, s, HF)


@njit(cache=True, nogil=True, parallel=True)
def patch_hessian_terms(el, nodal, Fe, Fs, project, g, HF):
    """Per patch, in :data:`PATCH_BLOCKS` parallel blocks: the nodal gradients g (S, 3)
    (:func:`_nodal_gradient`) and HF (P, 9, 9) = d2psi/dF2 at Fs_a, projected to positive
    semi-definite where ``project`` (zeros without volume or smoothing)."""
    P = nodal.volume.shape[0]
    for b in prange(PATCH_BLOCKS):
        B = np.empty((4, 3))
        C = np.empty((3, 3))
        for a in range(P * b // PATCH_BLOCKS, P * (b + 1) // PATCH_BLOCKS):
            _nodal_gradient(el, nodal, Fe, a, B, C, g)
            if nodal.volume[a] <= 0.0 or nodal.smoothing <= 0.0:
                HF[a] = 0.0
                continue
            s = _unit_deviatoric(Fs[a], C)[1]
            _unit_stress_hessian(Fs[a], C, s, HF[a])
            project_hf(Fs[a], 1.0, 1.0 / 3.0, s, project, HF[a])


PatchHessian = namedtuple("PatchHessian", ["bulk", "g", "HF", "w"])
PatchHessian.__doc__ = """What the patches add to the Hessian: ``bulk`` (P,) kv_a / V_a^2 (0 without
pressure volume), ``g`` (S, 3) the nodal gradients, ``HF`` (P, 9, 9) the smoothed stress
Hessians and ``w`` (S, 3) the smoothed weights (:func:`smoothed_deformations`)."""


@njit(cache=True, nogil=True)
def _add_nodal_row(nodal, ph, s, col, base_row, deg, data):
    """Add member s's block row kv_a/V_a^2 g_s g_q^T of its patch a (every member q) into its
    node's CSR row (``col``: each column's block, ``base_row`` = 9 ptr[i], ``deg`` its blocks)."""
    a = nodal.member_patch[s]
    ca = ph.bulk[a]
    for q in range(nodal.member_ptr[a], nodal.member_ptr[a + 1]):
        base = base_row + 3 * col[nodal.member_node[q]]
        for r in range(3):
            for t in range(3):
                data[base + 3 * r * deg + t] += ca * ph.g[s, r] * ph.g[q, t]


@njit(cache=True, nogil=True)
def _add_smoothed_row(nodal, ph, s, col, base_row, deg, Y, data):
    """Add member s's block row alpha G_a w_s^T HF_a w_q of its patch a (every member q)."""
    a = nodal.member_patch[s]
    g = nodal.smoothing * nodal.shear[a]
    for r in range(3):
        for c in range(3):
            for td in range(9):
                Y[r, c, td] = ph.w[s, c] * ph.HF[a, 3 * r + c, td]
    for q in range(nodal.member_ptr[a], nodal.member_ptr[a + 1]):
        base = base_row + 3 * col[nodal.member_node[q]]
        for r in range(3):
            for t in range(3):
                acc = 0.0
                for c in range(3):
                    for d in range(3):
                        acc += Y[r, c, 3 * t + d] * ph.w[q, d]
                data[base + 3 * r * deg + t] += g * acc


@njit(cache=True, nogil=True, parallel=True)
def add_patch_rows(nodal, ph, pattern, data):
    """data += the patches' part of the Hessian, each node's row gathering its patches in order:
    the nodal terms of every patch, then the smoothed terms (a serial loop's sums)."""
    n = pattern.node_ptr.shape[0] - 1
    for b in prange(PATCH_BLOCKS):
        col = np.zeros(n, np.int64)
        Y = np.empty((3, 3, 9))
        for i in range(n * b // PATCH_BLOCKS, n * (b + 1) // PATCH_BLOCKS):
            lo, hi = pattern.node_ptr[i], pattern.node_ptr[i + 1]
            for k in range(lo, hi):
                col[pattern.node_idx[k]] = k - lo
            for e in range(nodal.row_ptr[i], nodal.row_ptr[i + 1]):
                if nodal.pressure_volume[nodal.member_patch[nodal.row_member[e]]] > 0.0:
                    _add_nodal_row(nodal, ph, nodal.row_member[e], col, 9 * lo, hi - lo, data)
            if nodal.smoothing <= 0.0:
                continue
            for e in range(nodal.row_ptr[i], nodal.row_ptr[i + 1]):
                if nodal.volume[nodal.member_patch[nodal.row_member[e]]] > 0.0:
                    _add_smoothed_row(nodal, ph, nodal.row_member[e], col, 9 * lo, hi - lo, Y, data)


@njit(cache=True, nogil=True)
def _patch_bulk(nodal, bulk):
    """bulk (P,) = kv_a / V_a^2, the weight of g_a g_a^T (0 without pressure volume)."""
    for a in range(nodal.volume.shape[0]):
        Va = nodal.pressure_volume[a]
        bulk[a] = nodal.bulk[a] / (Va * Va) if Va > 0.0 else 0.0


@njit(cache=True, nogil=True, parallel=True)
def element_hessians(x, el, nodal, pi, first, project, H):
    """H (k, 12, 12): the element parts of elements ``first .. first + k - 1`` (inactive ones are
    not written), their average nodal pressures from pi (P,)."""
    k = H.shape[0]
    keep = 1.0 - nodal.smoothing
    for b in prange(PATCH_BLOCKS):
        for q in range(k * b // PATCH_BLOCKS, k * (b + 1) // PATCH_BLOCKS):
            t = first + q
            if el.volume[t] > 0.0:
                element_hessian(x, el, t, _element_pressure(el, nodal, t, pi), keep, project, H[q])


def assemble_hessian(x, el, nodal, pattern, project, data):
    """The ANP Hessian (element parts, projected where ``project``, the nodal rank-one parts and the
    smoothed deviatoric part) into the CSR ``data`` (zeroed here) of a pattern that holds every
    patch pair (``cutkit.relax.anp.anp_pattern``).  The element parts are made in parallel and
    added in element order (:func:`cutkit.relax._newton_kernels.add_element_blocks`), the
    patches' parts by node rows (:func:`add_patch_rows`): the same sums on any thread count."""
    data[:] = 0.0
    m = el.tets.shape[0]
    P = nodal.volume.shape[0]
    J = np.zeros(m)
    volume_ratios(x, el, J)
    pi = np.empty(P)
    nodal_pressures(el, J, nodal, pi)
    H = np.empty((min(ASSEMBLY_CHUNK, m), 12, 12))
    for first in range(0, m, ASSEMBLY_CHUNK):
        part = H[:min(ASSEMBLY_CHUNK, m - first)]
        element_hessians(x, el, nodal, pi, first, project, part)
        add_element_blocks(el, pattern, first, part, data)
    Fe = np.empty((m, 3, 3))
    tet_deformations(x, el, Fe)
    Fs = np.empty((P, 3, 3))
    w = np.empty((nodal.member_node.shape[0], 3))
    smoothed_deformations(el, nodal, Fe, Fs, w)
    g = np.empty_like(w)
    HF = np.empty((P, 9, 9))
    patch_hessian_terms(el, nodal, Fe, Fs, project, g, HF)
    bulk = np.empty(P)
    _patch_bulk(nodal, bulk)
    add_patch_rows(nodal, PatchHessian(bulk, g, HF, w), pattern, data)
