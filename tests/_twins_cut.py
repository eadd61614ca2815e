"""Slow, obviously correct mesh checks for the cutting tests."""

import math
from collections import Counter

import numpy as np


def face_counts(tets):
    c = Counter()
    for t in tets:
        for f in ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)):
            c[tuple(sorted(int(t[i]) for i in f))] += 1
    return c


def boundary_edges_ok(tets):
    """Every face in <= 2 tets and the boundary a closed 2-manifold (each edge in 2 faces)."""
    fc = face_counts(tets)
    if max(fc.values()) > 2:
        return False, "face in more than two tets"
    ec = Counter()
    for f, n in fc.items():
        if n == 1:
            for i in range(3):
                ec[tuple(sorted((f[i], f[(i + 1) % 3])))] += 1
    bad = [e for e, n in ec.items() if n != 2]
    return (not bad), f"{len(bad)} boundary edges not in exactly two boundary faces"


def hanging_nodes(points, tets, tol=1e-9):
    """Boundary nodes lying strictly inside a boundary edge they are not part of."""
    fc = face_counts(tets)
    bnodes = set()
    bedges = set()
    for f, n in fc.items():
        if n == 1:
            bnodes.update(f)
            for i in range(3):
                bedges.add(tuple(sorted((f[i], f[(i + 1) % 3]))))
    bn = np.array(sorted(bnodes))
    out = 0
    for a, b in bedges:
        d = points[b] - points[a]
        L2 = d @ d
        s = (points[bn] - points[a]) @ d / L2
        r = np.linalg.norm(points[bn] - points[a] - s[:, None] * d, axis=1)
        m = (s > 1e-6) & (s < 1 - 1e-6) & (r < tol * np.sqrt(L2))
        m &= (bn != a) & (bn != b)
        # coincident duplicate copies are expected (cut surface); only count distinct positions
        out += int(m.sum())
    return out


def components(tets):
    """Number of connected components of tets linked through shared faces."""
    fc = {}
    parent = list(range(len(tets)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for ti, t in enumerate(tets):
        for f in ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)):
            key = tuple(sorted(int(t[i]) for i in f))
            if key in fc:
                parent[find(ti)] = find(fc[key])
            else:
                fc[key] = ti
    return len({find(i) for i in range(len(tets))})


def volumes(points, tets):
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


# ---------------------------------------------------------------- twins of cutkit.cutting._kernels_step

def tet_bary_twin(x, tv, p):
    """Barycentric coordinates (4,) of p in the tet x[tv] (np.linalg.solve)."""
    return barycentric(np.asarray(p, float), x[tv])


def walk_twin(x, tets, neighbors, start, target, max_walk=10000):
    """findTrajectoryTetra: cross the face opposite the most negative coordinate; -1 if it leaves."""
    t, prev = int(start), -1
    for _ in range(max_walk):
        b = tet_bary_twin(x, tets[t], target)
        if b.min() >= -1e-12:
            return t
        for i in np.argsort(b, kind="stable"):
            if b[i] >= 0:
                return -1
            nb = int(neighbors[t, i])
            if nb >= 0 and nb != prev:
                prev, t = t, nb
                break
        else:
            return -1
    return -1


