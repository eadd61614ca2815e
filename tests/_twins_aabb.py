"""Slow, obviously correct NumPy twins of cutkit.collision._kernels."""

import numpy as np

from cutkit.mesh import geometry as G


def pair_level(box_min, box_max, nodes, adjacency):
    """Greedy pairing of one level; ``adjacency`` is a list of sets of positions."""
    n = len(nodes)
    order, seen = [], [False] * n
    for s in range(n):
        if seen[s]:
            continue
        seen[s] = True
        queue = [s]
        while queue:
            i = queue.pop(0)
            order.append(i)
            for j in sorted(adjacency[i]):
                if not seen[j]:
                    seen[j] = True
                    queue.append(j)
    paired = [False] * n
    groups = []
    for i in order:
        if paired[i]:
            continue
        paired[i] = True
        a = nodes[i]
        cands = []
        for j in sorted(adjacency[i]):
            if paired[j]:
                continue
            b = nodes[j]
            parent = np.prod(np.maximum(box_max[a], box_max[b]) - np.minimum(box_min[a], box_min[b]))
            overlap = np.prod(np.clip(np.minimum(box_max[a], box_max[b]) - np.maximum(box_min[a], box_min[b]), 0, None))
            cands.append((parent - overlap, j))
        best = min(cands)[1] if cands else -1
        if best >= 0:
            paired[best] = True
        groups.append((i, best))
    return groups


def expected_boxes(bvh):
    """Boxes recomputed from scratch: leaves from the tolerance boxes, inner nodes as unions."""
    k = bvh.n_nodes
    bmin = np.full((k, 3), np.inf)
    bmax = np.full((k, 3), -np.inf)

    def visit(node):
        l, r = bvh.child[node]
        if l < 0:
            f = bvh.leaf_face[node]
            if bvh.face_alive[f]:
                bmin[node] = bvh.tol_min[bvh.faces[f]].min(axis=0)
                bmax[node] = bvh.tol_max[bvh.faces[f]].max(axis=0)
        else:
            visit(l)
            visit(r)
            bmin[node] = np.minimum(bmin[l], bmin[r])
            bmax[node] = np.maximum(bmax[l], bmax[r])

    visit(bvh.root)
    return bmin, bmax


def refit_tolerance(points, tol_min, tol_max, s_tol):
    """Which nodes leave their tolerance box, and the new tolerance boxes."""
    moved = np.any((points < tol_min) | (points > tol_max), axis=1)
    new_min = np.where(moved[:, None], points - s_tol, tol_min)
    new_max = np.where(moved[:, None], points + s_tol, tol_max)
    return moved, new_min, new_max


def _coplanar_entry(p0, d, tri):
    """Smallest t in [0, 1] with p0 + t d in the (closed) triangle, both in one plane."""
    nrm = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    drop = int(np.argmax(np.abs(nrm)))
    keep = [i for i in range(3) if i != drop]
    q0, dd, T = p0[keep], d[keep], tri[:, keep]

    def inside(q):
        # barycentric coordinates by areas in 2D
        def cross2(a, b):
            return a[0] * b[1] - a[1] * b[0]
        area = cross2(T[1] - T[0], T[2] - T[0])
        w = [cross2(T[(i + 1) % 3] - q, T[(i + 2) % 3] - q) / area for i in range(3)]
        return min(w) >= -G.EPS_BARY

    ts = []
    if inside(q0):
        ts.append(0.0)
    for i in range(3):
        a, b = T[i], T[(i + 1) % 3]
        e = b - a
        m = np.array([[dd[0], -e[0]], [dd[1], -e[1]]])
        if abs(np.linalg.det(m)) < 1e-300:
            continue
        t, s = np.linalg.solve(m, a - q0)
        if -G.EPS_T <= t <= 1 + G.EPS_T and -G.EPS_BARY <= s <= 1 + G.EPS_BARY:
            ts.append(min(max(t, 0.0), 1.0))
    return min(ts) if ts else None


