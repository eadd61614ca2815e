"""Numba kernels of the subdivision of one cut tetrahedron: its face patterns and compact splits.

:func:`face_triangles` triangulates the four faces of a tetrahedron by the
paper's Fig. 2 patterns (:mod:`cutkit.cutting.subdivision`).  A completely split tetrahedron (``corner`` or ``quad``) is tetrahedralised
by coning each side to one of its original vertices: the cut polygon is
fanned from one of its nodes, and every fan rotation, side and allowed apex
is a candidate, scored by its smallest dihedral angle.  One kernel call per
re-subdivided tetrahedron finds the loop, the apexes, the candidates and
the best choice; it checks nothing (:func:`cutkit.cutting.splits.compact_split`
hands it plain arrays).  The slow, obviously correct twins (dicts and lists,
as the rules were first written) are ``tests/_twins_cut.face_triangles_twin``
and ``compact_split_twin``.
"""

import numpy as np
from numba import njit

from cutkit.cutting.subdivision import FACE_EDGES
from cutkit.mesh.geometry import min_volume, tet_dihedrals
from cutkit.mesh.topology import TET_FACES

#: At most this many cut nodes per tet: two copies of each of six edge nodes and of four face nodes.
_MAX_KEYS = 20
#: At most this many face triangles per tet: four faces of at most six triangles (three cut edges).
MAX_FACE_TRIANGLES = 24


@njit(cache=True, nogil=True, inline="always")
def _edge_copy(ct, e, vertex):
    """The copy of cut edge e's node on the side of its end ``vertex``."""
    return ct.edge_node[e, 0 if ct.edges[e, 0] == vertex else 1]


@njit(cache=True, nogil=True, inline="always")
def _put(tris, corner, face, k, a, b, c, owner, lf):
    tris[k, 0], tris[k, 1], tris[k, 2] = a, b, c
    corner[k], face[k] = owner, lf
    return k + 1


@njit(cache=True, nogil=True, inline="always")
def _face_cut_edges(mask, lf):
    """How many of local face ``lf``'s edges ``mask`` cuts, its first cut and first uncut edge (-1: none)."""
    n_cut = 0
    first_cut = np.int64(-1)  # not the literal -1: the callees it is passed to compile once
    first_uncut = np.int64(-1)
    for j in range(3):
        if mask >> FACE_EDGES[lf, j] & 1:
            n_cut += 1
            first_cut = j if first_cut < 0 else first_cut
        elif first_uncut < 0:
            first_uncut = j
    return n_cut, first_cut, first_uncut


@njit(cache=True, nogil=True, inline="always")
def _face_vertices(ct, o, lf):
    """Local face ``lf``'s local corners (outward cyclic order) and their global vertices."""
    lc = TET_FACES[lf]
    return lc, (ct.orig_tets[o, lc[0]], ct.orig_tets[o, lc[1]], ct.orig_tets[o, lc[2]])


@njit(cache=True, nogil=True)
def _face_three_cuts(ct, o, lf, out, k):
    """Fig. 2 pattern of a face with three cut edges: each corner's quad round its own copy of the
    centre node C (copy i: the face's vertex of i-th smallest global id, so both tets sharing the
    face pick the same copies).  Appends to ``out`` from row ``k``; returns the new count."""
    tris, corner, face = out
    lc, gv = _face_vertices(ct, o, lf)
    f = ct.tet_faces[o, lf]
    for j in range(3):
        p, q, r = gv[j], gv[(j + 1) % 3], gv[(j + 2) % 3]
        C = ct.face_node[f, (p > q) + (p > r)]
        e_pq = ct.tet_edges[o, FACE_EDGES[lf, j]]
        e_rp = ct.tet_edges[o, FACE_EDGES[lf, (j + 2) % 3]]
        k = _put(tris, corner, face, k, p, _edge_copy(ct, e_pq, p), C, lc[j], lf)
        k = _put(tris, corner, face, k, p, C, _edge_copy(ct, e_rp, p), lc[j], lf)
    return k


