"""Element quality: signed volumes and dihedral angles of tetrahedra."""

from __future__ import annotations

import numpy as np

from cutkit.errors import MeshError
from cutkit.mesh import _quality_kernels as _k
from cutkit.mesh.geometry import signed_volumes_serial
from cutkit.mesh.topology import _check_tets

#: Below this many tets the per-tet measures run on the calling thread: the parallel kernels split
#: their work into chunks of this size (``_quality_kernels._CHUNK``), so a smaller set gains nothing
#: from the threads and pays a thread-pool start per call (the cut's vertex smoothing looks at one
#: tet to a few hundred per call, thousands of calls on a long incision; on a loaded 2-core machine
#: a one-tet call to the parallel kernel took 11 ms).  The same values to the bit either way.
SERIAL_MAX_TETS = _k._CHUNK

__all__ = ["signed_volumes", "dihedral_angles", "min_dihedral_angles"]


def _check(points, tets):
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise MeshError(f"points must have shape (n, 3), got {pts.shape}")
    if pts.size and not np.issubdtype(pts.dtype, np.number):
        raise MeshError(f"points must be numeric, got dtype {pts.dtype}")
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    return pts, _check_tets(tets, pts.shape[0])


def signed_volumes(points, tets):
    """Signed volume of each tet.

    Parameters
    ----------
    points : (n, 3) float
    tets : (m, 4) int

    Returns
    -------
    volumes : (m,) float64
        ``det[p1 - p0, p2 - p0, p3 - p0] / 6``; positive for a positively oriented tet.
    """
    pts, tets = _check(points, tets)
    if tets.shape[0] < SERIAL_MAX_TETS:
        return signed_volumes_serial(pts, tets)
    return _k.signed_volumes(pts, tets)


def dihedral_angles(points, tets):
    """Interior dihedral angle at each of the six edges of each tet.

    Parameters
    ----------
    points : (n, 3) float
    tets : (m, 4) int

    Returns
    -------
    angles : (m, 6) float64
        Degrees in [0, 180]; column k is the angle at local edge
        ``TET_EDGES[k]``, between the planes of the two faces that share it.
        Computed from the face normals with atan2, exact-minded for slivers
        (a flat tet gives 0 and 180).  The angles do not depend on the tet's
        orientation.
    """
    pts, tets = _check(points, tets)
    if tets.shape[0] < SERIAL_MAX_TETS:
        return _k.dihedral_angles_serial(pts, tets)
    return _k.dihedral_angles(pts, tets)


def min_dihedral_angles(points, tets):
    """Smallest dihedral angle of each tet.

    Parameters
    ----------
    points : (n, 3) float
    tets : (m, 4) int

    Returns
    -------
    angles : (m,) float64
        Degrees.
    """
    return dihedral_angles(points, tets).min(axis=1)
