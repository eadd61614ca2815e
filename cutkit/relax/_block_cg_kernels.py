"""Numba kernels of the block-Jacobi conjugate gradients of the Newton solver.

The Newton matrix (:mod:`cutkit.relax._newton_kernels`' scalar CSR) is
symmetric with one 3 x 3 block per pair of nodes sharing an element.  The
conjugate gradients read it as :class:`BlockMatrix`: each node's diagonal
block and the blocks above the diagonal (node j > i) of each node row, each
off-diagonal block used twice in a product (``y_i += A_ij p_j``,
``y_j += A_ij^T p_i``).  That reads a third of the bytes the scalar CSR
product reads (its int64 column of every entry and both triangles), which
is what bounds a product: on the knee's 88k x 88k settle system 1.3 ms
against scipy's 2.8 ms on one core, and a CG solve to 1e-2 0.14 s against
0.32 s with the same iterations (``benchmarks/newton_linear.py --json
--knee knee.h5``: ``block_spmv_ms``, ``spmv_ms``, ``cg``).

On one thread a product scatters each block above the diagonal into both
its rows (:func:`block_product`); on more it runs row by row in parallel
(:func:`block_product_rows`), each row reading the blocks left of its
diagonal through :func:`lower_blocks`' index, which reads those blocks a
second time but writes no row of another thread.  Both add every row's
terms in the same order (its diagonal block, the blocks left of it by
column, then the sum of those right of it), so the two products are the
same to the bit, and the dot products are summed in :data:`CG_CHUNKS`
fixed chunks: the iterates are the same on any number of threads
(``tests/test_newton.py``).  The kernels check nothing
(:mod:`cutkit.relax.newton` does); their NumPy twin is
:func:`cutkit.relax.newton.pcg` with scipy's products
(``tests/test_newton_block_cg.py``).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

from cutkit.relax._coarse_kernels import add_correction
from cutkit.relax._stop_flag import flag_up

#: The symmetric block form of a Newton matrix: ``diag`` (n, 3, 3) float64 the diagonal blocks;
#: ``ptr`` (n + 1,) int64 and ``col`` (nu,) int64 the blocks above the diagonal of each node row
#: (columns sorted), their values ``off`` (nu, 3, 3) float64 (row i's block of column col[q]);
#: ``lower_ptr`` (n + 1,), ``lower_row`` (nu,) and ``lower_q`` (nu,) int64 the same blocks by
#: column (:func:`lower_blocks`): row j's blocks left of its diagonal, ``off[lower_q]``
#: transposed, of rows ``lower_row`` ascending.
BlockMatrix = namedtuple("BlockMatrix", ["diag", "ptr", "col", "off", "lower_ptr", "lower_row", "lower_q"])

#: The dot products of :func:`block_pcg` are summed in this many fixed chunks of rows, then the
#: chunks in order: the same sums on any number of threads.
CG_CHUNKS = 64

#: What :func:`block_pcg` returns beside the iterations: the residual reached the tolerance or the
#: iterations ran out; a search direction of non-positive curvature (the matrix is not positive
#: definite); the halt flag was set.
CG_DONE, CG_NEGATIVE_CURVATURE, CG_HALTED = 0, 1, 2


@njit(cache=True, nogil=True)
def upper_blocks(node_ptr, node_idx):
    """The blocks above the diagonal of the node pattern (``node_ptr`` (n + 1,), sorted ``node_idx``
    (nb,) int64): their row pointers (n + 1,), columns (nu,) and positions in ``node_idx`` (nu,)."""
    n = node_ptr.shape[0] - 1
    ptr = np.zeros(n + 1, np.int64)
    for i in range(n):
        count = 0
        for k in range(node_ptr[i], node_ptr[i + 1]):
            if node_idx[k] > i:
                count += 1
        ptr[i + 1] = ptr[i] + count
    col = np.empty(ptr[n], np.int64)
    src = np.empty(ptr[n], np.int64)
    for i in range(n):
        q = ptr[i]
        for k in range(node_ptr[i], node_ptr[i + 1]):
            if node_idx[k] > i:
                col[q] = node_idx[k]
                src[q] = k
                q += 1
    return ptr, col, src


@njit(cache=True, nogil=True)
def lower_blocks(ptr, col, n):
    """The blocks above the diagonal (row pointers ``ptr`` (n + 1,), columns ``col`` (nu,)) by
    column: ``lower_ptr`` (n + 1,), and for each column j its rows ascending ``lower_row`` and the
    blocks' positions ``lower_q`` (nu,) int64 (a counting sort)."""
    lower_ptr = np.zeros(n + 1, np.int64)
    for q in range(col.shape[0]):
        lower_ptr[col[q] + 1] += 1
    for j in range(n):
        lower_ptr[j + 1] += lower_ptr[j]
    fill = lower_ptr[:n].copy()
    lower_row = np.empty(col.shape[0], np.int64)
    lower_q = np.empty(col.shape[0], np.int64)
    for i in range(n):
        for q in range(ptr[i], ptr[i + 1]):
            j = col[q]
            lower_row[fill[j]] = i
            lower_q[fill[j]] = q
            fill[j] += 1
    return lower_ptr, lower_row, lower_q


