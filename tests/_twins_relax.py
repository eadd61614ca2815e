"""Slow, obviously correct NumPy twins of the relaxation kernels and test meshes."""

from __future__ import annotations

import numpy as np

# the six tets of a unit cube sharing the diagonal 0-7 (Kuhn triangulation);
# corner c = (c & 1, (c >> 1) & 1, (c >> 2) & 1)
_KUHN = np.array(
    [[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]],
    np.int64,
)


def kuhn_grid(nx, ny, nz, h=1.0, origin=(0.0, 0.0, 0.0)):
    """Box of nx*ny*nz cubes of edge h, six positively oriented tets per cube.

    Returns points (n, 3) float64 and tets (6 nx ny nz, 4) int64.
    """
    ii, jj, kk = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    points = np.stack([ii, jj, kk], -1).reshape(-1, 3) * float(h) + np.asarray(origin, float)

    def nid(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    ci, cj, ck = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    ci, cj, ck = ci.ravel(), cj.ravel(), ck.ravel()
    corners = np.stack([nid(ci + (c & 1), cj + ((c >> 1) & 1), ck + ((c >> 2) & 1)) for c in range(8)], 1)
    tets = corners[:, _KUHN].reshape(-1, 4)
    p = points[tets]
    det = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return points, tets


def relax_nodes_twin(nodes, target_time, x, v, stamp, springs, rest, stiffness, mass, damping, f_ext, gravity, mode,
                     gauss_seidel_order=None):
    """Twin of ``_kernels.relax_nodes`` one node at a time, springs from the (s, 2) list.

    Jacobi unless ``gauss_seidel_order`` is given (then nodes in that order, in place).
    Returns new x, v, stamp.
    """
    x_in, v_in, ts_in = x.copy(), v.copy(), stamp.copy()
    x_out, v_out, ts_out = x.copy(), v.copy(), stamp.copy()
    order = nodes if gauss_seidel_order is None else gauss_seidel_order
    for k in order:
        src = (x_out, v_out, ts_out) if gauss_seidel_order is not None else (x_in, v_in, ts_in)
        xs, vs, ss = src
        h = target_time - ss[k]
        if h <= 0:
            continue
        pk = xs[k] if mode == 2 else xs[k] + h * vs[k]
        force = np.zeros(3)
        kimp = 0.0
        for s, (a, b) in enumerate(springs):
            if k not in (a, b):
                continue
            j = b if a == k else a
            hj = 0.0 if mode == 2 else target_time - ss[j]
            d = xs[j] + hj * vs[j] - pk
            length = np.linalg.norm(d)
            c = stiffness[s] * (length - rest[s]) / length
            force += c * d
            kimp += stiffness[s] if mode == 0 else (max(c, 0.0) if mode == 1 else 0.0)
        m = mass[k]
        total = f_ext[k] + m * gravity + force
        nv = ((m + h * h * kimp) * vs[k] + h * total) / (m + h * damping[k] * m + h * h * kimp)
        x_out[k] = xs[k] + h * nv
        v_out[k] = nv
        ts_out[k] = target_time
    return x_out, v_out, ts_out


def spring_forces_twin(x, springs, rest, stiffness):
    """Physical spring force per node, spring by spring."""
    f = np.zeros_like(x)
    for s, (a, b) in enumerate(springs):
        d = x[b] - x[a]
        length = np.linalg.norm(d)
        fa = stiffness[s] * (length - rest[s]) / length * d
        f[a] += fa
        f[b] -= fa
    return f


def greedy_colouring_twin(springs, n):
    """Greedy colouring in node order with Python sets."""
    nbrs = [set() for _ in range(n)]
    for a, b in springs:
        nbrs[a].add(b)
        nbrs[b].add(a)
    colour = [-1] * n
    for k in range(n):
        used = {colour[j] for j in nbrs[k]}
        c = 0
        while c in used:
            c += 1
        colour[k] = c
    return np.array(colour)


def halo_nodes_twin(nodes, springs):
    """Nodes and their spring neighbours with set operations."""
    out = set(int(k) for k in nodes)
    chosen = set(out)
    for a, b in springs:
        if a in chosen:
            out.add(int(b))
        if b in chosen:
            out.add(int(a))
    return np.array(sorted(out), np.int64)


def spring_coefficients_twin(springs, p, rest, stiffness):
    """k (|d| - l) / |d| spring by spring."""
    return np.array([stiffness[s] * (np.linalg.norm(p[b] - p[a]) - rest[s]) / np.linalg.norm(p[b] - p[a])
                     for s, (a, b) in enumerate(springs)])


def spring_csr_twin(springs, n):
    """CSR of the spring graph by a lexicographic sort of (node, other end, spring)."""
    springs = np.asarray(springs, np.int64)
    src = np.concatenate([springs[:, 0], springs[:, 1]])
    dst = np.concatenate([springs[:, 1], springs[:, 0]])
    sid = np.concatenate([np.arange(len(springs)), np.arange(len(springs))])
    order = np.lexsort((sid, dst, src))
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=offsets[1:])
    return offsets, dst[order], sid[order]


def gather_spring_arrays_twin(springs, adj_springs, rest_length, stiffness, n):
    """CSR-ordered rest lengths and stiffnesses, and per-node stiffness sums, by NumPy indexing."""
    return rest_length[adj_springs], stiffness[adj_springs], np.bincount(springs.ravel(), np.repeat(stiffness, 2), minlength=n)


def volume_forces_twin(x, tets, rest_volume, bulk):
    """Forces (n, 3) and diagonal stiffnesses (n,) of the volume term, tet by tet with NumPy."""
    f = np.zeros_like(x)
    k = np.zeros(x.shape[0])
    for t, (a, b, c, d) in enumerate(tets):
        V = np.linalg.det(np.stack([x[b] - x[a], x[c] - x[a], x[d] - x[a]])) / 6.0
        grads = {b: np.cross(x[c] - x[a], x[d] - x[a]) / 6.0,
                 c: np.cross(x[d] - x[a], x[b] - x[a]) / 6.0,
                 d: np.cross(x[b] - x[a], x[c] - x[a]) / 6.0}
        grads[a] = -(grads[b] + grads[c] + grads[d])
        for node, g in grads.items():
            f[node] -= bulk[t] * (V - rest_volume[t]) / rest_volume[t] * g
            k[node] += bulk[t] * g @ g / rest_volume[t]
    return f, k


def graph_components_twin(springs, n):
    """Connected components of the spring graph (scipy): (n_components, (n,) labels), numbered in
    order of their smallest node."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    s = np.asarray(springs, np.int64).reshape(-1, 2)
    g = coo_matrix((np.ones(len(s)), (s[:, 0], s[:, 1])), shape=(n, n))
    k, lab = connected_components(g, directed=False)
    # renumber by smallest node
    first = {}
    out = np.empty(n, np.int64)
    for i, c in enumerate(lab.tolist()):
        out[i] = first.setdefault(c, len(first))
    return k, out