def sweep_twin(x, tets, neighbors, tet_edges, tet_faces, edges, faces, edge_t, stamp, step, seeds, swept, blade, p0):
    """The per-tet Python traversal of a cut step: (active, ev_kind, ev_id, ev_val); modifies stamp."""
    from cutkit.mesh.topology import TET_EDGES
    q1, p1 = blade
    active, kinds, ids, vals = [], [], [], []
    queue = list(dict.fromkeys(int(s) for s in seeds))
    while queue:
        o = queue.pop()
        if stamp[o] == step:
            continue
        stamp[o] = step
        tv = tets[o]
        touched = False
        for k, (i, j) in enumerate(TET_EDGES):
            par = -1.0
            for tri in swept:
                par = segment_triangle(x[tv[i]], x[tv[j]], *tri)
                if par >= 0:
                    break
            if par < 0:
                continue
            touched = True
            e = int(tet_edges[o, k])
            if np.isnan(edge_t[e]):
                kinds.append(0); ids.append(e)
                vals.append([par if tv[i] == edges[e, 0] else 1.0 - par, 0.0, 0.0])
        if not touched:
            touched = segment_hits_tet(q1, p1, x[tv]) or segment_hits_tet(p0, p1, x[tv])
        if not touched:
            continue
        active.append(o)
        for lf in range(4):
            fp = segment_triangle(q1, p1, *x[tv[[(lf + 1) % 4, (lf + 2) % 4, (lf + 3) % 4]]])
            if fp < 0:
                continue
            f = int(tet_faces[o, lf])
            fv = faces[f]
            m = np.stack([x[fv[1]] - x[fv[0]], x[fv[2]] - x[fv[0]]], 1)
            uv = np.linalg.lstsq(m, q1 + fp * (p1 - q1) - x[fv[0]], rcond=None)[0]
            kinds.append(1); ids.append(f); vals.append([1 - uv.sum(), uv[0], uv[1]])
        queue.extend(int(nb) for nb in neighbors[o] if nb >= 0 and stamp[nb] != step)
    return (np.array(active, np.int64), np.array(kinds, np.int64), np.array(ids, np.int64),
            np.array(vals, float).reshape(-1, 3))


def clamp_bary_twin(b, lo):
    """Clip to >= 0, normalise, then mix with the centroid until the smallest weight is lo."""
    b = np.maximum(np.asarray(b, np.float64), 0.0)
    s = b.sum()
    b = b / s if s > 0 else np.full(b.shape, 1.0 / b.size)
    m = b.min()
    if m < lo:
        c = np.full(b.size, 1.0 / b.size)
        w = (lo - m) / (1.0 / b.size - m)
        b = (1 - w) * b + w * c
    return b


def set_node_twin(x, X, uvw, nodes, w):
    """(x, X, uvw) of a node with weights w on nodes: w @ rows (uvw None when absent)."""
    nodes = np.asarray(nodes, np.int64)
    w = np.asarray(w, np.float64)
    return w @ x[nodes], w @ X[nodes], (None if uvw is None else w @ uvw[nodes])


def min_volume_twin(x, tets):
    return float(volumes(x, np.asarray(tets).reshape(-1, 4)).min()) if len(tets) else np.inf


def _cross3(u, v):
    """u x v of two 3-vectors given as lists (np.cross on single 3-vectors is ~50x slower)."""
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _dihedrals_twin(p):
    """The six dihedral angles (degrees) of a tet with corners p (4, 3), by face normals."""
    q = np.asarray(p, np.float64).tolist()
    faces = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
    n = [_cross3([q[b][i] - q[a][i] for i in range(3)], [q[c][i] - q[a][i] for i in range(3)]) for a, b, c in faces]
    out = []
    for f, g in [(2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1)]:  # faces meeting at each edge
        m = _cross3(n[f], n[g])
        dot = n[f][0] * n[g][0] + n[f][1] * n[g][1] + n[f][2] * n[g][2]
        out.append(math.degrees(math.atan2(math.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]), -dot)))
    return out


def best_cone_apex_twin(x, corners, tb, blends, tris, bary_min):
    """Each blend's apex, its cone's smallest dihedral angle, and the first best: by plain loops."""
    best, best_b = -1.0, None
    for w in blends:
        b = clamp_bary_twin((1.0 - w) * np.asarray(tb) + 0.25 * w, bary_min)
        apex = b @ x[corners]
        worst = min(min(_dihedrals_twin(np.array([x[t[0]], x[t[2]], x[t[1]], apex]))) for t in tris)
        if worst > best:
            best, best_b = worst, b
    return best_b, best


