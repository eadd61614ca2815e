"""Per-tet tables and clipping rules of the marching isovolume (numba, no checks).

Local nodes of one Kuhn tet: 0-3 its corners (in path order), 4 + e the
crossing on its local edge e, 10 its centre node.  ``ref`` maps them to
cube refs, ``key`` to the global order of the quad rule, ``pos`` to
index-space positions (for the orientation of each emitted tet).  See
:mod:`cutkit.isovolume._kernels` for the passes that call these.
"""

from __future__ import annotations

from collections import namedtuple

from itertools import permutations

import numpy as np
from numba import njit

# ---------------------------------------------------------------- tables ---


def _kuhn_paths() -> np.ndarray:
    paths = []
    for perm in permutations(range(3)):
        code, path = 0, [0]
        for axis in perm:
            code |= 4 >> axis  # axis 0 (x) is bit 4, y bit 2, z bit 1
            path.append(code)
        paths.append(path)
    return np.array(paths, np.int64)


#: (8, 3) int64: offset (dx, dy, dz) of cube corner ``code = 4 dx + 2 dy + dz``.
CORNER_OFFSETS = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)], np.int64)
#: (6, 4) int64: corner codes of the six Kuhn tets, walking from corner 0 to
#: corner 7 one axis at a time (so every later corner's bits contain the earlier's).
KUHN_PATHS = _kuhn_paths()


def _kuhn_positive() -> np.ndarray:
    out = KUHN_PATHS.copy()
    for t in range(6):
        p = CORNER_OFFSETS[out[t]].astype(np.float64)
        if np.linalg.det(p[1:] - p[0]) < 0:
            out[t, 2], out[t, 3] = out[t, 3], out[t, 2]
    return out


#: (6, 4) int64: the same tets reordered to a positive volume in index space.
KUHN_POSITIVE = _kuhn_positive()
#: Local edges (a, b), a < b, of a tet in path order.
EDGE_A = np.array([0, 0, 0, 1, 1, 2], np.int64)
EDGE_B = np.array([1, 2, 3, 2, 3, 3], np.int64)
#: (4, 4) int64: local edge index of vertex pair (a, b); -1 on the diagonal.
LOCAL_EDGE = np.full((4, 4), -1, np.int64)
for _e in range(6):
    LOCAL_EDGE[EDGE_A[_e], EDGE_B[_e]] = _e
    LOCAL_EDGE[EDGE_B[_e], EDGE_A[_e]] = _e
#: Popcount of a 7-bit edge mask.
POPCOUNT = np.array([bin(m).count("1") for m in range(128)], np.int64)

#: Ref of the centre node of Kuhn tet t is REF_CENTRE + t.
REF_CENTRE = 64
#: Most tets one Kuhn tet can become (cone scheme: 4 faces x 4 triangles).
MAX_PIECES = 16

MODE_SCALAR = 0
MODE_LABELS = 1


#: Bisection steps of :func:`label_crossing` (2^-48 of an edge: exact in float64 positions).
LABEL_CROSSING_STEPS = 48


@njit(cache=True, nogil=True)
def label_crossing(lab, g, code, ny, nz):
    """Crossing parameter on grid edge ``(g, code)`` between two labels.

    The edge is the diagonal of the box it spans (a segment, a square or a
    cube, by its number of steps n).  With h = 1 at box corners of the low
    end's label, -1 at those of the high end's label and 0 elsewhere, the
    crossing is where the multilinear interpolant of h along the diagonal,
    sum_c h(c) s^|c| (1 - s)^(n - |c|), is zero: an axis edge gets its
    midpoint (the crossing of marching cubes on a label map), a diagonal
    edge a point that follows the neighbouring samples, not the midpoint
    that would put a lone corner's tip at the centre of its cube.  It only
    depends on the box's samples, so every tet sharing the edge sees it.
    """
    dx = (code >> 2) & 1
    dy = (code >> 1) & 1
    dz = code & 1
    n = dx + dy + dz
    if n == 1:
        return 0.5
    a = lab[g]
    b = lab[g + (dx * ny + dy) * nz + dz]
    w0 = 0.0
    w1 = 0.0
    w2 = 0.0
    w3 = 0.0
    for sub in range(8):
        if sub & ~code:
            continue
        gc = g + (((sub >> 2) & 1) * ny + ((sub >> 1) & 1)) * nz + (sub & 1)
        lc = lab[gc]
        h = 1.0 if lc == a else (-1.0 if lc == b else 0.0)
        k = ((sub >> 2) & 1) + ((sub >> 1) & 1) + (sub & 1)
        if k == 0:
            w0 += h
        elif k == 1:
            w1 += h
        elif k == 2:
            w2 += h
        else:
            w3 += h
    lo = 0.0
    hi = 1.0
    for _ in range(LABEL_CROSSING_STEPS):
        s = 0.5 * (lo + hi)
        r = 1.0 - s
        if n == 2:
            val = w0 * r * r + w1 * s * r + w2 * s * s
        else:
            val = w0 * r * r * r + w1 * s * r * r + w2 * s * s * r + w3 * s * s * s
        if val > 0.0:
            lo = s
        else:
            hi = s
    return 0.5 * (lo + hi)


