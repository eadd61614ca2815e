"""Placement of the centre node of a coned tet (label maps; numba, no checks).

A Kuhn tet whose corners carry three or four labels (or a skew 2|2 split)
is cut into pieces coned to one centre node (:func:`cutkit.isovolume._clip._cone`).
Any point strictly inside the Kuhn tet keeps every cone tet valid, so the
centre is free to move inside it; only this tet's pieces use it.  With a
background corner the centre is the mean of the crossings with the
background, which keeps the outer surface close to flat, and it stays
there.  Without one it starts at the mean of all crossings, and when that
makes a cone tet with a dihedral angle below
:data:`CENTRE_MIN_DIHEDRAL_DEG` it moves towards the Kuhn tet's centroid, to
the blend (:data:`CENTRE_BLENDS`) whose cone has the largest smallest angle.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cutkit.isovolume._clip import EDGE_A, EDGE_B, KUHN_PATHS, REF_CENTRE
from cutkit.isovolume._crossings import crossing_node
from cutkit.mesh.geometry import tet_max_cos

#: A centre whose cone has a smaller dihedral angle (degrees) is moved.  Above
#: the decimator's default floor (10 degrees), so that floor is met with margin.
CENTRE_MIN_DIHEDRAL_DEG = 15.0
#: Fractions of the way from the default centre to a better-shaped target.
CENTRE_BLENDS = np.array([0.25, 0.5, 0.75, 1.0])
#: A candidate replaces the best so far only if its smallest angle is larger by
#: this much (degrees): near-ties, common in symmetric configurations, keep
#: the earlier candidate whatever the rounding.
CENTRE_GAIN_DEG = 1e-6


@njit(cache=True, nogil=True, inline="always")
def _grid_id(g0, c, ny, nz):
    return g0 + (((c >> 2) & 1) * ny + ((c >> 1) & 1)) * nz + (c & 1)


@njit(cache=True, nogil=True)
def _index_position(x, cube, crossings, out):
    """Index-space position of cube ref ``x`` (a corner, < 8, or a crossing, < REF_CENTRE) of ``cube``
    (``_structs.Cube``; ``crossings`` a ``_structs.Crossings``)."""
    g0, i, j, k, ny, nz = cube
    mask, eoff, n_v, cross_s = crossings
    if x < 8:
        c = x
        s = 0.0
        code = 0
    else:
        c = (x - 8) // 7
        code = (x - 8) - 7 * c + 1
        s = cross_s[crossing_node(_grid_id(g0, c, ny, nz), code - 1, mask, eoff) - n_v]
    out[0] = i + ((c >> 2) & 1) + s * ((code >> 2) & 1)
    out[1] = j + ((c >> 1) & 1) + s * ((code >> 1) & 1)
    out[2] = k + (c & 1) + s * (code & 1)


@njit(cache=True, nogil=True, inline="always")
def _to_world(affine, p, out):
    for q in range(3):
        out[q] = affine[q, 0] * p[0] + affine[q, 1] * p[1] + affine[q, 2] * p[2] + affine[q, 3]


@njit(cache=True, nogil=True)
def _background_crossing_mean(lab, cube, t, crossings, out):
    """Index-space mean of Kuhn tet ``t``'s crossings with the background.

    There is one on an edge of every corner, so the mean is strictly inside the tet.
    """
    g0, i, j, k, ny, nz = cube
    mask, eoff, n_v, cross_s = crossings
    p = np.empty(3)
    out[:] = 0.0
    nw = 0
    for e in range(6):
        ca = KUHN_PATHS[t, EDGE_A[e]]
        cb = KUHN_PATHS[t, EDGE_B[e]]
        la = lab[_grid_id(g0, ca, ny, nz)]
        lb = lab[_grid_id(g0, cb, ny, nz)]
        if la == lb:
            continue
        if la != 0 and lb != 0:
            continue
        sc = cross_s[crossing_node(_grid_id(g0, ca, ny, nz), (ca ^ cb) - 1, mask, eoff) - n_v]
        p[0] = i + ((ca >> 2) & 1) + sc * (((cb >> 2) & 1) - ((ca >> 2) & 1))
        p[1] = j + ((ca >> 1) & 1) + sc * (((cb >> 1) & 1) - ((ca >> 1) & 1))
        p[2] = k + (ca & 1) + sc * ((cb & 1) - (ca & 1))
        out += p
        nw += 1
    out /= nw


@njit(cache=True, nogil=True)
def _cone_min_angle(rows, m, centre_ref, centre, world, p):
    """Smallest dihedral angle (degrees) of the rows (cube refs; ``world`` positions) that use the centre.

    ``p`` (4, 3) float64 is scratch space.
    """
    worst = -1.0
    for r in range(m):
        uses = False
        for v in range(4):
            if rows[r, v] == centre_ref:
                uses = True
        if not uses:
            continue
        for v in range(4):
            x = rows[r, v]
            if x == centre_ref:
                p[v] = centre
            else:
                p[v] = world[x]
        worst = max(worst, tet_max_cos(p[0], p[1], p[2], p[3]))
    return math.degrees(math.acos(min(1.0, worst)))


@njit(cache=True, nogil=True)
def place_centre(rows, m, t, lab, cube, crossings, affine, scratch, out):
    """World position of the centre node of Kuhn tet ``t`` of ``cube`` (``_structs.Cube``).

    Parameters
    ----------
    rows : (>= m, 4) int64
        The cube's pieces as cube refs; those holding ``REF_CENTRE + t`` are
        the cone of this centre.
    crossings : Crossings
        The crossing table (:mod:`cutkit.isovolume._crossings`).
    affine : (3, 4) float64
        Index space to world (mm).
    scratch : tuple
        (``world`` (REF_CENTRE, 3) float64, ``known`` (REF_CENTRE,) bool,
        ``work`` (8, 3) float64): world positions of cube refs, which are
        filled in, and work space.
    out : (3,) float64
        Receives the position.
    """
    world, known, work = scratch
    g0, ny, nz = cube.g0, cube.ny, cube.nz
    has_bg = False
    for w in range(4):
        if lab[_grid_id(g0, KUHN_PATHS[t, w], ny, nz)] == 0:
            has_bg = True
    c0 = work[0]
    if has_bg:
        # A centre on the outer surface stays at the mean of the background
        # crossings: moving it would move the boundary away from the
        # segmentation (docs/isovolume.md, the half-voxel bound).
        _background_crossing_mean(lab, cube, t, crossings, c0)
        _to_world(affine, c0, out)
        return
    centre_ref = REF_CENTRE + t
    # World positions of the cube refs of this cone: its corners and all its
    # crossings (every crossing of the tet bounds a face piece), each once.
    known[:] = False
    for r in range(m):
        uses = False
        for v in range(4):
            if rows[r, v] == centre_ref:
                uses = True
        if not uses:
            continue
        for v in range(4):
            x = rows[r, v]
            if x < REF_CENTRE and not known[x]:
                known[x] = True
                _index_position(x, cube, crossings, work[1])
                _to_world(affine, work[1], world[x])
    # The crossing mean and the centroid, in world space (the map is affine).
    centroid = work[1]
    c0[:] = 0.0
    centroid[:] = 0.0
    nw = 0
    for e in range(6):
        ca = KUHN_PATHS[t, EDGE_A[e]]
        cb = KUHN_PATHS[t, EDGE_B[e]]
        if lab[_grid_id(g0, ca, ny, nz)] != lab[_grid_id(g0, cb, ny, nz)]:
            c0 += world[8 + 7 * ca + (ca ^ cb) - 1]
            nw += 1
    c0 /= nw
    for w in range(4):
        centroid += 0.25 * world[KUHN_PATHS[t, w]]
    p = work[4:8]
    best_angle = _cone_min_angle(rows, m, centre_ref, c0, world, p)
    out[:] = c0
    if best_angle < CENTRE_MIN_DIHEDRAL_DEG:
        cand = work[2]
        for b in range(CENTRE_BLENDS.shape[0]):
            f = CENTRE_BLENDS[b]
            for q in range(3):
                cand[q] = c0[q] + f * (centroid[q] - c0[q])
            angle = _cone_min_angle(rows, m, centre_ref, cand, world, p)
            if angle > best_angle + CENTRE_GAIN_DEG:
                best_angle = angle
                out[:] = cand
