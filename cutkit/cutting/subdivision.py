"""Crack-free subdivision of cut tetrahedra (paper section 3, Figs. 2-4).

Every original tetrahedron is re-subdivided from scratch, from its
original vertices and its accumulated cut state, whenever that state
changes (progressive cutting: subdivisions never compound).

The construction, in two parts:

1. Each original face is triangulated by one of the three permitted
   patterns of Fig. 2, chosen only from *global* face data (which of its
   edges are cut, the face node) so the two tetrahedra sharing the face
   always agree (crack-free):

   * 0 cut edges: the face itself;
   * 1 cut edge (notch, Fig. 2b): edge node E and face node F, 4 triangles;
   * 2 cut edges (complete split, Fig. 2c): the two edge nodes and the
     centre node C on the cut line, 5 triangles (or, with
     ``centre_nodes=False``, 3 triangles with the quad's diagonal taken
     through its original vertex of smallest global id);
   * 3 cut edges (beyond the paper: a second cut crossing the first in
     the face, or a swept surface folded over it): each corner's quad
     (the corner, its two edge nodes and its own copy of a centre node C
     inside the face), 6 triangles; the cut in the face is a Y.

2. The interior is the cone of all face triangles to one interior cut
   node T (the blade tip while the tip is inside, else the centroid of
   the tetrahedron's cut nodes, kept strictly interior).  Because T is
   strictly inside the convex original tetrahedron, every cone tet has
   positive volume and the cones tile it exactly (volume is conserved).
   The cut surface inside the tetrahedron is the fan (T, a, b) over the
   face cut segments; its two sides are distinct faces because the face
   triangles on either side of a cut segment use different copies of
   the cut nodes.

The face patterns are built by ``_kernels_split.face_triangles`` and the
compact complete splits (each side coned to one of its vertices, fewer
tetrahedra than the cone to T) by ``_kernels_split.compact_split``; this
module keeps the tables of edge masks and cases.

Node copies (duplication so the cut can open): an edge node has two
copies, one attached to each end vertex of its *global* edge; a centre
node C has a copy for the face's lone vertex side and one for its pair
side; a notch face node F and the tip node T of a partial cut lie on the
crack front and have one copy; T of a completely split tetrahedron
(corner or quad pattern) has one copy per side.  A face with three cut
edges has three copies of C, one per corner, and a tetrahedron with such a
face (case ``general``) one copy of T per piece: the components of its
uncut edges (:func:`vertex_groups`), up to four.
"""

from __future__ import annotations

import numpy as np

from cutkit.mesh.topology import TET_EDGES, TET_FACES

#: local edge id of the local vertex pair (i, j)
LOCAL_EDGE = -np.ones((4, 4), np.int64)
for _k, (_i, _j) in enumerate(TET_EDGES):
    LOCAL_EDGE[_i, _j] = LOCAL_EDGE[_j, _i] = _k
#: local edges of local face i (face opposite vertex i), in cyclic order
#: (f0,f1), (f1,f2), (f2,f0) of TET_FACES[i]
FACE_EDGES = np.array([[LOCAL_EDGE[f[0], f[1]], LOCAL_EDGE[f[1], f[2]], LOCAL_EDGE[f[2], f[0]]]
                       for f in TET_FACES], np.int64)


def face_ok(mask: int) -> bool:
    """True if no face of the tet has three cut edges (6-bit edge mask): one of the paper's Fig. 3 cases."""
    for fe in FACE_EDGES:
        if all(mask >> int(e) & 1 for e in fe):
            return False
    return True


def vertex_groups(mask: int) -> np.ndarray:
    """(4,) int64 the piece of each local vertex: the components of the tet's uncut edges.

    Two corners joined by an uncut edge stay together; a cut edge between
    two corners of one group is a crack (the cut has not gone round yet).
    Groups are numbered in order of their first corner.
    """
    group = -np.ones(4, np.int64)
    n = 0
    for v in range(4):
        if group[v] >= 0:
            continue
        group[v], todo = n, [v]
        while todo:
            a = todo.pop()
            for k, (i, j) in enumerate(TET_EDGES.tolist()):
                if not mask >> k & 1 and a in (i, j):
                    b = j if a == i else i
                    if group[b] < 0:
                        group[b] = n
                        todo.append(b)
        n += 1
    return group


def classify(mask: int):
    """Case of Fig. 3 for a 6-bit mask and the side (piece) of each corner.

    Returns
    -------
    case : str
        ``'uncut'``, ``'partial'``, ``'corner'`` (3 edges at one vertex:
        a corner cut off), ``'quad'`` (4 edges: split into two wedges), or
        ``'general'``: a face has three cut edges (a second cut crossing
        the first in this tet, or a swept surface folded over it), beyond
        the paper's Fig. 3; its corners fall into :func:`vertex_groups`.
    group : (4,) int
        Side of each local vertex: 0 or 1 for a complete split (all 0 for
        the partial cases), the :func:`vertex_groups` for ``general``.
    """
    edges = [k for k in range(6) if mask >> k & 1]
    group = np.zeros(4, np.int64)
    if not edges:
        return "uncut", group
    if not face_ok(mask):
        return "general", vertex_groups(mask)
    if len(edges) == 3:
        for v in range(4):
            if all(v in TET_EDGES[e] for e in edges):
                group[v] = 1
                return "corner", group
    if len(edges) == 4:
        uncut = [k for k in range(6) if not mask >> k & 1]
        a, b = TET_EDGES[uncut[0]]
        if not set(TET_EDGES[uncut[1]]) & {a, b}:
            group[a] = group[b] = 1
            return "quad", group
    return "partial", group