def best_compact_split_twin(x, candidates, vol_min, n_rotations):
    """The compact split choice by plain loops: ``candidates`` is a list of (rotation, side, tets);
    returns the two picked candidates' indices and the worse side's angle, or (-1, -1, 0.0).
    Scores within ``tie`` degrees are equal (the first kept); rotations whose worse sides tie are
    ranked by their better sides."""
    from cutkit.cutting._kernels_split import SCORE_TIE_DEG as tie

    best = {}  # (rotation, side) -> (score, index); the first of equals kept
    for i, (r, s, tets) in enumerate(candidates):
        vols = [np.linalg.det(x[list(t[1:])] - x[t[0]]) / 6.0 for t in tets]
        angle = min(min(_dihedrals_twin(x[list(t)])) for t in tets)
        score = angle if min(vols) >= vol_min else -1.0
        if score > best.get((r, s), (-1.0, -1))[0] + tie:
            best[(r, s)] = (score, i)
    pick, worse_best, other_best = None, -np.inf, -np.inf
    for r in range(n_rotations):
        pair = [best.get((r, 0), (-1.0, -1))[0], best.get((r, 1), (-1.0, -1))[0]]
        worse, other = min(pair), max(pair)
        if worse > worse_best + tie or (abs(worse - worse_best) <= tie and other > other_best + tie):
            worse_best, other_best, pick = worse, other, r
    if worse_best < 0.0:
        return -1, -1, 0.0
    return best[(pick, 0)][1], best[(pick, 1)][1], worse_best


def cut_nodes_centroid_twin(cm, o, mask):
    """The mean of original tet ``o``'s cut nodes in barycentric weights, by plain loops over its
    edges (those in ``mask``) and its notched faces."""
    v = cm.orig_tets[o].tolist()
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    acc, n = np.zeros(4), 0
    for k, e in enumerate(cm.tet_edges[o].tolist()):
        if mask >> k & 1:
            i, j = pairs[k]
            s = float(cm.edge_t[e])
            a = np.zeros(4)
            a[i], a[j] = (1 - s, s) if cm.edges[e, 0] == v[i] else (s, 1 - s)
            acc, n = acc + a, n + 1
    for f in cm.tet_faces[o].tolist():
        fn = int(cm.face_node[f, 0])
        if fn >= 0 and cm.face_ncut[f] >= 1:
            for q in range(3):
                acc[v.index(int(cm._def_nodes[fn, q]))] += cm._def_w[fn, q]
            n += 1
    return acc / n


# ---- the compact complete split, as first written (dicts and lists): cutkit.cutting.splits

def _cut_loop_twin(cm, o, tris, vgroup):
    """The cut polygon of a complete split and each side's copy of its nodes.

    Returns (keys, copy): keys, the canonical key ('e', edge) | ('f', face)
    of each loop node in order; copy[side][key], the node id of that side's
    copy.  None when the face cut segments do not close into one loop.
    """
    key = {}
    for e in cm.tet_edges[o].tolist():
        if cm.edge_t[e] == cm.edge_t[e]:  # cut (not NaN)
            n0, n1 = cm.edge_node[e].tolist()
            key[n0] = key[n1] = ("e", e)
    for f in cm.tet_faces[o].tolist():
        for c in cm.face_node[f].tolist():
            if c >= 0:
                key[c] = ("f", f)
    nxt = [dict(), dict()]
    copy = [dict(), dict()]
    for tri, owner, _ in tris:
        side = vgroup[owner]
        for k in range(3):
            a, b = tri[k], tri[(k + 1) % 3]
            if a in key and b in key:
                nxt[side][b] = a  # the cut polygon runs the other way
                copy[side][key[a]] = a
                copy[side][key[b]] = b
    if not nxt[0] or len(nxt[0]) != len(nxt[1]):
        return None
    start = next(iter(nxt[0]))
    loop = [start]
    while True:
        n = nxt[0].get(loop[-1])
        if n is None:
            return None
        if n == start:
            break
        loop.append(n)
        if len(loop) > len(nxt[0]):
            return None
    if len(loop) != len(nxt[0]):
        return None
    keys = [key[n] for n in loop]
    if any(k not in copy[1] for k in keys):
        return None
    return keys, copy