# ------------------------------------------------------- tet clipping ---

#: One Kuhn tet being clipped: its local nodes' cube refs ``ref`` (11,) int64, global keys ``key``
#: (11,) int64 and index-space positions ``pos`` (11, 3) float64 (local 0-3 the corners, 4 + e the
#: crossing of edge e, 10 the centre), the orientation ``sgn`` (+1 / -1), and where its pieces go:
#: ``out`` (k, 4) int64 (cube refs) and ``out_lab`` (k,) int32.
Cell = namedtuple("Cell", ["ref", "key", "pos", "sgn", "out", "out_lab"])


@njit(cache=True, nogil=True)
def _emit(a, b, c, d, label, cell, n):
    """Append tet (a, b, c, d) (local node numbers) oriented so sgn * det > 0."""
    ref, pos, sgn, out, out_lab = cell.ref, cell.pos, cell.sgn, cell.out, cell.out_lab
    ax = pos[b, 0] - pos[a, 0]
    ay = pos[b, 1] - pos[a, 1]
    az = pos[b, 2] - pos[a, 2]
    bx = pos[c, 0] - pos[a, 0]
    by = pos[c, 1] - pos[a, 1]
    bz = pos[c, 2] - pos[a, 2]
    cx = pos[d, 0] - pos[a, 0]
    cy = pos[d, 1] - pos[a, 1]
    cz = pos[d, 2] - pos[a, 2]
    det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
    det *= sgn
    if det == 0.0:
        # Cannot happen for snap > 0 (crossings stay >= snap from both ends);
        # kept so that a zero-volume tet is never written.
        return n
    out[n, 0] = ref[a]
    out[n, 1] = ref[b]
    if det > 0.0:
        out[n, 2] = ref[c]
        out[n, 3] = ref[d]
    else:
        out[n, 2] = ref[d]
        out[n, 3] = ref[c]
    out_lab[n] = label
    return n + 1


@njit(cache=True, nogil=True)
def _quad(q0, q1, q2, q3, key):
    """Diagonal of quad (q0 q1 q2 q3) (cyclic): True for q0-q2, False for q1-q3.

    The diagonal starts at the quad's node of smallest global key, a rule
    both tets sharing the quad apply identically (Dompierre et al. 1999:
    with it every prism of the clip can be split without a Steiner node).
    """
    m = min(min(key[q0], key[q1]), min(key[q2], key[q3]))
    return key[q0] == m or key[q2] == m


@njit(cache=True, nogil=True)
def _pyramid(apex, q0, q1, q2, q3, label, cell, n):
    if _quad(q0, q1, q2, q3, cell.key):
        n = _emit(apex, q0, q1, q2, label, cell, n)
        n = _emit(apex, q0, q2, q3, label, cell, n)
    else:
        n = _emit(apex, q1, q2, q3, label, cell, n)
        n = _emit(apex, q1, q3, q0, label, cell, n)
    return n


@njit(cache=True, nogil=True)
def _prism(p0, p1, p2, r0, r1, r2, label, cell, n):
    """Split the prism with triangles (p0 p1 p2), (r0 r1 r2), pk joined to rk.

    V, the node of smallest key, cones the triangle opposite to it and the
    pyramid over the quad opposite to it; the two quads that contain V are
    then split along diagonals from V, as the quad rule demands.
    """
    key = cell.key
    best = p0
    for v in (p1, p2, r0, r1, r2):
        if key[v] < key[best]:
            best = v
    if best == r0 or best == r1 or best == r2:
        p0, p1, p2, r0, r1, r2 = r0, r1, r2, p0, p1, p2
    if best == p1:
        p0, p1, p2, r0, r1, r2 = p1, p2, p0, r1, r2, r0
    elif best == p2:
        p0, p1, p2, r0, r1, r2 = p2, p0, p1, r2, r0, r1
    a0, a1, a2, b0, b1, b2 = p0, p1, p2, r0, r1, r2
    n = _emit(a0, b0, b1, b2, label, cell, n)
    return _pyramid(a0, a1, a2, b2, b1, label, cell, n)


