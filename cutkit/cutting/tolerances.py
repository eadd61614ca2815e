"""Where cut nodes may lie: the clamps that keep cut-made tetrahedra from degenerating.

Shared by the cut state (:mod:`.cutmesh`) and the re-subdivision
(:mod:`.resubdivision`), which import them from here.
"""

from __future__ import annotations

import numpy as np

from cutkit.mesh.geometry import clamp_bary as _clamp_bary_kernel

#: Edge intersection parameters are clamped into [EDGE_SNAP, 1 - EDGE_SNAP]
#: (a crossing near a vertex, or through it, becomes a crossing near it).
#: Measured on random blade paths (docs/cutting.md): 0.1 gives cut-made
#: dihedral angles down to 0.5 degrees, 0.25 keeps them above about 3 degrees
#: (median worst 7-8) for a cut surface at most a quarter edge off the blade.
EDGE_SNAP = 0.25
#: Face nodes keep every barycentric coordinate >= FACE_BARY_MIN (same reason).
FACE_BARY_MIN = 0.2
#: Tip/centre nodes T keep every barycentric coordinate >= TET_BARY_MIN (same reason).
TET_BARY_MIN = 0.15


def clamp_bary(b, lo):
    """Valid barycentric weights, each >= ``lo`` (:func:`cutkit.mesh.geometry.clamp_bary`).

    Parameters
    ----------
    b : (k,) float64
    lo : float

    Returns
    -------
    (k,) float64
    """
    return _clamp_bary_kernel(np.asarray(b, np.float64), float(lo))
