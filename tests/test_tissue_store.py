"""The run-time tissue store: one numbering, its writers and their log, growth, the rebase."""

import numpy as np
import pytest

from _fem_reference import kuhn_box
from cutkit.cutting import CutMesh, cut_step
from cutkit.errors import InputError
from cutkit.mesh.topology import face_topology, unique_edges
from cutkit.tissue import TissueStore
from cutkit.tissue.store import NODE_ROOM, TET_ROOM_MIN


def box():
    p, t = kuhn_box((2.0, 1.0, 1.0), (2, 1, 1))
    uvw = p / 2.0
    return TissueStore(p, t, rest_points=p + 0.5, texcoords=uvw, labels=np.arange(len(t), dtype=np.int32) % 3), p, t


def test_the_store_starts_as_the_model_with_room_and_its_topology():
    s, p, t = box()
    assert s.n_nodes == s.n_orig_nodes == len(p) and s.n_tets_total == s.n_orig_tets == len(t)
    np.testing.assert_array_equal(s.points, p)
    np.testing.assert_array_equal(s.rest_points, p + 0.5)
    np.testing.assert_array_equal(s.tets, t)
    np.testing.assert_array_equal(s.tet_origin, np.arange(len(t)))
    assert s.node_buffers.x.shape[0] == len(p) + NODE_ROOM and s.tet_capacity == len(t) + TET_ROOM_MIN
    assert (s.defining_nodes == -1).all()
    edges, tet_edges = unique_edges(t)
    topo = face_topology(t)
    np.testing.assert_array_equal(s.edges, edges)
    np.testing.assert_array_equal(s.tet_edges, tet_edges)
    np.testing.assert_array_equal(s.boundary_faces, topo.boundary_faces)
    assert not s.boundary_faces.flags.writeable  # one truth: nobody edits the boundary in place
    np.testing.assert_array_equal(s.model_tet, np.arange(len(t)))
    assert not s.made_by_cut(np.arange(len(t))).any()


@pytest.mark.parametrize("points, tets, message", [
    (np.zeros((4, 2)), np.zeros((1, 4), np.int64), r"points: shape \(4, 2\), expected \(n, 3\)"),
    (np.zeros((4, 3)), np.zeros((1, 3), np.int64), r"tets: shape \(1, 3\), expected \(m, 4\)"),
])
def test_a_bad_shape_is_refused_by_name(points, tets, message):
    with pytest.raises(InputError, match=message):
        TissueStore(points, tets)


def test_a_new_node_interpolates_every_node_array_and_is_logged():
    s, p, _ = box()
    s.begin_step()
    i = s.add_node([0, 1], [0.25, 0.75])
    assert i == len(p) and s.n_nodes == len(p) + 1
    np.testing.assert_allclose(s.points[i], 0.25 * p[0] + 0.75 * p[1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.rest_points[i], 0.25 * p[0] + 0.75 * p[1] + 0.5, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.texcoords[i], (0.25 * p[0] + 0.75 * p[1]) / 2.0, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(s.defining_nodes[i], [0, 1, -1, -1])
    np.testing.assert_array_equal(s.defining_weights[i], [0.25, 0.75, 0.0, 0.0])
    j = s.add_node([0, 1, 2], [1.0, 0.0, 0.0], lo=0.2)  # clamped: every weight at least 0.2
    assert s.defining_weights[j, :3].min() == pytest.approx(0.2) and s.defining_weights[j].sum() == pytest.approx(1.0)
    assert s.step_log.added_nodes == [i, j] and s.step_log.moved_nodes == []


def test_a_moved_node_keeps_its_rest_position_before_the_steps_first_move():
    s, p, _ = box()
    i = s.add_node([0, 1], [0.5, 0.5])
    s.begin_step()
    before = s.rest_points[i].copy()
    s.move_node(i, [0, 1], [0.3, 0.7])
    s.move_node(i, [0, 1], [0.1, 0.9])
    assert s.step_log.moved_nodes == [i, i] and s.step_log.added_nodes == []
    np.testing.assert_array_equal(s.step_log.moved_from[i], before)
    np.testing.assert_allclose(s.rest_points[i], 0.1 * p[0] + 0.9 * p[1] + 0.5, rtol=0, atol=1e-15)
    s.move_original_node(3, np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.2, 0.0]))
    np.testing.assert_allclose(s.points[3], p[3] + [0.1, 0.0, 0.0])
    np.testing.assert_allclose(s.rest_points[3], p[3] + 0.5 + [0.0, 0.2, 0.0])
    np.testing.assert_array_equal(s.step_log.moved_from[3], p[3] + 0.5)


def test_the_arrays_grow_by_doubling_and_keep_what_they_held():
    s, p, t = box()
    for k in range(NODE_ROOM + 5):  # past the spare rows
        s.add_node([k % len(p), (k + 1) % len(p)], [0.5, 0.5])
    assert s.n_nodes == len(p) + NODE_ROOM + 5 and s.node_buffers.x.shape[0] == 2 * (len(p) + NODE_ROOM)
    np.testing.assert_array_equal(s.points[:len(p)], p)
    assert (s.node_buffers.parents[s.n_nodes:] == -1).all()  # spare rows define no node
    first = len(t)
    ids = s.add_tets([tuple(t[0])] * (TET_ROOM_MIN + 3), origin=0)
    assert ids == list(range(first, first + TET_ROOM_MIN + 3)) and s.tet_capacity == 2 * (len(t) + TET_ROOM_MIN)
    np.testing.assert_array_equal(s.tet_corners[:len(t)], t)
    assert s.tet_alive.all() and (s.tet_origins[first:] == 0).all()


