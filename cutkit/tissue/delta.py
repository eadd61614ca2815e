"""The typed change message of one cut step.

A cut step (Bielser & Gross 2000, section 4: the blade's swept surface cuts
edges, the touched tetrahedra are re-subdivided) removes some tetrahedra,
adds others, adds cut nodes and re-interpolates nodes that follow the blade
(the notch and tip nodes, paper figure 6).  :class:`TopologyDelta` carries
exactly that, on the cut mesh's numbering, so that a physics can grow its own
arrays from it without reading the cutting's state.  This module imports
nothing of cutkit: both sides may import it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TopologyDelta:
    """What one cut step changed (net of tets made and unmade within it).

    Node ids ``< n_nodes_before`` existed before the step; the added nodes
    are exactly ``n_nodes_before .. n_nodes_after - 1``.  The material of a
    tet is that of its origin tet (the original tet it subdivides): a
    physics indexes its per-original-tet material rows with
    ``added_tet_origin``.

    Attributes
    ----------
    n_nodes_before : int
        Nodes before the step.
    n_nodes_after : int
        Nodes after the step.
    added_nodes : (a,) int64
        New node ids, ascending.
    added_node_parents : (a, 4) int64
        Defining nodes of each new node (original nodes it interpolates), -1 padded.
    added_node_weights : (a, 4) float64
        Their interpolation weights (0 where the parent is -1).
    added_node_rest : (a, 3) float64
        Rest positions of the new nodes, mm.
    added_node_twin : (a,) int64
        Another node added in this step with the same defining nodes and
        weights (the copy on the other side of the cut), -1 if none.
    moved_nodes : (b,) int64
        Nodes whose rest position the step changed after they existed (cut
        nodes re-interpolated as the blade moves, snapped original nodes),
        ascending; a node added and moved in the same step is in both lists.
    moved_rest_from : (b, 3) float64
        Their rest positions before the step, mm.
    moved_rest_to : (b, 3) float64
        Their rest positions after the step, mm.
    moved_node_parents : (b, 4) int64
        Their defining nodes after the step, -1 padded.
    moved_node_weights : (b, 4) float64
        Their interpolation weights after the step (0 where the parent is -1).
    removed_tets : (r,) int64
        Tet ids alive before the step and not after.
    removed_tet_corners : (r, 4) int64
        Their corner nodes.
    added_tets : (c,) int64
        Tet ids alive after the step and not before.
    added_tet_corners : (c, 4) int64
        Their corner nodes (positive orientation at rest).
    added_tet_origin : (c,) int64
        Their origin (original) tet, which gives their material row.
    n_tets_total : int
        Tet id bound after the step (ids ``< n_tets_total``).
    """

    n_nodes_before: int
    n_nodes_after: int
    added_nodes: np.ndarray
    added_node_parents: np.ndarray
    added_node_weights: np.ndarray
    added_node_rest: np.ndarray
    added_node_twin: np.ndarray
    moved_nodes: np.ndarray
    moved_rest_from: np.ndarray
    moved_rest_to: np.ndarray
    moved_node_parents: np.ndarray
    moved_node_weights: np.ndarray
    removed_tets: np.ndarray
    removed_tet_corners: np.ndarray
    added_tets: np.ndarray
    added_tet_corners: np.ndarray
    added_tet_origin: np.ndarray
    n_tets_total: int

    @property
    def is_empty(self) -> bool:
        """Whether the step changed nothing the physics sees."""
        return (self.added_nodes.size == 0 and self.moved_nodes.size == 0
                and self.removed_tets.size == 0 and self.added_tets.size == 0)


def twins_of(parents: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """For each row, another row with the same defining nodes and weights, or -1.

    Parameters
    ----------
    parents : (a, 4) int64
    weights : (a, 4) float64

    Returns
    -------
    twin : (a,) int64
        Index (into the rows) of the first other row equal to it; -1 if none.
    """
    twin = np.full(parents.shape[0], -1, np.int64)
    seen: dict = {}
    for i in range(parents.shape[0]):
        key = (parents[i].tobytes(), weights[i].tobytes())
        j = seen.setdefault(key, i)
        if j != i:
            twin[i], twin[j] = j, i if twin[j] < 0 else twin[j]
    return twin
