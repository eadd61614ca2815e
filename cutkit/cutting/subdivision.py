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
     through its original vertex of smallest global id).

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
(corner or quad pattern) has one copy per side.
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
    """True if no face of the tet has three cut edges (6-bit edge mask)."""
    for fe in FACE_EDGES:
        if all(mask >> int(e) & 1 for e in fe):
            return False
    return True


def reduce_mask(mask: int) -> int:
    """Nearest valid edge-cut pattern of a 6-bit mask (documented rule).

    A planar blade cuts at most two edges of a face.  Cut states are kept
    valid globally (an edge cut that would give a face three cut edges is
    refused, see ``CutMesh``), so this reduction is only a safety net:
    drop the highest-numbered cut edge until no face has three.
    """
    mask = int(mask) & 63
    while not face_ok(mask):
        top = mask.bit_length() - 1
        mask &= ~(1 << top)
    return mask


def classify(mask: int):
    """Case of Fig. 3 for a valid 6-bit mask and, for complete splits, the sides.

    Returns
    -------
    case : str
        ``'uncut'``, ``'partial'``, ``'corner'`` (3 edges at one vertex:
        a corner cut off) or ``'quad'`` (4 edges: split into two wedges).
    group : (4,) int
        Side of each local vertex (0 or 1); all 0 unless complete.
    """
    edges = [k for k in range(6) if mask >> k & 1]
    group = np.zeros(4, np.int64)
    if not edges:
        return "uncut", group
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


#: Masks of two opposite cut edges only (01+23, 02+13, 03+12): the cut would be two
#: crack sheets meeting at the tet's single crack-front node (non-manifold), so
#: ``CutMesh`` defers the second edge until a third links them.
OPPOSITE_MASKS = frozenset((1 << 0 | 1 << 5, 1 << 1 | 1 << 4, 1 << 2 | 1 << 3))

#: reduce_mask of every 6-bit mask (a lookup for the per-step subdivision).
REDUCE_TABLE = tuple(reduce_mask(_m) for _m in range(64))
#: (case, group as a tuple of 4 ints) of classify for every 6-bit mask.
CLASSIFY_TABLE = tuple((_c, tuple(int(_g) for _g in _grp)) for _c, _grp in (classify(_m) for _m in range(64)))
