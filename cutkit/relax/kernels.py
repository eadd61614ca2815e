"""Numba kernels of the relaxation that other packages call, by their public names.

These are numba functions: call them from Python or from other ``@njit``
kernels.  Their implementations live in the private kernel modules of
:mod:`cutkit.relax`.
"""

from cutkit.relax._adjacency_kernels import loaded_nodes, loose_nodes, node_rings, tets_around
from cutkit.relax._shape_kernels import corner_edge_inverses

__all__ = ["corner_edge_inverses", "loaded_nodes", "loose_nodes", "node_rings", "tets_around"]
