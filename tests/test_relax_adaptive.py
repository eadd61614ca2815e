"""Adaptive node lists and the eq. (8) scheduler (section 5.2); reproducibility."""

import numpy as np
import pytest
from test_relax import block

from cutkit.errors import InputError
from cutkit.relax import (
    Control,
    add_nodes,
    add_springs,
    build_spring_model,
    initial_state,
    remove_springs,
    step,
)
from cutkit.relax.adaptive import NodeLists


def _local_load_model(damping=100.0):
    tm = block(12, 12, 4, h=2.0, damping=damping)
    sm = build_spring_model(tm)
    pts = tm.points
    f = np.zeros((sm.n_nodes, 3))
    top = np.flatnonzero((pts[:, 2] == 8) & (np.abs(pts[:, 0] - 4) <= 2) & (np.abs(pts[:, 1] - 4) <= 2))
    f[top, 2] = -0.005 / len(top)  # 5 mN pressed on a 4 x 4 mm patch of a 24 x 24 x 8 mm block
    return sm, Control(external_forces=f)


def test_single_list_equals_uniform_steps_bitwise():
    sm, control = _local_load_model()
    ref = initial_state(sm)
    for _ in range(30):
        step(sm, ref, control, 2e-4, gauss_seidel=True)
    st = initial_state(sm)
    lists = NodeLists(sm, st, 2e-4, 1)
    assert lists.advance(control, 30 * 2e-4) == 30
    np.testing.assert_array_equal(st.positions, ref.positions)
    np.testing.assert_array_equal(st.velocities, ref.velocities)


def test_adaptive_matches_uniform_with_a_fraction_of_the_updates():
    sm, control = _local_load_model()
    dt0, T = 2e-4, 0.2
    ref = initial_state(sm)
    for _ in range(int(round(T / dt0))):
        step(sm, ref, control, dt0, gauss_seidel=True)
    st = initial_state(sm)
    lists = NodeLists(sm, st, dt0, 5, displacement_tolerance=1e-5)
    lists.advance(control, T)
    assert st.time == pytest.approx(T) and np.all(st.time_stamps[~sm.fixed] == pytest.approx(T))
    u_max = np.abs(ref.positions - sm.rest_positions).max()
    err = np.abs(st.positions - ref.positions).max()
    fraction = st.n_updates.sum() / ref.n_updates.sum()
    # measured: error 1% of the largest displacement with 29% of the node updates
    assert err < 0.015 * u_max
    assert fraction < 0.35
    assert sum(len(x) for x in lists.node_lists[1:]) > len(lists.node_lists[0])


def test_scheduler_picks_smallest_next_time_and_steps_by_stamp_difference():
    sm, control = _local_load_model()
    st = initial_state(sm)
    lists = NodeLists(sm, st, 1e-4, 3, displacement_tolerance=1.0)
    free = sm.free_nodes
    lists.move_node_up(free[::2])
    lists.move_node_up(free[::4])  # every 4th node in list 2, others of the even ones in list 1
    assert np.all(st.node_list[free[::4]] == 2) and np.all(st.node_list[free[2::4]] == 1)
    order = []
    f, g = np.zeros((sm.n_nodes, 3)), np.zeros(3)
    for _ in range(7):
        i = lists.next_list()
        order.append(i)
        lists._reassign = lambda nodes, i: None  # keep the lists fixed for this check
        lists.process(i, f, g)
    # eq. (8): t_i + dt_i smallest, ties to the finest list
    assert order == [0, 0, 1, 0, 0, 1, 2]
    np.testing.assert_allclose(lists.list_time, [4e-4, 4e-4, 4e-4])
    assert st.n_updates[free[1]] == 4 and st.n_updates[free[2]] == 2 and st.n_updates[free[0]] == 1
    # a node moved down steps by its list's time minus its own stamp
    k = free[0]
    lists.move_node_down([k, k])
    lists.move_node_down([k])
    assert st.node_list[k] == 0 and st.time_stamps[k] == pytest.approx(4e-4)
    lists.process(lists.next_list(), f, g)
    assert st.time_stamps[k] == pytest.approx(5e-4)


def test_cut_nodes_enter_the_finest_list():
    sm, control = _local_load_model()
    st = initial_state(sm)
    lists = NodeLists(sm, st, 2e-4, 4, displacement_tolerance=1e-3)
    lists.advance(control, 0.02)
    k = int(np.flatnonzero(st.node_list == st.node_list.max())[0])
    new = add_nodes(sm, st, sm.rest_positions[[k]], st.positions[[k]], [[k]], [[0.5]])
    # the duplicate takes over k's springs to its higher neighbours (one side of a cut)
    mine = np.flatnonzero(sm.springs[:, 0] == k)
    pairs = np.stack([np.full(len(mine), new[0]), sm.springs[mine, 1]], 1)
    add_springs(sm, pairs, sm.stiffness[mine], sm.rest_length[mine])
    remove_springs(sm, mine)
    control.external_forces = np.vstack([control.external_forces, np.zeros((1, 3))])
    assert st.node_list[new[0]] == 0 and new[0] in lists.node_lists[0]
    before = st.positions[new[0]].copy()
    lists.advance(control, 0.03)  # no restart, no explicit notice of the edit
    assert st.time_stamps[new[0]] == pytest.approx(0.03)
    assert np.all(np.isfinite(st.positions)) and np.any(st.positions[new[0]] != before)


def test_runs_are_bitwise_reproducible_and_async_equals_sync():
    def run(use_async):
        sm, control = _local_load_model()
        st = initial_state(sm)
        lists = NodeLists(sm, st, 2e-4, 4, displacement_tolerance=1e-5)
        if use_async:
            lists.run_async(control, 0.02).result()
            lists.close()
        else:
            lists.advance(control, 0.02)
        return st

    a, b, c = run(False), run(False), run(True)
    for other in (b, c):
        np.testing.assert_array_equal(a.positions, other.positions)
        np.testing.assert_array_equal(a.velocities, other.velocities)
        np.testing.assert_array_equal(a.node_list, other.node_list)


def test_jacobi_subset_path_is_reproducible_and_parallel_safe():
    # a list smaller than a quarter of the nodes takes the per-node spring path
    sm, control = _local_load_model()
    outs = []
    for _ in range(2):
        st = initial_state(sm)
        lists = NodeLists(sm, st, 2e-4, 4, displacement_tolerance=1e-5, gauss_seidel=False)
        lists.advance(control, 0.02)
        outs.append(st.positions)
    np.testing.assert_array_equal(outs[0], outs[1])


def test_bad_node_list_arguments():
    sm, _ = _local_load_model()
    st = initial_state(sm)
    with pytest.raises(InputError, match="dt0 must be a positive number of seconds, got 0.0"):
        NodeLists(sm, st, 0.0)
    with pytest.raises(InputError, match="n_lists must lie in 1..30, got 0"):
        NodeLists(sm, st, 1e-4, 0)