def test_removed_and_added_tets_are_logged_and_count_as_made_by_a_cut():
    s, _, t = box()
    s.begin_step()
    s.remove_tets([2])
    new = s.add_tets([tuple(t[2])], origin=2)
    assert s.step_log.removed_tets == [2] and s.step_log.added_tets == new
    assert not s.tet_alive[2] and s.tet_alive[new[0]]
    np.testing.assert_array_equal(s.made_by_cut([1, new[0]]), [False, True])


def test_the_rebase_renumbers_the_live_tets_in_place_and_keeps_the_records():
    s, p, t = box()
    i = s.add_node([0, 1], [0.5, 0.5])
    s.remove_tets([1])
    new = s.add_tets([(t[1][0], t[1][1], t[1][2], i)], origin=1)
    labels = s.labels.copy()
    old_ids = s.rebase()
    np.testing.assert_array_equal(old_ids, [0] + list(range(2, len(t))) + new)
    assert s.n_rebases == 1 and s.n_orig_nodes == s.n_nodes == len(p) + 1
    assert s.n_orig_tets == len(t)
    np.testing.assert_array_equal(s.labels, labels[[0] + list(range(2, len(t))) + [1]])
    np.testing.assert_array_equal(s.model_tet, [0] + list(range(2, len(t))) + [1])
    np.testing.assert_array_equal(s.orig_made_by_cut, [False] * (len(t) - 1) + [True])
    assert s.model_node[i] == 0  # a cut node takes point data from its first defining node
    edges, _ = unique_edges(s.orig_tets)
    np.testing.assert_array_equal(s.edges, edges)  # the topology is that of the new original tets
    assert (s.defining_nodes == -1).all()  # every node is an original one now


def test_a_session_pairs_one_store_with_its_cut_mesh_and_its_physics():
    """The cut writes the store, the physics reads the same arrays (no copy), and a rebase of the cut
    mesh renumbers the store every holder sees."""
    from cutkit.model.tetmodel import Materials, TetModel
    from cutkit.relax.elastic_tissue import ElasticTissue
    from test_newton_tissue import ROW

    p, t = kuhn_box((6.0, 3.0, 3.0), (6, 3, 3))
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW]))
    store = TissueStore.from_model(model)
    cm = CutMesh.over(store, blade_length=1.6)
    tis = ElasticTissue(model, store, step_s=0.02)
    assert tis.store is store and cm.store is store
    for xb in np.linspace(-0.5, 6.5, 8):
        tis.apply_cut(cut_step(cm, [xb, 1.37, 3.5], [0.0, 0.0, 1.0]))
    assert store.n_nodes > len(p) and tis.n_nodes == store.n_nodes
    assert np.shares_memory(cm.rest_points, tis.store.rest_points)
    old_of_new = cm.rebase()
    tis.rebase(old_of_new)
    assert store.n_rebases == 1 and store.n_orig_tets == old_of_new.shape[0]
    np.testing.assert_array_equal(tis.em.tets[:store.n_orig_tets], store.orig_tets)  # element t is tet t


def test_a_physics_is_made_only_over_its_models_uncut_store():
    from cutkit.model.tetmodel import Materials, TetModel
    from cutkit.relax.spring_tissue import Tissue
    from test_newton_tissue import ROW

    p, t = kuhn_box((2.0, 1.0, 1.0), (2, 1, 1))
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW]))
    store = TissueStore.from_model(model)
    tis = Tissue(model, store, dt0=1e-3, n_lists=1, tolerance_fraction=1e-3)
    np.testing.assert_array_equal(tis.springs.springs, store.edges)  # spring k is the store's edge k
    store.remove_tets([0])
    store.add_tets([tuple(t[0])], origin=0)
    with pytest.raises(InputError, match="before anything is cut"):
        Tissue(model, store, dt0=1e-3, n_lists=1, tolerance_fraction=1e-3)


def test_held_nodes_come_from_the_boundary_conditions_and_a_cut_between_held_nodes_is_held():
    from cutkit.model.tetmodel import BoundaryConditions, Materials, TetModel
    from test_newton_tissue import ROW

    p, t = kuhn_box((2.0, 1.0, 1.0), (2, 1, 1))
    base = np.flatnonzero(p[:, 2] == 0)
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW]),
                                 boundary=BoundaryConditions(fixed_nodes=base[:2], prescribed_nodes=base[2:],
                                                             prescribed_displacement=np.zeros((len(base) - 2, 3))))
    s = TissueStore.from_model(model)
    np.testing.assert_array_equal(s.held, p[:, 2] == 0)  # fixed and prescribed alike
    top = np.flatnonzero(p[:, 2] > 0)
    between_held = s.add_node(base[:2], [0.5, 0.5])
    across = s.add_node([base[0], top[0]], [0.5, 0.5])
    assert s.held[between_held] and not s.held[across]
    s.rebase()
    assert s.held[between_held] and not s.held[across] and s.held.shape == (s.n_nodes,)
    with pytest.raises(InputError, match=r"held: shape \(3,\)"):
        TissueStore(p, t, held=np.zeros(3, bool))
