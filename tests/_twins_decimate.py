"""NumPy twins of the decimation kernels and a voxel-shape mesh generator for the tests."""

from __future__ import annotations

from itertools import combinations

import numpy as np

from cutkit.mesh.generate import KUHN_TETS


def voxel_ellipsoid(n=16, radii=(0.45, 0.4, 0.35), inner=None, spacing=1.0):
    """Kuhn-split voxels whose centres lie inside an ellipsoid (two labels optional).

    Parameters
    ----------
    n : int
        Voxels per axis of the bounding grid.
    radii : (3,) float
        Semi-axes as fractions of the grid size.
    inner : float, optional
        Voxels with normalised radius below ``inner`` get label 2 (else 1).

    Returns
    -------
    points : (n_points, 3) float64
    tets : (m, 4) int64, positively oriented
    labels : (m,) int32
    """
    c = (np.arange(n) + 0.5) / n - 0.5
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt((x / radii[0]) ** 2 + (y / radii[1]) ** 2 + (z / radii[2]) ** 2)
    inside = r <= 1.0
    ci, cj, ck = np.nonzero(inside)
    vox_label = np.where((inner is not None) & (r[ci, cj, ck] < (inner or 0)), 2, 1).astype(np.int32)

    def node(i, j, k):
        return (i * (n + 1) + j) * (n + 1) + k

    tets = np.empty((6 * ci.size, 4), np.int64)
    for t, corners in enumerate(KUHN_TETS):
        for v, (a, b, cc) in enumerate(corners):
            tets[t::6, v] = node(ci + a, cj + b, ck + cc)
    labels = np.repeat(vox_label, 6)
    g = np.arange(n + 1) * spacing
    gi, gj, gk = np.meshgrid(g, g, g, indexing="ij")
    points = np.stack([gi.ravel(), gj.ravel(), gk.ravel()], axis=1).astype(np.float64)
    p = points[tets]
    det = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    neg = det < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    used = np.unique(tets)
    renum = np.full(points.shape[0], -1, np.int64)
    renum[used] = np.arange(used.size)
    return points[used], renum[tets], labels


# --------------------------------------------------------------------------- geometry twins


def volume6(points, tets):
    """6 * signed volume of each tet: (m,) float64."""
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])


def dihedral_angles(points, tets):
    """The six dihedral angles of each tet, degrees: (m, 6) float64 (slow, obvious)."""
    p = points[tets]
    out = np.empty((tets.shape[0], 6))
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    for e, (a, b) in enumerate(pairs):
        c, d = [k for k in range(4) if k not in (a, b)]
        axis = p[:, b] - p[:, a]
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        # Components of the two other vertices perpendicular to the edge.
        vc = p[:, c] - p[:, a]
        vd = p[:, d] - p[:, a]
        vc -= np.sum(vc * axis, axis=1, keepdims=True) * axis
        vd -= np.sum(vd * axis, axis=1, keepdims=True) * axis
        cosang = np.sum(vc * vd, axis=1) / (np.linalg.norm(vc, axis=1) * np.linalg.norm(vd, axis=1))
        out[:, e] = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
    return out


def min_dihedral(points, tets):
    return dihedral_angles(points, tets).min(axis=1)


def point_triangle_distance(p, a, b, c, n_grid=400):
    """Distance from p to triangle abc by dense barycentric sampling plus the exact edges."""
    best = np.inf
    for s, e in ((a, b), (b, c), (c, a)):
        d = e - s
        t = np.clip(np.dot(p - s, d) / max(np.dot(d, d), 1e-300), 0.0, 1.0)
        best = min(best, np.linalg.norm(p - (s + t * d)))
    n = np.cross(b - a, c - a)
    nn = np.dot(n, n)
    if nn > 0:
        q = p - np.dot(p - a, n) / nn * n
        # barycentric of the projection
        v0, v1, v2 = b - a, c - a, q - a
        d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
        d20, d21 = v2 @ v0, v2 @ v1
        den = d00 * d11 - d01 * d01
        beta = (d11 * d20 - d01 * d21) / den
        gamma = (d00 * d21 - d01 * d20) / den
        if beta >= 0 and gamma >= 0 and beta + gamma <= 1:
            best = min(best, np.linalg.norm(p - q))
    return best


