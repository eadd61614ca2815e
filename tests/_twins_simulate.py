"""Slow, obviously correct twins of cutkit.relax._handover_kernels."""

import numpy as np


def lookup_springs_twin(springs, n, a, b):
    """Spring index of each pair (either orientation), -1 where none or a node >= n."""
    index = {}
    for s, (u, w) in enumerate(np.asarray(springs)):
        index.setdefault((int(u), int(w)), s)
        index.setdefault((int(w), int(u)), s)
    return np.array([index.get((int(u), int(w)), -1) if u < n and w < n else -1 for u, w in zip(a, b)], np.int64)


def place_through_old_shape_twin(rest, X, x, Tinv, reach, fallback):
    """Each node through the affine map of the tet with the largest smallest barycentric weight
    (first on a tie) when that weight is >= -reach, else ``fallback``: all pairs at once."""
    lam = np.einsum("rij,prj->pri", Tinv, rest[:, None, :] - X[None, :, 0])
    bary = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)  # (p, r, 4)
    worst = bary.min(axis=2)
    best = np.argmax(worst, axis=1)
    rows = np.arange(best.size)
    inside = worst[rows, best] >= -reach
    return np.where(inside[:, None], np.einsum("pk,pkc->pc", bary[rows, best], x[best]), fallback)


def old_shape_corners_twin(tets, X, x, n, moved, moved_from):
    """Rest (moved nodes at their old place) and current corners and inverse rest edge matrices of
    the tets with every corner < n and a non-zero rest volume, by NumPy."""
    q = tets[np.all(tets < n, axis=1)]
    Xc = X[q]
    for b, a in enumerate(moved):
        Xc[q == a] = moved_from[b]
    T = np.stack([Xc[:, 1] - Xc[:, 0], Xc[:, 2] - Xc[:, 0], Xc[:, 3] - Xc[:, 0]], axis=2)
    ok = np.linalg.det(T) != 0.0
    return Xc[ok], x[q][ok], np.linalg.inv(T[ok])


def step_tet_sets_twin(added, removed, around):
    """The hand-over's tet sets by NumPy's set operations (as ElasticTissue.apply_cut did)."""
    both = np.intersect1d(added, removed)
    added, removed = np.setdiff1d(added, both), np.setdiff1d(removed, both)
    again = np.setdiff1d(around, np.concatenate([added, removed]))
    return added, removed, again, np.union1d(removed, around)



def nodes_near_blade_twin(x, back, tip, radius, nodes):
    """{node: squared distance} of the nodes of ``nodes`` within ``radius`` of the blade segment from
    ``back`` to ``tip`` (each (3,)), by checking each."""
    d = tip - back
    out = {}
    for i in nodes:
        s = min(max(float(np.dot(x[i] - back, d)) / float(d @ d), 0.0), 1.0)
        d2 = float(np.sum((x[i] - (back + s * d)) ** 2))
        if d2 < radius ** 2:
            out[int(i)] = d2
    return out


def rest_displacement_twin(x, X, nodes, tip, axis, length, radius):
    """The weighted mean displacement of ``nodes`` around the blade, node by node (None: no weight)."""
    back = tip - length * axis
    usum, wsum = np.zeros(3), 0.0
    for i in nodes:
        s = min(max(float(np.dot(x[i] - back, axis)) / length, 0.0), 1.0)
        d = np.linalg.norm(x[i] - (back + s * length * axis))
        if d < radius:
            w = (1.0 - (d / radius) ** 2) ** 3
            usum += w * (x[i] - X[i])
            wsum += w
    return usum / wsum if wsum > 0 else None