def _apexes_twin(v, tris, vgroup):
    """Allowed apexes of each side, with the cone tets of their side's face triangles."""
    apexes = ([], [])
    for ia, apex in enumerate(v):
        side = vgroup[apex]
        # the cone tiles each face through the apex by a fan from the apex:
        # conforming (crack-free) only if the face pattern is that fan
        if any(vgroup[ow] == side and lf != ia and apex not in t for t, ow, lf in tris):
            continue
        # face triangles on a face through the apex are flat cones: skip them
        apexes[side].append((apex, [(t[0], t[2], t[1], apex) for t, ow, lf in tris
                                    if vgroup[ow] == side and lf == ia]))
    return apexes


def compact_split_twin(cm, o, tris, vgroup, vol_frac=1e-3):
    """Best compact tetrahedralisation of the complete split of original tet ``o``.

    Parameters
    ----------
    cm : CutMesh
    o : int  original tet
    tris : list of ((3,) node ids, owner vertex, local face)  its Fig. 2 face triangles
    vgroup : dict  original vertex -> side (0 or 1)

    Returns
    -------
    (tets, angle) : list of 4-tuples and their smallest dihedral angle in
        degrees, or (None, 0.0) when no choice passes the volume test
        (``vol_frac`` of the tet's volume, ``splits.COMPACT_VOL_MIN``).
    """
    v = [int(q) for q in cm.orig_tets[o]]
    lp = _cut_loop_twin(cm, o, tris, vgroup)
    if lp is None:
        return None, 0.0
    keys, copy = lp
    apexes = _apexes_twin(v, tris, vgroup)
    if not apexes[0] or not apexes[1]:
        return None, 0.0
    cands = []  # (rotation, side, tets)
    for r in range(len(keys)):
        kk = keys[r:] + keys[:r]
        poly = [(kk[0], kk[i], kk[i + 1]) for i in range(1, len(kk) - 1)]
        for side in (0, 1):
            cs = copy[side]
            # cone tets of the cut triangles (side 1 sees them flipped)
            if side == 0:
                cut_tris = [(cs[t[0]], cs[t[2]], cs[t[1]]) for t in poly]
            else:
                cut_tris = [(cs[t[0]], cs[t[1]], cs[t[2]]) for t in poly]
            for apex, face_cone in apexes[side]:
                cands.append((r, side, face_cone + [t + (apex,) for t in cut_tris]))
    return _best_twin(cm._x, cands, vol_frac * float(cm._vol0(o)), len(keys))


def _best_twin(x, cands, vol_min, n_rot):
    p0, p1, angle = best_compact_split_twin(x, cands, vol_min, n_rot)
    return (None, 0.0) if p0 < 0 else (cands[p0][2] + cands[p1][2], angle)


# ---- the Fig. 2 face patterns, as first written: cutkit.cutting._kernels_split.face_triangles

