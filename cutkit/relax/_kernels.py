"""Numba kernels of the relaxation (paper section 5).

The kernels never check their input; the public functions in
:mod:`cutkit.relax.integrate` and :mod:`cutkit.relax.adaptive` do.  Every
kernel has a NumPy twin in ``tests/_twins_relax.py``.

Each node writes only its own outputs and sums its springs in CSR order,
so a ``prange`` over nodes gives bitwise the same result for any thread
count.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

#: Integrator modes of :func:`relax_nodes` (see docs/relaxation.md).
MODE_AXIAL = 0  # eq. (6), implicit stiffness k_jk per spring (the default)
MODE_SECANT = 1  # eq. (6) as printed, implicit stiffness max(E_jk, 0)
MODE_EXPLICIT = 2  # symplectic Euler (no prediction, no implicit stiffness)

#: Reassociation, contraction and reciprocal approximations only (no
#: "no-NaN" assumptions): lets LLVM vectorise the spring loop; still the
#: same result for every thread count.
FASTMATH = {"reassoc", "contract", "arcp"}

#: Each node's springs as :func:`relax_nodes` reads them (CSR over nodes): ``adj_offsets`` (n + 1,)
#: int64, the other ends ``adj_nodes``, the springs ``adj_springs``, their rest lengths
#: ``adj_rest`` (mm) and stiffnesses ``adj_stiffness`` (N/mm), and ``coefficients`` (s,) float64,
#: :func:`spring_coefficients` of the predicted positions, or empty (each node computes its own).
NodeSprings = namedtuple("NodeSprings", ["adj_offsets", "adj_nodes", "adj_springs", "adj_rest", "adj_stiffness",
                                         "coefficients"])
#: What else acts on each node (n,): ``node_stiffness`` (N/mm, the sum of its springs' k),
#: ``mass``, ``damping`` (1/s), the loads ``f_ext`` (n, 3) N and ``gravity`` (3,) mm/s^2.
NodeTerms = namedtuple("NodeTerms", ["node_stiffness", "mass", "damping", "f_ext", "gravity"])
#: Nodes' positions ``x`` (n, 3), velocities ``v`` (n, 3) and time stamps ``stamp`` (n,).
NodeStates = namedtuple("NodeStates", ["x", "v", "stamp"])
#: Where :func:`relax_nodes` writes: the :class:`NodeStates` fields, and each node's recent
#: accelerations ``accel_window`` (n, w) and update count ``n_updates`` (n,), updated in place.
NodeUpdates = namedtuple("NodeUpdates", ["x", "v", "stamp", "accel_window", "n_updates"])


@njit(cache=True, parallel=True, nogil=True)
def predict_positions(nodes, target_time, x, v, stamp, explicit, p):
    """Eq. (7) for ``nodes``: ``p[k] = x[k] + (target_time - stamp[k]) v[k]``.

    With ``explicit`` (symplectic Euler) ``p[k] = x[k]``.
    """
    for ii in prange(nodes.shape[0]):
        k = nodes[ii]
        h = 0.0 if explicit else target_time - stamp[k]
        p[k, 0] = x[k, 0] + h * v[k, 0]
        p[k, 1] = x[k, 1] + h * v[k, 1]
        p[k, 2] = x[k, 2] + h * v[k, 2]


@njit(cache=True, parallel=True, nogil=True, fastmath=FASTMATH)
def spring_coefficients(spring_a, spring_b, p, rest_length, stiffness, c_out):
    """Force coefficient of every spring at the predicted positions ``p``.

    ``c_out[s] = k_s (|d| - l_s) / |d|`` with ``d = p[b] - p[a]`` (minus the
    paper's E of eq. 6): one square root per spring instead of per spring end.
    """
    for s in prange(spring_a.shape[0]):
        a = spring_a[s]
        b = spring_b[s]
        d0 = p[b, 0] - p[a, 0]
        d1 = p[b, 1] - p[a, 1]
        d2 = p[b, 2] - p[a, 2]
        l2 = d0 * d0 + d1 * d1 + d2 * d2
        ks = stiffness[s]
        c_out[s] = ks - ks * rest_length[s] / np.sqrt(l2) if l2 > 0.0 else 0.0


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def _spring_forces_precomputed(k, p, springs, secant):
    """Spring force on node k (eq. 6) from the coefficients ``c_spring`` of :func:`spring_coefficients`,
    summed in CSR order, and with ``secant`` the implicit stiffness sum of max(c, 0).

    Returns
    -------
    (f0, f1, f2, kimp) : float
    """
    pk0 = p[k, 0]
    pk1 = p[k, 1]
    pk2 = p[k, 2]
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    kimp = 0.0
    for a in range(springs.adj_offsets[k], springs.adj_offsets[k + 1]):
        j = springs.adj_nodes[a]
        c = springs.coefficients[springs.adj_springs[a]]
        f0 += c * (p[j, 0] - pk0)
        f1 += c * (p[j, 1] - pk1)
        f2 += c * (p[j, 2] - pk2)
        if secant:
            kimp += max(c, 0.0)
    return f0, f1, f2, kimp


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def _spring_forces(k, p, springs, secant):
    """Spring force on node k (eq. 6) at the predicted positions ``p``, each spring's coefficient
    computed here, summed in CSR order; with ``secant`` also the sum of max(c, 0).

    Returns
    -------
    (f0, f1, f2, kimp) : float
    """
    pk0 = p[k, 0]
    pk1 = p[k, 1]
    pk2 = p[k, 2]
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    kimp = 0.0
    for a in range(springs.adj_offsets[k], springs.adj_offsets[k + 1]):
        j = springs.adj_nodes[a]
        d0 = p[j, 0] - pk0
        d1 = p[j, 1] - pk1
        d2 = p[j, 2] - pk2
        l2 = d0 * d0 + d1 * d1 + d2 * d2
        ks = springs.adj_stiffness[a]
        # physical force coefficient, minus the paper's E (eq. 6); 0 for coincident ends
        c = ks - ks * springs.adj_rest[a] / np.sqrt(l2) if l2 > 0.0 else 0.0
        f0 += c * d0
        f1 += c * d1
        f2 += c * d2
        if secant:
            kimp += max(c, 0.0)
    return f0, f1, f2, kimp


@njit(cache=True, nogil=True, inline="always")
def _store_node(x_out, v_out, k, x0, x1, x2, v0, v1, v2):
    """Write node k's position and velocity."""
    x_out[k, 0] = x0
    x_out[k, 1] = x1
    x_out[k, 2] = x2
    v_out[k, 0] = v0
    v_out[k, 1] = v1
    v_out[k, 2] = v2


@njit(cache=True, parallel=True, nogil=True, fastmath=FASTMATH)
def relax_nodes(nodes, target_time, before, after, p, springs, terms, mode, in_place):
    """Advance every node of ``nodes`` from its own time stamp to ``target_time``.

    The step of node k is ``target_time - before.stamp[k]`` (section 5.2,
    last paragraph).  ``p`` holds every node's position predicted to
    ``target_time`` by eq. (7) (:func:`predict_positions`), at least for
    ``nodes`` and their neighbours.  Where ``after`` is ``before`` (the same
    arrays: Gauss-Seidel over a colour class, no two listed nodes share a
    spring, ``in_place`` True) ``p[k]`` is set to the new position, so later classes use it as
    is (``in_place``).  ``springs.coefficients`` holds :func:`spring_coefficients` of ``p``
    (Jacobi sweeps) or is empty (then each node computes its springs').

    Parameters
    ----------
    nodes : (k,) int64
    target_time : float
    before : NodeStates
    after : NodeUpdates
        Written (its states may be ``before``'s arrays).
    p : (n, 3) float64
    springs : NodeSprings
    terms : NodeTerms
    mode : int
        :data:`MODE_AXIAL`, :data:`MODE_SECANT` or :data:`MODE_EXPLICIT`.
    in_place : bool
    """
    x, v, stamp = before.x, before.v, before.stamp
    x_out, v_out, stamp_out = after.x, after.v, after.stamp
    accel_window, n_updates = after.accel_window, after.n_updates
    mass, damping, f_ext, gravity = terms.mass, terms.damping, terms.f_ext, terms.gravity
    window = accel_window.shape[1]
    precomputed = springs.coefficients.shape[0] > 0
    secant = mode == MODE_SECANT
    for ii in prange(nodes.shape[0]):
        k = nodes[ii]
        h = target_time - stamp[k]
        xk0 = x[k, 0]
        xk1 = x[k, 1]
        xk2 = x[k, 2]
        vk0 = v[k, 0]
        vk1 = v[k, 1]
        vk2 = v[k, 2]
        if h <= 0.0:
            _store_node(x_out, v_out, k, xk0, xk1, xk2, vk0, vk1, vk2)
            stamp_out[k] = stamp[k]
            continue
        m = mass[k]
        if precomputed:
            f0, f1, f2, kimp = _spring_forces_precomputed(k, p, springs, secant)
        else:
            f0, f1, f2, kimp = _spring_forces(k, p, springs, secant)
        if mode == MODE_AXIAL:
            kimp = terms.node_stiffness[k]
        # m (v' - v) = h (f - D v' + F* - K (x' - p)),  x' - p = h (v' - v)
        fx0 = f_ext[k, 0] + m * gravity[0] + f0
        fx1 = f_ext[k, 1] + m * gravity[1] + f1
        fx2 = f_ext[k, 2] + m * gravity[2] + f2
        hk = h * h * kimp
        den = m + h * damping[k] * m + hk
        nv0 = ((m + hk) * vk0 + h * fx0) / den
        nv1 = ((m + hk) * vk1 + h * fx1) / den
        nv2 = ((m + hk) * vk2 + h * fx2) / den
        a0 = (nv0 - vk0) / h
        a1 = (nv1 - vk1) / h
        a2 = (nv2 - vk2) / h
        slot = n_updates[k] % window
        accel_window[k, slot] = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        n_updates[k] += 1
        nx0 = xk0 + h * nv0
        nx1 = xk1 + h * nv1
        nx2 = xk2 + h * nv2
        _store_node(x_out, v_out, k, nx0, nx1, nx2, nv0, nv1, nv2)
        stamp_out[k] = target_time
        if in_place:
            p[k, 0] = nx0
            p[k, 1] = nx1
            p[k, 2] = nx2


@njit(cache=True, nogil=True)
def greedy_colouring(adj_offsets, adj_nodes, n_nodes):
    """Greedy colouring of the spring graph in node order.

    Returns ``colour`` (n,) int32 with ``colour[j] != colour[k]`` for every
    spring (j, k); at most max degree + 1 colours.
    """
    colour = np.full(n_nodes, -1, np.int32)
    max_deg = 0
    for k in range(n_nodes):
        deg = adj_offsets[k + 1] - adj_offsets[k]
        if deg > max_deg:
            max_deg = deg
    used = np.full(max_deg + 2, -1, np.int64)
    for k in range(n_nodes):
        for a in range(adj_offsets[k], adj_offsets[k + 1]):
            c = colour[adj_nodes[a]]
            if c >= 0:
                used[c] = k
        c = 0
        while used[c] == k:
            c += 1
        colour[k] = c
    return colour


@njit(cache=True, parallel=True, nogil=True)
def spring_forces(x, adj_offsets, adj_nodes, adj_rest, adj_stiffness):
    """Physical spring force on every node (minus eq. (3)'s F_spring), N.

    Returns ``forces`` (n, 3) float64.
    """
    n = adj_offsets.shape[0] - 1
    out = np.zeros((n, 3))
    for k in prange(n):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for a in range(adj_offsets[k], adj_offsets[k + 1]):
            j = adj_nodes[a]
            d0 = x[j, 0] - x[k, 0]
            d1 = x[j, 1] - x[k, 1]
            d2 = x[j, 2] - x[k, 2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if length > 0.0:
                c = adj_stiffness[a] * (length - adj_rest[a]) / length
                f0 += c * d0
                f1 += c * d1
                f2 += c * d2
        out[k, 0] = f0
        out[k, 1] = f1
        out[k, 2] = f2
    return out


@njit(cache=True, nogil=True)
def halo_nodes(nodes, adj_offsets, adj_nodes, n_nodes):
    """``nodes`` and all their spring neighbours, ascending: (h,) int64."""
    mark = np.zeros(n_nodes, np.bool_)
    for ii in range(nodes.shape[0]):
        k = nodes[ii]
        mark[k] = True
        for a in range(adj_offsets[k], adj_offsets[k + 1]):
            mark[adj_nodes[a]] = True
    return np.flatnonzero(mark).astype(np.int64)


@njit(cache=True, nogil=True)
def spring_csr(spring_a, spring_b, n_nodes):
    """CSR spring graph by counting sort: rows by node, columns ascending.

    Parameters
    ----------
    spring_a, spring_b : (s,) int64
        The two nodes of each spring.
    n_nodes : int

    Returns
    -------
    offsets : (n + 1,) int64
    adj_nodes : (2 s,) int32
        Other end of each spring of node k in ``offsets[k]:offsets[k + 1]``, ascending.
    adj_springs : (2 s,) int32
        The spring ids, in the same order.
    """
    s = spring_a.shape[0]
    offsets = np.zeros(n_nodes + 1, np.int64)
    for i in range(s):
        offsets[spring_a[i] + 1] += 1
        offsets[spring_b[i] + 1] += 1
    for k in range(n_nodes):
        offsets[k + 1] += offsets[k]
    fill = offsets[:-1].copy()
    adj_nodes = np.empty(2 * s, np.int32)
    adj_springs = np.empty(2 * s, np.int32)
    for i in range(s):
        a = spring_a[i]
        b = spring_b[i]
        adj_nodes[fill[a]] = b
        adj_springs[fill[a]] = i
        fill[a] += 1
        adj_nodes[fill[b]] = a
        adj_springs[fill[b]] = i
        fill[b] += 1
    # rows are short (a node has tens of springs): insertion sort by (node, spring)
    for k in range(n_nodes):
        lo = offsets[k]
        hi = offsets[k + 1]
        for p in range(lo + 1, hi):
            vn = adj_nodes[p]
            vs = adj_springs[p]
            q = p - 1
            while q >= lo and (adj_nodes[q] > vn or (adj_nodes[q] == vn and adj_springs[q] > vs)):
                adj_nodes[q + 1] = adj_nodes[q]
                adj_springs[q + 1] = adj_springs[q]
                q -= 1
            adj_nodes[q + 1] = vn
            adj_springs[q + 1] = vs
    return offsets, adj_nodes, adj_springs


@njit(cache=True, parallel=True, nogil=True)
def gather_spring_arrays(adj_offsets, adj_springs, rest_length, stiffness, adj_rest, adj_stiffness, node_stiffness):
    """Rest lengths and stiffnesses in CSR order, and each node's total stiffness, in one pass.

    ``adj_rest[a] = rest_length[adj_springs[a]]`` and the same for
    ``adj_stiffness``; ``node_stiffness[k]`` is the sum of ``stiffness`` over
    node k's springs (its CSR row).  A cut refreshes these every geometry
    update; one parallel pass replaces two gathers and a bincount.

    adj_rest, adj_stiffness : (2 s,) float64 out; node_stiffness : (n,) float64 out.
    """
    for k in prange(adj_offsets.shape[0] - 1):
        total = 0.0
        for a in range(adj_offsets[k], adj_offsets[k + 1]):
            sp = adj_springs[a]
            adj_rest[a] = rest_length[sp]
            ks = stiffness[sp]
            adj_stiffness[a] = ks
            total += ks
        node_stiffness[k] = total
