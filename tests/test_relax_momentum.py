"""A free piece's momentum under the springs' semi-implicit steps (cutkit.relax.momentum): Newton's
second law for its centre of mass, exactly (to rounding), under uniform steps, Gauss-Seidel sweeps and
the adaptive node lists; held tissue is left as it was."""

import numpy as np
import pytest
from test_relax import block

from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import BoundaryConditions, TetModel
from cutkit.relax import Control, build_spring_model, initial_state, step, total_momentum
from cutkit.relax.adaptive import NodeLists
from cutkit.relax.momentum import spring_pieces

G = np.array([0.0, 0.0, -9806.65])  # mm/s^2


def _free_block(damping, seed=0):
    sm = build_spring_model(block(3, 3, 3, damping=damping, fixed_z0=False))
    st = initial_state(sm)
    st.positions[:] += np.random.default_rng(seed).normal(0.0, 0.2, st.positions.shape)  # out of balance
    return sm, st


@pytest.mark.parametrize("gauss_seidel", [False, True])
def test_uniform_steps_give_a_free_piece_the_impulse_of_its_loads(gauss_seidel):
    sm, st = _free_block(damping=0.0)
    mass = sm.masses.sum()
    h, n = 1e-4, 200
    for _ in range(n):
        step(sm, st, Control(gravity=G), h, method="semi-implicit", gauss_seidel=gauss_seidel)
    np.testing.assert_allclose(total_momentum(sm, st), mass * G * n * h, rtol=1e-10, atol=1e-18)


def test_adaptive_lists_give_a_free_piece_the_impulse_of_its_loads_at_each_frame():
    """Damping (eq. 4, -D v'), gravity and a force on one node; frames every 1 ms; five lists."""
    sm, st = _free_block(damping=5.0)
    mass, c = sm.masses.sum(), 5.0
    f = np.zeros((sm.n_nodes, 3))
    f[0] = [1e-4, 0.0, 0.0]  # N
    lists = NodeLists(sm, st, 1e-4, 5, displacement_tolerance=1.0)
    p = total_momentum(sm, st)
    coarse = 0
    for frame in range(1, 21):
        lists.advance(Control(external_forces=f, gravity=G), frame * 1e-3)
        # every node's damping is c m: P' = (P + h (F + M g)) / (1 + c h) over the frame
        p = (p + 1e-3 * (f.sum(axis=0) + mass * G)) / (1.0 + c * 1e-3)
        np.testing.assert_allclose(total_momentum(sm, st), p, rtol=1e-9, atol=1e-18)
        coarse = max(coarse, sm.n_nodes - len(lists.node_lists[0]))
    assert coarse > 0  # nodes did step at different rates


def test_without_the_correction_the_piece_would_drift(monkeypatch):
    """The figure the correction removes (docs/relaxation.md): without it, the free block's centre of
    mass moves by about 1.8e-4 mm in 400 steps; with it, by rounding only."""
    from cutkit.relax import integrate

    def com_shift():
        sm, st = _free_block(damping=10.0)
        com0 = sm.masses @ st.positions / sm.masses.sum()
        for _ in range(400):
            step(sm, st, None, 1e-4, method="semi-implicit")
        return np.linalg.norm(sm.masses @ st.positions / sm.masses.sum() - com0)

    assert com_shift() < 1e-12
    monkeypatch.setattr(integrate, "keep_free_momentum", lambda *a: None)
    assert com_shift() > 1e-5


def test_held_tissue_is_left_as_it_was():
    """A held block and a loose one in one model: the held block moves exactly as it does alone."""
    p, t = box_mesh((3, 3, 3), spacing=(2.0, 2.0, 2.0))
    fixed = np.flatnonzero(p[:, 2] == 0)
    two = TetModel.from_arrays(np.concatenate([p, p + [20.0, 0.0, 0.0]]), np.concatenate([t, t + len(p)]),
                               materials=block(1, 1, 1).materials, boundary=BoundaryConditions(fixed_nodes=fixed))
    one = TetModel.from_arrays(p, t, materials=block(1, 1, 1).materials, boundary=BoundaryConditions(fixed_nodes=fixed))
    sm2, sm1 = build_spring_model(two), build_spring_model(one)
    assert spring_pieces(sm2)[0] == 2
    st2, st1 = initial_state(sm2), initial_state(sm1)
    for _ in range(50):
        step(sm2, st2, Control(gravity=G), 1e-4)
        step(sm1, st1, Control(gravity=G), 1e-4)
    n = len(p)
    np.testing.assert_array_equal(st2.positions[:n], st1.positions)
    np.testing.assert_array_equal(st2.velocities[:n], st1.velocities)
    # ... and the loose block falls: its momentum is its weight's impulse
    m = sm2.masses[n:].sum()
    np.testing.assert_allclose((sm2.masses[n:, None] * st2.velocities[n:]).sum(axis=0), m * G * 50 * 1e-4,
                               rtol=1e-10, atol=1e-18)


def test_pieces_follow_the_topology():
    sm, _ = _free_block(damping=0.0)
    assert spring_pieces(sm)[0] == 1
    version = sm.topology_version
    sm.springs = sm.springs[:0]
    sm.stiffness, sm.rest_length = sm.stiffness[:0], sm.rest_length[:0]
    sm.rebuild_adjacency()
    assert sm.topology_version == version + 1
    assert spring_pieces(sm)[0] == sm.n_nodes


def test_graph_components_match_their_twin():
    from _twins_relax import graph_components_twin

    from cutkit.relax._graph_kernels import graph_components
    from cutkit.relax._kernels import spring_csr

    rng = np.random.default_rng(3)
    for n, s in [(1, 0), (5, 0), (40, 30), (200, 150), (200, 600)]:
        springs = rng.integers(0, n, (s, 2))
        springs = springs[springs[:, 0] != springs[:, 1]]
        off, adj, _ = spring_csr(np.ascontiguousarray(springs[:, 0], np.int64),
                                 np.ascontiguousarray(springs[:, 1], np.int64), n)
        k, lab = graph_components(off, adj)
        k2, lab2 = graph_components_twin(springs, n)
        assert k == k2
        np.testing.assert_array_equal(lab, lab2)