def _face_pattern_twin(gv, cut, edge_copy, face_node, centre_nodes, diag=-1, rep=None):
    """Triangles of one face by the Fig. 2 patterns.

    Parameters
    ----------
    gv : (3,) int  global vertex ids, outward cyclic order
    cut : (3,) bool  whether edge (gv[k], gv[k+1]) is cut
    edge_copy : callable (k, vertex) -> node id of the copy of edge k's node
        on the side of ``vertex``
    face_node : callable (side) -> node id; side 0 = notch F or lone-side C,
        1 = pair-side C; with three cut edges, the copy of C of the vertex
        ranked ``side`` by global id
    centre_nodes : bool
    diag : int  the split face's fixed diagonal vertex, or -1 (default: the quad's base vertex of smaller ``rep``)
    rep : sequence, optional  each vertex's representative id (default: its id)

    Returns
    -------
    tris : list of ((3,) node ids, owner original vertex or -1, on_cut) where
        ``owner`` is an original vertex of the triangle (decides the side).
    """
    cut = [bool(c) for c in cut]
    n = sum(cut)
    if n == 0:
        return [((gv[0], gv[1], gv[2]), gv[0])]
    if n == 1:
        k = cut.index(True)
        p, q, r = gv[k], gv[(k + 1) % 3], gv[(k + 2) % 3]
        F = face_node(0)
        return [((p, edge_copy(k, p), F), p), ((edge_copy(k, q), q, F), q),
                ((q, r, F), q), ((r, p, F), r)]
    if n == 3:  # forked: each corner, its two edge nodes and its copy of C
        tris = []
        for k in range(3):
            p, q, r = gv[k], gv[(k + 1) % 3], gv[(k + 2) % 3]
            C = face_node(sorted(gv).index(p))
            tris += [((p, edge_copy(k, p), C), p), ((p, C, edge_copy((k + 2) % 3, p)), p)]
        return tris
    # two cut edges: lone vertex p is shared by both cut edges
    k_uncut = cut.index(False)
    q, r = gv[k_uncut], gv[(k_uncut + 1) % 3]
    p = gv[(k_uncut + 2) % 3]
    k1 = (k_uncut + 2) % 3  # edge (p, q)
    k2 = (k_uncut + 1) % 3  # edge (r, p)
    if centre_nodes:
        Cl, Cp = face_node(0), face_node(1)
        return [((Cl, p, edge_copy(k1, p)), p), ((Cl, edge_copy(k2, p), p), p),
                ((Cp, edge_copy(k1, q), q), q), ((Cp, q, r), q), ((Cp, r, edge_copy(k2, r)), r)]
    tris = [((p, edge_copy(k1, p), edge_copy(k2, p)), p)]
    E1, E2 = edge_copy(k1, q), edge_copy(k2, r)
    rep = (lambda i: i) if rep is None else rep.__getitem__
    if (diag if diag >= 0 else min((q, r), key=rep)) == q:  # the quad's diagonal through the fixed vertex
        tris += [((E1, q, E2), q), ((q, r, E2), q)]
    else:
        tris += [((E1, q, r), q), ((E1, r, E2), r)]
    return tris


def face_triangles_twin(cm, o, mask):
    """The Fig. 2 triangles of the four faces of original tet ``o``: a list of
    ((3,) node ids, owner original vertex, local face), as the rule was first written."""
    from cutkit.cutting.subdivision import FACE_EDGES
    from cutkit.mesh.topology import TET_FACES

    v = cm.orig_tets[o].tolist()
    te, tf = cm.tet_edges[o].tolist(), cm.tet_faces[o].tolist()
    tris = []
    for lf in range(4):
        gv = [v[i] for i in TET_FACES[lf].tolist()]
        ge = [te[k] for k in FACE_EDGES[lf].tolist()]
        cut = [bool(mask >> k & 1) for k in FACE_EDGES[lf].tolist()]
        f = tf[lf]

        def edge_copy(k, vert, ge=ge):
            e = ge[k]
            return int(cm.edge_node[e, 0 if cm.edges[e, 0] == vert else 1])

        def f_node(side, f=f):
            return int(cm.face_node[f, side])

        tris.extend((tri, ow, lf) for tri, ow in _face_pattern_twin(gv, cut, edge_copy, f_node, cm.centre_nodes,
                                                                    int(cm.face_diag[f]), cm.node_rep.tolist()))
    return tris


def best_face_apex_twin(x, tris, tri_face, face_nodes, vol_min):
    """Each notched face's cone (its node to the other faces' triangles), its volume test and
    smallest dihedral angle, and the first best: by plain loops."""
    best_lf, best = -1, -1.0
    for lf, F in enumerate(face_nodes):
        if F < 0:
            continue
        cone = [(t[0], t[2], t[1], F) for t, f in zip(tris, tri_face) if f != lf]
        if not cone or min_volume_twin(x, cone) < vol_min:
            continue
        worst = min(min(_dihedrals_twin(x[list(c)])) for c in cone)
        if worst > best + 1e-9:
            best_lf, best = lf, worst
    return best_lf, best


# Segment and edge tests (twins of cutkit.mesh.geometry.segment_triangle_crossing,
# segment_meets_tet and edge_triangle_crossing) and barycentric coordinates.