# --------------------------------------------------------------------------- topology twins


def faces_of(tets):
    """All 4 m faces, sorted ids: (4m, 3) int64, and the tet of each: (4m,)."""
    f = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    owner = np.tile(np.arange(tets.shape[0]), 4)
    return np.sort(f, axis=1), owner


def boundary_faces(points, tets):
    """Boundary faces, outward oriented: (b, 3) int64."""
    loc = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    f_all = np.concatenate([tets[:, l] for l in loc])
    key = np.sort(f_all, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return f_all[cnt[inv.ravel()] == 1]


def surface_faces_twin(tets, labels, x):
    """S-faces (boundary or interface) containing vertex x: set of (frozenset(face), sheet)."""
    key, owner = faces_of(tets)
    out = set()
    has = np.any(key == x, axis=1)
    groups = {}
    for f, t in zip(map(tuple, key[has]), owner[has]):
        groups.setdefault(f, []).append(t)
    for f, ts in groups.items():
        if len(ts) == 1:
            out.add((frozenset(f), (-1, int(labels[ts[0]]))))
        elif labels[ts[0]] != labels[ts[1]]:
            a, b = sorted((int(labels[ts[0]]), int(labels[ts[1]])))
            out.add((frozenset(f), (a, b)))
    return out


def link_condition(tets, u, v, surface=None):
    """Edelsbrunner's link condition Lk(u) & Lk(v) == Lk(uv), by brute force on simplices.

    ``surface`` : optional set of S-faces (frozensets) coned to a virtual vertex -1.
    """
    simplices = set()
    for t in tets:
        t = [int(a) for a in t]
        for r in range(1, 5):
            for s in combinations(sorted(t), r):
                simplices.add(frozenset(s))
    if surface:
        for f in surface:
            f = sorted(f)
            for r in range(0, 4):
                for s in combinations(f, r):
                    simplices.add(frozenset(s) | {-1})

    def link(s):
        s = frozenset(s)
        return {frozenset(x - s) for x in simplices if s <= x and x != s}

    return (link({u}) & link({v})) == link({u, v})


def cheapest_neighbours_twin(points, tets, vclass, star, u, w_surface, w_touch, k):
    """The ``k`` cheapest allowed half-edges ``u -> w`` of the star ``star`` (tet ids in list order).

    Neighbours in order of first appearance in the star, stable-sorted by
    ``(factor |u w|)^2`` (factor 1, ``1 + w_touch``, ``w_surface``; surface onto
    interior is never allowed).  Returns ``(neighbours, keys)``.
    """
    seen = []
    for t in star:
        for w in tets[t]:
            if w != u and w not in seen:
                seen.append(int(w))
    keys = []
    for w in seen:
        if vclass[u] and not vclass[w]:
            keys.append(np.inf)
            continue
        f = w_surface if vclass[u] else (1.0 + w_touch if vclass[w] else 1.0)
        keys.append(f * f * float(np.sum((points[u] - points[w]) ** 2)))
    keys = np.array(keys)
    order = [i for i in np.argsort(keys, kind="stable") if np.isfinite(keys[i])][:k]
    return [seen[i] for i in order], keys[order]


def moved_tets_volume6(points, tets, star, u, x):
    """6 * volume of the tets of ``star`` without ``x`` once ``u`` is replaced by vertex ``x``."""
    moved = np.array([t for t in star if x not in tets[t]], np.int64)
    new = tets[moved].copy()
    new[new == u] = x
    return volume6(points, new)


def legal_collapse_twin(points, tets, labels, u, v, cos_min, tol, normal_cos, locked=()):
    """Slow reference of the legality rules 1, 2 and 3a-3c (not the accumulated distance)."""
    if u in locked:
        return False
    star_u = np.flatnonzero(np.any(tets == u, axis=1))
    dying = [t for t in star_u if v in tets[t]]
    if not dying:
        return False
    moved = np.array([t for t in star_u if v not in tets[t]], np.int64)
    new = tets[moved].copy()
    new[new == u] = v
    old_worst = np.cos(np.radians(min_dihedral(points, tets[star_u]).min()))
    thr = max(cos_min, old_worst)
    if moved.size:
        if np.any(volume6(points, new) <= 0):
            return False
        if np.any(np.cos(np.radians(min_dihedral(points, new))) > thr + 1e-12):
            return False
    # no vertex may be left without tets
    after = tets.copy()
    after[after == u] = v
    keep = np.array([len(set(t)) == 4 for t in after])
    used_after = set(np.unique(after[keep]).tolist())
    if set(np.unique(tets).tolist()) - {u} - used_after:
        return False
    su = surface_faces_twin(tets, labels, u)
    sv = surface_faces_twin(tets, labels, v)
    if not link_condition(tets, u, v):
        return False
    if su:
        sheets = {s for _, s in su}
        for s in sheets:
            if not any(v in f for f, s2 in su if s2 == s):
                return False
        all_s = {f for f, _ in su} | {f for f, _ in sv}
        if not link_condition(tets, u, v, surface=all_s):
            return False
    return True


def points_to_triangles_distance(query, points, faces, k=16):
    """Distance of each query point to the closest of the triangles (exact, vectorised).

    Candidates are the ``k`` triangles with the nearest centroids (scipy cKDTree),
    plus the triangles around the nearest vertex, so the answer is exact unless a
    triangle is much larger than its neighbours.
    """
    from scipy.spatial import cKDTree

    tri = points[faces]
    cen = tri.mean(axis=1)
    k = min(k, faces.shape[0])
    _, cand = cKDTree(cen).query(query, k=k)
    cand = cand.reshape(query.shape[0], -1)
    a, b, c = tri[cand, 0], tri[cand, 1], tri[cand, 2]
    p = query[:, None, :]
    return np.sqrt(_pt_tri_dist2_vec(p, a, b, c).min(axis=1))


def _pt_tri_dist2_vec(p, a, b, c):
    """Squared point-triangle distances by projection + the three edges (broadcasting)."""

    def seg(p, s, e):
        d = e - s
        t = np.clip(np.sum((p - s) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0, 1)
        q = s + t[..., None] * d
        return np.sum((p - q) ** 2, -1)

    best = np.minimum(np.minimum(seg(p, a, b), seg(p, b, c)), seg(p, c, a))
    n = np.cross(b - a, c - a)
    nn = np.sum(n * n, -1)
    ok = nn > 0
    dist_plane = np.sum((p - a) * n, -1) / np.where(ok, nn, 1.0)
    q = p - dist_plane[..., None] * n
    v0, v1, v2 = b - a, c - a, q - a
    d00, d01, d11 = np.sum(v0 * v0, -1), np.sum(v0 * v1, -1), np.sum(v1 * v1, -1)
    d20, d21 = np.sum(v2 * v0, -1), np.sum(v2 * v1, -1)
    den = np.where(ok, d00 * d11 - d01 * d01, 1.0)
    beta = (d11 * d20 - d01 * d21) / den
    gamma = (d00 * d21 - d01 * d20) / den
    inside = ok & (beta >= 0) & (gamma >= 0) & (beta + gamma <= 1)
    return np.where(inside, np.minimum(best, np.sum((p - q) ** 2, -1)), best)


def sample_triangles(points, faces, per_face=10, seed=0):
    """Random points on each triangle plus the triangles' vertices: (s, 3) float64."""
    r = np.random.default_rng(seed).random((faces.shape[0], per_face, 2))
    flip = r.sum(axis=2) > 1
    r[flip] = 1 - r[flip]
    p = points[faces]
    s = p[:, None, 0] + r[..., :1] * (p[:, None, 1] - p[:, None, 0]) + r[..., 1:] * (p[:, None, 2] - p[:, None, 0])
    return np.concatenate([s.reshape(-1, 3), points[np.unique(faces)]])


def hausdorff(points_a, faces_a, points_b, faces_b, per_face=10):
    """Symmetric Hausdorff distance of two triangle surfaces, sampled one way, exact the other."""
    d_ab = points_to_triangles_distance(sample_triangles(points_a, faces_a, per_face), points_b, faces_b).max()
    d_ba = points_to_triangles_distance(sample_triangles(points_b, faces_b, per_face), points_a, faces_a).max()
    return max(d_ab, d_ba)
