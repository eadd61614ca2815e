"""Volume term of the mass-spring model (an addition to the paper's section 5).

A tetrahedral mass-spring network has no resistance to a change of volume
beyond what its edge springs give (a lattice of central springs behaves like
a material with Poisson's ratio 1/4), so soft tissue under prestress or tool
load compresses and its tets can invert.  Each tet gets the energy

    W_t = bulk_t (V_t - V0_t)^2 / (2 V0_t),    bulk_t = volume_stiffness * E_t

(a volume-preservation constraint as in Teschner et al., "A versatile and
robust model for geometrically complex deformable solids", CGI 2004), whose
forces the integrator adds to the external forces of each node it advances,
evaluated at the eq. (7) predictions like the springs; the node's diagonal
volume stiffness at that shape joins its spring stiffness sum in the
implicit part of eq. (6).  See docs/relaxation.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.errors import InputError


@dataclass
class VolumeTerm:
    """Per-tet volume springs and their node incidence (part of the Model).

    Attributes
    ----------
    tets : (m, 4) int64
        Positively oriented tets.
    rest_volume : (m,) float64
        V0, mm^3 (positive).
    bulk : (m,) float64
        Volume stiffness, N/mm^2 (MPa).
    tet_offsets, node_tets
        Node -> tet CSR (:func:`cutkit.mesh.topology.node_to_tets`): ``(n + 1,)``, ``(4 m,)`` int64.
    """

    tets: np.ndarray
    rest_volume: np.ndarray
    bulk: np.ndarray
    tet_offsets: np.ndarray
    node_tets: np.ndarray
    _f_scratch: np.ndarray | None = None
    _k_scratch: np.ndarray | None = None

    def kernel_tets(self):
        """The term's arrays as ``_volume_kernels.add_volume_forces`` reads them (``VolumeTets``)."""
        from cutkit.relax._volume_kernels import VolumeTets

        return VolumeTets(self.tets, self.tet_offsets, self.node_tets, self.rest_volume, self.bulk)

    def scratch(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Force (n, 3) and stiffness (n,) work arrays of the integrator, reused between passes."""
        if self._f_scratch is None or self._f_scratch.shape[0] != n:
            self._f_scratch = np.zeros((n, 3))
            self._k_scratch = np.zeros(n)
        return self._f_scratch, self._k_scratch

    @classmethod
    def build(cls, rest_positions: np.ndarray, tets: np.ndarray, rest_volume: np.ndarray, bulk: np.ndarray) -> "VolumeTerm":
        """The term of ``tets`` over ``rest_positions`` (n, 3) float64; checks shapes and signs.

        Parameters
        ----------
        rest_positions : (n, 3) float64
        tets : (m, 4) int64
        rest_volume : (m,) float64, > 0
        bulk : (m,) float64, >= 0
        """
        from cutkit.mesh.topology import node_to_tets

        x = np.ascontiguousarray(rest_positions, np.float64)
        tets = np.ascontiguousarray(tets, np.int64)
        rest_volume = np.ascontiguousarray(rest_volume, np.float64)
        bulk = np.ascontiguousarray(bulk, np.float64)
        m = tets.shape[0]
        if tets.ndim != 2 or tets.shape[1] != 4 or rest_volume.shape != (m,) or bulk.shape != (m,):
            raise InputError(f"volume term: tets (m, 4), rest_volume (m,) and bulk (m,) expected, got "
                             f"{tets.shape}, {rest_volume.shape}, {bulk.shape}")
        if m and (tets.min() < 0 or tets.max() >= x.shape[0]):
            raise InputError(f"volume term: tets index nodes outside 0..{x.shape[0] - 1}")
        if np.any(rest_volume <= 0) or np.any(bulk < 0) or not np.all(np.isfinite(bulk)):
            raise InputError("volume term: rest volumes must be > 0 and bulk moduli finite and >= 0")
        offsets, node_tets = node_to_tets(tets, x.shape[0])
        return cls(tets, rest_volume, bulk, offsets, node_tets)
