"""Contact of the whole blade with the tissue surface (paper section 4.1, extended).

The paper finds the entry from the tip's path alone.  A blade also meets
the tissue with its edge: a cleaver coming down, a through-cut whose tip
stays outside, or a surface that relaxes past a resting blade.  Between two
poses the blade (tip P, back Q) sweeps the quad (P0, Q0, Q1, P1), taken as
the triangles (P0, Q0, Q1) and (P0, Q1, P1); every boundary face that quad
or the blade at its new pose meets is a contact.  The queries descend the
same :class:`~cutkit.collision.bvh.SurfaceBVH` as the segment queries, so
they follow the deformed surface (after ``update``) and cost what the
hierarchy's overlap with the quad costs, not the model's size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.collision import _swept_kernels as K
from cutkit.collision.bvh import SurfaceBVH, _points, _vec3
from cutkit.errors import InputError

#: First guess of the number of faces one swept triangle meets.
_HIT_ROOM = 64
#: A swept triangle whose |sin| of the angle between its sides is below this is
#: flat (the blade pushed along its own axis sweeps no area); the blade
#: segment query covers it.
FLAT_TRIANGLE_EPS = 1e-12
#: The kinds of :class:`Contact` by the kernel's entry codes.
_ENTRY_KINDS = {K.ENTRY_TIP_PATH: "tip_path", K.ENTRY_BLADE: "blade", K.ENTRY_SWEPT: "swept"}


@dataclass
class Contact:
    """A blade contact: the boundary face, a point where the blade meets it, how it was found."""

    face: int
    point: np.ndarray
    kind: str  # 'tip_path' | 'blade' | 'swept'


def query_triangle(bvh: SurfaceBVH, points, tri):
    """Live boundary faces met by triangle ``tri`` (3, 3): (faces (h,) int64, points (h, 3) float64)."""
    points = np.ascontiguousarray(points, np.float64)
    tri = np.ascontiguousarray(tri, np.float64).reshape(3, 3)
    cap = _HIT_ROOM
    while True:
        face, pt = np.empty(cap, np.int64), np.empty((cap, 3))
        n = K.query_triangle(points, bvh.kernel_surface(), bvh.kernel_tree(), tri, face, pt)
        if n <= cap:
            return face[:n], pt[:n]
        cap = n


def swept_faces(bvh: SurfaceBVH, points, p0, q0, p1, q1):
    """Boundary faces met by the quad the blade swept from (p0, q0) to (p1, q1), or by the blade now.

    Returns
    -------
    faces : (h,) int64  unique, ascending
    points : (h, 3) float64  a point of each where the blade meets it
    """
    p0, q0, p1, q1 = (np.asarray(v, np.float64) for v in (p0, q0, p1, q1))
    fs, ps = [], []
    for tri in ((p0, q0, q1), (p0, q1, p1)):
        u, v = tri[1] - tri[0], tri[2] - tri[0]
        if np.linalg.norm(np.cross(u, v)) > FLAT_TRIANGLE_EPS * np.linalg.norm(u) * np.linalg.norm(v):
            f, p = query_triangle(bvh, points, np.array(tri))
            fs.append(f)
            ps.append(p)
    if np.any(p1 != q1):
        hits = bvh.query_segment(points, q1, p1)
        fs.append(hits.face)
        ps.append(hits.point)
    if not fs:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    f, p = np.concatenate(fs), np.concatenate(ps)
    u, first = np.unique(f, return_index=True)
    return u, p[first]


def blade_entry(bvh: SurfaceBVH, points, p0, q0, p1, q1) -> Contact | None:
    """Where the blade moving from pose (p0, q0) to (p1, q1) enters the tissue, or None.

    In order: the tip's path crossing a face inwards (the paper's entry);
    the blade at its new pose crossing a face inwards from back to tip
    (e.g. the surface moved past a resting tip); any face the swept quad
    meets whose outward normal faces against the blade's motion (an edge-first
    entry: cleaver, through-cut with the tip outside), the one nearest to
    the previous blade first.  One kernel call (``_swept_kernels.blade_entry``;
    its twin, the same tests made with :meth:`SurfaceBVH.query_segment` and
    :func:`swept_faces`, is in the tests): a live session makes it for every
    pose of a blade outside the tissue, a thousand times a second.

    Parameters
    ----------
    bvh : SurfaceBVH
    points : (n, 3) float64
        The positions last passed to ``bvh.update``.
    p0, q0, p1, q1 : (3,) float64
        The blade's tip and back before and now, mm.
    """
    points = _points(points, check_finite=False)
    if points.shape[0] != bvh.tol_min.shape[0]:
        raise InputError(f"points: {points.shape[0]} rows, expected {bvh.tol_min.shape[0]} (call update first)")
    p0, q0, p1, q1 = (_vec3(v, name) for v, name in ((p0, "p0"), (q0, "q0"), (p1, "p1"), (q1, "q1")))
    point = np.empty(3)
    code, face = K.blade_entry(points, bvh.kernel_surface(), bvh.kernel_tree(), p0, q0, p1, q1,
                               FLAT_TRIANGLE_EPS, point)
    if code == K.ENTRY_NONE:
        return None
    return Contact(int(face), point, _ENTRY_KINDS[code])