def _face_pattern_keys(mask, lf, lc):
    """The Fig. 2 triangles of local face ``lf`` (corners ``lc``, outward) with symbolic node keys, and
    the corner owning each (the rules of ``_kernels_split.face_triangles``, any quad diagonal)."""
    cut = [bool(mask >> int(k) & 1) for k in FACE_EDGES[lf]]  # edges (lc0 lc1), (lc1 lc2), (lc2 lc0)

    def e(a, b, side):
        return ("e", min(a, b), max(a, b), side)

    n_cut = sum(cut)
    if n_cut == 0:
        return [(tuple(lc), lc[0])]
    out = []
    if n_cut == 1:
        j = cut.index(True)
        p, q, r = lc[j], lc[(j + 1) % 3], lc[(j + 2) % 3]
        F = ("f", lf)
        return [((p, e(p, q, p), F), p), ((e(p, q, q), q, F), q), ((q, r, F), q), ((r, p, F), r)]
    if n_cut == 2:
        ju = cut.index(False)
        q, r, p = lc[ju], lc[(ju + 1) % 3], lc[(ju + 2) % 3]
        return [((p, e(p, q, p), e(r, p, p)), p), ((e(p, q, q), q, e(r, p, r)), q), ((q, r, e(r, p, r)), q)]
    for j in range(3):  # three cut edges: each corner's quad round its copy of the centre node C
        p, q, r = lc[j], lc[(j + 1) % 3], lc[(j + 2) % 3]
        C = ("c", lf, p)
        out += [((p, e(p, q, p), C), p), ((p, C, e(r, p, p)), p)]
    return out


def _cone_links(mask: int) -> list:
    """For each interior node T of the T-cone of ``mask`` (one per piece), the number of loops of its link.

    A symbolic lone tet: the face patterns with every cut node's copies as
    keys, each triangle coned to the T of its corner's piece.  The boundary
    of the cones around a T is a disc (a manifold vertex) only when the
    boundary edges opposite T form one loop.
    """
    group = vertex_groups(mask)
    cones = []
    for lf, lc in enumerate(TET_FACES.tolist()):
        for tri, owner in _face_pattern_keys(mask, lf, lc):
            cones.append((tri, ("T", int(group[owner]))))
    faces = {}
    for (p, a, b), t in cones:
        for tri in ((p, a, t), (a, b, t), (b, p, t)):
            key = frozenset(tri)
            faces[key] = faces.get(key, 0) + 1
    links = []
    for g in sorted(set(group.tolist())):
        t = ("T", g)
        adj = {}
        for key, n in faces.items():
            if n == 1 and t in key:
                a, b = [x for x in key if x != t]
                adj.setdefault(a, []).append(b)
                adj.setdefault(b, []).append(a)
        loops, seen = 0, set()
        for a in adj:
            if a not in seen:
                loops += 1
                todo = [a]
                while todo:
                    x = todo.pop()
                    if x not in seen:
                        seen.add(x)
                        todo.extend(adj[x])
        links.append(loops)
    return links


def reduce_mask(mask: int) -> int:
    """Nearest mask that is not two opposite cut edges alone (:data:`OPPOSITE_MASKS`): a safety net.

    ``CutMesh`` defers an edge cut that would give a tet such a mask, so
    this only drops the higher cut edge of a state that should not occur.
    """
    mask = int(mask) & 63
    while mask in OPPOSITE_MASKS:
        top = mask.bit_length() - 1
        mask &= ~(1 << top)
    return mask


#: Masks of two opposite cut edges only (01+23, 02+13, 03+12): the cut would be two crack
#: sheets meeting at the tet's single crack-front node (non-manifold), so ``CutMesh`` defers
#: the second edge until a third links them.  They are the only masks whose T-cone joins two
#: sheets at a T (:func:`_cone_links`, checked by the tests), the general ones included.
OPPOSITE_MASKS = frozenset((1 << 0 | 1 << 5, 1 << 1 | 1 << 4, 1 << 2 | 1 << 3))

#: reduce_mask of every 6-bit mask (a lookup for the per-step subdivision).
REDUCE_TABLE = tuple(reduce_mask(_m) for _m in range(64))
#: (case, group as a tuple of 4 ints) of classify for every 6-bit mask.
CLASSIFY_TABLE = tuple((_c, tuple(int(_g) for _g in _grp)) for _c, _grp in (classify(_m) for _m in range(64)))
