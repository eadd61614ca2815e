"""Element model kernels against their NumPy twins; invariants of vertex block descent."""

import numba
import numpy as np
import pytest

import _twins_elastic as T
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import Materials, Prestress, TetModel
from cutkit.relax import _elastic_kernels as K
from cutkit.relax.elastic import (
    ElementState,
    build_element_model,
    elastic_energy,
    elastic_forces,
    implicit_step,
    lame,
    rest_shape,
    static_solve,
)


def block(nu=0.45, prestrain=0.0, shape=(3, 2, 2)):
    p, t = box_mesh(shape, spacing=(1.0, 1.2, 0.9))
    row = dict(label=1, name="m", E=30e3, poisson_ratio=nu, density=1090.0, damping=8.0, F_enter=0.8,
               mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
               c_edge=1.0, c_shape=1.0)
    ps = Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[0.0, 0.6, 0.8]]),
                   prestrain=np.array([prestrain]))
    return TetModel.from_arrays(p, t, materials=Materials.from_rows([row]), prestress=ps)


def arrays(em):
    n = em.n_elements
    return em.tets[:n], em.Dminv[:n], em.volume[:n], em.mu[:n], em.lam[:n]


@pytest.fixture
def deformed():
    model = block(prestrain=0.05)
    em = build_element_model(model)
    rng = np.random.default_rng(3)
    x = model.points + rng.normal(scale=0.08, size=model.points.shape)
    return model, em, x


def test_lame_parameters_of_known_materials():
    mu, lam = lame(3.0, 0.25)
    assert mu == pytest.approx(1.2) and lam == pytest.approx(1.2)
    mu, lam = lame(1.0, 0.0)
    assert mu == pytest.approx(0.5) and lam == 0.0


def test_rest_shape_with_prestrain_is_shortened_along_the_fibre():
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    Dminv, V, V0 = rest_shape(X, np.array([[0, 1, 2, 3]]), np.array([0.1]), np.array([[0.0, 0.0, 1.0]]))
    assert V0[0] == pytest.approx(1 / 6)
    assert V[0] == pytest.approx(0.9 / 6)
    # the rest shape itself is then stretched by 1/0.9 along z
    F = np.eye(3) @ Dminv[0]
    assert np.allclose(F, np.diag([1.0, 1.0, 1 / 0.9]))


def test_forces_and_energy_match_the_twin(deformed):
    model, em, x = deformed
    assert elastic_energy(em, x) == pytest.approx(T.energy(x, *arrays(em)), rel=1e-12)
    assert np.allclose(elastic_forces(em, x), T.forces(x, *arrays(em)), atol=1e-14, rtol=1e-10)


def test_forces_are_minus_the_energy_gradient(deformed):
    model, em, x = deformed
    f = elastic_forces(em, x)
    h = 1e-6
    for i, c in [(0, 0), (5, 1), (17, 2)]:
        xp, xm = x.copy(), x.copy()
        xp[i, c] += h
        xm[i, c] -= h
        grad = (elastic_energy(em, xp) - elastic_energy(em, xm)) / (2 * h)
        assert -grad == pytest.approx(f[i, c], rel=1e-6, abs=1e-12)


def test_rest_shape_has_no_force_without_prestrain():
    model = block()
    em = build_element_model(model)
    assert np.abs(elastic_forces(em, model.points)).max() < 1e-15
    assert elastic_energy(em, model.points) == pytest.approx(0.0, abs=1e-15)


def test_energy_is_exactly_quadratic_in_one_vertex_even_through_inversion(deformed):
    """J is affine in one vertex: third differences of the energy along any line vanish."""
    model, em, x = deformed
    i = 7
    d = np.array([0.3, -0.5, 0.8])
    e = [elastic_energy(em, np.where(np.arange(len(x))[:, None] == i, x + s * d, x)) for s in (-3, -1, 1, 3)]
    third = e[3] - 3 * e[2] + 3 * e[1] - e[0]
    assert abs(third) < 1e-9 * max(abs(v) for v in e)


