"""Mass-spring model, semi-implicit integrator (eqs. 4-7), topology edits."""

import numpy as np
import pytest
from _twins_relax import (
    spring_csr_twin,
    greedy_colouring_twin,
    halo_nodes_twin,
    kuhn_grid,
    relax_nodes_twin,
    spring_coefficients_twin,
    spring_forces_twin,
)

from cutkit.errors import InputError, MeshError
from cutkit.model.tetmodel import MATERIAL_FIELDS, BoundaryConditions, Materials, Prestress, TetModel
from cutkit.relax import (
    Control,
    add_nodes,
    add_springs,
    build_spring_model,
    initial_state,
    remove_springs,
    spring_forces,
    step,
    total_momentum,
)
from cutkit.relax import _kernels as K
from cutkit.relax.integrate import colour_classes
from cutkit.relax.run import explicit_time_limit
from cutkit.relax.static import static_equilibrium

G = np.array([0.0, 0.0, -9806.65])  # mm/s^2


def materials(E=1e4, density=1000.0, damping=0.0, label=1):
    row = {k: 0.0 for k in MATERIAL_FIELDS}
    row.update(label=label, name="tissue", E=E, density=density, damping=damping)
    return Materials.from_rows([row])


def block(nx=3, ny=3, nz=3, h=2.0, damping=0.0, fixed_z0=True, **kw):
    pts, tets = kuhn_grid(nx, ny, nz, h)
    fixed = np.flatnonzero(pts[:, 2] == 0) if fixed_z0 else np.zeros(0, np.int64)
    return TetModel.from_arrays(pts, tets, materials=materials(damping=damping),
                                boundary=BoundaryConditions(fixed_nodes=fixed), **kw)


def csr_springs(sm):
    return sm.springs, sm.rest_length, sm.stiffness


# -- the model ---------------------------------------------------------------

def test_masses_are_lumped_tet_masses_in_tonnes():
    tm = block(2, 2, 2, h=2.0)
    sm = build_spring_model(tm)
    volume_mm3 = 4.0 * 4.0 * 4.0
    # 1000 kg/m^3 = 1e-9 t/mm^3
    assert sm.masses.sum() == pytest.approx(volume_mm3 * 1e-9, rel=1e-12)
    # a corner node of the cube on the shared diagonal gets a quarter of 6 tets
    corner = np.flatnonzero(np.all(tm.points == 0, axis=1))[0]
    assert sm.masses[corner] == pytest.approx(6 * (8.0 / 6) / 4 * 1e-9)


def test_stiffness_follows_volume_formula():
    # one tet: k_e = E V / l_e^2 for each of its six edges
    pts = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0], [0, 0, 4]], float)
    tm = TetModel.from_arrays(pts, [[0, 1, 2, 3]], materials=materials(E=2e5))
    sm = build_spring_model(tm)
    vol = 2 * 3 * 4 / 6
    length = np.linalg.norm(pts[sm.springs[:, 1]] - pts[sm.springs[:, 0]], axis=1)
    np.testing.assert_allclose(sm.stiffness, 2e5 * 1e-6 * vol / length**2, rtol=1e-12)
    np.testing.assert_allclose(sm.rest_length, length)


def test_prestress_shortens_rest_length_along_fibre():
    tm = block(2, 2, 2, h=1.0, prestress=Prestress(label=np.array([1], np.int32),
                                                  fibre_direction=np.array([[2.0, 0, 0]]),
                                                  prestrain=np.array([0.1])))
    sm = build_spring_model(tm)
    d = tm.points[sm.springs[:, 1]] - tm.points[sm.springs[:, 0]]
    length = np.linalg.norm(d, axis=1)
    cos2 = (d[:, 0] / length) ** 2
    np.testing.assert_allclose(sm.rest_length, length * (1 - 0.1 * cos2), rtol=1e-12)
    # edges across the fibre keep their length
    across = np.abs(d[:, 0]) == 0
    assert across.any() and np.all(sm.rest_length[across] == length[across])


def test_boundary_conditions_fix_and_displace_nodes():
    tm = block(2, 2, 2)
    tm.boundary.prescribed_nodes = np.array([26])
    tm.boundary.prescribed_displacement = np.array([[0.5, 0, 0]])
    sm = build_spring_model(tm)
    st = initial_state(sm)
    assert sm.fixed[26] and np.allclose(st.positions[26], tm.points[26] + [0.5, 0, 0])
    assert np.all(st.node_list[sm.fixed] == -1) and np.all(st.node_list[~sm.fixed] == 0)
    x_fixed = st.positions[sm.fixed].copy()
    for _ in range(5):
        step(sm, st, Control(gravity=G), 1e-4)
    np.testing.assert_array_equal(st.positions[sm.fixed], x_fixed)