@njit(cache=True, nogil=True)
def _face_notch(ct, o, lf, j, out, k):
    """Fig. 2b pattern of a face whose only cut edge is its ``j``-th: four triangles round the face
    node F.  Appends to ``out`` from row ``k``; returns the new count."""
    tris, corner, face = out
    lc, gv = _face_vertices(ct, o, lf)
    p, q, r = gv[j], gv[(j + 1) % 3], gv[(j + 2) % 3]
    cp, cq, cr = lc[j], lc[(j + 1) % 3], lc[(j + 2) % 3]
    e = ct.tet_edges[o, FACE_EDGES[lf, j]]
    F = ct.face_node[ct.tet_faces[o, lf], 0]
    k = _put(tris, corner, face, k, p, _edge_copy(ct, e, p), F, cp, lf)
    k = _put(tris, corner, face, k, _edge_copy(ct, e, q), q, F, cq, lf)
    k = _put(tris, corner, face, k, q, r, F, cq, lf)
    k = _put(tris, corner, face, k, r, p, F, cr, lf)
    return k


@njit(cache=True, nogil=True)
def _face_two_cuts(ct, o, lf, ju, centre_nodes, out, k):
    """Fig. 2c pattern of a face whose only uncut edge is its ``ju``-th (the lone vertex p is on both
    cut edges): p's triangle and the quad split by its diagonal, or with ``centre_nodes`` five
    triangles round the centre node's two copies.  Appends to ``out`` from row ``k``; returns the
    new count."""
    tris, corner, face = out
    lc, gv = _face_vertices(ct, o, lf)
    f = ct.tet_faces[o, lf]
    q, r, p = gv[ju], gv[(ju + 1) % 3], gv[(ju + 2) % 3]
    cq, cr, cp = lc[ju], lc[(ju + 1) % 3], lc[(ju + 2) % 3]
    e1 = ct.tet_edges[o, FACE_EDGES[lf, (ju + 2) % 3]]  # edge (p, q)
    e2 = ct.tet_edges[o, FACE_EDGES[lf, (ju + 1) % 3]]  # edge (r, p)
    if centre_nodes:
        Cl, Cp = ct.face_node[f, 0], ct.face_node[f, 1]
        k = _put(tris, corner, face, k, Cl, p, _edge_copy(ct, e1, p), cp, lf)
        k = _put(tris, corner, face, k, Cl, _edge_copy(ct, e2, p), p, cp, lf)
        k = _put(tris, corner, face, k, Cp, _edge_copy(ct, e1, q), q, cq, lf)
        k = _put(tris, corner, face, k, Cp, q, r, cq, lf)
        k = _put(tris, corner, face, k, Cp, r, _edge_copy(ct, e2, r), cr, lf)
        return k
    k = _put(tris, corner, face, k, p, _edge_copy(ct, e1, p), _edge_copy(ct, e2, p), cp, lf)
    E1, E2 = _edge_copy(ct, e1, q), _edge_copy(ct, e2, r)
    d = ct.face_diag[f]  # the vertex the quad's diagonal passes through
    if d < 0:  # not fixed yet: the vertex of smaller global id (of its representative, so
        # a coincident copy of the face along an earlier cut takes the same diagonal)
        d = q if ct.node_rep[q] < ct.node_rep[r] else r
    if d == q:
        k = _put(tris, corner, face, k, E1, q, E2, cq, lf)
        k = _put(tris, corner, face, k, q, r, E2, cq, lf)
    else:
        k = _put(tris, corner, face, k, E1, q, r, cq, lf)
        k = _put(tris, corner, face, k, E1, r, E2, cr, lf)
    return k


@njit(cache=True, nogil=True)
def face_triangles(ct, o, mask, centre_nodes):
    """The Fig. 2 triangles of the four faces of original tet ``o``, outward.

    Each face is triangulated from global data only (its cut edges, its
    node), so the two tets sharing it agree: no cut edge, the face; one
    (notch, Fig. 2b), four triangles around the face node F; two (complete,
    Fig. 2c), the lone vertex's triangle and the quad split by its diagonal
    through the vertex ``face_diag`` names (fixed by the first complete split
    that used the face, :func:`cutkit.cutting.splits.fix_diagonals`; until
    then the smaller global vertex id, compared on ``node_rep``), or with ``centre_nodes`` five
    triangles around the centre node's two copies; three, two triangles per
    corner round its copy of the centre node C.

    Parameters
    ----------
    ct : CutTables
    o : int
    mask : int
        The tet's cut edges (6-bit, reduced).
    centre_nodes : bool

    Returns
    -------
    (tris, corner, face) : (k, 3), (k,), (k,) int64
        The triangles, the local corner that owns each (its side), and the
        local face each lies on.
    """
    tris = np.empty((MAX_FACE_TRIANGLES, 3), np.int64)
    corner = np.empty(MAX_FACE_TRIANGLES, np.int64)
    face = np.empty(MAX_FACE_TRIANGLES, np.int64)
    out = (tris, corner, face)
    k = np.int64(0)  # not the literal 0: the face kernels that take it compile once
    for lf in range(4):
        lc = TET_FACES[lf]  # local corners in outward cyclic order
        n_cut, first_cut, first_uncut = _face_cut_edges(mask, lf)
        if n_cut == 0:
            g = ct.orig_tets[o]
            k = _put(tris, corner, face, k, g[lc[0]], g[lc[1]], g[lc[2]], lc[0], lf)
        elif n_cut == 3:
            k = _face_three_cuts(ct, o, lf, out, k)
        elif n_cut == 1:
            k = _face_notch(ct, o, lf, first_cut, out, k)
        else:
            k = _face_two_cuts(ct, o, lf, first_uncut, centre_nodes, out, k)
    return tris[:k], corner[:k], face[:k]