@njit(cache=True, nogil=True)
def gather_blocks(node_ptr, diagonal, src, data, diag, ptr, off):
    """Copy the scalar CSR ``data`` (its layout: the module docstring of ``_newton_kernels``;
    ``diagonal`` (3n,) the positions of its diagonal entries) into ``diag`` (n, 3, 3) and ``off``
    (nu, 3, 3) (``src`` (nu,) from :func:`upper_blocks`, row pointers ``ptr``)."""
    n = node_ptr.shape[0] - 1
    for i in range(n):
        deg = node_ptr[i + 1] - node_ptr[i]
        for a in range(3):
            first = diagonal[3 * i + a] - a  # entry (3i + a, 3i) of the diagonal block
            for b in range(3):
                diag[i, a, b] = data[first + b]
        for q in range(ptr[i], ptr[i + 1]):
            k = src[q] - node_ptr[i]
            for a in range(3):
                first = 9 * node_ptr[i] + 3 * a * deg + 3 * k
                for b in range(3):
                    off[q, a, b] = data[first + b]


@njit(cache=True, nogil=True)
def block_jacobi(diag, inv):
    """Invert each diagonal block (n, 3, 3) into ``inv`` (n, 3, 3); False where one has no Cholesky
    factor (then the matrix is not positive definite either)."""
    for i in range(diag.shape[0]):
        A = diag[i]
        d0 = A[0, 0]
        if not d0 > 0.0:
            return False
        l10 = A[1, 0] / np.sqrt(d0)
        l20 = A[2, 0] / np.sqrt(d0)
        d1 = A[1, 1] - l10 * l10
        if not d1 > 0.0:
            return False
        l21 = (A[2, 1] - l20 * l10) / np.sqrt(d1)
        if not A[2, 2] - l20 * l20 - l21 * l21 > 0.0:
            return False
        c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
        c01 = A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]
        c02 = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
        det = A[0, 0] * c00 + A[1, 0] * c01 + A[2, 0] * c02
        B = inv[i]
        B[0, 0] = c00 / det
        B[0, 1] = c01 / det
        B[0, 2] = c02 / det
        B[1, 0] = (A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]) / det
        B[1, 1] = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / det
        B[1, 2] = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / det
        B[2, 0] = (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]) / det
        B[2, 1] = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / det
        B[2, 2] = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / det
    return True


@njit(cache=True, nogil=True, inline="always")
def _times(B, v0, v1, v2):
    """B v for a 3 x 3 block B: its three components, each summed left to right (both products
    add these same terms)."""
    return (B[0, 0] * v0 + B[0, 1] * v1 + B[0, 2] * v2,
            B[1, 0] * v0 + B[1, 1] * v1 + B[1, 2] * v2,
            B[2, 0] * v0 + B[2, 1] * v1 + B[2, 2] * v2)