@pytest.mark.parametrize(
    "edit, exc, message",
    [
        (lambda tm: setattr(tm, "labels", np.full(tm.n_tets, 7, np.int32)), InputError,
         "tet label 7 has no row in the materials table"),
        (lambda tm: tm.tets.__setitem__(0, tm.tets[0, [1, 0, 2, 3]]), MeshError,
         "tet 0 has non-positive volume"),
        (lambda tm: tm.tets.__setitem__(0, [0, 1, 2, 999]), MeshError, "tets index nodes outside 0..26"),
        (lambda tm: setattr(tm.boundary, "fixed_nodes", np.array([27])), InputError,
         "fixed node index outside 0..26"),
    ],
)
def test_bad_models_get_one_line_errors(edit, exc, message):
    tm = block(2, 2, 2)
    edit(tm)
    with pytest.raises(exc, match=message.replace(".", r"\.")):
        build_spring_model(tm)


def test_bad_step_arguments():
    sm = build_spring_model(block(2, 2, 2))
    st = initial_state(sm)
    with pytest.raises(InputError, match="time step must be a positive number of seconds, got -1.0"):
        step(sm, st, None, -1.0)
    with pytest.raises(InputError, match="unknown relaxation method 'rk4'"):
        step(sm, st, None, 1e-4, method="rk4")
    with pytest.raises(InputError, match=r"external_forces must have shape \(27, 3\), got \(3,\)"):
        step(sm, st, Control(external_forces=np.zeros(3)), 1e-4)


# -- kernels against their twins -----------------------------------------------

def _perturbed(sm, seed):
    rng = np.random.default_rng(seed)
    st = initial_state(sm)
    st.positions += rng.normal(scale=0.1, size=st.positions.shape) * ~sm.fixed[:, None]
    st.velocities += rng.normal(scale=5.0, size=st.positions.shape) * ~sm.fixed[:, None]
    st.time_stamps[:] = rng.choice([0.0, 1e-4, 2e-4], size=sm.n_nodes)
    return st