#: Scores (degrees) closer than this are equal: the first candidate is kept, so a tie is broken by
#: the candidates' order and never by the last bits of rounding (which differ between this kernel
#: and NumPy, and between platforms).  Rotations whose worse sides tie are told apart by their
#: better sides.
SCORE_TIE_DEG = 1e-9


@njit(cache=True, nogil=True)
def best_compact_split(x, tets, starts, rotation, side, n_rotations, vol_min):
    """The compact split whose worse side is best shaped, among candidate cones.

    Candidate ``i`` is the tets ``starts[i] .. starts[i + 1] - 1``: the cone
    of one side (``side[i]``) to one apex for one rotation of the cut
    polygon's fan (``rotation[i]``).  Its score is its smallest dihedral
    angle, or -1 when a tet has a signed volume below ``vol_min`` (the
    paper's Fig. 4 penetration test).  Each side of each rotation takes its
    best candidate (the first of equals); the rotation whose worse side
    scores best wins, and among rotations whose worse sides tie, the one whose
    better side scores best (the first of equals; equal within
    :data:`SCORE_TIE_DEG`).

    Parameters
    ----------
    x : (n, 3) float64
    tets : (k, 4) int64
    starts : (c + 1,) int64
    rotation, side : (c,) int64
    n_rotations : int
    vol_min : float
        mm^3.

    Returns
    -------
    (pick0, pick1, angle) : int, int, float
        The candidates of side 0 and side 1 and the worse side's angle in
        degrees; (-1, -1, 0.0) when every rotation has a side without a
        candidate passing the volume test.
    """
    n_c = starts.shape[0] - 1
    side_best = np.full((n_rotations, 2), -1.0)
    side_pick = np.full((n_rotations, 2), -1, np.int64)
    normals = np.empty((4, 3))
    angles = np.empty((tets.shape[0], 6))
    for i in range(n_c):
        worst = np.inf
        lowest = np.inf
        r, s = rotation[i], side[i]
        for t in range(starts[i], starts[i + 1]):
            lowest = min(lowest, min_volume(x, tets[t:t + 1]))
            tet_dihedrals(x, tets, t, normals, angles)
            for e in range(6):
                worst = min(worst, angles[t, e])
            if worst <= side_best[r, s] + SCORE_TIE_DEG:
                break  # its score can only fall (or be -1): it cannot replace the side's best
        score = worst if lowest >= vol_min else -1.0
        if score > side_best[r, s] + SCORE_TIE_DEG:
            side_best[r, s] = score
            side_pick[r, s] = i
    best_r = -1
    best = -np.inf
    best_other = -np.inf
    for r in range(n_rotations):
        worse = min(side_best[r, 0], side_best[r, 1])
        other = max(side_best[r, 0], side_best[r, 1])
        if worse > best + SCORE_TIE_DEG or (worse >= best - SCORE_TIE_DEG and other > best_other + SCORE_TIE_DEG):
            best, best_other, best_r = worse, other, r
    if best < 0.0:
        return -1, -1, 0.0
    return side_pick[best_r, 0], side_pick[best_r, 1], best


@njit(cache=True, nogil=True, inline="always")
def _find(keys, n, k):
    """Index of ``k`` among ``keys[:n]``, or -1."""
    for i in range(n):
        if keys[i] == k:
            return i
    return -1


@njit(cache=True, nogil=True, inline="always")
def _find_or_add(keys, counts, s, k):
    """Index of ``k`` among ``keys[s, :counts[s]]``, appended first if missing (a dict's insertion order)."""
    i = _find(keys[s], counts[s], k)
    if i < 0:
        i = counts[s]
        counts[s] += 1
        keys[s, i] = k
    return i


