"""Numba kernels of the six-tetrahedra marching isovolume.

The grid is a flat C-ordered array of ``nx * ny * nz`` samples, vertex
``g = (i * ny + j) * nz + k``.  Every cube is split into the six Kuhn
(Freudenthal) tetrahedra sharing the main diagonal (0,0,0)-(1,1,1); every
cube uses the same diagonal, so the split is conforming across cubes.  The
grid edges of that split go from a vertex to its seven forward neighbours
``+d``, ``d`` in {0,1}^3 \\ {0}; edge ``(g, d)`` has direction index
``code(d) - 1`` with ``code(dx, dy, dz) = 4 dx + 2 dy + dz``.

Work is split into passes that never need a lock (parallel over x-slabs):

1. :func:`classify_scalar` - per-vertex label and the ON flag of the
   snapping rule (scalar fields only).
2. :func:`edge_masks` - per vertex, the bit mask of its forward edges that
   carry a crossing point (endpoints of different labels, neither ON).
3. :func:`count_pieces` - per slab, the number of output tets and tet-centre
   nodes; marks the grid vertices that a tet uses.
4. prefix sums (NumPy) give every used vertex, crossing and centre its node id;
5. label maps: :func:`cutkit.isovolume._crossings.label_crossing_params`
   places every crossing on its edge once, in a table the next pass reads;
6. :func:`fill_points` and :func:`fill_pieces` write nodes and tets.

Inside a cube, a node is named by a *ref*: ``0..7`` a cube corner (its code),
``8 + 7 * corner + dir`` a crossing on the forward edge ``dir`` of a corner,
``REF_CENTRE + t`` the centre node of Kuhn tet ``t``.  The quad-split rule
orders nodes by a global *key*: ``g`` for grid vertex ``g`` and
``n_grid + 7 * g + dir`` for the crossing on edge ``(g, dir)``; both tets
that share a quadrilateral see the same keys and so pick the same diagonal.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, prange

from cutkit.isovolume._clip import (  # noqa: F401  (tables re-exported for callers)
    CORNER_OFFSETS,
    EDGE_A,
    EDGE_B,
    KUHN_PATHS,
    KUHN_POSITIVE,
    LOCAL_EDGE,
    MAX_PIECES,
    MODE_LABELS,
    MODE_SCALAR,
    POPCOUNT,
    REF_CENTRE,
    Cell,
    _clip_side,
    _cone,
    _emit,
)
from cutkit.isovolume._centre import place_centre
from cutkit.isovolume._structs import Cube

#: Work space of :func:`_cube_pieces`, one per slab: ``ref``, ``key`` (11,) int64, ``pos`` (11, 3)
#: float64, ``tlab`` (4,) int64, ``ton`` (4,) bool, ``sets`` (3, 4) int64, ``tmp`` (MAX_PIECES, 4)
#: int64, ``tmp_lab`` (MAX_PIECES,) int32; its output ``out`` (6 MAX_PIECES, 4) int64 (cube refs)
#: and ``out_lab`` (6 MAX_PIECES,) int32.
CubeScratch = namedtuple("CubeScratch", ["ref", "key", "pos", "tlab", "ton", "sets", "tmp", "tmp_lab", "out",
                                         "out_lab"])


# --------------------------------------------------------- vertex passes ---


@njit(cache=True, parallel=True)
def classify_scalar(f, nx, ny, nz, level, snap, label, lab, on):
    """Label and ON flag of every vertex of a scalar field (the snapping rule).

    A vertex is ON (on the surface) when its value equals ``level`` or when
    a crossing on one of its 14 grid edges lies closer than ``snap`` (as a
    fraction of that edge) to it: its value is then taken as ``level``, so
    the crossing point coincides with the vertex and no sliver is made.

    f : (n,) float64; lab : (n,) int32 out (``label`` where f >= level or ON,
    else 0); on : (n,) uint8 out.
    """
    for i in prange(nx):
        for j in range(ny):
            for k in range(nz):
                g = (i * ny + j) * nz + k
                fu = f[g]
                is_on = fu == level
                if not is_on:
                    for d in range(1, 8):
                        if is_on:
                            break
                        dx = (d >> 2) & 1
                        dy = (d >> 1) & 1
                        dz = d & 1
                        step = (dx * ny + dy) * nz + dz
                        for s in range(2):
                            if s == 0:
                                if i + dx >= nx or j + dy >= ny or k + dz >= nz:
                                    continue
                                fv = f[g + step]
                            else:
                                if i - dx < 0 or j - dy < 0 or k - dz < 0:
                                    continue
                                fv = f[g - step]
                            if (fu > level and fv < level) or (fu < level and fv > level):
                                t = (level - fu) / (fv - fu)
                                if t < snap:
                                    is_on = True
                                    break
                on[g] = 1 if is_on else 0
                lab[g] = label if (is_on or fu > level) else 0


@njit(cache=True, parallel=True)
def edge_masks(lab, on, nx, ny, nz, mask):
    """Bit ``dir`` of ``mask[g]`` is set when forward edge ``(g, dir)`` has a crossing.

    lab : (n,) int32; on : (n,) uint8; mask : (n,) uint8 out.
    """
    for i in prange(nx):
        for j in range(ny):
            for k in range(nz):
                g = (i * ny + j) * nz + k
                m = 0
                if on[g] == 0:
                    lu = lab[g]
                    for d in range(1, 8):
                        dx = (d >> 2) & 1
                        dy = (d >> 1) & 1
                        dz = d & 1
                        if i + dx >= nx or j + dy >= ny or k + dz >= nz:
                            continue
                        gv = g + (dx * ny + dy) * nz + dz
                        if on[gv] == 0 and lab[gv] != lu:
                            m |= 1 << (d - 1)
                mask[g] = m


@njit(cache=True, nogil=True)
def _cube_uniform(lab, on, g0, ny, nz):
    """The label of a cube whose 8 samples share it and none is ON, else -1."""
    l0 = lab[g0]
    for c in range(1, 8):
        g = g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)
        if lab[g] != l0:
            return -1
    for c in range(8):
        g = g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)
        if on[g] != 0:
            return -1
    return l0


@njit(cache=True, nogil=True)
def _cube_pieces(i, j, k, dims, field, scratch):
    """All tets of cube (i, j, k) into ``scratch.out`` (refs) and ``scratch.out_lab``; returns their count.

    ``dims`` (nx, ny, nz); ``field`` a ``_structs.Field``; ``scratch`` a :class:`CubeScratch`.
    """
    nx, ny, nz = dims
    n_grid = nx * ny * nz
    lab, on, f, level, mode, sgn = field
    ref, key, pos, tlab, ton, sets, tmp, tmp_lab, out, out_lab = scratch
    cell = Cell(ref, key, pos, sgn, tmp, tmp_lab)
    g0 = (i * ny + j) * nz + k
    n = 0
    # Fast path: a cube of one label and no ON vertex is six whole tets.
    l0 = lab[g0]
    uniform = True
    for c in range(8):
        g = g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)
        if lab[g] != l0 or on[g] != 0:
            uniform = False
            break
    if uniform:
        if l0 == 0:
            return 0
        for t in range(6):
            for v in range(4):
                out[n, v] = KUHN_POSITIVE[t, v] if sgn > 0 else KUHN_POSITIVE[t, v ^ (v >> 1)]
            out_lab[n] = l0
            n += 1
        return n
    for t in range(6):
        for v in range(4):
            c = KUHN_PATHS[t, v]
            g = g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)
            tlab[v] = lab[g]
            ton[v] = on[g] != 0
            ref[v] = c
            key[v] = g
            pos[v, 0] = (c >> 2) & 1
            pos[v, 1] = (c >> 1) & 1
            pos[v, 2] = c & 1
        # distinct labels among the corners
        nlab = 1
        for v in range(1, 4):
            new = True
            for w in range(v):
                if tlab[w] == tlab[v]:
                    new = False
            if new:
                nlab += 1
        # np.int64: a constant argument is typed as its literal, and numba compiles a callee once
        # for each literal it is called with (docs/performance.md, "Compiling")
        m = np.int64(0)
        if nlab == 1:
            if tlab[0] != 0:
                m = _emit(np.int64(0), np.int64(1), np.int64(2), np.int64(3), tlab[0], cell, m)
        else:
            for e in range(6):
                a = EDGE_A[e]
                b = EDGE_B[e]
                ca = KUHN_PATHS[t, a]
                cb = KUHN_PATHS[t, b]
                d = (ca ^ cb) - 1
                ref[4 + e] = 8 + 7 * ca + d
                key[4 + e] = n_grid + 7 * key[a] + d
                if tlab[a] != tlab[b] and not ton[a] and not ton[b]:
                    if mode == MODE_SCALAR:
                        fa = f[key[a]]
                        s = (level - fa) / (f[key[b]] - fa)
                    else:
                        # Label pieces (corner cuts, cones) are valid for any
                        # crossings in (0, 1), so their orientation is that at
                        # the midpoints; fill_points places the true crossing.
                        s = 0.5
                    for q in range(3):
                        pos[4 + e, q] = pos[a, q] + s * (pos[b, q] - pos[a, q])
            split22 = False
            if nlab == 2 and mode == MODE_LABELS:
                n0 = 0
                for v in range(4):
                    if tlab[v] == tlab[0]:
                        n0 += 1
                # label crossings need not be coplanar: a 2|2 tet's cut quad may
                # be skew, so it is coned from the centre like a 3-label tet
                split22 = n0 == 2
            if nlab == 2 and not split22:
                x0 = tlab[0]
                x1 = x0
                for v in range(1, 4):
                    if tlab[v] != x0:
                        x1 = tlab[v]
                if x0 != 0:
                    m = _clip_side(x0, tlab, ton, x0, cell, sets, m)
                if x1 != 0:
                    m = _clip_side(x1, tlab, ton, x1, cell, sets, m)
            else:
                ref[10] = REF_CENTRE + t
                for q in range(3):
                    pos[10, q] = 0.25 * (pos[0, q] + pos[1, q] + pos[2, q] + pos[3, q])
                m = _cone(tlab, cell, m)
        for r in range(m):
            for v in range(4):
                out[n, v] = tmp[r, v]
            out_lab[n] = tmp_lab[r]
            n += 1
    return n


# ---------------------------------------------------------- cube passes ---


@njit(cache=True, nogil=True)
def _cube_scratch(out, out_lab):
    """A fresh :class:`CubeScratch` writing to ``out`` and ``out_lab``."""
    return CubeScratch(np.empty(11, np.int64), np.empty(11, np.int64), np.zeros((11, 3), np.float64),
                       np.empty(4, np.int64), np.empty(4, np.bool_), np.empty((3, 4), np.int64),
                       np.empty((MAX_PIECES, 4), np.int64), np.empty(MAX_PIECES, np.int32), out, out_lab)


# The parallel kernels below take each array out of its struct before the prange, one name per
# line: numba's parfors (0.68) lose writes made through a struct's field inside the loop, or through
# names unpacked from a tuple argument (tests/test_numba_structs.py checks every parallel kernel).
@njit(cache=True, parallel=True)
def count_pieces(field, dims, counts, used):
    """Per x-slab i, the number of tets and of centre nodes; marks used grid vertices.

    ``field`` a ``_structs.Field``, ``dims`` (nx, ny, nz); ``counts`` = (n_tets, n_centres), both
    (nx - 1,) int64 out; used : (n,) uint8, zeroed, out.  Two slabs may both set a shared vertex's
    flag to 1 (same value).
    """
    nx = dims[0]
    ny = dims[1]
    nz = dims[2]
    lab = field.lab
    on = field.on
    n_tets = counts[0]
    n_centres = counts[1]
    for i in prange(nx - 1):
        out = np.empty((6 * MAX_PIECES, 4), np.int64)
        scratch = _cube_scratch(out, np.empty(6 * MAX_PIECES, np.int32))
        seen = np.empty(6, np.bool_)
        nt = 0
        nc = 0
        for j in range(ny - 1):
            for k in range(nz - 1):
                g0 = (i * ny + j) * nz + k
                u = _cube_uniform(lab, on, g0, ny, nz)
                if u == 0:
                    continue
                if u > 0:  # six whole Kuhn tets
                    nt += 6
                    for c in range(8):
                        used[g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)] = 1
                    continue
                m = _cube_pieces(np.int64(i), j, k, dims, field, scratch)
                nt += m
                seen[:] = False
                for r in range(m):
                    for v in range(4):
                        x = out[r, v]
                        if x < 8:
                            used[g0 + (((x >> 2) & 1) * ny + ((x >> 1) & 1)) * nz + (x & 1)] = 1
                        elif x >= REF_CENTRE:
                            seen[x - REF_CENTRE] = True
                for t in range(6):
                    if seen[t]:
                        nc += 1
        n_tets[i] = nt
        n_centres[i] = nc


@njit(cache=True, parallel=True)
def fill_points(field, crossings, used, vmap, dims, affine, points):
    """World positions of the used grid vertices and of the crossing points.

    field : ``_structs.Field``; crossings : ``_structs.Crossings`` (label maps
    read its ``cross_s``; see :mod:`._crossings`); used : (n,) uint8; vmap :
    (n,) int64 node id of each used vertex; dims : (nx, ny, nz); affine :
    (3, 4) float64 index -> world; points : (n_nodes, 3) float64 out.
    """
    nx = dims[0]
    ny = dims[1]
    nz = dims[2]
    f = field.f
    level = field.level
    mode = field.mode
    mask = crossings.mask
    eoff = crossings.eoff
    n_v = crossings.n_v
    cross_s = crossings.cross_s
    for i in prange(nx):
        for j in range(ny):
            for k in range(nz):
                g = (i * ny + j) * nz + k
                if used[g]:
                    p = vmap[g]
                    for q in range(3):
                        points[p, q] = affine[q, 0] * i + affine[q, 1] * j + affine[q, 2] * k + affine[q, 3]
                m = mask[g]
                if m == 0:
                    continue
                r = 0
                for d in range(7):
                    if (m >> d) & 1:
                        code = d + 1
                        dx = (code >> 2) & 1
                        dy = (code >> 1) & 1
                        dz = code & 1
                        if mode == MODE_SCALAR:
                            fa = f[g]
                            s = (level - fa) / (f[g + (dx * ny + dy) * nz + dz] - fa)
                        else:
                            s = cross_s[eoff[g] + r - n_v]
                        x = i + s * dx
                        y = j + s * dy
                        z = k + s * dz
                        p = eoff[g] + r
                        for q in range(3):
                            points[p, q] = affine[q, 0] * x + affine[q, 1] * y + affine[q, 2] * z + affine[q, 3]
                        r += 1


@njit(cache=True, parallel=True)
def fill_pieces(field, crossings, vmap, offsets, dims, affine, outputs):
    """Write the tets of every slab at ``tet_off[i]`` and its centre nodes at ``centre_off[i]``.

    field : ``_structs.Field``; crossings : ``_structs.Crossings``; vmap : (n,) int64; offsets =
    (tet_off, centre_off), both (nx - 1,) int64; dims : (nx, ny, nz); affine : (3, 4) float64;
    outputs = (tets (m, 4) int64 out, tet_labels (m,) int32 out, points (n_nodes, 3) float64
    (centre rows out)).
    """
    nx = dims[0]
    ny = dims[1]
    nz = dims[2]
    lab = field.lab
    on = field.on
    sgn = field.sgn
    mask = crossings.mask
    eoff = crossings.eoff
    tet_off = offsets[0]
    centre_off = offsets[1]
    tets = outputs[0]
    tet_labels = outputs[1]
    points = outputs[2]
    for i in prange(nx - 1):
        out = np.empty((6 * MAX_PIECES, 4), np.int64)
        out_lab = np.empty(6 * MAX_PIECES, np.int32)
        scratch = _cube_scratch(out, out_lab)
        centre_id = np.empty(6, np.int64)
        cworld = np.empty((REF_CENTRE, 3))
        cknown = np.zeros(REF_CENTRE, np.bool_)
        cwork = np.empty((8, 3))
        corner_id = np.empty(8, np.int64)
        nt = tet_off[i]
        nc = centre_off[i]
        for j in range(ny - 1):
            for k in range(nz - 1):
                g0 = (i * ny + j) * nz + k
                u = _cube_uniform(lab, on, g0, ny, nz)
                if u == 0:
                    continue
                if u > 0:  # six whole Kuhn tets
                    for c in range(8):
                        corner_id[c] = vmap[g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)]
                    for t in range(6):
                        tets[nt, 0] = corner_id[KUHN_POSITIVE[t, 0]]
                        tets[nt, 1] = corner_id[KUHN_POSITIVE[t, 1]]
                        if sgn > 0:
                            tets[nt, 2] = corner_id[KUHN_POSITIVE[t, 2]]
                            tets[nt, 3] = corner_id[KUHN_POSITIVE[t, 3]]
                        else:
                            tets[nt, 2] = corner_id[KUHN_POSITIVE[t, 3]]
                            tets[nt, 3] = corner_id[KUHN_POSITIVE[t, 2]]
                        tet_labels[nt] = u
                        nt += 1
                    continue
                m = _cube_pieces(np.int64(i), j, k, dims, field, scratch)
                if m == 0:
                    continue
                centre_id[:] = -1
                for r in range(m):
                    for v in range(4):
                        x = out[r, v]
                        if x < 8:
                            node = vmap[g0 + (((x >> 2) & 1) * ny + ((x >> 1) & 1)) * nz + (x & 1)]
                        elif x < REF_CENTRE:
                            c = (x - 8) // 7
                            d = (x - 8) - 7 * c
                            g = g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)
                            node = eoff[g] + POPCOUNT[mask[g] & ((1 << d) - 1)]
                        else:
                            t = x - REF_CENTRE
                            if centre_id[t] < 0:
                                centre_id[t] = nc
                                # default: the mean of its crossings (with the background
                                # if it has some), moved where that cone makes a sliver
                                place_centre(out, m, t, lab, Cube(g0, np.int64(i), j, k, ny, nz), crossings, affine,
                                             (cworld, cknown, cwork), points[nc])
                                nc += 1
                            node = centre_id[t]
                        tets[nt, v] = node
                    tet_labels[nt] = out_lab[r]
                    nt += 1
