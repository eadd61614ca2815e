"""Dihedral-angle figures of an isovolume mesh.

Uses :mod:`cutkit.mesh.quality` where it exists; the small NumPy version
below stands in for it otherwise (same definition: the angle between the
two faces at each of the six edges, in degrees).
"""

from __future__ import annotations

import numpy as np

_FACE_PAIRS = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))  # faces meeting at edge (0,1), (0,2), ...


def _dihedral_angles(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    p = points[tets]
    # outward-or-inward face normals n_i of the face opposite vertex i; the
    # interior dihedral angle at the edge shared by faces i, j is pi - angle(n_i, n_j)
    # when both normals point outward.
    faces = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))
    normals = np.empty((len(tets), 4, 3))
    for i, (a, b, c) in enumerate(faces):
        normals[:, i] = np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a])
    lengths = np.linalg.norm(normals, axis=2)
    normals /= np.where(lengths > 0, lengths, 1.0)[..., None]
    out = np.empty((len(tets), 6))
    for e, (i, j) in enumerate(_FACE_PAIRS):
        cosang = -np.einsum("ij,ij->i", normals[:, i], normals[:, j])
        out[:, e] = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
    return out


def min_dihedral_angles(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Smallest dihedral angle of each tet.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64

    Returns
    -------
    angles : (m,) float64, degrees
    """
    try:
        from cutkit.mesh.quality import min_dihedral_angles as shared
    except ImportError:
        shared = None
    if shared is not None:
        return np.asarray(shared(points, tets))
    out = np.empty(len(tets))
    for s in range(0, len(tets), 1 << 20):  # bounded temporary memory
        out[s : s + (1 << 20)] = _dihedral_angles(points, tets[s : s + (1 << 20)]).min(axis=1)
    return out


def dihedral_summary(points: np.ndarray, tets: np.ndarray) -> tuple[float, float]:
    """Minimum and 1st-percentile of the per-tet minimum dihedral angle, degrees."""
    if len(tets) == 0:
        return float("nan"), float("nan")
    m = min_dihedral_angles(points, tets)
    return float(m.min()), float(np.percentile(m, 1.0))
