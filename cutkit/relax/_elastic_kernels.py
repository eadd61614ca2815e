"""Numba kernels of the element model: stable neo-Hookean tetrahedra, vertex block descent.

The energy of one tetrahedron (docs/relaxation.md, "Element model") is

    W = V psi(F),  psi = mu/2 (tr F^T F - 3) - mu (J - 1) + (lam + mu)/2 (J - 1)^2

with ``F = Ds Dminv`` and ``J = det F`` (Smith, de Goes & Kim 2018, in the
form of Kim & Eberle's course notes whose small-strain limit is linear
elasticity with Lame parameters mu, lam).  ``J`` is affine in any single
vertex position, so the energy of the tets around one vertex is an exact
convex quadratic in that vertex: its 3x3 Newton step (Chen et al. 2024,
vertex block descent) is the exact minimiser, whatever the step size and
even for an inverted tetrahedron.  Where a tet around the vertex is in the
band of the :data:`BARRIER_J` barrier, the vertex's energy is convex but
no longer quadratic, and a line search along the Newton step finds its
minimiser (:func:`_barrier_line_minimum`).

The kernels take a few struct-like arguments: ``el`` (:class:`Elements`),
``adj`` (:class:`Adjacency`) and ``nt`` (:class:`NodeTerms`); they check
nothing (:mod:`cutkit.relax.elastic` does).  A node update reads only its
own adjacency row (the three other corners of each of its tets and six
constants, :data:`INCIDENCE_TERMS`) and the positions: contiguous reads
in place of gathering each tet's corners and constants.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

from cutkit.mesh.geometry import TET_EDGES, TET_FACES_INWARD
from cutkit.relax._stop_flag import flag_up

#: tets (m, 4) int64, Dminv (m, 3, 3) float64, volume (m,) float64 (0: inactive), mu, lam (m,) float64 MPa
Elements = namedtuple("Elements", ["tets", "Dminv", "volume", "mu", "lam"])

#: Columns of a tet's node-term row: the six edge weights V mu b_j . b_c (corner pairs (j, c)
#: in the order of the mesh core's local edges, ``TET_EDGES``), then 1 / det Dm,
#: V (lam + mu) and V mu.
NODE_TERMS = 9
#: For corner c, the corners (j, k, l) with (j, c, k, l) an even permutation of (0, 1, 2, 3):
#: det Ds = (x_c - x_j) . ((x_k - x_j) x (x_l - x_j)), so d det Ds / d x_c is the cross product.
OPPOSITE = TET_FACES_INWARD
#: Column of the edge (c, j) for corner c and each other corner j (-1 on the diagonal).
EDGE_COLUMN = np.array([[-1, 0, 1, 2], [0, -1, 3, 4], [1, 3, -1, 5], [2, 4, 5, -1]], np.int64)
#: What a node's adjacency row holds of each tet around it (``Adjacency.terms``): the edge
#: weights to its three other corners (in :data:`OPPOSITE` order), 1 / det Dm, V (lam + mu), V mu.
INCIDENCE_TERMS = 6
#: A sweep splits each colour class into this many blocks (at most), each with its own scratch
#: row: a fixed count, so the result does not depend on the number of threads.
SWEEP_BLOCKS = 64
#: Passes that a live cut may stop (:func:`refresh_volume_ratios`, the Newton pattern's build)
#: read the stop flag every this many elements (about 20 us of work on one core).
STOP_EVERY = 1024


@njit(cache=True, nogil=True)
def node_term_rows(Dminv, volume, mu, lam):
    """The per-tet constants of a node update, (m, NODE_TERMS) float64.

    With the shape-function gradients b_0..b_3 (b_c = row c-1 of Dminv,
    b_0 = -(b_1 + b_2 + b_3)), F = sum_j x_j b_j^T, so the mu F b_c part of a
    node's force is sum_j V mu (b_j . b_c) (x_j - x_c): six edge weights per
    tet (the cotangent Laplacian).  J = det Ds / det Dm and dJ/dx_c is the
    cross product of the opposite face's edges over det Dm (:data:`OPPOSITE`).
    :func:`~cutkit.relax._adjacency_kernels.add_to_adjacency` hands each corner its part.
    A cut hands over a few dozen tets at a time: one pass, no temporaries.
    """
    m = Dminv.shape[0]
    out = np.zeros((m, NODE_TERMS))
    B = np.empty((4, 3))
    for t in range(m):
        for d in range(3):
            B[0, d] = -(Dminv[t, 0, d] + Dminv[t, 1, d] + Dminv[t, 2, d])
            B[1, d] = Dminv[t, 0, d]
            B[2, d] = Dminv[t, 1, d]
            B[3, d] = Dminv[t, 2, d]
        vm = volume[t] * mu[t]
        for col in range(6):
            j, c = TET_EDGES[col, 0], TET_EDGES[col, 1]
            # summed in the order NumPy's einsum pairs them (0 and 2, then 1): the rows are
            # bit-identical to the NumPy version's (tests/_twins_elastic.node_term_rows)
            out[t, col] = vm * ((B[j, 0] * B[c, 0] + B[j, 2] * B[c, 2]) + B[j, 1] * B[c, 1])
        if volume[t] > 0.0:
            out[t, 6] = 1.0 / (6.0 * volume[t])
        out[t, 7] = volume[t] * (lam[t] + mu[t])
        out[t, 8] = vm
    return out


#: The tets around each node, one row per node in a shared pool: node i's are the slots
#: ``start[i] .. start[i] + degree[i] - 1``.  start (rows,) int64, degree (n,) int32; per slot
#: tets (P,) int32, corner (P,) int8, and what a node update reads of the tet: opposite (P, 3)
#: int32 (its three other corners) and terms (P, INCIDENCE_TERMS) float64 (its part of the
#: tet's node-term row).
Adjacency = namedtuple("Adjacency", ["start", "degree", "tets", "corner", "opposite", "terms"])
#: inertia (n,) m/h^2, damping (n,) c m / h, fixed (n, 3) bool, target y (n, 3), previous x (n, 3),
#: external force (n, 3) N (gravity included)
NodeTerms = namedtuple("NodeTerms", ["inertia", "damping", "fixed", "target", "previous", "force"])

#: A node step may shrink the volume ratio J of a tet around it to at most this
#: fraction of its value before the step: no step inverts a tet that was not
#: inverted, and since the node's energy is a convex quadratic along the step,
#: a shortened step still lowers it.  (A tet already inverted is not held back.)
KEEP_J_FRACTION = 0.1
#: Below this volume ratio J a tet's energy gets a barrier that grows without
#: bound as J -> 0 (the IPC form of Li et al. 2020 applied to J):
#: ``b(J) = -(lam + mu) (J - BARRIER_J)^2 ln(J / BARRIER_J)`` for 0 < J <
#: BARRIER_J, zero above, twice continuously differentiable at BARRIER_J.
#: The stable neo-Hookean energy is finite at J = 0, so a concentrated load
#: (the blade pressing on a node) can crush a tet: the step limit keeps J > 0
#: but lets it fall towards 0 geometrically until rounding turns it over.
#: The barrier makes the crushed state cost what it physically would; it
#: acts only far outside the strains of the reference tests (J > 0.7).
BARRIER_J = 0.1
# The kernels take no fast-math licence.  Letting the compiler reassociate the sums over a
# node's tets and fuse multiply-adds saved 6-10 % of a sweep, but the rounding then depended on
# how the kernel was inlined, which differed between two compilations of the same source: the
# knee's incision took 1,704 or 1,843 sweeps depending on which kernel was compiled first.
#: A node whose 3x3 block has |det| below this times its trace cubed is left where it is
#: (no tet and no mass: an orphan the cut left behind).
SINGULAR_BLOCK = 1e-14


@njit(cache=True, nogil=True)
def barrier(J, k):
    """The barrier energy density of a tet with volume ratio J and modulus k = lam + mu, and its
    first and second derivatives in J: (b, b', b''), all 0 outside 0 < J < BARRIER_J."""
    if J <= 0.0 or J >= BARRIER_J:
        return 0.0, 0.0, 0.0
    d = J - BARRIER_J
    ln = np.log(J / BARRIER_J)
    return (-k * d * d * ln, -k * (2.0 * d * ln + d * d / J),
            -k * (2.0 * ln + 4.0 * d / J - d * d / (J * J)))


@njit(cache=True, nogil=True, inline="always")
def _add_outer(h00, h01, h02, h11, h12, h22, w, g0, g1, g2):
    """The upper triangle of h + w g g^T."""
    return (h00 + w * g0 * g0, h01 + w * g0 * g1, h02 + w * g0 * g2,
            h11 + w * g1 * g1, h12 + w * g1 * g2, h22 + w * g2 * g2)


@njit(cache=True, nogil=True, error_model="numpy")
def _accumulate(i, x, adj, scratch):
    """-dW/dx_i (f0, f1, f2) and the upper triangle of d2W/dx_i^2 over the tets of node i.

    Scalars only in the innermost loop, from the node's adjacency row
    (:func:`node_term_rows`, :data:`INCIDENCE_TERMS`): W = V psi(F) + V b(J)
    with P = mu F + s cof F, s = (lam + mu)(J - 1) - mu + b'(J), so

        dW/dx_i = sum_j w_ij (x_j - x_i) + V s dJ/dx_i  (w_ij <= 0 on good tets),
        d2W/dx_i^2 = -(sum_j w_ij) I + V ((lam + mu) + b''(J)) dJ/dx_i dJ/dx_i^T

    (the J-Hessian term vanishes: J is affine in one vertex; b is the
    :data:`BARRIER_J` barrier).  ``scratch`` (K, 4) receives J and dJ/dx_i of
    each tet (J = 0: no energy) for :func:`_max_step`.

    The loop over the tets has no branch: an inactive tet (no volume, below
    MIN_ELEMENT_QUALITY) has an all-zero row (:func:`node_term_rows`), so it adds
    nothing and gets J = 0; removed tets are not in the rows at all.  The barrier,
    which only a tet with J < BARRIER_J feels, is added by a second loop over
    the scratch row when one does.
    """
    f0 = f1 = f2 = 0.0
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    diagonal = 0.0  # sum of the rows' edge weights: minus V mu |b_c|^2 summed
    lowest = np.inf  # the smallest J of a live tet
    xi0, xi1, xi2 = x[i, 0], x[i, 1], x[i, 2]
    s0 = adj.start[i]
    degree = adj.degree[i]
    for k in range(degree):
        # unsigned indices: no negative-index wrap-around test on each of the 22 reads (9 % of a sweep)
        r = np.uint64(s0 + k)
        aj = np.uint64(adj.opposite[r, 0])
        ak = np.uint64(adj.opposite[r, 1])
        al = np.uint64(adj.opposite[r, 2])
        xj0, xj1, xj2 = x[aj, 0], x[aj, 1], x[aj, 2]
        e0, e1, e2 = xi0 - xj0, xi1 - xj1, xi2 - xj2  # x_i - x_j
        p0, p1, p2 = x[ak, 0] - xj0, x[ak, 1] - xj1, x[ak, 2] - xj2  # x_k - x_j
        q0, q1, q2 = x[al, 0] - xj0, x[al, 1] - xj1, x[al, 2] - xj2  # x_l - x_j
        # the mu F b_c part: edge weights to the three other corners
        wk = adj.terms[r, 1]
        wl = adj.terms[r, 2]
        wsum = adj.terms[r, 0] + wk + wl
        # J and dJ/dx_i from the opposite face
        alpha = adj.terms[r, 3]
        Vk = adj.terms[r, 4]
        gb0 = (p1 * q2 - p2 * q1) * alpha
        gb1 = (p2 * q0 - p0 * q2) * alpha
        gb2 = (p0 * q1 - p1 * q0) * alpha
        J = e0 * gb0 + e1 * gb1 + e2 * gb2
        ku = np.uint64(k)
        scratch[ku, 0] = J
        scratch[ku, 1] = gb0
        scratch[ku, 2] = gb1
        scratch[ku, 3] = gb2
        s = Vk * (J - 1.0) - adj.terms[r, 5]  # V s without the barrier
        # sum_m w_m (x_i - x_m) with x_i - x_k = e - p, x_i - x_l = e - q
        f0 += wsum * e0 - wk * p0 - wl * q0 - s * gb0
        f1 += wsum * e1 - wk * p1 - wl * q1 - s * gb1
        f2 += wsum * e2 - wk * p2 - wl * q2 - s * gb2
        diagonal += wsum
        h00, h01, h02, h11, h12, h22 = _add_outer(h00, h01, h02, h11, h12, h22, Vk, gb0, gb1, gb2)
        lowest = min(lowest, J if Vk > 0.0 else np.inf)
    if lowest < BARRIER_J:
        for k in range(degree):
            _, db, ddb = barrier(scratch[k, 0], adj.terms[s0 + k, 4])
            gb0, gb1, gb2 = scratch[k, 1], scratch[k, 2], scratch[k, 3]
            f0 -= db * gb0
            f1 -= db * gb1
            f2 -= db * gb2
            h00, h01, h02, h11, h12, h22 = _add_outer(h00, h01, h02, h11, h12, h22, ddb, gb0, gb1, gb2)
    return f0, f1, f2, h00 - diagonal, h01, h02, h11 - diagonal, h12, h22 - diagonal


@njit(cache=True, nogil=True, error_model="numpy")
def _node_update(i, x, adj, nt, scratch):
    """Move x_i to the exact minimiser of the incremental potential in x_i; return the squared residual."""
    f0, f1, f2, h00, h01, h02, h11, h12, h22 = _accumulate(i, x, adj, scratch)
    m, c = nt.inertia[i], nt.damping[i]
    f0 += m * (nt.target[i, 0] - x[i, 0]) - c * (x[i, 0] - nt.previous[i, 0]) + nt.force[i, 0]
    f1 += m * (nt.target[i, 1] - x[i, 1]) - c * (x[i, 1] - nt.previous[i, 1]) + nt.force[i, 1]
    f2 += m * (nt.target[i, 2] - x[i, 2]) - c * (x[i, 2] - nt.previous[i, 2]) + nt.force[i, 2]
    h00 += m + c
    h11 += m + c
    h22 += m + c
    # held components: their row and column become the identity, their force zero
    if nt.fixed[i, 0]:
        f0, h00, h01, h02 = 0.0, 1.0, 0.0, 0.0
    if nt.fixed[i, 1]:
        f1, h11, h01, h12 = 0.0, 1.0, 0.0, 0.0
    if nt.fixed[i, 2]:
        f2, h22, h02, h12 = 0.0, 1.0, 0.0, 0.0
    r2 = f0 * f0 + f1 * f1 + f2 * f2
    i00 = h11 * h22 - h12 * h12
    i01 = h02 * h12 - h01 * h22
    i02 = h01 * h12 - h02 * h11
    det = h00 * i00 + h01 * i01 + h02 * i02
    tr = h00 + h11 + h22
    if not det > SINGULAR_BLOCK * tr * tr * tr:
        return r2
    i11 = h00 * h22 - h02 * h02
    i12 = h02 * h01 - h00 * h12
    i22 = h00 * h11 - h01 * h01
    d0 = (i00 * f0 + i01 * f1 + i02 * f2) / det
    d1 = (i01 * f0 + i11 * f1 + i12 * f2) / det
    d2 = (i02 * f0 + i12 * f1 + i22 * f2) / det
    a, near_barrier = _max_step(adj.degree[i], scratch, d0, d1, d2)
    if near_barrier:
        a = _barrier_line_minimum(i, adj, scratch, d0, d1, d2, f0 * d0 + f1 * d1 + f2 * d2, a)
    x[i, 0] += a * d0
    x[i, 1] += a * d1
    x[i, 2] += a * d2
    return r2


@njit(cache=True, nogil=True, error_model="numpy")
def _max_step(degree, scratch, d0, d1, d2):
    """The largest a in [0, 1] for which x_i + a d keeps every tet of node i with J > 0 at
    J >= KEEP_J_FRACTION of its present value (J is affine in x_i: J(a) = J + a (dJ/dx_i) . d),
    and whether a tet is in the :data:`BARRIER_J` band at a = 0 or a = 1 (then possibly along
    the step: :func:`_barrier_line_minimum` decides).

    ``scratch`` holds J and dJ/dx_i of each tet as :func:`_accumulate` found them.  Without a
    branch: the fastest rate -slope / ((1 - KEEP_J_FRACTION) J) at which a tet with J > 0 loses
    its allowance gives a = 1 / rate.
    """
    rate = 0.0
    lowest = np.inf  # the smallest J along the step (at a = 0 or a = 1) of a tet with J > 0
    for k in range(np.uint64(degree)):  # unsigned: no wrap-around test on the reads
        J = scratch[k, 0]
        slope = scratch[k, 1] * d0 + scratch[k, 2] * d1 + scratch[k, 3] * d2
        live = J > 0.0
        lowest = min(lowest, J + min(slope, 0.0) if live else np.inf)
        rate = max(rate, -slope / ((1.0 - KEEP_J_FRACTION) * J) if live else 0.0)
    return (1.0 / rate if rate > 1.0 else 1.0), lowest < BARRIER_J


#: The line search along a node's Newton step (:func:`_barrier_line_minimum`) stops once the
#: potential's slope along the step is this fraction of its slope at the start ...
LINE_SEARCH_TOLERANCE = 1e-10
#: ... or after this many safeguarded Newton iterations in the step length.
LINE_SEARCH_ITERATIONS = 50


@njit(cache=True, nogil=True)
def _barrier_line_minimum(i, adj, scratch, d0, d1, d2, fd, a_max):
    """The step length in [0, a_max] that minimises node i's incremental potential along d.

    Without a tet in the :data:`BARRIER_J` band along the step, the node's
    potential is an exact quadratic in x_i, the Newton step a = 1 is its
    minimiser, and the minimiser on [0, a_max] is min(1, a_max).  A barrier
    term is not quadratic: its Newton model, taken at the present J, can
    overshoot to a J where the barrier is far steeper, and the next update
    overshoots back; two nodes of a crushed tet then push each other ever
    further from balance (the residual grew twenty-fold over 400 sweeps on the
    knee).  So along d, whose potential is convex (the barrier is convex in J
    and J is affine in x_i), the step length is the root of

        phi'(a) = -fd + a (fd - sum V b''(J_t) s_t^2) + sum V (b'(J_t + a s_t) - b'(J_t)) s_t

    with s_t = dJ_t/dx_i . d and fd = f . d = d^T H d, found by Newton's
    method safeguarded by bisection.  The terms at a = 0 are summed once:
    phi'(a) = offset + a curvature + sum V b'(J_t + a s_t) s_t.  ``scratch``
    holds J and dJ/dx_i of each tet (:func:`_accumulate`); a tet outside the
    band all along the step adds nothing.
    """
    s0 = adj.start[i]
    active = False
    curvature = fd  # d^T H d without the barrier terms
    offset = -fd  # phi'(0) without the barrier terms
    for k in range(adj.degree[i]):
        J = scratch[k, 0]
        if J <= 0.0:
            continue
        s = scratch[k, 1] * d0 + scratch[k, 2] * d1 + scratch[k, 3] * d2
        if J < BARRIER_J or J + a_max * s < BARRIER_J:
            active = True
            _, db, ddb = barrier(J, adj.terms[s0 + k, 4])
            curvature -= ddb * s * s
            offset -= db * s
    if not active or fd <= 0.0:
        return min(1.0, a_max)
    lo, hi = 0.0, a_max
    a = min(1.0, a_max)
    for _ in range(LINE_SEARCH_ITERATIONS):
        slope = offset + a * curvature
        bend = curvature
        for k in range(adj.degree[i]):
            J = scratch[k, 0]
            if J <= 0.0:
                continue
            s = scratch[k, 1] * d0 + scratch[k, 2] * d1 + scratch[k, 3] * d2
            if s == 0.0:
                continue
            _, db, ddb = barrier(J + a * s, adj.terms[s0 + k, 4])
            slope += db * s
            bend += ddb * s * s
        if a == a_max and slope <= 0.0:
            return a_max  # the potential still falls at the step limit
        if abs(slope) <= LINE_SEARCH_TOLERANCE * fd:
            return a  # at the minimiser (to rounding): below the potential at a = 0
        if slope < 0.0:
            lo = a
        else:
            hi = a
        step = a - slope / bend if bend > 0.0 else -1.0
        a = step if lo < step < hi else 0.5 * (lo + hi)
    return lo  # phi' < 0 on [0, lo]: the potential there is below its value at a = 0


@njit(cache=True, parallel=True, nogil=True, error_model="numpy")
def vbd_sweep(x, adj, nt, colour_offsets, colour_nodes, r2, stop):
    """One Gauss-Seidel sweep of vertex block descent, colour class by colour class.

    Nodes of one colour share no tet, so they update in parallel and the
    result does not depend on the number of threads.  ``r2[i]`` receives the
    squared residual (out-of-balance force, N^2) of node i before its update.
    ``stop`` ((1,) int64) is read before each colour class: non-zero ends
    the sweep there (a live cut waiting for the tissue; every node update
    made lowers the energy, so a part sweep is a valid descent).  Returns
    the colour classes swept.
    """
    n_classes = colour_offsets.shape[0] - 1
    for c in range(n_classes):
        if flag_up(stop):
            return c
        lo, hi = colour_offsets[c], colour_offsets[c + 1]
        blocks = min(SWEEP_BLOCKS, hi - lo)
        for b in prange(blocks):
            first, end = lo + (hi - lo) * b // blocks, lo + (hi - lo) * (b + 1) // blocks
            scratch = np.empty((_max_degree(adj, colour_nodes[first:end]), 4))
            for q in range(first, end):
                i = colour_nodes[q]
                r2[i] = _node_update(i, x, adj, nt, scratch)
    return n_classes


@njit(cache=True, nogil=True)
def _max_degree(adj, nodes):
    """The most tets any of ``nodes`` has (the rows a block's scratch needs)."""
    most = 0
    for q in range(nodes.shape[0]):
        most = max(most, adj.degree[nodes[q]])
    return most


@njit(cache=True, parallel=True, nogil=True)
def node_forces(x, adj, out):
    """Elastic force -dW/dx on every node, N: ``out`` (n, 3)."""
    n = x.shape[0]
    most = adj.degree[:n].max() if n else 0
    for b in prange(SWEEP_BLOCKS):
        scratch = np.empty((most, 4))
        for i in range(n * b // SWEEP_BLOCKS, n * (b + 1) // SWEEP_BLOCKS):
            f0, f1, f2, h00, h01, h02, h11, h12, h22 = _accumulate(i, x, adj, scratch)
            out[i, 0] = f0
            out[i, 1] = f1
            out[i, 2] = f2


@njit(cache=True, nogil=True)
def forces_at(x, adj, nodes, out):
    """Elastic force -dW/dx on each of ``nodes`` (k,) int64, N: ``out`` (k, 3); the same sums as
    :func:`node_forces` makes for them."""
    scratch = np.empty((_max_degree(adj, nodes), 4))
    for q in range(nodes.shape[0]):
        f0, f1, f2, h00, h01, h02, h11, h12, h22 = _accumulate(nodes[q], x, adj, scratch)
        out[q, 0] = f0
        out[q, 1] = f1
        out[q, 2] = f2


@njit(cache=True, nogil=True)
def _deformation(x, el, t):
    """F = Ds Dm^-1 of element t, row by row, as nine scalars (summed in the order of the corners)."""
    a0 = el.tets[t, 0]
    D = el.Dminv[t]
    F00 = F01 = F02 = F10 = F11 = F12 = F20 = F21 = F22 = 0.0
    for j in range(3):
        aj = el.tets[t, j + 1]
        e0, e1, e2 = x[aj, 0] - x[a0, 0], x[aj, 1] - x[a0, 1], x[aj, 2] - x[a0, 2]
        d0, d1, d2 = D[j, 0], D[j, 1], D[j, 2]
        F00 += e0 * d0
        F01 += e0 * d1
        F02 += e0 * d2
        F10 += e1 * d0
        F11 += e1 * d1
        F12 += e1 * d2
        F20 += e2 * d0
        F21 += e2 * d1
        F22 += e2 * d2
    return F00, F01, F02, F10, F11, F12, F20, F21, F22


@njit(cache=True, nogil=True)
def element_energy(x, el):
    """Total elastic energy sum V psi(F), N mm (= mJ)."""
    total = 0.0
    for t in range(el.tets.shape[0]):
        V = el.volume[t]
        if V <= 0.0:
            continue
        # F = Ds Dm^-1 in scalars: a per-element array and LAPACK's det made a whole-model energy
        # (each Newton line search trial) cost 40 ms on the cut knee, 2.6 ms without them
        F00, F01, F02, F10, F11, F12, F20, F21, F22 = _deformation(x, el, t)
        J = F00 * (F11 * F22 - F12 * F21) - F01 * (F10 * F22 - F12 * F20) + F02 * (F10 * F21 - F11 * F20)
        mu = el.mu[t]
        ic = (F00 * F00 + F01 * F01 + F02 * F02 + F10 * F10 + F11 * F11 + F12 * F12
              + F20 * F20 + F21 * F21 + F22 * F22)
        lm = el.lam[t] + mu
        total += V * (0.5 * mu * (ic - 3.0) - mu * (J - 1.0) + 0.5 * lm * (J - 1.0) ** 2 + barrier(J, lm)[0])
    return total


@njit(cache=True, nogil=True, inline="always")
def _volume_ratio(x, el, t):
    """J = det F of element t at x."""
    F00, F01, F02, F10, F11, F12, F20, F21, F22 = _deformation(x, el, t)
    return F00 * (F11 * F22 - F12 * F21) - F01 * (F10 * F22 - F12 * F20) + F02 * (F10 * F21 - F11 * F20)


@njit(cache=True, nogil=True, parallel=True)
def volume_ratio_extremes(x, el, below):
    """The smallest volume ratio J = det F over the elements with V > 0 (1.0 if none), and how many
    have J < ``below``: the report of how near a state came to crushing a tet, in one pass over
    every element (the tissue keeps its ratios between steps instead: :func:`refresh_volume_ratios`).
    A minimum and a count do not depend on the order they are taken in, so the blocks run in
    parallel."""
    m = el.tets.shape[0]
    lowest = np.full(SWEEP_BLOCKS, np.inf)
    counts = np.zeros(SWEEP_BLOCKS, np.int64)
    for b in prange(SWEEP_BLOCKS):
        for t in range(m * b // SWEEP_BLOCKS, m * (b + 1) // SWEEP_BLOCKS):
            if el.volume[t] <= 0.0:
                continue
            J = _volume_ratio(x, el, t)
            if J < lowest[b]:
                lowest[b] = J
            if J < below:
                counts[b] += 1
    least = lowest.min()
    return (least if least < np.inf else 1.0), counts.sum()


@njit(cache=True, nogil=True)
def refresh_volume_ratios(x, el, adj, at, stale, mark, J, stop):
    """Compute again the kept volume ratios ``J`` (m,) that a change can reach: the elements
    around a node whose position in ``x`` (n, 3) differs from ``at`` (n, 3, where they were
    computed; NaN: never) and the ``stale`` (k,) int64 elements; ``at`` is brought up to ``x``.
    ``mark`` (m,) bool holds the elements still to compute (True on entry for any the caller
    adds; all False on a complete exit).  Each J is :func:`volume_ratio_extremes`'s, bit for bit.
    ``stop`` ((1,) int64) is read every :data:`STOP_EVERY` elements computed: non-zero ends the
    pass with the rest still marked, and the result is False (True: complete)."""
    n = at.shape[0]
    for i in range(n):
        if x[i, 0] != at[i, 0] or x[i, 1] != at[i, 1] or x[i, 2] != at[i, 2]:
            for r in range(adj.start[i], adj.start[i] + adj.degree[i]):
                mark[adj.tets[r]] = True
            at[i, 0], at[i, 1], at[i, 2] = x[i, 0], x[i, 1], x[i, 2]
    for q in range(stale.shape[0]):
        mark[stale[q]] = True
    done = 0
    for t in range(el.tets.shape[0]):
        if not mark[t]:
            continue
        if done % STOP_EVERY == 0 and flag_up(stop):
            return False
        done += 1
        mark[t] = False
        if el.volume[t] > 0.0:
            J[t] = _volume_ratio(x, el, t)
    return True


@njit(cache=True, nogil=True)
def kept_ratio_extremes(J, volume, below):
    """The smallest of the kept volume ratios ``J`` (m,) over the elements with ``volume`` > 0 (1.0
    if none) and how many are below ``below``: :func:`volume_ratio_extremes` of kept values."""
    lowest = np.inf
    count = 0
    for t in range(J.shape[0]):
        if volume[t] > 0.0:
            if J[t] < lowest:
                lowest = J[t]
            if J[t] < below:
                count += 1
    return (lowest if lowest < np.inf else 1.0), count


@njit(cache=True, nogil=True)
def refresh_forces(x, adj, at, stale, most, mark, forces):
    """Sum again the kept elastic forces ``forces`` (n, 3) that a change can reach: the nodes whose
    position in ``x`` (n, 3) differs from ``at`` (n, 3, where the forces were summed; NaN: never),
    the ``stale`` (k,) int64 nodes, and every node sharing a tet with one of them; ``at`` is
    brought up to ``x`` there.  Each force is :func:`forces_at`'s sum, so the kept forces stay
    the whole pass's, bit for bit.  ``mark`` (n,) bool is scratch (all False on entry and exit).

    Returns the nodes summed again, or -1 (nothing changed) where more than ``most`` nodes moved
    or were stale (the caller then sums the whole model: cheaper than the gather).
    """
    n = at.shape[0]
    seeds = np.empty(n, np.int64)
    k = 0
    for i in range(n):
        if x[i, 0] != at[i, 0] or x[i, 1] != at[i, 1] or x[i, 2] != at[i, 2]:
            mark[i] = True
            seeds[k] = i
            k += 1
    for q in range(stale.shape[0]):
        if not mark[stale[q]]:
            mark[stale[q]] = True
            seeds[k] = stale[q]
            k += 1
    if k > most:
        for q in range(k):
            mark[seeds[q]] = False
        return -1
    for q in range(k):  # the seeds' neighbours (the other corners of their tets)
        i = seeds[q]
        for r in range(adj.start[i], adj.start[i] + adj.degree[i]):
            for c in range(3):
                mark[adj.opposite[r, c]] = True
    nodes = np.flatnonzero(mark)
    out = np.empty((nodes.shape[0], 3))
    if nodes.shape[0]:
        forces_at(x, adj, nodes, out)
    for q in range(nodes.shape[0]):
        i = nodes[q]
        mark[i] = False
        for c in range(3):
            forces[i, c] = out[q, c]
            at[i, c] = x[i, c]
    return nodes.shape[0]
