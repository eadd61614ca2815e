"""The isovolume kernels' structs: namedtuples of the arrays ``isovolume.isovolume`` makes.

The kernels (``_kernels``, ``_centre``) take these instead of the arrays one
by one; none checks them.
"""

from __future__ import annotations

from collections import namedtuple

#: The classified samples (grid vertex ``g = (i ny + j) nz + k``): ``lab`` (n,) int64 label,
#: ``on`` (n,) uint8 (the value is the level: a vertex on the surface), ``f`` (n,) float64 the scalar
#: (scalar mode), the iso ``level`` (float), ``mode`` (``MODE_SCALAR`` / ``MODE_LABELS``) and the
#: orientation ``sgn`` (+1 / -1: the sign of the index-to-world map's determinant).
Field = namedtuple("Field", ["lab", "on", "f", "level", "mode", "sgn"])
#: The crossing nodes (``_crossings``): each vertex's forward-edge bits ``mask`` (n,) uint8, the node
#: id of its first crossing ``eoff`` (n,) int64, the grid nodes' count ``n_v`` (int) and the
#: parameter ``cross_s`` (n_e,) float64 of crossing node ``n_v + e`` (label maps).
Crossings = namedtuple("Crossings", ["mask", "eoff", "n_v", "cross_s"])
#: A cube: its first vertex ``g0``, its index (``i``, ``j``, ``k``) and the grid's ``ny``, ``nz``.
Cube = namedtuple("Cube", ["g0", "i", "j", "k", "ny", "nz"])