@njit(cache=True, nogil=True)
def _loop_keys(ct, o):
    """The cut nodes of original tet ``o`` and the key of each: edge e -> e, face f -> -1 - f.

    Returns (nodes (q,), keys (q,)) in the twin's order (edges, then faces).
    """
    nodes = np.empty(_MAX_KEYS, np.int64)
    keys = np.empty(_MAX_KEYS, np.int64)
    q = 0
    for k in range(6):
        e = ct.tet_edges[o, k]
        if ct.edge_t[e] == ct.edge_t[e]:  # cut (not NaN)
            for c in range(2):
                nodes[q], keys[q] = ct.edge_node[e, c], e
                q += 1
    for lf in range(4):
        f = ct.tet_faces[o, lf]
        for c in range(2):
            if ct.face_node[f, c] >= 0:
                nodes[q], keys[q] = ct.face_node[f, c], -1 - f
                q += 1
    return nodes[:q], keys[:q]


@njit(cache=True, nogil=True)
def _cut_loop(ct, o, tris, tri_side):
    """The cut polygon: its nodes' keys in order (side 0's loop), and each side's node of each key.

    Each face triangle's edges between two cut nodes are the polygon's edges
    on that triangle's side, run the other way.  Returns (loop_keys (L,),
    copy_keys (2, q), copy_nodes (2, q), n_copy (2,)); L = 0 when the
    segments do not close into one loop seen from both sides.
    """
    nodes, keys = _loop_keys(ct, o)
    q = nodes.shape[0]
    k3 = 3 * tris.shape[0]
    nxt_b = np.empty((2, k3), np.int64)  # b -> a, in first-insertion order of b
    nxt_a = np.empty((2, k3), np.int64)
    n_nxt = np.zeros(2, np.int64)
    copy_keys = np.empty((2, q), np.int64)
    copy_nodes = np.empty((2, q), np.int64)
    n_copy = np.zeros(2, np.int64)
    for t in range(tris.shape[0]):
        s = tri_side[t]
        for j in range(3):
            a, b = tris[t, j], tris[t, (j + 1) % 3]
            ia, ib = _find(nodes, q, a), _find(nodes, q, b)
            if ia < 0 or ib < 0:
                continue
            nxt_a[s, _find_or_add(nxt_b, n_nxt, s, b)] = a
            copy_nodes[s, _find_or_add(copy_keys, n_copy, s, keys[ia])] = a
            copy_nodes[s, _find_or_add(copy_keys, n_copy, s, keys[ib])] = b
    none = np.zeros(0, np.int64)
    m = n_nxt[0]
    if m == 0 or m != n_nxt[1]:
        return none, copy_keys, copy_nodes, n_copy
    loop = np.empty(m, np.int64)
    loop[0] = nxt_b[0, 0]
    L = 1
    while True:
        i = _find(nxt_b[0], m, loop[L - 1])
        if i < 0:
            return none, copy_keys, copy_nodes, n_copy
        if nxt_a[0, i] == loop[0]:
            break
        if L == m:
            return none, copy_keys, copy_nodes, n_copy
        loop[L] = nxt_a[0, i]
        L += 1
    if L != m:
        return none, copy_keys, copy_nodes, n_copy
    loop_keys = np.empty(L, np.int64)
    for i in range(L):
        loop_keys[i] = keys[_find(nodes, q, loop[i])]
        if _find(copy_keys[1], n_copy[1], loop_keys[i]) < 0:
            return none, copy_keys, copy_nodes, n_copy
    return loop_keys, copy_keys, copy_nodes, n_copy


@njit(cache=True, nogil=True)
def _allowed_apexes(corners, tris, tri_side, tri_face, group):
    """Whether each corner may be its side's apex, (4,) bool: every face triangle of its side on a
    face through the corner contains it (the cone then reproduces the face patterns: no crack).
    Face ``lf`` is the one opposite corner ``lf``; its triangles are the cone's flat ones."""
    ok = np.ones(4, np.bool_)
    for ia in range(4):
        apex = corners[ia]
        for t in range(tris.shape[0]):
            if tri_side[t] == group[ia] and tri_face[t] != ia:
                if tris[t, 0] != apex and tris[t, 1] != apex and tris[t, 2] != apex:
                    ok[ia] = False
                    break
    return ok


