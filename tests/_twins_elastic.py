"""Slow, obviously correct NumPy twins of cutkit.relax._elastic_kernels."""

import numpy as np


def deformation_gradients(x, tets, Dminv):
    """F = Ds Dminv of every tet: (m, 3, 3)."""
    p = x[tets]
    Ds = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    return Ds @ Dminv


BARRIER_J = 0.1  # as cutkit.relax._elastic_kernels.BARRIER_J


def barrier(J, k):
    """-k (J - Jb)^2 ln(J / Jb) for 0 < J < Jb, else 0, and its derivative in J (by sympy-free hand)."""
    inside = (J > 0) & (J < BARRIER_J)
    Js = np.where(inside, J, BARRIER_J)
    d, ln = Js - BARRIER_J, np.log(Js / BARRIER_J)
    return np.where(inside, -k * d * d * ln, 0.0), np.where(inside, -k * (2 * d * ln + d * d / Js), 0.0)


def energy(x, tets, Dminv, volume, mu, lam):
    """sum V [mu/2 (|F|^2 - 3) - mu (J - 1) + (lam + mu)/2 (J - 1)^2 + b(J)]."""
    F = deformation_gradients(x, tets, Dminv)
    J = np.linalg.det(F)
    ic = np.einsum("mij,mij->m", F, F)
    psi = 0.5 * mu * (ic - 3.0) - mu * (J - 1.0) + 0.5 * (lam + mu) * (J - 1.0) ** 2 + barrier(J, lam + mu)[0]
    return float(np.sum(volume * psi))


def forces(x, tets, Dminv, volume, mu, lam):
    """-dW/dx from P = mu F + ((lam + mu)(J - 1) - mu) J F^-T: (n, 3)."""
    F = deformation_gradients(x, tets, Dminv)
    J = np.linalg.det(F)
    G = J[:, None, None] * np.linalg.inv(F).transpose(0, 2, 1)
    P = mu[:, None, None] * F + ((lam + mu) * (J - 1.0) - mu + barrier(J, lam + mu)[1])[:, None, None] * G
    # dF/dx_j = I (x) b_j, b_j = row j-1 of Dminv, b_0 = -sum
    B = np.concatenate([-Dminv.sum(axis=1, keepdims=True), Dminv], axis=1)  # (m, 4, 3)
    g = np.einsum("mrc,mjc->mjr", P, B) * volume[:, None, None]  # (m, 4, 3) dW/dx_j
    out = np.zeros_like(x)
    np.add.at(out, tets.ravel(), -g.reshape(-1, 3))
    return out


def node_hessian_fd(x, i, tets, Dminv, volume, mu, lam, h=1e-6):
    """d2W/dx_i^2 by central differences of the twin's forces: (3, 3)."""
    H = np.zeros((3, 3))
    for c in range(3):
        xp, xm = x.copy(), x.copy()
        xp[i, c] += h
        xm[i, c] -= h
        H[:, c] = -(forces(xp, tets, Dminv, volume, mu, lam)[i] - forces(xm, tets, Dminv, volume, mu, lam)[i]) / (2 * h)
    return H


def vbd_sweep(x, tets, Dminv, volume, mu, lam, inertia, target, force, fixed, order, newton_steps=1,
              line_search=True):
    """Gauss-Seidel over ``order``: each node moves by Newton steps on its own incremental potential.

    Uses finite-difference Hessians of the twin's forces, so it shares no
    formula with the kernel.  Each step goes to the minimum of the node's
    potential along it (``line_search``), else as far as the step limit lets it.
    """
    x = x.copy()
    for i in order:
        for _ in range(newton_steps):
            f = forces(x, tets, Dminv, volume, mu, lam)[i] + inertia[i] * (target[i] - x[i]) + force[i]
            H = node_hessian_fd(x, i, tets, Dminv, volume, mu, lam) + inertia[i] * np.eye(3)
            for c in range(3):
                if fixed[i, c]:
                    f[c] = 0.0
                    H[c, :] = 0.0
                    H[:, c] = 0.0
                    H[c, c] = 1.0
            d = np.linalg.solve(H, f)
            a_max = step_limit(x, i, d, tets, volume)
            args = (tets, Dminv, volume, mu, lam, inertia, target, force, fixed)
            x[i] += (line_minimum(x, i, d, a_max, *args) if line_search else a_max) * d
    return x


def node_slope(x, i, d, a, tets, Dminv, volume, mu, lam, inertia, target, force, fixed):
    """d/da of node i's incremental potential at x_i + a d: -(its out-of-balance force) . d."""
    y = x.copy()
    y[i] += a * d
    f = forces(y, tets, Dminv, volume, mu, lam)[i] + inertia[i] * (target[i] - y[i]) + force[i]
    f[fixed[i]] = 0.0
    return -float(f @ d)


def line_minimum(x, i, d, a_max, *args):
    """The a in [0, a_max] minimising node i's potential along d: bisection
    on its slope (increasing: the potential is convex along d), from the twin's forces."""
    if node_slope(x, i, d, a_max, *args) <= 0.0:
        return a_max
    lo, hi = 0.0, a_max
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if node_slope(x, i, d, mid, *args) < 0.0 else (lo, mid)
    return 0.5 * (lo + hi)


def potential(x, tets, Dminv, volume, mu, lam, inertia, target, force):
    """The incremental potential a sweep lowers: W + sum m/(2 h^2) |x - y|^2 - f . x."""
    return (energy(x, tets, Dminv, volume, mu, lam) + 0.5 * float(np.sum(inertia[:, None] * (x - target) ** 2))
            - float(np.sum(force * x)))