#: Relative tolerance of the segment/triangle test (scaled by edge length).
SEG_TRI_EPS = 1e-12


def segment_triangle(p0, p1, a, b, c):
    """Parameter s in [0, 1] where segment p0-p1 crosses triangle abc, or -1.

    Moeller-Trumbore; a segment parallel to the triangle's plane misses.
    """
    d = p1 - p0
    e1 = b - a
    e2 = c - a
    h = np.cross(d, e2)
    det = float(e1 @ h)
    scale = float(np.linalg.norm(e1) * np.linalg.norm(e2) * np.linalg.norm(d)) + 1e-300
    if abs(det) <= SEG_TRI_EPS * scale:
        return -1.0
    inv = 1.0 / det
    s = p0 - a
    u = float(s @ h) * inv
    if u < 0.0 or u > 1.0:
        return -1.0
    q = np.cross(s, e1)
    v = float(d @ q) * inv
    if v < 0.0 or u + v > 1.0:
        return -1.0
    t = float(e2 @ q) * inv
    if t < 0.0 or t > 1.0:
        return -1.0
    return t


def segment_triangle_many(p0, p1, a, b, c):
    """:func:`segment_triangle` for k segments ``p0``, ``p1`` (k, 3) against one triangle: (k,) s or -1.

    The same Moeller-Trumbore steps, each on all segments at once (a segment
    that fails a test keeps -1 whatever the later tests give).
    """
    d = p1 - p0
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = h @ e1
    scale = np.linalg.norm(e1) * np.linalg.norm(e2) * np.linalg.norm(d, axis=1) + 1e-300
    ok = np.abs(det) > SEG_TRI_EPS * scale
    inv = 1.0 / np.where(ok, det, 1.0)
    s = p0 - a
    u = np.einsum("ij,ij->i", s, h) * inv
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", d, q) * inv
    t = (q @ e2) * inv
    ok &= (u >= 0.0) & (u <= 1.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= 0.0) & (t <= 1.0)
    return np.where(ok, t, -1.0)


def barycentric(x, tet_points):
    """Barycentric coordinates (4,) of x in the tetrahedron (4, 3)."""
    p0 = tet_points[0]
    m = (tet_points[1:] - p0).T
    try:
        l123 = np.linalg.solve(m, x - p0)
    except np.linalg.LinAlgError:
        return np.full(4, -1.0)
    return np.array([1.0 - l123.sum(), l123[0], l123[1], l123[2]])


def segment_hits_tet(p0, p1, tet_points):
    """Whether segment p0-p1 meets the (positively oriented) tetrahedron.

    Clips the segment's parameter interval against the four face planes.
    """
    lo, hi = 0.0, 1.0
    d = p1 - p0
    for i, (a, b, c) in enumerate(((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))):
        n = np.cross(tet_points[b] - tet_points[a], tet_points[c] - tet_points[a])  # outward
        dist0 = float(n @ (p0 - tet_points[a]))
        dd = float(n @ d)
        if abs(dd) < 1e-300:
            if dist0 > 0.0:
                return False
            continue
        t = -dist0 / dd
        if dd > 0.0:
            hi = min(hi, t)
        else:
            lo = max(lo, t)
        if lo > hi:
            return False
    return True


def edge_crosses_triangle(p, q, tri, end_eps=1e-9, bary_eps=1e-12):
    """Twin of ``cutkit.mesh.geometry.edge_triangle_crossing``: parameter where edge p-q crosses triangle tri (3, 3), or -1.

    An end within ``end_eps`` (relative to the edge's length) of the plane
    is on it and counts as just below it; the crossing point must lie in the
    closed triangle.
    """
    tri = np.asarray(tri, float)
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    if np.linalg.norm(n) <= SEG_TRI_EPS * np.linalg.norm(tri[1] - tri[0]) * np.linalg.norm(tri[2] - tri[0]):
        return -1.0  # flat triangle
    n = n / np.linalg.norm(n)
    dp, dq = float(n @ (p - tri[0])), float(n @ (q - tri[0]))
    tol = end_eps * float(np.linalg.norm(q - p))
    if (dp > tol) == (dq > tol):
        return -1.0
    dp = 0.0 if abs(dp) <= tol else dp
    dq = 0.0 if abs(dq) <= tol else dq
    t = dp / (dp - dq)
    x = p + t * (q - p)
    m = np.stack([tri[1] - tri[0], tri[2] - tri[0]], axis=1)
    b1, b2 = np.linalg.lstsq(m, x - tri[0], rcond=None)[0]
    if b1 < -bary_eps or b2 < -bary_eps or b1 + b2 > 1 + bary_eps:
        return -1.0
    return t


