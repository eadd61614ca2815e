"""The decimation's state as its kernels read it: namedtuples of the arrays ``decimate.decimate`` makes.

The kernels (``_kernels``, ``_legality``, ``_candidates``) take these
structs instead of the arrays one by one; none checks them.
"""

from __future__ import annotations

from collections import namedtuple

#: The tets (m, 4) int64 and each vertex's star: its tets' ids ``pool[adj_start[w]:][:adj_len[w]]``
#: in a shared pool (``_pool``; the room of each list is :class:`Decimation`'s ``room``).
Stars = namedtuple("Stars", ["tets", "adj_start", "adj_len", "pool"])
#: The vertices and tets: ``points`` (n, 3) float64, ``labels`` (m,) label of each tet, ``tet_lab``
#: (m,) int64 its index 0..L-1, ``tet_alive`` (m,) uint8, ``tet_maxcos`` (m,) float64 its largest
#: dihedral cosine, ``vert_alive`` (n,) uint8, ``vclass`` (n,) the vertex class (0: inside),
#: ``locked`` (n,) bool (never moved).
Mesh = namedtuple("Mesh", ["points", "labels", "tet_lab", "tet_alive", "tet_maxcos", "vert_alive", "vclass",
                           "locked"])
#: The priority queue: per vertex its entry's version ``ver``, key ``qkey`` and lower bound ``qlow``
#: (n,); the heap ``heap_key`` / ``heap_u`` / ``heap_stamp`` (cap,).
Queue = namedtuple("Queue", ["ver", "qkey", "qlow", "heap_key", "heap_u", "heap_stamp"])
#: The original surface points each vertex represents: ``own_pts`` (n + k, 3) float64, linked lists
#: ``own_tail`` (n,) and ``own_next`` (n + k,) int64.
Owners = namedtuple("Owners", ["own_pts", "own_tail", "own_next"])
#: Each label's volume gained so far ``vol_drift`` (L,) and the drift allowed ``vol_budget`` (L,).
Budget = namedtuple("Budget", ["vol_drift", "vol_budget"])
#: The collapses made: ``collapse_u``, ``collapse_v`` (n,) int64 and the tets alive after each,
#: ``tet_counts`` (n + 1,) int64.
Log = namedtuple("Log", ["collapse_u", "collapse_v", "tet_counts"])
#: The outer boundary's nodes binned on a grid (``_legality.conforming_after``).
Boundary = namedtuple("Boundary", ["bnd_keys", "bnd_nodes", "grid"])
#: All of it; ``room`` (n,) int64 the room of each star's list in the pool, ``marks`` two (n,) int64
#: stamp arrays.
Decimation = namedtuple("Decimation", ["mesh", "stars", "room", "queue", "owners", "marks", "budget", "log",
                                       "boundary"])
