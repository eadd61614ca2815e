"""Numba kernel of the re-subdivision of a tetrahedron coned over its faces, in one call.

:func:`partial_cone` makes the choices :func:`cutkit.cutting.resubdivision.resubdivide`
makes for a partly cut tetrahedron, or a complete split with compact splits
off (docs/cutting.md, "Interior: cone to the cut node T"): where T goes, the Fig. 2 face triangles, and whether the cone
from a notch node F replaces the T-cone.  It calls the kernels the Python
code called one by one (:func:`_kernels_step.cut_nodes_centroid`,
:func:`cutkit.mesh.geometry.clamp_bary`, :func:`_kernels_split.face_triangles`,
:func:`_kernels_split.best_face_apex`, :func:`_kernels_step.best_cone_apex`)
in the same order on the same data; what one call saves is their
dispatches (a cut tables tuple costs about 4 µs a call to unpack).

Slow, obviously correct twin: ``tests/_twins_cut.py::partial_cone_twin``
(the rule in plain Python over the twins of those kernels).
"""

from collections import namedtuple

import numpy as np
from numba import njit

from cutkit.cutting._kernels_split import best_face_apex, face_triangles
from cutkit.cutting._kernels_step import best_cone_apex, cut_nodes_centroid
from cutkit.mesh.geometry import clamp_bary, min_volume

#: The rule of a partly cut tet's cone (constants of a :class:`~cutkit.cutting.cutmesh.CutMesh`):
#: ``centre_nodes`` (bool), ``blends`` (q,) float64 (where a free T may go,
#: ``resubdivision.T_BLENDS``), ``at_centroid`` (1,) float64 (a T at the tip stays), ``bary_min``
#: (``TET_BARY_MIN``), ``vol_fraction`` (``splits.COMPACT_VOL_MIN``), ``angle_good`` and
#: ``angle_gain`` (degrees, ``splits.SPLIT_ANGLE_GOOD`` and ``SPLIT_ANGLE_GAIN``).
ConeRule = namedtuple("ConeRule", "centre_nodes blends at_centroid bary_min vol_fraction angle_good angle_gain")


@njit(cache=True, nogil=True)
def _t_cone(tris, keep):
    """The tets (t0, t2, t1, -1) of the triangles ``tris`` (k, 3) where ``keep`` (k,) is set; the apex
    column is left -1 for the caller's node."""
    out = np.empty((int(keep.sum()), 4), np.int64)
    p = 0
    for j in range(tris.shape[0]):
        if keep[j]:
            out[p, 0], out[p, 1], out[p, 2], out[p, 3] = tris[j, 0], tris[j, 2], tris[j, 1], -1
            p += 1
    return out


@njit(cache=True, nogil=True)
def partial_cone(ct, x, o, mask, tb, free_T, notch_cone, rule, spare):
    """The sub-tets of original tet ``o``, coned over its Fig. 2 face triangles.

    Where the tip's path crossed the tet and left it (``notch_cone``), its
    crack front runs between its notched faces' nodes F: the cone from one
    of them over the other faces' triangles (:func:`best_face_apex`) tiles
    the tet without T and with fewer tets (the notched face's own triangles
    are not coned).  It is kept unless it is poor (below ``angle_good``) and
    the T-cone is better by ``angle_gain``, the rule of the complete
    splits' compact cones.  Otherwise the triangles are coned to T: at the
    tip, or (``free_T``) from the cut nodes' centroid towards the tet's
    centroid where its cone is best shaped (:func:`best_cone_apex`).

    Parameters
    ----------
    ct : CutTables
    x : (n, 3) float64
        Positions; row ``spare`` (no node's) is written (the T candidates).
    o, mask : int
        The tet and its cut edges (6-bit, reduced).
    tb : (4,) float64
        The tip's weights in the tet (ignored where ``free_T``).
    free_T : bool
        No tip inside: T goes where its cone is best shaped.
    notch_cone : bool
        The tip is not in the tet: the cone from a notch node F may replace the T-cone.
    rule : ConeRule
    spare : int

    Returns
    -------
    (tets, corner, t_cone, tb)
        The sub-tets (k, 4) int64 and the local corner owning each one's face
        triangle (k,) int64; ``t_cone`` True where their apex column is T's
        (left -1), and T's weights (4,) float64.
    """
    if free_T:  # the mean of the tet's cut nodes
        tb = cut_nodes_centroid(ct, o, mask)
    tb = clamp_bary(tb, rule.bary_min)
    tris, corner, face = face_triangles(ct, o, mask, rule.centre_nodes)
    everything = np.ones(tris.shape[0], np.bool_)
    blends = rule.blends if free_T else rule.at_centroid
    if not notch_cone:
        if free_T:
            tb, _ = best_cone_apex(x, ct.orig_tets[o], tb, blends, tris, rule.bary_min, spare)
        return _t_cone(tris, everything), corner, True, tb
    face_nodes = np.full(4, -1, np.int64)
    for lf in range(4):
        f = ct.tet_faces[o, lf]
        if ct.face_ncut[f] == 1:
            face_nodes[lf] = ct.face_node[f, 0]
    lf, angle = -1, -1.0
    if (face_nodes >= 0).any():
        lf, angle = best_face_apex(x, tris, face, face_nodes, rule.vol_fraction * min_volume(x, ct.orig_tets[o:o + 1]))
    if lf < 0 or angle < rule.angle_good:  # a poor F-cone: the T-cone may be better
        tb, cone = best_cone_apex(x, ct.orig_tets[o], tb, blends, tris, rule.bary_min, spare)
        if lf < 0 or cone > angle + rule.angle_gain:
            return _t_cone(tris, everything), corner, True, tb
    keep = face != lf
    new = _t_cone(tris, keep)
    new[:, 3] = face_nodes[lf]
    return new, corner[keep], False, tb
