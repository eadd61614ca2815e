"""The typed change message of a cut step (cutkit.tissue.TopologyDelta) against the cut mesh itself."""

import numpy as np

from cutkit.cutting import CutMesh, cut_step
from cutkit.mesh.generate import box_mesh
from cutkit.tissue.delta import twins_of


def test_delta_is_the_difference_of_the_cut_mesh_before_and_after():
    """Alive tets after = before - removed + added; new nodes' rest = weights over their parents' rest."""
    points, tets = box_mesh((6, 4, 4), spacing=(2.0, 2.0, 2.0))
    cm = CutMesh(points, tets, blade_length=20.0)
    steps = 0
    for x in np.linspace(1.0, 9.0, 9):
        before = {int(i): tuple(int(v) for v in cm.tet_corners[i]) for i in _alive_ids(cm)}
        n_before, X_before = cm.n_points, cm.rest_points.copy()
        d = cut_step(cm, [x, 3.0, 4.3], [0.0, 1.0, 0.0]).delta
        after = {int(i): tuple(int(v) for v in cm.tet_corners[i]) for i in _alive_ids(cm)}
        assert d.n_nodes_before == n_before and d.n_nodes_after == cm.n_points
        np.testing.assert_array_equal(d.added_nodes, np.arange(n_before, cm.n_points))
        assert set(d.removed_tets.tolist()) == set(before) - set(after)
        assert set(d.added_tets.tolist()) == set(after) - set(before)
        for t, c in zip(d.added_tets.tolist(), d.added_tet_corners.tolist()):
            assert tuple(c) == after[t]
        for t, c in zip(d.removed_tets.tolist(), d.removed_tet_corners.tolist()):
            assert tuple(c) == before[t]
        # cut nodes interpolate original nodes, which a plain cut leaves in place
        rest = np.einsum("pq,pqc->pc", d.added_node_weights, points[np.maximum(d.added_node_parents, 0)])
        np.testing.assert_allclose(d.added_node_rest, rest, atol=1e-12)
        old = d.moved_nodes < n_before
        np.testing.assert_array_equal(d.moved_rest_from[old], X_before[d.moved_nodes[old]])
        np.testing.assert_array_equal(d.moved_rest_to, cm.rest_points[d.moved_nodes])
        steps += not d.is_empty
    assert steps > 0


def _alive_ids(cm):
    """Ids of the alive tets."""
    return np.flatnonzero(cm.tet_alive).tolist()


def test_twins_pair_equal_rows():
    parents = np.array([[0, 1, -1, -1], [2, 3, -1, -1], [0, 1, -1, -1], [4, 5, -1, -1]])
    weights = np.array([[0.5, 0.5, 0, 0], [0.3, 0.7, 0, 0], [0.5, 0.5, 0, 0], [0.5, 0.5, 0, 0]])
    np.testing.assert_array_equal(twins_of(parents, weights), [2, -1, 0, -1])