def step_limit(x, i, d, tets, volume, keep=0.1):
    """Largest a <= 1 keeping det Ds of every non-inverted tet of node i at >= keep of its value.

    det Ds is affine in x_i, so its change along d is det(x + d) - det(x)."""
    a = 1.0
    for t in np.flatnonzero((tets == i).any(axis=1) & (volume > 0)):
        p = x[tets[t]]
        q = p.copy()
        q[list(tets[t]).index(i)] += d
        d0 = np.linalg.det(np.stack([p[1] - p[0], p[2] - p[0], p[3] - p[0]], axis=1))
        d1 = np.linalg.det(np.stack([q[1] - q[0], q[2] - q[0], q[3] - q[0]], axis=1))
        if d0 > 0 and d1 - d0 < 0:
            a = min(a, (1 - keep) * d0 / (d0 - d1))
    return a


def awake_after_sweep(tets, movable, r2, tau2, nodes):
    """Of ``nodes``, those with r2 > tau2, with every node sharing a tet: the movable ones, ascending."""
    hot = [i for i in np.asarray(nodes) if r2[i] > tau2]
    near = set(int(i) for i in hot)
    for t in np.asarray(tets):
        if any(int(i) in t for i in hot):
            near.update(int(c) for c in t)
    return np.array(sorted(i for i in near if movable[i]), np.int64)


def step_seeds(masses, fixed, degree, velocities, r2, h, tau2, seeds):
    """(movable, r2 with the immovable zeroed, the first nodes to wake) of a local step."""
    movable = ~fixed.all(axis=1) & (degree > 0)
    r2 = np.where(movable, r2, 0.0)
    moving = movable & (masses * np.linalg.norm(velocities, axis=1) / h > np.sqrt(tau2))
    wake = np.unique(np.concatenate([np.asarray(seeds, np.int64), np.flatnonzero(moving),
                                     np.flatnonzero(movable & (r2 > tau2))]))
    return movable, r2, wake


def rest_shape(X, tets, prestrain=None, fibre=None, quality_min=1e-6):
    """Inverse natural edge matrices, natural and rest volumes (NumPy's batched det and inv)."""
    p = X[tets]
    Dm = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns
    rest_volume = np.linalg.det(Dm) / 6.0
    if prestrain is not None:
        ff = np.einsum("mi,mj->mij", fibre, fibre)
        Dm = Dm - prestrain[:, None, None] * np.einsum("mij,mjk->mik", ff, Dm)
    volume = np.linalg.det(Dm) / 6.0
    edges = np.concatenate([Dm, Dm[:, :, [1, 2, 0]] - Dm], axis=2)
    l_rms = np.sqrt(np.einsum("mij,mij->m", edges, edges) / 6.0)
    quality = 6.0 * np.sqrt(2.0) * volume / np.maximum(l_rms, 1e-300) ** 3
    active = quality >= quality_min
    Dminv = np.zeros_like(Dm)
    if active.any():
        Dminv[active] = np.linalg.inv(Dm[active])
    return Dminv, np.where(active, volume, 0.0), rest_volume


def node_term_rows(Dminv, volume, mu, lam):
    """The per-tet constants of a node update by NumPy: (m, 9) float64 (the six edge weights
    V mu b_j . b_c, then 1 / (6 V) where V > 0, V (lam + mu), V mu)."""
    B = np.concatenate([-Dminv.sum(axis=1, keepdims=True), Dminv], axis=1)  # (m, 4, 3)
    L = np.einsum("mjd,mcd->mjc", B, B)
    out = np.zeros((Dminv.shape[0], 9))
    for col, (j, c) in enumerate([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]):
        out[:, col] = volume * mu * L[:, j, c]
    active = volume > 0
    out[active, 6] = 1.0 / (6.0 * volume[active])
    out[:, 7] = volume * (lam + mu)
    out[:, 8] = volume * mu
    return out


def make_room_twin(start, degree, capacity, slots, corners, used, slack):
    """Rows too small for their new slots moved to the pool's end by NumPy (as ElementModel did):
    returns start, capacity, the slot arrays (a dict of copies) and the slots in use."""
    nodes, more = np.unique(corners, return_counts=True)
    start, capacity = start.copy(), capacity.copy()
    need = degree[nodes] + more
    grow = need > capacity[nodes]
    short = nodes[grow]
    cap = np.maximum(2 * capacity[short], need[grow] + slack)
    new_start = used + np.concatenate([[0], np.cumsum(cap)[:-1]]).astype(np.int64)
    end = used + int(cap.sum())
    out = {}
    for name, a in slots.items():
        b = np.zeros((max(end, a.shape[0]),) + a.shape[1:], a.dtype)
        b[:used] = a[:used]
        for i, s in zip(short, new_start):
            b[s:s + degree[i]] = a[start[i]:start[i] + degree[i]]
        out[name] = b
    start[short] = new_start
    capacity[short] = cap
    return start, capacity, out, end


def copy_rows_twin(start, degree, slots, nodes, new_start, size):
    """A fresh pool of ``size`` slots holding the row of each ``nodes[i]`` at ``new_start[i]``:
    gather the old slots, scatter them (``slots``: name -> array, as in make_room_twin)."""
    deg = degree[nodes].astype(np.int64)
    src = np.concatenate([np.arange(start[v], start[v] + d) for v, d in zip(nodes, deg)] + [np.zeros(0, np.int64)])
    dst = np.concatenate([np.arange(s, s + d) for s, d in zip(new_start, deg)] + [np.zeros(0, np.int64)])
    out = {}
    for name, old in slots.items():
        new = np.zeros((size,) + old.shape[1:], old.dtype)
        new[dst] = old[src]
        out[name] = new
    return out
