"""Compact complete splits: each side of a split tetrahedron coned to one of its vertices.

A complete split (``corner`` or ``quad`` pattern) can be tetrahedralised
with far fewer tetrahedra than the cone to an interior node T: the cut
polygon (the closed loop of face cut segments) is triangulated once by a
fan from one loop node, and each side is the cone of its face triangles and
the cut triangles to one original vertex of that side (the apex).

An apex is allowed only if every face triangle of its side on a face
through it contains it (the cone then reproduces the face's Fig. 2 pattern,
so the neighbours still conform).  All fan nodes and apexes are tried and
scored by the smallest dihedral angle of their tetrahedra; a choice whose
tetrahedra are not all of volume >= ``COMPACT_VOL_MIN`` times the
original's is refused.  This plays the role of the paper's Fig. 4
intersection tests (an interior edge that would make tetrahedra penetrate
shows up as a negative volume) and, by taking the best-shaped choice,
avoids slivers where a better choice exists.
"""

from __future__ import annotations

import numpy as np

from cutkit.cutting import _kernels_step as KS
from cutkit.mesh import _quality_kernels as Q

#: Compact complete splits accept only sub-tets of at least this fraction
#: of the original tet's volume (else the always-valid T-cone is used).
COMPACT_VOL_MIN = 1e-3
#: Smallest dihedral angle (degrees) of a compact split that is taken without
#: looking at the T-cone: at or above it the compact split (fewer tets) wins.
#: Just above the 5-degree goal: at 10 the T-cone (twice the tets) was taken
#: so often that a wobbling incision made 7.2 tets per cut tet instead of 6.4,
#: for a median worst angle 1 degree better.
SPLIT_ANGLE_GOOD = 6.0
#: Below SPLIT_ANGLE_GOOD the T-cone (about twice the tets) replaces the
#: compact split only when its worst angle is better by this many degrees.
SPLIT_ANGLE_GAIN = 2.0


def min_angles_per_group(x, tets, n_groups):
    """Smallest dihedral angle (degrees) of each of ``n_groups`` equal consecutive groups of tets (k, 4)."""
    return Q.dihedral_angles_serial(x, tets).min(axis=1).reshape(n_groups, -1).min(axis=1)


def _cut_loop(cm, o, tris, vgroup):
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


def _apexes(v, tris, vgroup):
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


def compact_split(cm, o, tris, vgroup):
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
        degrees, or (None, 0.0) when no choice passes the volume test.
    """
    v = [int(q) for q in cm.orig_tets[o]]
    lp = _cut_loop(cm, o, tris, vgroup)
    if lp is None:
        return None, 0.0
    keys, copy = lp
    apexes = _apexes(v, tris, vgroup)
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
    return _best(cm._x, cands, COMPACT_VOL_MIN * float(cm._vol0(o)), len(keys))


def _best(x, cands, vol_min, n_rot):
    """The fan rotation whose worse side is best; each side takes its best apex
    (``_kernels_step.best_compact_split``)."""
    flat = np.array([t for _, _, c in cands for t in c], np.int64)
    starts = np.zeros(len(cands) + 1, np.int64)
    np.cumsum([len(c) for _, _, c in cands], out=starts[1:])
    rotation = np.array([r for r, _, _ in cands], np.int64)
    side = np.array([s for _, s, _ in cands], np.int64)
    p0, p1, angle = KS.best_compact_split(x, flat, starts, rotation, side, n_rot, vol_min)
    if p0 < 0:
        return None, 0.0
    return cands[p0][2] + cands[p1][2], float(angle)
