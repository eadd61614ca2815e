"""Dihedral-angle figures of an isovolume mesh (the angles are :mod:`cutkit.mesh.quality`'s)."""

from __future__ import annotations

import numpy as np

from cutkit.mesh.quality import min_dihedral_angles


def dihedral_summary(points: np.ndarray, tets: np.ndarray) -> tuple[float, float]:
    """Minimum and 1st-percentile of the per-tet minimum dihedral angle.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64

    Returns
    -------
    minimum, first_percentile : float
        Degrees; NaN for no tets.
    """
    if len(tets) == 0:
        return float("nan"), float("nan")
    m = min_dihedral_angles(points, tets)
    return float(m.min()), float(np.percentile(m, 1.0))
