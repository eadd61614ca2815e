"""The run-time tissue: what the cutting and the physics exchange.

:class:`TopologyDelta` is the typed message of one cut step (what it
removed, added and moved); the physics consume only it.
:class:`TissuePhysics` names what a session asks of a physics.
"""

from cutkit.tissue.delta import TopologyDelta
from cutkit.tissue.physics import BLADE_LOAD_RINGS, TissuePhysics

__all__ = ["BLADE_LOAD_RINGS", "TopologyDelta", "TissuePhysics"]
