"""What a session asks of a tissue's physics: the :class:`TissuePhysics` protocol.

Two implementations: the paper's springs (Bielser & Gross 2000, section 5:
:class:`cutkit.relax.spring_tissue.Tissue`) and the element model
(:class:`cutkit.relax.elastic_tissue.ElasticTissue`).  The session
(:mod:`cutkit.simulate.session`) uses a tissue only through these names; a
cut step reaches the physics only as a :class:`~cutkit.tissue.TopologyDelta`.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from cutkit.tissue.delta import TopologyDelta

#: The reaction of the cut force is carried by the nodes of the tets the blade touches grown by this
#: many rings of tets through the tissue's own connectivity (so never across a cut), each node in
#: proportion to its lumped mass (:meth:`TissuePhysics.load_shares`).  Equal shares on the touched
#: tets' corners alone crushed tets: a node a cut has left with few tets got the same 0.04-0.1 N
#: as one deep in the tissue (on the demo knee 42 of 150 steps of the hybrid solver had a tet below
#: J = 1e-3; mass shares over the corners alone 27; over one ring 2; over two rings none, the
#: smallest J 0.19).  Measured by ``benchmarks/relax.py --json --knee-simulate knee.h5 --lift``.
BLADE_LOAD_RINGS = 2


@runtime_checkable
class TissuePhysics(Protocol):
    """The physics of a cut tissue, on the cut mesh's node numbering.

    Attributes
    ----------
    n_nodes : int
    positions : (n, 3) float64
        Current positions, mm.
    rest_positions : (n, 3) float64
        Rest positions, mm.
    velocities : (n, 3) float64
        mm/s.
    fixed : (n,) or (n, 3) bool
        Held nodes (or components).
    time : float
        Simulated time, s.
    """

    @property
    def n_nodes(self) -> int: ...

    @property
    def positions(self) -> np.ndarray: ...

    @property
    def rest_positions(self) -> np.ndarray: ...

    @property
    def velocities(self) -> np.ndarray: ...

    @property
    def fixed(self) -> np.ndarray: ...

    @property
    def time(self) -> float: ...

    def settle(self, iterations: int, tolerance: float) -> dict:
        """Relax to static equilibrium under prestress and boundary conditions, then rest at time 0.

        ``tolerance`` is the model's own: the sweeps' step (s) for the
        springs, the relative residual for the elements.
        """
        ...

    def advance(self, f_ext: np.ndarray, until: float, stop=None) -> int:
        """Bring every node to time ``until`` s under the loads ``f_ext`` (n, 3) float64, N.

        ``stop`` ((1,) int64 or None) is read between steps: non-zero ends
        the call early.  Returns the sweeps (or list passes) made.
        """
        ...

    def apply_delta(self, delta: TopologyDelta) -> dict:
        """Grow the model by one cut step's change; returns counts of what was added and removed."""
        ...

    def rebase(self, old_of_new: np.ndarray) -> None:
        """Renumber the tets after the store's rebase: (m,) int64 old tet id of each new one (the store's
        labels and records give the rest)."""
        ...

    def at_rest(self) -> bool:
        """Whether the last step ended at rest within the model's rest tolerance (False where the model
        has none): a live session starts a stroke's rebase then."""
        ...

    def prepare_resting(self) -> None:
        """Build now what the first resting step would otherwise build on its way (a live session
        calls it before its clock starts); nothing where the model keeps nothing."""
        ...

    @property
    def masses(self) -> np.ndarray:
        """(n,) float64: each node's lumped mass (0 for a node without tets)."""
        ...

    def load_shares(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Who carries the blade's reaction: ``nodes`` (k,) int64 (the corners of the tets the blade
        touches) grown by :data:`BLADE_LOAD_RINGS` rings, those that can bear it, and their shares
        (proportional to mass, summing to 1): ((j,) int64, (j,) float64), both empty where none can."""
        ...
