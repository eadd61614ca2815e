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

from cutkit.cutting import _kernels_split as KP

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


def compact_split(cm, ct, o, tris, corner, face, group):
    """Best compact tetrahedralisation of the complete split of original tet ``o``.

    Parameters
    ----------
    cm : CutMesh
    ct : CutTables  its cut state (``cm.cut_tables()``)
    o : int  original tet
    tris, corner, face : (k, 3), (k,), (k,) int64  its Fig. 2 face triangles, the local corner
        owning each and the local face each lies on (``_kernels_split.face_triangles``)
    group : (4,) int64  side (0 or 1) of each corner of the tet

    Returns
    -------
    (tets, angle) : (p, 4) int64 and their smallest dihedral angle in
        degrees, or (None, 0.0) when no choice passes the volume test
        (``_kernels_split.compact_split``).
    """
    tets, angle = KP.compact_split(ct, cm._x, o, tris, corner, face, group, COMPACT_VOL_MIN * float(cm._vol0(o)))
    return (None, 0.0) if tets.shape[0] == 0 else (tets, float(angle))