@njit(cache=True, nogil=True, inline="always")
def _times_transposed(B, v0, v1, v2):
    """B^T v for a 3 x 3 block B (the block below the diagonal of a symmetric matrix)."""
    return (B[0, 0] * v0 + B[1, 0] * v1 + B[2, 0] * v2,
            B[0, 1] * v0 + B[1, 1] * v1 + B[2, 1] * v2,
            B[0, 2] * v0 + B[1, 2] * v1 + B[2, 2] * v2)


@njit(cache=True, nogil=True)
def block_product(A, p, y):
    """y (n, 3) = A p (p (n, 3)) for a :class:`BlockMatrix` A, each block above the diagonal read
    once and scattered into both its rows."""
    n = A.diag.shape[0]
    for i in range(n):
        y[i, 0], y[i, 1], y[i, 2] = _times(A.diag[i], p[i, 0], p[i, 1], p[i, 2])
    for i in range(n):
        p0, p1, p2 = p[i, 0], p[i, 1], p[i, 2]
        u0 = 0.0
        u1 = 0.0
        u2 = 0.0
        for q in range(A.ptr[i], A.ptr[i + 1]):
            j = A.col[q]
            a0, a1, a2 = _times(A.off[q], p[j, 0], p[j, 1], p[j, 2])
            u0 += a0
            u1 += a1
            u2 += a2
            b0, b1, b2 = _times_transposed(A.off[q], p0, p1, p2)  # the block below: A_ji = A_ij^T
            y[j, 0] += b0
            y[j, 1] += b1
            y[j, 2] += b2
        y[i, 0] += u0
        y[i, 1] += u1
        y[i, 2] += u2


