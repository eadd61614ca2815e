"""Numba kernel of the spring graph's connected components (the pieces a cut sets apart).

Its slow, obviously correct twin is ``tests/_twins_relax.graph_components_twin`` (scipy's
``connected_components``).
"""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def graph_components(adj_offsets, adj_nodes):
    """Connected components of a graph in CSR form, by breadth-first search.

    Parameters
    ----------
    adj_offsets : (n + 1,) int64
    adj_nodes : (2 s,) int32 or int64
        The neighbours of node k are ``adj_nodes[adj_offsets[k]:adj_offsets[k + 1]]``.

    Returns
    -------
    (n_components, labels) : int, (n,) int64
        Components numbered in order of their smallest node.
    """
    n = adj_offsets.shape[0] - 1
    labels = np.full(n, -1, np.int64)
    queue = np.empty(n, np.int64)
    n_comp = 0
    for seed in range(n):
        if labels[seed] >= 0:
            continue
        labels[seed] = n_comp
        head, tail = 0, 1
        queue[0] = seed
        while head < tail:
            k = queue[head]
            head += 1
            for a in range(adj_offsets[k], adj_offsets[k + 1]):
                j = adj_nodes[a]
                if labels[j] < 0:
                    labels[j] = n_comp
                    queue[tail] = j
                    tail += 1
        n_comp += 1
    return n_comp, labels