def test_sweep_matches_the_twin_in_colour_order(deformed):
    model, em, x = deformed
    n = em.n_nodes
    inertia = np.full(n, 1e-3)
    target = model.points.copy()
    force = np.zeros((n, 3))
    force[3] = [1e-4, 0.0, -2e-4]
    fixed = np.zeros((n, 3), bool)
    fixed[0] = True
    fixed[4, 1] = True
    em.fixed[:] = fixed
    em._classes = None
    offsets, nodes = em.colour_classes()
    terms = K.NodeTerms(inertia, np.zeros(n), em.fixed, target, x.copy(), force)
    xk = x.copy()
    K.vbd_sweep(xk, em.elements, em.adjacency, terms, offsets, nodes, np.zeros(n))
    xt = T.vbd_sweep(x, *arrays(em), inertia, target, force, fixed, nodes)
    assert np.allclose(xk, xt, atol=1e-7)
    assert np.array_equal(xk[0], x[0]) and xk[4, 1] == x[4, 1]


def test_no_two_nodes_of_an_element_share_a_colour():
    model = block(shape=(4, 3, 3))
    em = build_element_model(model)
    c = em.colour[em.tets[: em.n_elements]]
    for a in range(4):
        for b in range(a + 1, 4):
            assert np.all(c[:, a] != c[:, b])


def test_results_do_not_depend_on_the_thread_count():
    model = block(prestrain=0.08, shape=(5, 4, 4))
    out = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        numba.set_num_threads(threads)
        em = build_element_model(model)
        em.fixed[model.points[:, 2] == 0] = True
        em._classes = None
        st = ElementState(model.points.copy(), np.zeros_like(model.points))
        for _ in range(3):
            implicit_step(em, st, 0.01, rtol=1e-6)
        out.append(st.positions.copy())
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(out[0], out[1])


def test_static_solve_stops_at_the_residual_it_was_asked_for():
    model = block(prestrain=0.08, shape=(5, 4, 4))
    em = build_element_model(model)
    em.fixed[model.points[:, 0] == 0] = True
    em._classes = None
    x = model.points.copy()
    info = static_solve(em, x, rtol=1e-6, atol=0.0)
    assert info.converged and info.residual <= 1e-6 * info.initial_residual
    free = ~em.fixed.all(axis=1)
    assert np.linalg.norm(elastic_forces(em, x)[free]) < 1e-4 * info.initial_residual


def one_tet_on_its_base():
    """The unit corner tet with its base (nodes 0-2) held: its element model and rest points."""
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    model = TetModel.from_arrays(X, np.array([[0, 1, 2, 3]]), materials=block().materials)
    em = build_element_model(model)
    em.fixed[:3] = True
    em._classes = None
    return em, X


def test_no_node_step_inverts_a_tet():
    """A pull that would fold a tet over moves the node only as far as keeps it positive."""
    em, X = one_tet_on_its_base()
    x = X.copy()
    force = np.zeros((4, 3))
    force[3, 2] = -1e3  # far more than the tet can hold
    terms = K.NodeTerms(np.zeros(4), np.zeros(4), em.fixed, x.copy(), x.copy(), force)
    offsets, nodes = em.colour_classes()
    for _ in range(20):
        K.vbd_sweep(x, em.elements, em.adjacency, terms, offsets, nodes, np.zeros(4))
        assert x[3, 2] > 0.0
    assert x[3, 2] < 1e-3  # squashed as far as it goes, never through


def test_inverted_tet_is_pushed_back():
    """A single tet with one vertex pushed through the opposite face recovers its orientation."""
    em, X = one_tet_on_its_base()
    x = X.copy()
    x[3, 2] = -0.5  # inverted
    static_solve(em, x, rtol=1e-10, atol=0.0)
    assert x[3] == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)