def brute_segment_hits(points, faces, alive, p0, p1):
    """Every live face the segment meets: {face: (kind, t)}, by solving p0 + t d = v0 + u e1 + v e2."""
    p0 = np.asarray(p0, float)
    p1 = np.asarray(p1, float)
    d = p1 - p0
    hits = {}
    for f in np.flatnonzero(alive):
        tri = points[faces[f]]
        e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
        nrm = np.cross(e1, e2)
        if not np.any(nrm) or not np.any(d):
            continue  # zero-area triangle or zero-length segment: no crossing defined
        if abs(np.dot(d, nrm)) <= G.EPS_PARALLEL * np.linalg.norm(nrm) * np.linalg.norm(d):
            size = max(np.linalg.norm(e1), np.linalg.norm(e2))
            if abs(np.dot(p0 - tri[0], nrm)) / np.linalg.norm(nrm) <= G.EPS_COPLANAR * size:
                t = _coplanar_entry(p0, d, tri)
                if t is not None:
                    hits[int(f)] = (G.HIT_COPLANAR, t)
            continue
        t, u, v = np.linalg.solve(np.column_stack([-d, e1, e2]), p0 - tri[0])
        w = 1 - u - v
        if min(u, v, w) < -G.EPS_BARY or not (-G.EPS_T <= t <= 1 + G.EPS_T):
            continue
        on = sum(abs(x) <= G.EPS_BARY for x in (u, v, w))
        kind = G.HIT_VERTEX if on >= 2 else G.HIT_EDGE if on == 1 else G.HIT_FACE
        hits[int(f)] = (kind, min(max(t, 0.0), 1.0))
    return hits


def triangle_faces_twin(points, faces, face_alive, tri):
    """Every live face triangle ``tri`` meets, testing all faces: an edge of one crossing the other.

    Plain NumPy: Moeller-Trumbore of each of the six edges (closed
    barycentric and parameter ranges), plus the coplanar case by 2D
    point-in-triangle of the vertices of each in the other.
    """
    out = []
    tri = np.asarray(tri, float)
    lo, hi = tri.min(axis=0), tri.max(axis=0)
    for f in range(faces.shape[0]):
        x = points[faces[f]]
        if np.any(x.min(axis=0) > hi + 1e-9) or np.any(x.max(axis=0) < lo - 1e-9):
            continue  # boxes apart: the triangles cannot meet
        if face_alive[f] and _tri_tri(x, tri):
            out.append(f)
    return np.array(out, np.int64)


def _seg_tri(p0, p1, a, b, c, eps=1e-10):
    d = p1 - p0
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = e1 @ h
    if abs(det) <= 1e-12 * np.linalg.norm(e1) * np.linalg.norm(e2) * np.linalg.norm(d):
        return False
    s = p0 - a
    u = (s @ h) / det
    q = np.cross(s, e1)
    v = (d @ q) / det
    t = (e2 @ q) / det
    return u >= -eps and v >= -eps and u + v <= 1 + eps and -eps <= t <= 1 + eps


def _tri_tri(T, U):
    for X, Y in ((T, U), (U, T)):
        for i in range(3):
            if _seg_tri(X[i], X[(i + 1) % 3], *Y):
                return True
    n = np.cross(T[1] - T[0], T[2] - T[0])
    if np.all(np.abs((U - T[0]) @ n) <= 1e-10 * np.linalg.norm(n) * (1 + np.abs(U - T[0]).max())):
        # coplanar: a vertex of one inside the other
        def inside(p, X):
            m = np.stack([X[1] - X[0], X[2] - X[0]], axis=1)
            uv = np.linalg.lstsq(m, p - X[0], rcond=None)[0]
            return uv.min() >= -1e-10 and uv.sum() <= 1 + 1e-10
        return any(inside(p, T) for p in U) or any(inside(p, U) for p in T)
    return False


def blade_entry_twin(bvh, points, p0, q0, p1, q1):
    """``cutkit.collision.blade_entry`` made of the public queries: (kind, face, point) or None.

    The tip's path, then the blade now, each crossing a face inwards first along the segment
    (``query_segment``'s order: parameter, then face); then of the faces the swept quad or the
    blade now meets (``swept_faces``: a face's first point), the one against the mean motion
    nearest the previous blade, the least face id first among equals."""
    from cutkit.collision import swept_faces

    def normal(f):
        x = points[bvh.faces[f]]
        return np.cross(x[1] - x[0], x[2] - x[0])

    for kind, a, b in (("tip_path", p0, p1), ("blade", q1, p1)):
        if np.any(a != b):
            hits = bvh.query_segment(points, a, b)
            for f, p in zip(hits.face.tolist(), hits.point):
                if np.dot(normal(f), b - a) < 0:
                    return kind, f, p
    faces, pts = swept_faces(bvh, points, p0, q0, p1, q1)
    motion = 0.5 * ((p1 - p0) + (q1 - q0))
    best, best_d = None, np.inf
    for f, p in zip(faces.tolist(), pts):
        if np.dot(normal(f), motion) >= 0:
            continue
        d = p0 - q0
        dd = float(d @ d)
        s = 0.0 if dd == 0.0 else min(max(float((p - q0) @ d) / dd, 0.0), 1.0)
        dist = float(np.linalg.norm(p - (q0 + s * d)))
        if dist < best_d:
            best, best_d = ("swept", f, p), dist
    return best