# ---------------------------------------------------------------- twin of cutkit.cutting._kernels_crumbs
def loose_small_pieces_twin(X, tets, alive, seeds, limit):
    """Crumb tets (sorted) and count: the pieces (live tets joined by shared nodes) through ``seeds``
    whose whole rest volume is at most ``limit``; every piece found with a union-find over the mesh."""
    live = np.flatnonzero(alive)
    parent = {int(t): int(t) for t in live}

    def find(i):
        while parent[i] != i:
            i = parent[i]
        return i

    by_node = {}
    for t in live.tolist():
        for v in tets[t].tolist():
            if v in by_node:
                parent[find(t)] = find(by_node[v])
            else:
                by_node[v] = t
    vol = {}
    for t in live.tolist():
        vol[find(t)] = vol.get(find(t), 0.0) + float(volumes(X, tets[t:t + 1])[0])
    crumbs = {find(int(s)) for s in seeds if alive[s] and vol[find(int(s))] <= limit}
    out = sorted(t for t in live.tolist() if find(t) in crumbs)
    return np.array(out, np.int64), len(crumbs)


def fair_place_twin(x, tets, copies, corners, w0, w_cut, lo, move_max, steps, directions):
    """The compass search of ``_kernels_fair.fair_place`` by plain loops: every move ``s d`` of each step
    inside the box, the best of each sweep taken while it gains; a candidate counts only if every tet
    stays positive."""
    x = x.copy()

    def worst(w):
        x[copies] = w @ x[corners]
        if volumes(x, tets).min() <= 0.0:
            return -1.0
        return min(min(_dihedrals_twin(x[t])) for t in tets)

    w = np.array(w0, float)
    best = worst(w)
    for s in steps:
        while True:
            best_w = None
            for d in directions:
                cand = w + s * d
                if cand.min() < lo or np.abs(cand - w_cut).max() > move_max:
                    continue
                a = worst(cand)
                if a > best + 1e-9:
                    best, best_w = a, cand
            if best_w is None:
                break
            w = best_w
    return w, best


def vertex_place_twin(x, tets, share, vertex, ends, swept, directions, steps, move_max):
    """The compass search of ``_kernels_fair.vertex_place`` by plain loops: from dx = 0, every move
    dx + s d of each step within ``move_max``, the best of each sweep taken while it gains; a
    candidate counts only where every tet stays positive and no edge from the vertex to one of
    ``ends`` that misses every triangle of ``swept`` now comes to cross one (strictly between its ends: one
    crossed at an end is not cut, so it counts as missing)."""

    def crossing(p):
        return np.array([any(0.0 < edge_crosses_triangle(p, q, tri) < 1.0 for tri in swept) for q in ends], bool)

    def worst(dx):
        y = x + share[:, None] * dx
        if volumes(y, tets).min() <= 0.0:
            return -1.0, None
        return min(min(_dihedrals_twin(y[t])) for t in tets), crossing(y[vertex])

    now = crossing(x[vertex])
    dx = np.zeros(3)
    start = best = worst(dx)[0]
    for s in steps:
        while True:
            pick = None
            for d in directions:
                cand = dx + s * d
                if cand @ cand > move_max * move_max:
                    continue
                a, after = worst(cand)
                if a > best + 1e-9 and not (after & ~now).any():
                    best, pick = a, cand
            if pick is None:
                break
            dx = pick
    return dx, best, start
