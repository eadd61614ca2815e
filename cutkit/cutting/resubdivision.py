"""Re-subdivision of one cut tetrahedron from its cut state (paper section 3, Figs. 2-3).

:func:`resubdivide` replaces the sub-tetrahedra of an original tetrahedron
of a :class:`~cutkit.cutting.cutmesh.CutMesh` by those its cut edges, face
nodes and tip give now.  A complete split is coned per side to one of its
vertices when that is well shaped (:mod:`cutkit.cutting.splits`); a partly
cut tetrahedron the tip has left, to one of its notch nodes F; otherwise
every face triangle is coned to the interior node T (docs/cutting.md,
"Interior: cone to the cut node T"), to its piece's copy of T in a
tetrahedron with a forked face (three cut edges).
"""

from __future__ import annotations

import numpy as np

from cutkit.cutting import _kernels_split as KP
from cutkit.cutting import _kernels_step as K
from cutkit.cutting import subdivision as S
from cutkit.cutting.crumbs import forget_crumb_tets
from cutkit.cutting.tolerances import TET_BARY_MIN, clamp_bary
from cutkit.cutting.splits import (COMPACT_VOL_MIN, SPLIT_ANGLE_GAIN, SPLIT_ANGLE_GOOD, compact_split, fix_diagonals,
                                   flipped_split, live_angle)

#: Where T may go when no tip is inside (fractions of the way from the cut
#: nodes' centroid to the tet's centroid): the best-shaped cone is taken.  0
#: keeps the cut surface flattest; further in, fewer slivers near the cut.
T_BLENDS = (0.0, 0.35, 0.7)
_T_BLENDS = np.array(T_BLENDS)
_T_AT_CENTROID = np.zeros(1)


def _cone(tris, apex):
    """(k, 4) int64 tets of outward triangles ``tris`` (k, 3) coned to ``apex`` (a node, or (k,)
    one per triangle): positively oriented, since the apex lies inside of each triangle."""
    new = np.empty((tris.shape[0], 4), np.int64)
    new[:, 0], new[:, 1], new[:, 2], new[:, 3] = tris[:, 0], tris[:, 2], tris[:, 1], apex
    return new


def resubdivide(cm, o, flips=True):
    """Re-subdivide original tet ``o`` from scratch from its cut state (``flips``: a poor complete
    split may flip a diagonal a neighbour fixed, :func:`~cutkit.cutting.splits.flipped_split`)."""
    mask = S.REDUCE_TABLE[cm.tet_mask(o)]
    case, group = S.CLASSIFY_TABLE[mask]
    if case == "uncut":
        return
    v = cm.orig_tets[o].tolist()
    ct = cm.cut_tables()
    tb, free_T = _T_start(cm, ct, o, mask)
    complete = case in ("corner", "quad")
    general = case == "general"  # a forked face: one T per piece, always the T-cone
    group = np.array(group, np.int64)  # side (piece) of each corner
    new, choice = None, []
    if general:
        tris, corner, face = KP.face_triangles(ct, o, mask, cm.centre_nodes)
        if free_T:
            tb, _ = _best_T(cm, v, tb, tris, free_T)
    elif complete and cm.compact_splits:
        tris, corner, face, new, choice, tb, _ = _complete_split(cm, ct, o, mask, group, (tb, free_T), flips)
    else:
        tris, corner, face = KP.face_triangles(ct, o, mask, cm.centre_nodes)
        if o != cm.tip_tet:  # no tip inside: the crack front may run between notch nodes
            new, tb = _face_apex_cone(cm, o, v, tb, free_T, tris, face)
        elif free_T:
            tb, _ = _best_T(cm, v, tb, tris, free_T)
    if new is None:
        for c in range(int(group.max()) + 1 if complete or general else 1):
            if cm.tet_T[o, c] < 0:
                cm.tet_T[o, c] = cm._new_node(v, tb)
            else:
                cm._move_node(cm.tet_T[o, c], v, tb)
        # the cone of the face triangles to T (each piece's copy of T for a complete split or a general tet)
        new = _cone(tris, cm.tet_T[o][group[corner]] if complete or general else cm.tet_T[o, 0])
    # replace the old sub-tets
    old = forget_crumb_tets(cm, cm.subtets.get(o, [o]))  # a crumb's tets are dead already
    cm.remove_tets(old)
    ids = cm.store.add_tets(new, o)
    cm.subtets[o] = ids
    cm.sub_start[o], cm.sub_count[o] = ids[0], len(ids)  # contiguous (TissueStore.add_tets)
    # a tet across a split face follows the diagonal this split chose (and flips none of its own)
    for nb in fix_diagonals(cm, o, choice):
        resubdivide(cm, nb, flips=False)


def _T_start(cm, ct, o, mask):
    """(tb (4,) float64, free): where the tet's node T starts, the tip's barycentric weights, or with
    no tip inside (``free``: T may go where its cone is best shaped) the mean of its cut nodes."""
    tb = cm.tip_bary.get(o)
    free_T = tb is None
    return clamp_bary(K.cut_nodes_centroid(ct, o, mask) if free_T else tb, TET_BARY_MIN), free_T