@njit(cache=True, nogil=True)
def _clip_side(x, lab, on, label, cell, sets, n):
    """Tets of the part of a tet on the side of label ``x`` (paper Fig. 2 cases).

    Vertices are *in* (label x, not ON), *on* (ON: value = level) or *out*;
    the part is the convex hull of the in and on vertices and the crossings
    of the in-out edges.  Local node 4 + e is the crossing of local edge e.
    """
    ins = sets[0]
    ons = sets[1]
    outs = sets[2]
    ni = 0
    nn = 0
    no = 0
    for v in range(4):
        if on[v]:
            ons[nn] = v
            nn += 1
        elif lab[v] == x:
            ins[ni] = v
            ni += 1
        else:
            outs[no] = v
            no += 1
    if ni == 0:
        return n
    if no == 0:  # np.int64: one compile of _emit, not one per literal (docs/performance.md, "Compiling")
        return _emit(np.int64(0), np.int64(1), np.int64(2), np.int64(3), label, cell, n)
    if ni == 1:
        i0 = ins[0]
        if no == 3:
            return _emit(i0, 4 + LOCAL_EDGE[i0, outs[0]], 4 + LOCAL_EDGE[i0, outs[1]],
                         4 + LOCAL_EDGE[i0, outs[2]], label, cell, n)
        if no == 2:
            return _emit(i0, ons[0], 4 + LOCAL_EDGE[i0, outs[0]], 4 + LOCAL_EDGE[i0, outs[1]],
                         label, cell, n)
        return _emit(i0, ons[0], ons[1], 4 + LOCAL_EDGE[i0, outs[0]], label, cell, n)
    if ni == 2:
        i0 = ins[0]
        i1 = ins[1]
        if no == 2:
            o0 = outs[0]
            o1 = outs[1]
            return _prism(i0, 4 + LOCAL_EDGE[i0, o0], 4 + LOCAL_EDGE[i0, o1],
                          i1, 4 + LOCAL_EDGE[i1, o0], 4 + LOCAL_EDGE[i1, o1],
                          label, cell, n)
        o0 = outs[0]
        return _pyramid(ons[0], i0, i1, 4 + LOCAL_EDGE[i1, o0], 4 + LOCAL_EDGE[i0, o0],
                        label, cell, n)
    # ni == 3, no == 1
    o0 = outs[0]
    return _prism(4 + LOCAL_EDGE[o0, ins[0]], 4 + LOCAL_EDGE[o0, ins[1]], 4 + LOCAL_EDGE[o0, ins[2]],
                  ins[0], ins[1], ins[2], label, cell, n)


@njit(cache=True, nogil=True)
def _cone(lab, cell, n):
    """Tets of a tet whose corners carry three or four labels (label maps only).

    Each face is partitioned by its own three labels alone (so both tets
    sharing it agree): one label - the whole face; two - a triangle and a
    quad (quad rule); three - three corner triangles and a middle triangle
    given to the tissue (label > 0) corner of smallest key.  Every piece is
    coned to the tet's centre node (local 10), so the interfaces inside the
    tet are cones that match up between the labels.
    """
    key = cell.key
    centre = np.int64(10)  # the local centre node, not a literal: one compile of _emit
    for o in range(4):
        a = (o + 1) % 4
        b = (o + 2) % 4
        c = (o + 3) % 4
        la = lab[a]
        lb = lab[b]
        lc = lab[c]
        if la == lb and lb == lc:
            if la != 0:
                n = _emit(centre, a, b, c, la, cell, n)
        elif la != lb and lb != lc and la != lc:
            eab = 4 + LOCAL_EDGE[a, b]
            ebc = 4 + LOCAL_EDGE[b, c]
            eca = 4 + LOCAL_EDGE[c, a]
            if la != 0:
                n = _emit(centre, a, eab, eca, la, cell, n)
            if lb != 0:
                n = _emit(centre, b, ebc, eab, lb, cell, n)
            if lc != 0:
                n = _emit(centre, c, eca, ebc, lc, cell, n)
            # the middle goes to the tissue corner of smallest key: never to
            # the background, so a tissue triple junction does not pinch the
            # outer surface
            lm = 0
            km = -1
            for v in (a, b, c):
                if lab[v] != 0 and (km < 0 or key[v] < km):
                    lm = lab[v]
                    km = key[v]
            if lm != 0:
                n = _emit(centre, eab, ebc, eca, lm, cell, n)
        else:
            # y is the odd corner, x0 x1 the pair
            if la == lb:
                y, x0, x1 = c, a, b
            elif lb == lc:
                y, x0, x1 = a, b, c
            else:
                y, x0, x1 = b, c, a
            e0 = 4 + LOCAL_EDGE[y, x0]
            e1 = 4 + LOCAL_EDGE[y, x1]
            if lab[y] != 0:
                n = _emit(centre, y, e0, e1, lab[y], cell, n)
            lx = lab[x0]
            if lx != 0:
                if _quad(x0, x1, e1, e0, key):
                    n = _emit(centre, x0, x1, e1, lx, cell, n)
                    n = _emit(centre, x0, e1, e0, lx, cell, n)
                else:
                    n = _emit(centre, x1, e1, e0, lx, cell, n)
                    n = _emit(centre, x1, e0, x0, lx, cell, n)
    return n