@pytest.mark.parametrize("mode", [K.MODE_AXIAL, K.MODE_SECANT, K.MODE_EXPLICIT])
@pytest.mark.parametrize("gauss_seidel", [False, True])
@pytest.mark.parametrize("every", [1, 5])  # all nodes (per-spring coefficients) or a sparse list (per node)
def test_relax_nodes_matches_twin(mode, gauss_seidel, every):
    sm = build_spring_model(block(3, 2, 2, damping=7.0))
    st = _perturbed(sm, 1)
    rng = np.random.default_rng(2)
    f = rng.normal(scale=1e-3, size=(sm.n_nodes, 3))
    nodes = sm.free_nodes[::every]
    T = 4e-4
    x, v, ts = st.positions.copy(), st.velocities.copy(), st.time_stamps.copy()
    order = np.concatenate(colour_classes(sm, nodes)) if gauss_seidel else None
    xt, vt, tst = relax_nodes_twin(nodes, T, x, v, ts, sm.springs, sm.rest_length, sm.stiffness, sm.masses,
                                   sm.damping, f, G, mode, gauss_seidel_order=order)
    from cutkit.relax.integrate import advance_nodes

    classes = colour_classes(sm, nodes) if gauss_seidel else None
    advance_nodes(sm, st, nodes, T, f, G, mode, classes)
    np.testing.assert_allclose(st.positions, xt, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(st.velocities, vt, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(st.time_stamps[nodes], T)
    assert np.all(st.n_updates[nodes] == 1) and st.n_updates.sum() == len(nodes)


def test_spring_forces_match_twin_and_balance():
    sm = build_spring_model(block(3, 2, 2))
    x = _perturbed(sm, 3).positions
    f = spring_forces(sm, x)
    np.testing.assert_allclose(f, spring_forces_twin(x, sm.springs, sm.rest_length, sm.stiffness), atol=1e-15)
    assert np.abs(f.sum(axis=0)).max() < 1e-15  # Newton's third law


def test_spring_coefficients_and_halo_match_twins():
    sm = build_spring_model(block(3, 2, 2))
    x = _perturbed(sm, 4).positions
    c = np.empty(sm.n_springs)
    K.spring_coefficients(sm.spring_a, sm.spring_b, x, sm.rest_length, sm.stiffness, c)
    np.testing.assert_allclose(c, spring_coefficients_twin(sm.springs, x, sm.rest_length, sm.stiffness),
                               rtol=1e-12, atol=1e-15)
    nodes = np.array([0, 7, 20], np.int64)
    np.testing.assert_array_equal(K.halo_nodes(nodes, sm.adj_offsets, sm.adj_nodes, sm.n_nodes),
                                  halo_nodes_twin(nodes, sm.springs))
    # coincident spring ends give no force (no NaN)
    x[sm.springs[0, 1]] = x[sm.springs[0, 0]]
    K.spring_coefficients(sm.spring_a, sm.spring_b, x, sm.rest_length, sm.stiffness, c)
    assert c[0] == 0.0 and np.all(np.isfinite(c))


def test_gather_spring_arrays_matches_twin():
    from _twins_relax import gather_spring_arrays_twin

    rng = np.random.default_rng(11)
    springs = rng.integers(0, 40, (300, 2))
    springs = springs[springs[:, 0] != springs[:, 1]]
    rest, stiff = rng.uniform(0.5, 2.0, len(springs)), rng.uniform(1.0, 9.0, len(springs))
    off, _, sid = K.spring_csr(springs[:, 0].copy(), springs[:, 1].copy(), 45)  # nodes 40..44 have no spring
    ar, ak, nk = np.empty(sid.size), np.empty(sid.size), np.full(45, np.nan)
    K.gather_spring_arrays(off, sid, rest, stiff, ar, ak, nk)
    tr, tk, tn = gather_spring_arrays_twin(springs, sid, rest, stiff, 45)
    assert np.array_equal(ar, tr) and np.array_equal(ak, tk)
    np.testing.assert_allclose(nk, tn, rtol=1e-13, atol=0.0)  # summation order differs
    assert np.all(nk[40:] == 0.0)


def test_spring_csr_matches_twin_with_duplicates_and_isolated_nodes():
    rng = np.random.default_rng(3)
    springs = rng.integers(0, 40, size=(300, 2))
    springs = springs[springs[:, 0] != springs[:, 1]]
    springs = np.concatenate([springs, springs[:7]])  # repeated pairs keep spring order
    off, nodes, sid = K.spring_csr(springs[:, 0].copy(), springs[:, 1].copy(), 45)  # nodes 40..44 isolated
    t_off, t_nodes, t_sid = spring_csr_twin(springs, 45)
    np.testing.assert_array_equal(off, t_off)
    np.testing.assert_array_equal(nodes, t_nodes)
    np.testing.assert_array_equal(sid, t_sid)


def test_colouring_is_proper_and_matches_twin():
    sm = build_spring_model(block(4, 3, 3))
    np.testing.assert_array_equal(sm.colour, greedy_colouring_twin(sm.springs, sm.n_nodes))
    assert np.all(sm.colour[sm.springs[:, 0]] != sm.colour[sm.springs[:, 1]])
    classes = colour_classes(sm, sm.free_nodes)
    assert sorted(np.concatenate(classes).tolist()) == sm.free_nodes.tolist()


# -- stability and equilibrium -------------------------------------------------

def _run(sm, control, dt, n, **kw):
    st = initial_state(sm)
    for _ in range(n):
        step(sm, st, control, dt, **kw)
        if not np.all(np.isfinite(st.positions)) or np.abs(st.positions).max() > 1e6:
            return None
    return st


def test_semi_implicit_stable_where_symplectic_euler_diverges():
    # overdamped tissue (1000 1/s): a quasi-static settle
    sm = build_spring_model(block(4, 4, 4, damping=1000.0))
    control = Control(gravity=G)
    dt = 5.0 * explicit_time_limit(sm)
    x_static = static_equilibrium(sm, control)
    assert _run(sm, control, dt, 200, method="symplectic-euler") is None
    for gs in (False, True):
        st = _run(sm, control, dt, 1000, gauss_seidel=gs)
        assert st is not None
        sag = np.abs(x_static - sm.rest_positions).max()
        # converged to the Newton equilibrium within 1e-4 of the largest displacement
        assert np.abs(st.positions - x_static).max() < 1e-4 * sag


def test_equilibrium_with_prestress_and_prescribed_displacement():
    tm = block(4, 2, 2, damping=1000.0, fixed_z0=False,
               prestress=Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[1.0, 0, 0]]),
                                   prestrain=np.array([0.05])))
    left = np.flatnonzero(tm.points[:, 0] == 0)
    right = np.flatnonzero(tm.points[:, 0] == 8)
    tm.boundary = BoundaryConditions(fixed_nodes=left, prescribed_nodes=right,
                                     prescribed_displacement=np.tile([0.4, 0.0, 0.1], (len(right), 1)))
    sm = build_spring_model(tm)
    x_static = static_equilibrium(sm)
    st = _run(sm, None, 3.0 * explicit_time_limit(sm), 1000, gauss_seidel=True)
    move = np.abs(x_static - sm.rest_positions)[~sm.fixed].max()
    assert move > 0.05
    assert np.abs(st.positions - x_static).max() < 1e-4 * move


