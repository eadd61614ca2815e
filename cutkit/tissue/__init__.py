"""The run-time tissue: where the cutting and the physics meet.

:class:`TissueStore` holds the tissue's nodes and tetrahedra on one
numbering and is their only writer (the cutting writes through it, the
physics read it); :class:`TopologyDelta` is the typed message of one cut
step (what it removed, added and moved), the only thing the physics
consume of a cut; :class:`TissuePhysics` names what a session asks of a
physics.  This package imports neither the cutting nor the physics.
"""

from cutkit.tissue.delta import TopologyDelta
from cutkit.tissue.physics import BLADE_LOAD_RINGS, TissuePhysics
from cutkit.tissue.store import TissueStore

__all__ = ["BLADE_LOAD_RINGS", "TissueStore", "TopologyDelta", "TissuePhysics"]
