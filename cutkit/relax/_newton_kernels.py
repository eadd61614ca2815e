"""Numba kernels of the projected Newton solver (:mod:`cutkit.relax.newton`).

Per element, with ``F = sum_j x_j b_j^T`` (b_j the rows of the gradient
operator, ``_elastic_kernels.node_term_rows``) and ``J = det F``, the energy
``W = V (psi(F) + b(J))`` of :mod:`cutkit.relax._elastic_kernels` has

    dpsi/dF   = P = mu F + s cof F,          s = (lam + mu)(J - 1) - mu + b'(J)
    d2psi/dF2 = mu I_9 + (lam + mu + b''(J)) vec(cof F) vec(cof F)^T + s d2J/dF2,
    d2J/dF_ia dF_jb = eps_ijk eps_abc F_kc

(Smith, de Goes & Kim, *Stable Neo-Hookean Flesh Simulation*, 2018, eqs.
(13)-(19); Kim & Eberle, *Dynamic Deformables*, 2022, section 7.3).  The
9x9 Hessian is projected to the nearest positive semi-definite matrix by
clamping its negative eigenvalues to zero (Teran et al. 2005; Smith et al.
2018, section 4.3: projected Newton), found from its analytic eigensystem
(:mod:`cutkit.relax._eigen_kernels`; LAPACK's eigh is kept as the
reference, :data:`CLAMP_EIGH`), and mapped to the element's 12 dofs by
``dF/dx`` (``d F_rc / d x_j,s = delta_rs b_j,c``), which keeps it
semi-definite.

The global matrix has one 3x3 block per pair of nodes sharing an element.
It is stored as scalar CSR over all 3n dofs with the columns of node row i
laid out block by block: entry (3i + a, 3j + b) of the k-th block of node
row i (``node_ptr[i] <= k < node_ptr[i + 1]``) is at
``9 node_ptr[i] + 3 a deg_i + 3 (k - node_ptr[i]) + b`` (``deg_i`` blocks
in the row), so the kernels write each element's blocks straight into the
matrix's data.  The kernels check nothing (:mod:`cutkit.relax.newton` does).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

from cutkit.relax._eigen_kernels import _cofactor, project_stress_hessian
from cutkit.relax._elastic_kernels import STOP_EVERY, barrier
from cutkit.relax._stop_flag import flag_up

#: The sparsity pattern of the global matrix: node rows ``node_ptr`` (n + 1,) int64 and their
#: sorted block columns ``node_idx`` (nb,) int64; each element's 16 blocks ``element_blocks``
#: (m, 4, 4) int64 (index into node_idx, -1 for an inactive element); the scalar CSR
#: ``indptr`` (3n + 1,) and ``indices`` (9 nb,), int32 (scipy's and cholespy's own index type, so
#: neither copies them; int64 past 2^31 - 1 entries), and the diagonal's positions ``diagonal``
#: (3n,) int64.
Pattern = namedtuple("Pattern", ["node_ptr", "node_idx", "element_blocks", "indptr", "indices", "diagonal"])


@njit(cache=True, nogil=True, inline="always")
def _levi(i, j):
    """eps_ijk for distinct i, j (k = 3 - i - j): +1 for an even permutation."""
    return 1.0 if (j - i) % 3 == 1 else -1.0


@njit(cache=True, nogil=True, inline="always")
def add_det_hessian(F, s, HF):
    """HF (9, 9) (index 3 r + c) += s d2J/dF2, J = det F: the entry (3 i + a, 3 j + b) of d2J/dF2 is
    eps_ijk eps_abc F_kc, zero for i = j or a = b."""
    for i in range(3):
        for j in range(3):
            if i == j:
                continue
            for a in range(3):
                for b in range(3):
                    if a == b:
                        continue
                    HF[3 * i + a, 3 * j + b] += s * _levi(i, j) * _levi(a, b) * F[3 - i - j, 3 - a - b]


@njit(cache=True, nogil=True, inline="always")
def gradient_operator(el, t, B):
    """Fill B (4, 3) with the rows b_j of the gradient operator of element t (F = sum x_j b_j^T)."""
    D = el.Dminv[t]
    for c in range(3):
        B[0, c] = -(D[0, c] + D[1, c] + D[2, c])
        B[1, c] = D[0, c]
        B[2, c] = D[1, c]
        B[3, c] = D[2, c]


@njit(cache=True, nogil=True)
def _deformation(x, el, t, B, F):
    """Fill B (4, 3) with the rows of the gradient operator of element t and F (3, 3) = sum x_j b_j^T."""
    gradient_operator(el, t, B)
    for r in range(3):
        for c in range(3):
            acc = 0.0
            for j in range(4):
                acc += x[el.tets[t, j], r] * B[j, c]
            F[r, c] = acc


@njit(cache=True, nogil=True)
def _positive_definite(A):
    """Whether the symmetric (9, 9) A has a Cholesky factor (it then needs no projection; a
    test costs about a tenth of the eigen-decomposition it saves)."""
    return _positive_definite_in(A, np.empty((9, 9)))


@njit(cache=True, nogil=True)
def _positive_definite_in(A, L):
    """:func:`_positive_definite` with the factor's scratch L (9, 9)."""
    for j in range(9):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, 9):
            v = A[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / L[j, j]
    return True


#: Scratch of one element's gradient and Hessian (:func:`hessian_scratch`), kept by a parallel
#: block across its elements: a (4, 3) gradient operator B, F, P and cof F (3, 3), HF (9, 9),
#: the Cholesky test's L (9, 9) and the product M (9, 12).  Allocating them per element cost
#: about a fifth of an assembly.
HessianScratch = namedtuple("HessianScratch", "B F P C HF L M")


@njit(cache=True, nogil=True)
def hessian_scratch():
    """A fresh :data:`HessianScratch`."""
    return HessianScratch(np.empty((4, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)),
                          np.empty((9, 9)), np.empty((9, 9)), np.empty((9, 12)))


#: ``project`` codes of the kernels: the exact d2psi/dF2; its negative eigenvalues clamped to
#: zero (projected Newton) or replaced by their absolute values, from the analytic eigensystem
#: (:func:`cutkit.relax._eigen_kernels.project_stress_hessian`); the same two from LAPACK's 9x9
#: ``eigh`` (the reference the analytic ones are tested against).
EXACT, CLAMP, ABSOLUTE, CLAMP_EIGH, ABSOLUTE_EIGH = 0, 1, 2, 3, 4


@njit(cache=True, nogil=True)
def _project_eigh(HF, factor):
    """Clamp (factor 1) or reflect (2) the negative eigenvalues of HF by LAPACK's eigh; a HF with
    a Cholesky factor is positive definite already and is left as it is."""
    if _positive_definite(HF):
        return
    lam_, Q = np.linalg.eigh(HF)
    if lam_[0] >= 0.0:
        return
    for p in range(9):
        for q in range(9):
            acc = 0.0
            for e in range(9):
                acc += Q[p, e] * (abs(lam_[e]) if factor == 2 else max(lam_[e], 0.0)) * Q[q, e]
            HF[p, q] = acc


@njit(cache=True, nogil=True)
def stress_hessian(F, mu, lam, project, P, HF):
    """First Piola stress P (3, 3) and d2psi/dF2 HF (9, 9) (index 3 r + c) of one element.

    ``project`` (:data:`EXACT` ... :data:`ABSOLUTE_EIGH`): with :data:`CLAMP` the negative
    eigenvalues of HF are clamped to zero (projected Newton, Smith et al. 2018 section 4.3)
    through the analytic eigensystem, with :data:`CLAMP_EIGH` through LAPACK's eigh; a HF
    without a negative eigenvalue is left as it is either way, and one with a Cholesky factor
    is not decomposed at all (on the knee most elements: the test costs a fifth of the
    analytic eigensystem).
    """
    return stress_hessian_in(F, mu, lam, project, P, HF, np.empty((3, 3)), np.empty((9, 9)))


@njit(cache=True, nogil=True)
def stress_hessian_in(F, mu, lam, project, P, HF, C, L):
    """:func:`stress_hessian` with the scratch cof F ``C`` (3, 3) and the Cholesky test's ``L`` (9, 9)."""
    J = _cofactor(F, C)
    k = lam + mu
    _, db, ddb = barrier(J, k)
    s = k * (J - 1.0) - mu + db
    w = k + ddb
    for r in range(3):
        for c in range(3):
            P[r, c] = mu * F[r, c] + s * C[r, c]
    for p in range(9):
        for q in range(9):
            HF[p, q] = w * C[p // 3, p % 3] * C[q // 3, q % 3]
        HF[p, p] += mu
    add_det_hessian(F, s, HF)
    project_hf_in(F, mu, w, s, project, HF, L)
    return J


@njit(cache=True, nogil=True)
def project_hf(F, mu, w, s, project, HF):
    """Project HF = mu I + w vec(cof F) vec(cof F)^T + s d2J/dF2 (9, 9) in place as ``project`` says
    (:data:`EXACT` ... :data:`ABSOLUTE_EIGH`); one with a Cholesky factor is left as it is."""
    project_hf_in(F, mu, w, s, project, HF, np.empty((9, 9)))


@njit(cache=True, nogil=True)
def project_hf_in(F, mu, w, s, project, HF, L):
    """:func:`project_hf` with the Cholesky test's scratch ``L`` (9, 9)."""
    if (project == CLAMP or project == ABSOLUTE) and not _positive_definite_in(HF, L):
        project_stress_hessian(F, mu, w, s, float(project), HF)
    elif project == CLAMP_EIGH or project == ABSOLUTE_EIGH:
        _project_eigh(HF, project - 2)


@njit(cache=True, nogil=True)
def element_gradient_hessian(x, el, t, project, g, H):
    """Gradient g (12,) and Hessian H (12, 12) (dof 3 j + s) of element t's energy W = V (psi + b).

    ``dW/dx_j,s = V sum_c P_sc b_j,c`` and ``d2W/dx_j,s dx_k,t = V sum_cq HF[3s+c, 3t+q] b_j,c b_k,q``.
    """
    element_gradient_hessian_in(x, el, t, project, g, H, hessian_scratch())


@njit(cache=True, nogil=True)
def element_gradient_hessian_in(x, el, t, project, g, H, sc):
    """:func:`element_gradient_hessian` in the scratch ``sc`` (:data:`HessianScratch`)."""
    B, F, P, HF, M = sc.B, sc.F, sc.P, sc.HF, sc.M
    _deformation(x, el, t, B, F)
    V = el.volume[t]
    stress_hessian_in(F, el.mu[t], el.lam[t], project, P, HF, sc.C, sc.L)
    for j in range(4):
        for s_ in range(3):
            acc = 0.0
            for c in range(3):
                acc += P[s_, c] * B[j, c]
            g[3 * j + s_] = V * acc
    for p in range(9):  # M[3s + c, 3k + t] = sum_q HF[3s+c, 3t+q] b_k,q
        for kk in range(4):
            for t_ in range(3):
                acc = 0.0
                for q in range(3):
                    acc += HF[p, 3 * t_ + q] * B[kk, q]
                M[p, 3 * kk + t_] = acc
    for j in range(4):
        for s_ in range(3):
            for col in range(12):
                acc = 0.0
                for c in range(3):
                    acc += B[j, c] * M[3 * s_ + c, col]
                H[3 * j + s_, col] = V * acc


@njit(cache=True, nogil=True)
def element_terms(x, el, ids, project, grads, hessians):
    """Gradients (k, 12) and Hessians (k, 12, 12) of the elements ``ids`` (k,) (for tests)."""
    for q in range(ids.shape[0]):
        element_gradient_hessian(x, el, ids[q], project, grads[q], hessians[q])


#: Elements whose Hessians :func:`assemble_hessian` computes at once (in parallel) before adding
#: them into the matrix in element order: 4096 x 12 x 12 float64 is 4.7 MB of scratch.
ASSEMBLY_CHUNK = 4096
#: Parallel blocks of one chunk: a fixed count, so no sum depends on the number of threads.
ASSEMBLY_BLOCKS = 64


@njit(cache=True, parallel=True, nogil=True)
def element_hessians(x, el, first, project, H):
    """H (k, 12, 12): the (projected, ``project``) Hessians of elements ``first .. first + k - 1``
    (inactive ones are not written), computed in :data:`ASSEMBLY_BLOCKS` parallel blocks."""
    k = H.shape[0]
    for b in prange(ASSEMBLY_BLOCKS):
        g = np.empty(12)
        sc = hessian_scratch()
        for q in range(k * b // ASSEMBLY_BLOCKS, k * (b + 1) // ASSEMBLY_BLOCKS):
            if el.volume[first + q] > 0.0:
                element_gradient_hessian_in(x, el, first + q, project, g, H[q], sc)


@njit(cache=True, nogil=True)
def add_element_blocks(el, pattern, first, H, data):
    """Add the Hessians H (k, 12, 12) of elements ``first ..`` into the CSR ``data``, element by
    element (the order of the sums is the elements', whatever the thread count)."""
    ptr = pattern.node_ptr
    for q in range(H.shape[0]):
        t = first + q
        if el.volume[t] <= 0.0:
            continue
        for a in range(4):
            i = el.tets[t, a]
            deg = ptr[i + 1] - ptr[i]
            for b in range(4):
                k = pattern.element_blocks[t, a, b]
                base = 9 * ptr[i] + 3 * (k - ptr[i])
                for r in range(3):
                    for c in range(3):
                        data[base + 3 * r * deg + c] += H[q, 3 * a + r, 3 * b + c]


def assemble_hessian(x, el, pattern, project, data, halt=None):
    """The (projected) Hessian of the elastic energy into the CSR ``data`` (9 nb,) (zeroed here):
    :data:`ASSEMBLY_CHUNK` elements' Hessians at a time in parallel
    (:func:`element_hessians`), added in element order (:func:`add_element_blocks`).  ``halt``
    ((1,) int64, optional) is read before each chunk: non-zero ends the assembly, and the result
    is False (``data`` unfinished); True otherwise."""
    data[:] = 0.0
    m = el.tets.shape[0]
    H = np.empty((min(ASSEMBLY_CHUNK, m), 12, 12))
    for first in range(0, m, ASSEMBLY_CHUNK):
        if halt is not None and halt[0]:
            return False
        part = H[:min(ASSEMBLY_CHUNK, m - first)]
        element_hessians(x, el, first, project, part)
        add_element_blocks(el, pattern, first, part, data)
    return True


@njit(cache=True, nogil=True)
def constrain(pattern, fixed, diagonal_add, data):
    """Held dofs get an identity row and column; the others ``diagonal_add`` (3n,) on the diagonal
    (the inertia and damping of backward Euler, ``m / h^2 + c m / h``)."""
    n3 = fixed.shape[0]
    for row in range(n3):
        for p in range(pattern.indptr[row], pattern.indptr[row + 1]):
            if fixed[row] or fixed[pattern.indices[p]]:
                data[p] = 0.0
        d = pattern.diagonal[row]
        data[d] = 1.0 if fixed[row] else data[d] + diagonal_add[row]


@njit(cache=True, nogil=True, inline="always")
def sort_unique(row):
    """Sort ``row`` (k,) int64 in place and move its distinct values to the front; returns how many."""
    row.sort()
    u = 0
    for q in range(row.shape[0]):
        if q == 0 or row[q] != row[q - 1]:
            row[u] = row[q]
            u += 1
    return u


@njit(cache=True, nogil=True)
def gather_rows(tets, volume, rows, halt):
    """The raw node rows of the nodes ``rows`` (n,) bool marks: each is the node itself, then the
    four corners of every active element (``volume`` > 0) it is a corner of, in element order,
    repeats kept (``raw[start[i]:start[i + 1]]``; the other nodes' rows are empty).  ``halt`` is
    read every ``STOP_EVERY`` elements; returns (start (n + 1,), raw, whether whole)."""
    n, m = rows.shape[0], tets.shape[0]
    count = np.zeros(n, np.int64)
    for i in range(n):
        if rows[i]:
            count[i] = 1
    for t in range(m):
        if t % STOP_EVERY == 0 and flag_up(halt):
            return count, np.empty(0, np.int64), False
        if volume[t] > 0.0:
            for a in range(4):
                if rows[tets[t, a]]:
                    count[tets[t, a]] += 4
    start = np.zeros(n + 1, np.int64)
    for i in range(n):
        start[i + 1] = start[i] + count[i]
    raw = np.empty(start[n], np.int64)
    fill = start[:n].copy()
    for i in range(n):
        if rows[i]:
            raw[fill[i]] = i
            fill[i] += 1
    for t in range(m):
        if t % STOP_EVERY == 0 and flag_up(halt):
            return start, np.empty(0, np.int64), False
        if volume[t] > 0.0:
            for a in range(4):
                i = tets[t, a]
                if rows[i]:
                    for b in range(4):
                        raw[fill[i]] = tets[t, b]
                        fill[i] += 1
    return start, raw, True


@njit(cache=True, nogil=True, parallel=True)
def node_neighbours(tets, volume, n, halt):
    """Node rows of the pattern: ``node_ptr`` (n + 1,) and sorted ``node_idx``; every node has its
    own diagonal block, the others come from active elements.  ``halt`` ((1,) int64) is read
    every ``STOP_EVERY`` elements of a pass and before each row's sort: non-zero ends the build,
    and the third result (whether the rows are whole) is False."""
    start, raw, whole = gather_rows(tets, volume, np.ones(n, np.bool_), halt)
    if not whole:
        return start, raw, False
    unique = np.empty(n, np.int64)
    for i in prange(n):  # sort and drop repeats, in place (rows are independent)
        if flag_up(halt):
            continue
        unique[i] = sort_unique(raw[start[i]:start[i + 1]])
    if flag_up(halt):
        return start, np.empty(0, np.int64), False
    ptr = np.zeros(n + 1, np.int64)
    for i in range(n):
        ptr[i + 1] = ptr[i] + unique[i]
    idx = np.empty(ptr[n], np.int64)
    for i in prange(n):
        idx[ptr[i]:ptr[i + 1]] = raw[start[i]:start[i] + unique[i]]
    return ptr, idx, True


@njit(cache=True, nogil=True, parallel=True)
def element_blocks(tets, volume, ptr, idx, halt):
    """(m, 4, 4) int64: the block of (corner a, corner b) of each element in its node row (-1: inactive),
    and whether every element was done: ``halt`` ((1,) int64) is read before each element, and
    non-zero skips the rest (False)."""
    m = tets.shape[0]
    out = np.full((m, 4, 4), -1, np.int64)
    for t in prange(m):
        if volume[t] <= 0.0 or flag_up(halt):
            continue
        for a in range(4):
            i = tets[t, a]
            row = idx[ptr[i]:ptr[i + 1]]
            for b in range(4):
                out[t, a, b] = ptr[i] + np.searchsorted(row, tets[t, b])
    return out, not flag_up(halt)


def scalar_pattern(ptr, idx):
    """Scalar CSR ``indptr`` (3n + 1,), ``indices`` (9 nb,) (int32 where 9 nb fits, else int64: see
    :data:`Pattern`) and diagonal positions (3n,) int64 of the node pattern, columns sorted (see
    the module's layout)."""
    n = ptr.shape[0] - 1
    entries = 9 * int(ptr[n])
    index = np.int32 if max(entries, 3 * n) <= np.iinfo(np.int32).max else np.int64
    indptr, indices = np.zeros(3 * n + 1, index), np.empty(entries, index)
    diagonal = np.empty(3 * n, np.int64)
    _fill_scalar_pattern(ptr, idx, indptr, indices, diagonal)
    return indptr, indices, diagonal


@njit(cache=True, nogil=True)
def _fill_scalar_pattern(ptr, idx, indptr, indices, diagonal):
    """The kernel of :func:`scalar_pattern`: fills ``indptr``, ``indices`` and ``diagonal``."""
    n = ptr.shape[0] - 1
    for i in range(n):
        deg = ptr[i + 1] - ptr[i]
        for a in range(3):
            row = 3 * i + a
            base = 9 * ptr[i] + 3 * a * deg
            indptr[row + 1] = base + 3 * deg
            for k in range(deg):
                j = idx[ptr[i] + k]
                for b in range(3):
                    indices[base + 3 * k + b] = 3 * j + b
                if j == i:
                    diagonal[row] = base + 3 * k + a


@njit(cache=True, nogil=True)
def _det_columns(a0, a1, a2):
    """det [a0 a1 a2] of three column 3-vectors (a triple product)."""
    return (a0[0] * (a1[1] * a2[2] - a1[2] * a2[1]) - a1[0] * (a0[1] * a2[2] - a0[2] * a2[1])
            + a2[0] * (a0[1] * a1[2] - a0[2] * a1[1]))


@njit(cache=True, nogil=True)
def _cubic(c0, c1, c2, c3, a):
    return c0 + a * (c1 + a * (c2 + a * c3))


#: Bisections of the first root of a tet's volume along a step (2^-60: to rounding).
ROOT_BISECTIONS = 60


@njit(cache=True, nogil=True)
def first_root(c0, c1, c2, c3, a_max):
    """The smallest a in (0, a_max] with c0 + c1 a + c2 a^2 + c3 a^3 <= 0 (c0 > 0), or a_max + 1
    where there is none: the cubic is monotone between the roots of its derivative, so each
    such piece is checked at its end and bisected where it changes sign."""
    ends = np.empty(3)
    ne = 0
    # roots of 3 c3 a^2 + 2 c2 a + c1 in (0, a_max)
    qa, qb, qc = 3.0 * c3, 2.0 * c2, c1
    if qa != 0.0:
        disc = qb * qb - 4.0 * qa * qc
        if disc >= 0.0:
            sq = np.sqrt(disc)
            for r in ((-qb - sq) / (2.0 * qa), (-qb + sq) / (2.0 * qa)):
                if 0.0 < r < a_max:
                    ends[ne] = r
                    ne += 1
    elif qb != 0.0:
        r = -qc / qb
        if 0.0 < r < a_max:
            ends[ne] = r
            ne += 1
    ends[ne] = a_max
    ne += 1
    ends[:ne].sort()
    lo = 0.0
    for e in range(ne):
        hi = ends[e]
        if _cubic(c0, c1, c2, c3, hi) <= 0.0:
            for _ in range(ROOT_BISECTIONS):
                mid = 0.5 * (lo + hi)
                if _cubic(c0, c1, c2, c3, mid) > 0.0:
                    lo = mid
                else:
                    hi = mid
            return hi
        lo = hi
    return a_max + 1.0


@njit(cache=True, parallel=True, nogil=True)
def step_bound(x, d, el, a_max):
    """The smallest a in (0, a_max] at which an element with det Ds > 0 reaches det Ds = 0 along
    x + a d (a_max + 1: none does).  det(A + a B) is a cubic in a with coefficients from
    A's and B's columns (multilinearity of the determinant); inverted and inactive elements
    are not held back."""
    m = el.tets.shape[0]
    best = np.full(m, a_max + 1.0)
    for t in prange(m):
        if el.volume[t] <= 0.0:
            continue
        A = np.empty((3, 3))
        Bm = np.empty((3, 3))
        i0 = el.tets[t, 0]
        for j in range(3):
            i = el.tets[t, j + 1]
            for r in range(3):
                A[j, r] = x[i, r] - x[i0, r]
                Bm[j, r] = d[i, r] - d[i0, r]
        c0 = _det_columns(A[0], A[1], A[2])
        if c0 <= 0.0:
            continue
        c1 = _det_columns(Bm[0], A[1], A[2]) + _det_columns(A[0], Bm[1], A[2]) + _det_columns(A[0], A[1], Bm[2])
        c2 = _det_columns(A[0], Bm[1], Bm[2]) + _det_columns(Bm[0], A[1], Bm[2]) + _det_columns(Bm[0], Bm[1], A[2])
        c3 = _det_columns(Bm[0], Bm[1], Bm[2])
        best[t] = first_root(c0, c1, c2, c3, a_max)
    return best.min() if m else a_max + 1.0