@njit(cache=True, nogil=True)
def _loop_nodes(loop_keys, copy_keys, copy_nodes, n_copy):
    """The cut polygon's node of each loop key on each side, (2, L) int64."""
    L = loop_keys.shape[0]
    node_of = np.empty((2, L), np.int64)
    for s in range(2):
        for i in range(L):
            node_of[s, i] = copy_nodes[s, _find(copy_keys[s], n_copy[s], loop_keys[i])]
    return node_of


@njit(cache=True, nogil=True)
def _candidate_cones(corners, ok, group, tris, tri_side, tri_face, node_of, n_apexes):
    """Every candidate cone of a compact split: for each fan rotation r, side s and allowed apex,
    the cone of the side's face triangles and of the cut polygon fanned from loop node r.

    Returns
    -------
    (flat, starts, rotation, side) : (p, 4), (c + 1,), (c,), (c,) int64
        The candidates' tets one after another (candidate i is ``flat[starts[i]:starts[i + 1]]``),
        and each candidate's rotation and side.
    """
    k = tris.shape[0]
    L = node_of.shape[1]
    fan = max(L - 2, 0)
    n_cand = L * n_apexes
    starts = np.zeros(n_cand + 1, np.int64)
    rotation = np.empty(n_cand, np.int64)
    side = np.empty(n_cand, np.int64)
    flat = np.empty((L * (4 * k + 2 * 4 * fan), 4), np.int64)
    c = 0
    p = 0
    for r in range(L):
        for s in range(2):
            for ia in range(4):
                if not ok[ia] or group[ia] != s:
                    continue
                apex = corners[ia]
                for t in range(k):  # the cone of the side's face triangles ...
                    if tri_side[t] == s and tri_face[t] == ia:
                        flat[p, 0], flat[p, 1], flat[p, 2], flat[p, 3] = tris[t, 0], tris[t, 2], tris[t, 1], apex
                        p += 1
                for i in range(1, L - 1):  # ... and of the fan from loop node r (side 1 sees it flipped)
                    n0, n1, n2 = node_of[s, r], node_of[s, (r + i) % L], node_of[s, (r + i + 1) % L]
                    if s == 0:
                        flat[p, 0], flat[p, 1], flat[p, 2], flat[p, 3] = n0, n2, n1, apex
                    else:
                        flat[p, 0], flat[p, 1], flat[p, 2], flat[p, 3] = n0, n1, n2, apex
                    p += 1
                rotation[c], side[c] = r, s
                c += 1
                starts[c] = p
    return flat[:p], starts, rotation, side


@njit(cache=True, nogil=True)
def compact_split(ct, x, o, tris, tri_corner, tri_face, group, vol_min):
    """The best compact split of original tet ``o`` (:func:`cutkit.cutting.splits.compact_split`).

    Parameters
    ----------
    ct : CutTables
    x : (n, 3) float64
    o : int
    tris : (k, 3) int64
        The tet's face triangles (Fig. 2 patterns), outward.
    tri_corner : (k,) int64
        Local corner of each triangle's owner vertex (which decides its side).
    tri_face : (k,) int64
        Local face each triangle lies on (face ``lf`` is opposite corner ``lf``).
    group : (4,) int64
        Side (0 or 1) of each corner.
    vol_min : float
        Smallest signed volume a tet of the split may have, mm^3.

    Returns
    -------
    (tets, angle) : (p, 4) int64 and float
        Side 0's cone, then side 1's, and the worse side's smallest
        dihedral angle in degrees; p = 0 when no choice passes the volume test.
    """
    k = tris.shape[0]
    tri_side = np.empty(k, np.int64)
    for t in range(k):
        tri_side[t] = group[tri_corner[t]]
    none = np.zeros((0, 4), np.int64)
    loop_keys, copy_keys, copy_nodes, n_copy = _cut_loop(ct, o, tris, tri_side)
    L = loop_keys.shape[0]
    if L == 0:
        return none, 0.0
    corners = ct.orig_tets[o]
    ok = _allowed_apexes(corners, tris, tri_side, tri_face, group)
    n_apex = np.zeros(2, np.int64)
    for ia in range(4):
        n_apex[group[ia]] += ok[ia]
    if n_apex[0] == 0 or n_apex[1] == 0:
        return none, 0.0
    node_of = _loop_nodes(loop_keys, copy_keys, copy_nodes, n_copy)
    flat, starts, rotation, side = _candidate_cones(corners, ok, group, tris, tri_side, tri_face,
                                                    node_of, n_apex[0] + n_apex[1])
    p0, p1, angle = best_compact_split(x, flat, starts, rotation, side, L, vol_min)
    if p0 < 0:
        return none, 0.0
    n0 = starts[p0 + 1] - starts[p0]
    out = np.empty((n0 + starts[p1 + 1] - starts[p1], 4), np.int64)
    out[:n0] = flat[starts[p0]:starts[p0 + 1]]
    out[n0:] = flat[starts[p1]:starts[p1 + 1]]
    return out, angle


