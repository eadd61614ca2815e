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

from cutkit.cutting import _kernels_split as KP
from cutkit.cutting.subdivision import FACE_EDGES
from cutkit.mesh.quality import min_dihedral_angles
from cutkit.mesh.topology import TET_EDGES

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
#: A complete split below SPLIT_ANGLE_GOOD may flip a split face's diagonal fixed before
#: (:func:`flipped_split`; False keeps every fixed diagonal).
FLIP_DIAGONALS = True


def compact_split(cm, ct, o, mask, group):
    """Best compact tetrahedralisation of the complete split of original tet ``o``, with its face patterns.

    The quad of a split face may be cut by either diagonal as long as both
    tetrahedra sharing the face agree.  A partly cut tetrahedron is coned to
    its node T and takes either, so only complete splits fix a face's
    diagonal (:func:`fix_diagonals`); the first to be made chooses.  Every
    combination of the free diagonals of this tet's split faces is tried
    with the cones and the best-shaped split kept (the smaller-id diagonals
    first, so equals keep them).  Three split faces give eight
    combinations; a corner cut off near a vertex by a tilted blade, whose
    smaller-id diagonals left 2 degrees on the knee, can then take its best
    prism split.  (Searching only below ``SPLIT_ANGLE_GOOD`` cost as much on
    the knee and left more slivers on the block: the splits made first then
    fix diagonals their neighbours would have chosen otherwise.)

    Parameters
    ----------
    cm : CutMesh
    ct : CutTables  its cut state (``cm.cut_tables()``)
    o : int  original tet
    mask : int  its cut edges (6-bit, reduced)
    group : (4,) int64  side (0 or 1) of each corner of the tet

    Returns
    -------
    (tris, corner, face, tets, angle, choice)
        Its Fig. 2 face triangles (k, 3), the local corner owning each (k,)
        and the local face each lies on (k,) (``_kernels_split.face_triangles``,
        with the chosen diagonals); the split's tets (p, 4) int64 and their
        smallest dihedral angle in degrees, or (None, 0.0) when no choice
        passes the volume test (``_kernels_split.compact_split``); and the
        chosen diagonals, a list of (face, vertex id, the vertex it had:
        the smaller-id one for a free face, the fixed one for a flipped
        face, :func:`flipped_split`), left unfixed.
    """
    free = _free_diagonals(cm, o, mask)
    return _as_split(_search(cm, ct, o, mask, group, COMPACT_VOL_MIN * float(cm._vol0(o)), free))


def flipped_split(cm, ct, o, mask, group, floor, neighbour_angle):
    """The compact split of ``o`` with diagonals fixed before flipped, where that lifts the worse of
    ``o`` and the neighbours re-split for it; as :func:`compact_split`, or None.

    A split face's diagonal is fixed by the first complete split that used it
    (:func:`fix_diagonals`), and every split of the tet across it may then be
    a sliver (a corner a retraced stroke cut off a tet the first pass made).
    Each fixed diagonal of a face on the surface or across a cut neighbour
    (:func:`_flippable_faces`) is tried both ways with the free ones; the
    best split is taken when its smallest angle, and that of every
    completely split neighbour re-split with the flipped diagonal, beat the
    worse of ``floor`` and those neighbours' now.  The caller re-splits the
    neighbours without flips of their own, so a flip never cascades.

    Parameters
    ----------
    cm, ct, o, mask, group : as :func:`compact_split`
    floor : float  smallest dihedral angle (degrees) of the split ``o`` gets without a flip
    neighbour_angle : callable
        ``neighbour_angle(cm, nb, face, vertex)``: smallest dihedral angle (degrees) of completely
        split ``nb`` re-split with ``face``'s diagonal through ``vertex`` (no flip).
    """
    flippable = _flippable_faces(cm, o, mask)
    if not (FLIP_DIAGONALS and flippable):
        return None
    free = _free_diagonals(cm, o, mask)
    trial = _search(cm, ct, o, mask, group, COMPACT_VOL_MIN * float(cm._vol0(o)),
                    free + [(f, d, e) for f, d, e, _ in flippable])
    bits = trial[1]
    flipped = [row for i, row in enumerate(flippable) if bits >= 0 and bits >> (len(free) + i) & 1]
    if not (flipped and trial[-1] > floor):
        return None
    worst_before, worst_after = floor, trial[-1]
    for f, _, e, nb in (row for row in flipped if row[3] >= 0):
        worst_before = min(worst_before, live_angle(cm, nb))
        worst_after = min(worst_after, neighbour_angle(cm, nb, f, e))
    return _as_split(trial) if worst_after > worst_before else None


