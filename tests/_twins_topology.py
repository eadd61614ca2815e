"""Slow, obviously correct NumPy/Python twins of the mesh-core kernels."""

from __future__ import annotations

import itertools

import numpy as np

FACES = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]
EDGES = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]


def unique_edges(tets):
    edges = sorted({tuple(sorted((int(t[a]), int(t[b])))) for t in tets for a, b in EDGES})
    index = {e: i for i, e in enumerate(edges)}
    tet_edges = [[index[tuple(sorted((int(t[a]), int(t[b]))))] for a, b in EDGES] for t in tets]
    return np.array(edges, np.int64).reshape(-1, 2), np.array(tet_edges, np.int64).reshape(-1, 6)


def face_users(tets):
    """dict sorted face -> list of (tet, local face)."""
    users = {}
    for t, tet in enumerate(tets):
        for i, f in enumerate(FACES):
            key = tuple(sorted(int(tet[j]) for j in f))
            users.setdefault(key, []).append((t, i))
    return users


def unique_faces(tets):
    users = face_users(tets)
    faces = sorted(users)
    index = {f: i for i, f in enumerate(faces)}
    tet_faces = np.zeros((len(tets), 4), np.int64)
    face_tets = np.full((len(faces), 2), -1, np.int64)
    for f, us in users.items():
        for k, (t, i) in enumerate(us):
            tet_faces[t, i] = index[f]
            if k < 2:
                face_tets[index[f], k] = t
    return np.array(faces, np.int64).reshape(-1, 3), tet_faces, face_tets


def tet_neighbors(tets):
    users = face_users(tets)
    out = np.full((len(tets), 4), -1, np.int64)
    for us in users.values():
        if len(us) == 2:
            (t0, i0), (t1, i1) = us
            out[t0, i0] = t1
            out[t1, i1] = t0
    return out


def boundary_faces(tets):
    """Set of outward-oriented boundary triangles (as rotations normalised) and their tets."""
    users = face_users(tets)
    out = []
    for us in users.values():
        if len(us) == 1:
            t, i = us[0]
            out.append((tuple(int(tets[t][j]) for j in FACES[i]), t))
    return out


def node_to_tets(tets, n):
    lists = [[] for _ in range(n)]
    for t, tet in enumerate(tets):
        for v in tet:
            lists[int(v)].append(t)
    offsets = np.zeros(n + 1, np.int64)
    offsets[1:] = np.cumsum([len(x) for x in lists])
    return offsets, np.array(list(itertools.chain(*lists)), np.int64)


def signed_volumes(points, tets):
    p = points[tets]
    return np.linalg.det(np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=1)) / 6.0


def dihedral_angles(points, tets):
    """Angle between the two face planes at each edge, via the planes' normals
    taken perpendicular to the edge (projection of the opposite vertices)."""
    out = np.zeros((len(tets), 6))
    for t, tet in enumerate(tets):
        p = points[tet]
        for k, (a, b) in enumerate(EDGES):
            c, d = [j for j in range(4) if j not in (a, b)]
            e = p[b] - p[a]
            e = e / np.linalg.norm(e)
            u = p[c] - p[a]
            v = p[d] - p[a]
            u = u - np.dot(u, e) * e  # component of each opposite vertex perpendicular to the edge
            v = v - np.dot(v, e) * e
            cosang = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
            out[t, k] = np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    return out


def hanging_nodes(points, tris, rel_tol):
    """Brute force: every boundary node against every boundary triangle."""
    out = set()
    cand = np.unique(tris)
    for tri in tris:
        a, b, c = points[tri]
        L = max(np.linalg.norm(b - a), np.linalg.norm(c - a), np.linalg.norm(c - b))
        n = np.cross(b - a, c - a)
        if not n.any():
            continue
        for x in cand:
            if x in tri:
                continue
            p = points[x]
            if abs(np.dot(p - a, n)) / np.linalg.norm(n) > rel_tol * L:
                continue
            # least-squares barycentrics
            M = np.stack([b - a, c - a], axis=1)
            beta, gamma = np.linalg.lstsq(M, p - a, rcond=None)[0]
            if min(1 - beta - gamma, beta, gamma) < -rel_tol:
                continue
            if min(np.linalg.norm(p - q) for q in (a, b, c)) <= rel_tol * L:
                continue
            out.add(int(x))
    return np.array(sorted(out), np.int64)