@njit(cache=True, nogil=True)
def compact_split_diagonals(ct, x, o, mask, group, vol_min, free, centre_nodes):
    """:func:`compact_split` of original tet ``o`` under every combination of its free diagonals, the best kept
    (:func:`cutkit.cutting.splits.compact_split`: one call instead of two per combination).

    Parameters
    ----------
    ct, x, o, group, vol_min : as :func:`compact_split`
    mask : int  the tet's cut edges (6-bit, reduced)
    free : (d, 3) int64
        The split faces whose diagonal is not fixed: face, the smaller-id vertex (bit 0), the other (bit 1).
        Combination ``bits`` sets face i's diagonal to column ``1 + (bits >> i & 1)`` of row i in
        ``ct.face_diag``, which is left at the last combination tried.
    centre_nodes : bool

    Returns
    -------
    (bits, tris, corner, face, tets, angle)
        The winning combination (the first of equals within :data:`SCORE_TIE_DEG`) with its face
        triangles (:func:`face_triangles`), its split's tets and their smallest dihedral angle; bits -1
        with combination 0's triangles, no tets and angle 0 when no combination passes the volume test.
    """
    best_bits, best_angle = -1, 0.0
    best_tris, best_tets = np.zeros((0, 3), np.int64), np.zeros((0, 4), np.int64)
    best_corner, best_face = np.zeros(0, np.int64), np.zeros(0, np.int64)
    for bits in range(1 << free.shape[0]):
        for i in range(free.shape[0]):
            ct.face_diag[free[i, 0]] = free[i, 1 + (bits >> i & 1)]
        tris, corner, face = face_triangles(ct, o, mask, centre_nodes)
        if bits == 0:
            best_tris, best_corner, best_face = tris, corner, face
        tets, angle = compact_split(ct, x, o, tris, corner, face, group, vol_min)
        if tets.shape[0] and (best_bits < 0 or angle > best_angle + SCORE_TIE_DEG):
            best_bits, best_angle = bits, angle
            best_tris, best_corner, best_face, best_tets = tris, corner, face, tets
    return best_bits, best_tris, best_corner, best_face, best_tets, best_angle


@njit(cache=True, nogil=True)
def best_face_apex(x, tris, tri_face, face_nodes, vol_min):
    """The notched face whose node F is the best apex of a cone over the other faces' triangles.

    A tetrahedron is star-shaped from any point of a face, and the cut's
    triangles inside it become a fan from F: the cone of every triangle not
    on F's face to F tiles a partly cut tet without its interior node T,
    with the triangles of F's own face left out (fewer tets than the T-cone;
    :func:`cutkit.cutting.resubdivision.resubdivide`).

    Parameters
    ----------
    x : (n, 3) float64
    tris : (k, 3) int64
        The tet's face triangles (Fig. 2 patterns), outward.
    tri_face : (k,) int64
        Local face each triangle lies on.
    face_nodes : (4,) int64
        The node F of each local face that is notched, -1 for the others.
    vol_min : float
        Smallest signed volume a tet of the cone may have, mm^3.

    Returns
    -------
    (lf, angle) : int, float
        The local face whose F is the apex (-1: none passes the volume test)
        and its cone's smallest dihedral angle, degrees; the first best wins a
        tie (:data:`SCORE_TIE_DEG`).
    """
    k = tris.shape[0]
    cone = np.empty((k, 4), np.int64)
    normals = np.empty((4, 3))
    angles = np.empty((k, 6))
    best_lf, best = -1, -1.0
    for lf in range(4):
        F = face_nodes[lf]
        if F < 0:
            continue
        m = 0
        for j in range(k):
            if tri_face[j] != lf:
                cone[m, 0], cone[m, 1], cone[m, 2], cone[m, 3] = tris[j, 0], tris[j, 2], tris[j, 1], F
                m += 1
        if m == 0 or min_volume(x, cone[:m]) < vol_min:
            continue
        worst = np.inf
        for j in range(m):
            tet_dihedrals(x, cone, j, normals, angles)
            for e in range(6):
                worst = min(worst, angles[j, e])
        if worst > best + SCORE_TIE_DEG:
            best_lf, best = lf, worst
    return best_lf, best