def _as_split(found):
    """:func:`compact_split`'s tuple from :func:`_search`'s."""
    rows, (bits, tris, corner, face, tets, angle) = found[0], found[1:]
    choice = [(f, hi if bits > 0 and bits >> i & 1 else lo, lo) for i, (f, lo, hi) in enumerate(rows)]
    return tris, corner, face, (tets if bits >= 0 else None), float(angle), choice


def _search(cm, ct, o, mask, group, vol_min, rows):
    """(rows, bits, tris, corner, face, tets, angle): ``KP.compact_split_diagonals`` of ``o`` over
    ``rows`` [(face, vertex of bit 0, vertex of bit 1)], the faces' diagonals left as they were."""
    faces = [f for f, _, _ in rows]
    kept = cm.face_diag[faces].copy()
    out = KP.compact_split_diagonals(ct, cm._x, o, mask, group, vol_min,
                                     np.array(rows, np.int64).reshape(-1, 3), cm.centre_nodes)
    cm.face_diag[faces] = kept
    return (rows, *out)


def _flippable_faces(cm, o, mask):
    """[(face, its fixed diagonal vertex, the other, the neighbour or -1)]: the split faces of ``o``
    whose diagonal is fixed, not along an earlier cut, on the model's surface (no neighbour: -1), or
    across a partly cut neighbour (its cone takes either diagonal: -1) or a completely split one (a
    crumb's tets it re-makes are found and removed again by the step,
    :func:`~cutkit.cutting.crumbs.remove_crumbs`)."""
    if cm.centre_nodes:
        return []
    out = []
    for lf in range(4):
        f = int(cm.tet_faces[o, lf])
        if cm.face_diag[f] < 0 or f in cm.face_twins:
            continue
        uncut = [k for k in FACE_EDGES[lf].tolist() if not mask >> k & 1]
        if len(uncut) != 1:
            continue
        nb = [int(t) for t in cm.face_tets[f] if t >= 0 and t != o]
        nb = nb[0] if nb and nb[0] in cm.subtets and cm.completely_split(nb[0]) else -1
        a, b = (int(q) for q in cm.orig_tets[o, TET_EDGES[uncut[0]]])
        d = int(cm.face_diag[f])
        out.append((f, d, b if d == a else a, nb))
    return out


def live_angle(cm, o) -> float:
    """Smallest dihedral angle (degrees) of the live sub-tets of ``o`` (180 where none is)."""
    ids = np.array(cm.subtets[o], np.int64)
    ids = ids[cm._alive[ids]]
    return float(min_dihedral_angles(cm._x, cm._tets[ids]).min()) if ids.size else 180.0


def _free_diagonals(cm, o, mask):
    """[(face, smaller, larger vertex of its quad's base (by ``node_rep``))] for the split faces of ``o`` whose diagonal
    is not fixed yet (none with centre nodes, nor on a face with copies along an earlier cut)."""
    if cm.centre_nodes:
        return []
    out = []
    for lf in range(4):
        f = int(cm.tet_faces[o, lf])
        if cm.face_diag[f] >= 0 or f in cm.face_twins:
            continue
        uncut = [k for k in FACE_EDGES[lf].tolist() if not mask >> k & 1]
        if len(uncut) == 1:  # two cut edges: split
            a, b = sorted((int(q) for q in cm.orig_tets[o, TET_EDGES[uncut[0]]]), key=lambda q: cm.node_rep[q])
            out.append((f, a, b))
    return out


def fix_diagonals(cm, o, choice):
    """Fix the diagonals ``choice`` [(face, vertex id, default vertex id)] a complete split of ``o`` was made with.

    Returns
    -------
    redo : list of int
        The cut tets across a face whose diagonal is now not the default
        (smaller-id) one they were subdivided with: re-subdivide them.
    """
    redo = []
    for f, d, default in choice:
        cm.face_diag[f] = d
        other = [int(t) for t in cm.face_tets[f] if t >= 0 and t != o]
        if d != default and other and other[0] in cm.subtets:
            redo.append(other[0])
    return redo
