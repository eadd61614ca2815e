"""Carry the blade from the deformed tissue into the rest configuration, where it cuts.

The cut is made in the rest configuration (docs/simulate.md).  Every
geometry update moves the blade back by the displacement of the tissue
around it: the weighted mean over the original nodes within ``radius`` of
the blade segment (deformed positions), a node at distance ``d`` weighing
``(1 - (d / radius)^2)^3``.  The nodes are found by a flood fill from the
last cut step's active tetrahedra (local work).  Every weight falls to zero
at the radius, so the blade's rest pose moves continuously with the hand.
First order: a translation; the local rotation and stretch are neglected.

The plain mean over the corners of the step's active tetrahedra, used
before, jumped whenever that set changed (a node's whole displacement over
the set's size; the nodes on the two sides of an opened cut move apart):
the rest pose of a steady hand wobbled, its swept surface folded and left
edges uncut (docs/simulate.md).  A straight line fitted through samples
along the blade, each carried by the nodes near it, would follow a tissue
that bends along the blade; it was tried and not kept: where the blade
leaves the tissue only a few samples near the surface remain, the fitted
direction swings from step to step, and the swept surface folded again
(10-21 edges left uncut on the side-entry slab of
tests/test_simulate_strokes.py, none with the translation).
"""

from __future__ import annotations

import numpy as np

#: Radius of the neighbourhood whose displacement carries the blade, in median edge lengths of the model.
#: Measured on the knee's incision (benchmarks/rest_map.py, sideways wobble of the cut path): 1 edge
#: 0.102 mm (no better than the plain mean before), 1.5 edges 0.041, 2 edges 0.032, 3 edges 0.009 mm;
#: a radius of 2 also needed the hand 15 mm past the far side of the side-entry slab instead of 10
#: (the tissue dragged along at the blade's end weighs more), 3 does not; about 0.6 ms per geometry
#: update on the knee (0.2 at 2).
REST_MAP_RADIUS_EDGES = 3.0


def rest_map_radius(points, tets) -> float:
    """The blade's neighbourhood radius for a model, mm: :data:`REST_MAP_RADIUS_EDGES` times the median
    length of the tets' edges (each edge once per tet around it).

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64
    """
    from cutkit.mesh.topology import TET_EDGES

    p, t = np.asarray(points, np.float64), np.asarray(tets, np.int64)
    length = np.linalg.norm(p[t[:, TET_EDGES[:, 0]]] - p[t[:, TET_EDGES[:, 1]]], axis=2)
    return REST_MAP_RADIUS_EDGES * float(np.median(length))


class BladeNeighbourhood:
    """The original nodes near the blade (kernel ``_rest_map_kernels.nodes_near_blade``).

    Keeps the flood fill's visit marks and work space between calls; made
    again after a rebase (``n_rebases``: the original tets have changed).

    Parameters
    ----------
    store : TissueStore
    radius : float  mm (:func:`rest_map_radius`)
    """

    def __init__(self, store, radius: float):
        self.n_rebases = store.n_rebases
        self.radius = float(radius)
        self.tet_stamp = np.zeros(store.orig_tets.shape[0], np.int64)
        self.node_stamp = np.zeros(store.n_orig_nodes, np.int64)
        self.stack = np.empty(store.orig_tets.shape[0], np.int64)
        self.out = np.empty(store.n_orig_nodes, np.int64)
        self.out_d2 = np.empty(store.n_orig_nodes, np.float64)
        self.mark = 0

    def nodes(self, store, positions, seeds, back, tip):
        """The original nodes (k,) int64 within the radius of the blade (deformed positions) and their
        squared distances (k,) float64 to it (views into buffers the next call overwrites).

        Parameters
        ----------
        store : TissueStore
        positions : (n, 3) float64  the tissue's nodes (the store's numbering)
        seeds : (s,) int64  original tets to start from (the last cut step's active tets)
        back, tip : (3,) float64  the blade's ends, mm
        """
        from cutkit.relax._rest_map_kernels import FloodFill, nodes_near_blade

        self.mark += 1
        blade = np.array([back, tip], np.float64)
        fill = FloodFill(self.tet_stamp, self.node_stamp, self.mark, self.stack, self.out, self.out_d2)
        n = nodes_near_blade(positions, store.orig_tets, store.neighbors, np.ascontiguousarray(seeds, np.int64), blade,
                             self.radius, fill)
        return self.out[:n], self.out_d2[:n]


def blade_weights(d2, radius):
    """(k,) float64 weight ``(1 - d^2 / radius^2)^3`` of each node at squared distance ``d2`` (k,) float64
    from the blade (none from ``radius`` on)."""
    return np.clip(1.0 - d2 / radius ** 2, 0.0, None) ** 3


def rest_displacement(x, X, nodes, weights):
    """The displacement (3,) float64 that carries the blade back into the rest configuration: the mean
    over ``nodes`` (k,) weighted by ``weights`` (k,) (:func:`blade_weights`); None when they are all 0.

    Parameters
    ----------
    x, X : (n, 3) float64  node positions (deformed) and rest positions
    nodes : (k,) int64
    weights : (k,) float64
    """
    total = weights.sum()
    if not total > 0.0:
        return None
    return weights @ (x[nodes] - X[nodes]) / total
