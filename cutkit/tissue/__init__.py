"""The run-time tissue: what the cutting and the physics exchange.

:class:`TopologyDelta` is the typed message of one cut step (what it
removed, added and moved); the physics consume only it.
"""

from cutkit.tissue.delta import TopologyDelta

__all__ = ["TopologyDelta"]