@njit(cache=True, nogil=True, inline="always")
def _upper_sum(A, p, i):
    """Row i's blocks right of its diagonal times p, summed from 0 by ascending column (what
    :func:`block_product` adds to row i last)."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for q in range(A.ptr[i], A.ptr[i + 1]):
        j = A.col[q]
        a0, a1, a2 = _times(A.off[q], p[j, 0], p[j, 1], p[j, 2])
        s0 += a0
        s1 += a1
        s2 += a2
    return s0, s1, s2


@njit(cache=True, nogil=True, parallel=True)
def block_product_rows(A, p, y):
    """y (n, 3) = A p, row by row in parallel: the same sums in the same order as
    :func:`block_product` (the row's diagonal block, the blocks left of it by ascending row, then
    the sum of the blocks right of it), so the same bits."""
    n = A.diag.shape[0]
    for i in prange(n):
        y0, y1, y2 = _times(A.diag[i], p[i, 0], p[i, 1], p[i, 2])
        for t in range(A.lower_ptr[i], A.lower_ptr[i + 1]):
            k = A.lower_row[t]
            b0, b1, b2 = _times_transposed(A.off[A.lower_q[t]], p[k, 0], p[k, 1], p[k, 2])
            y0 += b0
            y1 += b1
            y2 += b2
        u0, u1, u2 = _upper_sum(A, p, i)
        y[i, 0] = y0 + u0
        y[i, 1] = y1 + u1
        y[i, 2] = y2 + u2


@njit(cache=True, nogil=True, parallel=True)
def _precondition(inv, r, z, part):
    """z = M r, M the block-Jacobi inverse (n, 3, 3); returns r . z (summed by chunks, ``part``
    (CG_CHUNKS,) scratch)."""
    n = inv.shape[0]
    for c in prange(CG_CHUNKS):
        acc = 0.0
        for i in range(n * c // CG_CHUNKS, n * (c + 1) // CG_CHUNKS):
            B = inv[i]
            for a in range(3):
                z[i, a] = B[a, 0] * r[i, 0] + B[a, 1] * r[i, 1] + B[a, 2] * r[i, 2]
                acc += r[i, a] * z[i, a]
        part[c] = acc
    return _sum(part)


@njit(cache=True, nogil=True)
def _preconditioned(inv, r, z, part, coarse):
    """z = M r by block Jacobi, plus the coarse correction where ``coarse`` is given; returns r . z."""
    if coarse is None:
        return _precondition(inv, r, z, part)
    _precondition(inv, r, z, part)
    add_correction(coarse, r, z)
    return _dot(r, z, part)


@njit(cache=True, nogil=True, inline="always")
def _sum(part):
    acc = 0.0
    for c in range(part.shape[0]):
        acc += part[c]
    return acc


@njit(cache=True, nogil=True, parallel=True)
def _dot(u, v, part):
    """u . v of (n, 3) arrays, summed by chunks (``part`` (CG_CHUNKS,) scratch)."""
    n = u.shape[0]
    for c in prange(CG_CHUNKS):
        acc = 0.0
        for i in range(n * c // CG_CHUNKS, n * (c + 1) // CG_CHUNKS):
            acc += u[i, 0] * v[i, 0] + u[i, 1] * v[i, 1] + u[i, 2] * v[i, 2]
        part[c] = acc
    return _sum(part)


@njit(cache=True, nogil=True, parallel=True)
def _step(d, r, p, Ap, alpha, part):
    """d += alpha p, r -= alpha Ap; returns r . r (summed by chunks)."""
    n = d.shape[0]
    for c in prange(CG_CHUNKS):
        acc = 0.0
        for i in range(n * c // CG_CHUNKS, n * (c + 1) // CG_CHUNKS):
            for a in range(3):
                d[i, a] += alpha * p[i, a]
                r[i, a] -= alpha * Ap[i, a]
                acc += r[i, a] * r[i, a]
        part[c] = acc
    return _sum(part)


@njit(cache=True, nogil=True, parallel=True)
def _direction(p, z, beta):
    """p = z + beta p."""
    for i in prange(p.shape[0]):
        for a in range(3):
            p[i, a] = z[i, a] + beta * p[i, a]


@njit(cache=True, nogil=True)
def block_pcg(A, inv, b, rtol, max_iterations, halt, d, rows, coarse=None):
    """Block-Jacobi preconditioned conjugate gradients for A d = b (Hestenes & Stiefel 1952; the
    preconditioned form of Saad, *Iterative Methods for Sparse Linear Systems*, 2003, Alg. 9.1),
    stopped at ``||b - A d|| <= rtol ||b||`` (the recursively updated residual) or after
    ``max_iterations``.  The same iterates on any number of threads (the module's docstring).

    Parameters
    ----------
    A : BlockMatrix
    inv : (n, 3, 3) float64
        :func:`block_jacobi`'s inverse diagonal blocks.
    b : (n, 3) float64
    rtol : float
    max_iterations : int
    halt : (1,) int64
        Read before every iteration: non-zero ends the solve (:data:`CG_HALTED`).
    d : (n, 3) float64
        The solution, written here (zero start).
    rows : bool
        Products row by row in parallel (:func:`block_product_rows`; more than one thread) or by
        scattering (:func:`block_product`; one): the same bits either way.
    coarse : Coarse, optional
        A coarse space (:mod:`cutkit.relax._coarse_kernels`) whose correction the block-Jacobi
        preconditioner adds (two-level, additive); None: block Jacobi alone.

    Returns
    -------
    (status, iterations): :data:`CG_DONE`, :data:`CG_NEGATIVE_CURVATURE` or :data:`CG_HALTED`.
    """
    n = b.shape[0]
    r = b.copy()
    z = np.empty((n, 3))
    Ap = np.empty((n, 3))
    part = np.empty(CG_CHUNKS)
    d[:] = 0.0
    rz = _preconditioned(inv, r, z, part, coarse)
    p = z.copy()
    stop2 = rtol * rtol * _dot(b, b, part)
    for k in range(max_iterations):
        if flag_up(halt):
            return CG_HALTED, k
        if rows:
            block_product_rows(A, p, Ap)
        else:
            block_product(A, p, Ap)
        curvature = _dot(p, Ap, part)
        if not curvature > 0.0:
            return CG_NEGATIVE_CURVATURE, k
        alpha = rz / curvature
        rr = _step(d, r, p, Ap, alpha, part)
        if rr <= stop2:
            return CG_DONE, k + 1
        rz_old = rz
        rz = _preconditioned(inv, r, z, part, coarse)
        _direction(p, z, rz / rz_old)
    return CG_DONE, max_iterations
