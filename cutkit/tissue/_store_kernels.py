"""Numba kernels of the tissue store: a cut node defined by weights on original nodes.

Slow, obviously correct NumPy twin: ``tests/_twins_cut.py`` (``set_node_twin``).
"""

from numba import njit

from cutkit.mesh.geometry import clamp_bary


@njit(cache=True, nogil=True)
def set_node(x, X, uvw, def_nodes, def_w, i, nodes, w):
    """Define node ``i`` by weights on original nodes and interpolate it.

    Parameters
    ----------
    x, X : (cap, 3) float64  current and rest positions (row i written)
    uvw : (cap, 3) or (0, 3) float64  texture coordinates (written if it has row i)
    def_nodes : (cap, 4) int64;  def_w : (cap, 4) float64  node definitions (row i written)
    i : int
    nodes : (k,) int64  defining original nodes, k <= 4
    w : (k,) float64  weights
    """
    for c in range(4):
        def_nodes[i, c] = -1
        def_w[i, c] = 0.0
    for c in range(nodes.size):
        def_nodes[i, c] = nodes[c]
        def_w[i, c] = w[c]
    has_uvw = uvw.shape[0] > i
    for d in range(3):
        sx = 0.0
        sX = 0.0
        su = 0.0
        for c in range(nodes.size):
            sx += w[c] * x[nodes[c], d]
            sX += w[c] * X[nodes[c], d]
            if has_uvw:
                su += w[c] * uvw[nodes[c], d]
        x[i, d] = sx
        X[i, d] = sX
        if has_uvw:
            uvw[i, d] = su



@njit(cache=True, nogil=True)
def set_node_clamped(x, X, uvw, def_nodes, def_w, i, nodes, w, lo):
    """:func:`set_node` with the weights :func:`clamp_bary` ``(w, lo)`` first, in one call (a notch
    node F following the blade across its face: a few dozen per cut step)."""
    set_node(x, X, uvw, def_nodes, def_w, i, nodes, clamp_bary(w, lo))


@njit(cache=True, nogil=True)
def set_nodes_clamped(x, X, uvw, def_nodes, def_w, ids, nodes, w, lo):
    """:func:`set_node_clamped` of nodes ``ids`` (p,) int64, node ``ids[r]`` by weights ``w[r]`` (p, k)
    float64 on original nodes ``nodes[r]`` (p, k) int64: the notch nodes F the blade moves in one step."""
    for r in range(ids.shape[0]):
        set_node(x, X, uvw, def_nodes, def_w, ids[r], nodes[r], clamp_bary(w[r], lo))