def _complete_split(cm, ct, o, mask, group, T_start, flips):
    """(tris, corner, face, tets or None (the T-cone), choice, tb, angle): the complete split of ``o``
    as :func:`resubdivide` makes it: the best compact split; below ``SPLIT_ANGLE_GOOD`` the T-cone
    where that is better by ``SPLIT_ANGLE_GAIN`` (more tets, but no sliver), and with ``flips`` a
    compact split with a fixed diagonal flipped where that is better still
    (:func:`~cutkit.cutting.splits.flipped_split`); ``angle`` its smallest dihedral angle (degrees).
    ``T_start``: :func:`_T_start`'s (tb, free)."""
    tb, free_T = T_start
    tris, corner, face, new, angle, choice = compact_split(cm, ct, o, mask, group)
    if new is not None and angle >= SPLIT_ANGLE_GOOD:
        return tris, corner, face, new, choice, tb, angle
    v = cm.orig_tets[o].tolist()
    if new is None:  # no compact split: the T-cone, T where the cut nodes are (the cut stays flat)
        angle = _best_T(cm, v, tb, tris, False)[1]
    else:
        tb_c, cone = _best_T(cm, v, tb, tris, free_T)
        if cone > angle + SPLIT_ANGLE_GAIN:
            new, tb, angle = None, tb_c, cone
    flipped = flipped_split(cm, ct, o, mask, group, angle, split_angle_with) if flips else None
    if flipped is not None:
        tris, corner, face, new, angle, choice = flipped
    return tris, corner, face, new, choice, tb, angle


def split_angle_with(cm, nb, f, d) -> float:
    """Smallest dihedral angle (degrees) of the complete split of ``nb`` as :func:`resubdivide` would
    make it (no flip) with face ``f``'s diagonal through vertex ``d``; ``cm`` is left as it was."""
    kept = int(cm.face_diag[f])
    cm.face_diag[f] = d
    angle = _split_angle(cm, nb, False)
    cm.face_diag[f] = kept
    return angle


def better_split(cm, o, gain) -> bool:
    """Whether :func:`resubdivide` would lift the smallest angle of completely split ``o``'s live
    sub-tets by more than ``gain`` degrees: a split made before a later move of its nodes, or before
    its neighbours fixed their diagonals, may be a sliver that another split of the same cut lifts
    (a fixed diagonal flipped, :func:`~cutkit.cutting.splits.flipped_split`)."""
    return _split_angle(cm, o, True) > live_angle(cm, o) + gain


def _split_angle(cm, o, flips) -> float:
    """Smallest dihedral angle (degrees) of the complete split :func:`resubdivide` would make of ``o``."""
    mask = S.REDUCE_TABLE[cm.tet_mask(o)]
    _, group = S.CLASSIFY_TABLE[mask]
    ct = cm.cut_tables()
    return float(_complete_split(cm, ct, o, mask, np.array(group, np.int64), _T_start(cm, ct, o, mask), flips)[-1])


def _face_apex_cone(cm, o, v, tb, free_T, tris, face):
    """The cone of a partly cut tet no tip is in from one of its notch nodes F, or the T-cone.

    The tip's path crossed the tet and left it, so its crack front runs
    between its notched faces' nodes: the cone from one of them over the
    other faces' triangles (``_kernels_split.best_face_apex``) tiles the tet
    without T and with fewer tets (a notched face's four triangles are not
    coned).  It is kept unless it is poor (below ``SPLIT_ANGLE_GOOD``) and the
    T-cone is better by ``SPLIT_ANGLE_GAIN``: the rule of the complete splits'
    compact cones.  Returns ``(cone, tb)``: the F-cone's tets (k, 4) or None
    for the T-cone, and T's barycentric weights (placed by
    :func:`_best_T` where it was looked at).
    """
    f = cm.tet_faces[o]
    face_nodes = np.where(cm.face_ncut[f] == 1, cm.face_node[f, 0], -1)
    lf, angle = -1, -1.0
    if (face_nodes >= 0).any():
        lf, angle = KP.best_face_apex(cm._x, tris, face, face_nodes, COMPACT_VOL_MIN * float(cm._vol0(o)))
    if lf < 0 or angle < SPLIT_ANGLE_GOOD:
        tb, cone = _best_T(cm, v, tb, tris, free_T)
        if lf < 0 or cone > angle + SPLIT_ANGLE_GAIN:
            return None, tb
    return _cone(tris[face != lf], face_nodes[lf]), tb


def _best_T(cm, v, tb, tris, free):
    """Barycentric weights of T (4,) and the smallest dihedral angle (degrees) of its cone.

    With ``free`` (no tip inside), T is moved from the cut nodes' centroid
    ``tb`` towards the tet's centroid by each of ``T_BLENDS`` and the
    best-shaped cone is kept.  The candidates are tried in the spare row
    ``n_points`` of the store's node arrays (no node is made), all in one kernel
    call (``_kernels_step.best_cone_apex``).
    """
    cm.store.reserve_nodes(1)  # the spare row
    b, angle = K.best_cone_apex(cm._x, np.asarray(v, np.int64), np.asarray(tb, np.float64),
                                _T_BLENDS if free else _T_AT_CENTROID, tris, TET_BARY_MIN, cm.n_points)
    return b, float(angle)


def load_cone_kernel() -> float:
    """Load (or compile) the T-cone scoring kernel that :func:`resubdivide` calls when no tip is
    inside a cut tet, on one unit tetrahedron; a live session calls it before its clock starts
    (the warm-up's short cut never frees a tip).  Returns the best cone's smallest dihedral
    angle, degrees."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    tris = np.array([[0, 1, 2]], np.int64)
    _, angle = K.best_cone_apex(x, np.arange(4, dtype=np.int64), np.full(4, 0.25), _T_BLENDS, tris,
                                TET_BARY_MIN, 4)
    return float(angle)