def test_bar_elongation_matches_hooke():
    # 20 x 2 x 2 mm bar, E = 10 kPa, end load 1 mN: F L / (E A) = 0.5 mm (small strain)
    nx, ny, nz = 20, 2, 2
    pts, tets = kuhn_grid(nx, ny, nz, 1.0)
    E = 1e4
    tm = TetModel.from_arrays(pts, tets, materials=materials(E=E),
                              boundary=BoundaryConditions(fixed_nodes=np.flatnonzero(pts[:, 0] == 0)))
    sm = build_spring_model(tm)
    F = 1e-3
    end = np.flatnonzero(pts[:, 0] == nx)
    y, z = pts[end, 1], pts[end, 2]
    w = np.where((y == 0) | (y == ny), 0.5, 1.0) * np.where((z == 0) | (z == nz), 0.5, 1.0)
    f = np.zeros((sm.n_nodes, 3))
    f[end, 0] = F * w / w.sum()
    x = static_equilibrium(sm, Control(external_forces=f))
    elongation = (x[end, 0] - pts[end, 0]).mean()
    expected = F * nx / (E * 1e-6 * ny * nz)
    # measured: 0.969 of Hooke (the Kuhn lattice is 3.4% stiffer along an axis)
    assert abs(elongation / expected - 1) < 0.05


# -- topology edits --------------------------------------------------------------

def test_add_nodes_keeps_mass_and_momentum_and_relaxation_continues():
    sm = build_spring_model(block(3, 3, 2, damping=10.0))
    st = initial_state(sm)
    for _ in range(20):
        step(sm, st, Control(gravity=G), 2e-4)
    m0, p0 = sm.masses.sum(), total_momentum(sm, st)
    # split edge 0 at its midpoint and duplicate the far node of edge 5 (a cut)
    a, b = sm.springs[0]
    c = sm.springs[5, 1]
    rest = np.array([(sm.rest_positions[a] + sm.rest_positions[b]) / 2, sm.rest_positions[c]])
    pos = np.array([(st.positions[a] + st.positions[b]) / 2, st.positions[c]])
    new = add_nodes(sm, st, rest, pos, parents=[[a, b], [c, -1]], weights=[[0.2, 0.2], [0.5, 0.0]])
    assert new.tolist() == [sm.n_nodes - 2, sm.n_nodes - 1]
    assert sm.masses.sum() == pytest.approx(m0, rel=1e-14)
    np.testing.assert_allclose(total_momentum(sm, st), p0, rtol=1e-12, atol=1e-30)
    assert np.all(st.node_list[new] == 0)  # cut nodes enter the finest list
    # replace spring (a, b) by (a, m), (m, b); hook the duplicate to a neighbour of c
    k = sm.stiffness[0]
    remove_springs(sm, [0])
    nb = sm.springs[sm.springs[:, 0] == c][0, 1]
    add_springs(sm, [[a, new[0]], [new[0], b], [new[1], nb]], stiffness=[2 * k, 2 * k, k])
    assert np.all(sm.colour[sm.springs[:, 0]] != sm.colour[sm.springs[:, 1]])
    assert len(sm.adj_nodes) == 2 * sm.n_springs
    for _ in range(20):
        step(sm, st, Control(gravity=G), 2e-4, gauss_seidel=True)
    assert np.all(np.isfinite(st.positions))
    # without external forces and fixed nodes, momentum is kept by the steps too
    sm.fixed[:] = False
    st.time_stamps[:] = st.time
    p1 = total_momentum(sm, st)
    sm.damping[:] = 0.0
    step(sm, st, None, 2e-4, method="symplectic-euler")
    np.testing.assert_allclose(total_momentum(sm, st), p1, atol=1e-12 * np.abs(p1).max() + 1e-25)


def test_add_nodes_rejects_taking_all_the_mass():
    sm = build_spring_model(block(2, 2, 2))
    st = initial_state(sm)
    with pytest.raises(InputError, match="add_nodes: node 3 would give away 1 >= 1 of its mass"):
        add_nodes(sm, st, sm.rest_positions[[3, 3]], sm.rest_positions[[3, 3]], [[3], [3]], [[0.5], [0.5]])


def test_semi_implicit_steps_keep_a_free_pieces_momentum():
    """A free block started out of balance, no load: its centre of mass must stay where it is. Symplectic
    Euler keeps it to rounding (4e-15 mm); the semi-implicit steps move it 1.8e-4 mm in 400 steps."""
    rng = np.random.default_rng(0)
    sm = build_spring_model(block(3, 3, 3, damping=10.0, fixed_z0=False))
    st = initial_state(sm)
    st.positions[:] += rng.normal(0.0, 0.2, st.positions.shape)
    com0 = sm.masses @ st.positions / sm.masses.sum()
    for _ in range(400):
        step(sm, st, None, 1e-4, method="semi-implicit")
    assert np.linalg.norm(sm.masses @ st.positions / sm.masses.sum() - com0) < 1e-9
