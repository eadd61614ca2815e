"""Element model kernels against their NumPy twins; invariants of vertex block descent."""

import numba
import numpy as np
import pytest

import _twins_elastic as T
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import Materials, Prestress, TetModel
from cutkit.relax import _elastic_kernels as K
from cutkit.relax import elastic
from cutkit.relax.materials import lame
from cutkit.relax.elastic import ElementState, build_element_model, rest_shape
from cutkit.relax.equilibrium import static_solve
from cutkit.relax.vbd import (elastic_energy, elastic_forces, implicit_step, kept_volume_ratios, local_step,
                              volume_ratio_extremes)


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


def test_volume_ratio_extremes_match_the_twin_with_removed_and_inverted_tets(deformed):
    """The smallest J and the count below a bound, against det F of every live tet by NumPy: a
    removed tet (volume 0) does not count, an inverted one does."""
    model, em, x = deformed
    x = x.copy()
    t0 = em.tets[0]
    x[t0[1]] = x[t0[0]] - (x[t0[1]] - x[t0[0]])  # mirror one corner through another: tet 0 inverts
    em.remove_elements(np.array([1]))
    tets, Dminv, volume = arrays(em)[:3]
    J = np.linalg.det(T.deformation_gradients(x, tets, Dminv))[volume > 0]
    assert J.min() < 0 and volume[1] == 0.0
    for below in (0.5, 0.9, 1.1):
        lowest, count = volume_ratio_extremes(em, x, below)
        assert lowest == pytest.approx(J.min(), rel=1e-12) and count == int((J < below).sum())
    assert volume_ratio_extremes(em, model.points, 0.5)[1] == 0
    stretched = model.points * 1.1  # every J above 1.1^3: the smallest is reported, not 1
    assert volume_ratio_extremes(em, stretched, 0.5)[0] > 1.0
    # kept between calls (the tissue's report): a waiting cut (the stop flag up) ends the pass, not
    # measured, the rest left marked; down, the next call finishes it: the whole pass's, bit for bit
    m = em.tets.shape[0]
    at, mark, J = np.full((em.n_nodes, 3), np.nan), np.ones(m, bool), np.ones(m)
    none = np.empty(0, np.int64)
    lowest, count = kept_volume_ratios(em, x, at, none, mark, J, 0.5, np.ones(1, np.int64))
    assert np.isnan(lowest) and count == 0 and mark.any()
    assert kept_volume_ratios(em, x, at, none, mark, J, 0.5, np.zeros(1, np.int64)) == volume_ratio_extremes(em, x, 0.5)
    assert not mark.any()


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


def crushed(model, em, J):
    """The block with node 0's tets' first tet flattened to volume ratio J by moving its corner 0."""
    t = em.tets[0]
    x = model.points.copy()
    p = x[t]
    n = np.cross(p[2] - p[1], p[3] - p[1])
    n /= np.linalg.norm(n)
    height = np.dot(p[0] - p[1], n)
    x[t[0]] -= (1.0 - J) * height * n  # J is affine in one corner: scale its height over the opposite face
    return x, t


def test_barrier_forces_match_the_twin_and_the_energy_gradient():
    """A tet crushed to J = 0.04 is inside the barrier band: kernel and twin agree, forces are -grad W."""
    model = block()
    em = build_element_model(model)
    x, t = crushed(model, em, 0.04)
    F = T.deformation_gradients(x, em.tets[:1], em.Dminv[:1])
    assert np.linalg.det(F)[0] == pytest.approx(0.04 * np.linalg.det(T.deformation_gradients(
        model.points, em.tets[:1], em.Dminv[:1]))[0], rel=1e-9)
    assert elastic_energy(em, x) == pytest.approx(T.energy(x, *arrays(em)), rel=1e-12)
    assert np.allclose(elastic_forces(em, x), T.forces(x, *arrays(em)), atol=1e-14, rtol=1e-10)
    h = 1e-7
    i = int(t[0])
    f = elastic_forces(em, x)[i]
    for c in range(3):
        xp, xm = x.copy(), x.copy()
        xp[i, c] += h
        xm[i, c] -= h
        grad = (elastic_energy(em, xp) - elastic_energy(em, xm)) / (2 * h)
        assert -grad == pytest.approx(f[c], rel=1e-5, abs=1e-6 * np.abs(f).max())


def test_barrier_energy_grows_without_bound_as_a_tet_is_crushed():
    model = block()
    em = build_element_model(model)
    W = [elastic_energy(em, crushed(model, em, J)[0]) for J in (0.2, 0.1, 1e-2, 1e-4, 1e-8)]
    assert W[0] < W[1] < W[2] < W[3] < W[4]
    # the stable neo-Hookean part alone levels off as J -> 0; the barrier grows like -ln J:
    # J from 1e-4 to 1e-8 (four decades) costs about twice what 1e-2 to 1e-4 (two) does
    assert W[4] - W[3] > 1.3 * (W[3] - W[2])


def test_a_node_step_into_the_barrier_goes_to_the_minimum_along_it():
    """A corner pressed into its tet, already in the barrier band (J = 0.09): the Newton step, whose
    model is taken at the present J, runs to the step limit (J = 0.009) where the barrier is far
    steeper, and raises the node's potential; the kernel stops at the minimum along the step."""
    model = block()
    em = build_element_model(model)
    x, t = crushed(model, em, 0.09)
    p = x[t]
    inward = np.cross(p[2] - p[1], p[3] - p[1])
    inward /= np.linalg.norm(inward)
    n = em.n_nodes
    inertia = np.full(n, 1e-4)
    force = np.zeros((n, 3))
    force[t[0]] = 0.05 * inward
    fixed = np.zeros((n, 3), bool)
    fixed[t[1:]] = True
    em.fixed[:] = fixed
    em._classes = None
    order = np.array([t[0]])
    args, node = arrays(em), (inertia, x.copy(), force)
    newton = T.vbd_sweep(x, *args, *node, fixed, order, line_search=False)
    twin = T.vbd_sweep(x, *args, *node, fixed, order)
    xk = x.copy()
    K.vbd_sweep(xk, em.adjacency, K.NodeTerms(inertia, np.zeros(n), em.fixed, x.copy(), x.copy(), force),
                np.array([0, 1]), order, np.zeros(n), np.zeros(1, np.int64))
    J0 = np.linalg.det(T.deformation_gradients(model.points, em.tets[:1], em.Dminv[:1]))[0]
    J = lambda y: np.linalg.det(T.deformation_gradients(y, em.tets[:1], em.Dminv[:1]))[0] / J0  # noqa: E731
    P = lambda y: T.potential(y, *args, *node)  # noqa: E731
    assert J(newton) == pytest.approx(0.009) and P(newton) > P(x)  # the plain Newton step goes uphill
    assert np.allclose(xk, twin, atol=1e-9)
    assert P(xk) < P(x) and 0.009 < J(xk) < 0.09


def test_a_point_load_does_not_crush_a_tet():
    """A node pressed into the fixed base by a load far above what the tissue can carry (the blade
    before it enters): every tet keeps a volume ratio well above rounding after 200 steps."""
    model = block(shape=(3, 3, 2))
    em = build_element_model(model)
    em.fixed[model.points[:, 2] == 0] = True
    em._classes = None
    top = int(np.flatnonzero((model.points[:, 2] == model.points[:, 2].max()))[4])
    f = np.zeros_like(model.points)
    f[top, 2] = -0.3  # N: ten times E over a 1 mm^2 face (E = 30 kPa)
    st = ElementState(model.points.copy(), np.zeros_like(model.points))
    r2 = np.zeros(em.n_nodes)
    for _ in range(200):  # as the tissue steps (the sweeps start from the last positions)
        local_step(em, st, 0.01, f, r2, np.arange(em.n_nodes), atol=1e-9, max_iterations=50)
    J = np.linalg.det(T.deformation_gradients(st.positions, *arrays(em)[:2]))
    assert J.min() > 1e-3
    assert st.positions[top, 2] < 0.5 * model.points[top, 2]  # the load did squash the block


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
    K.vbd_sweep(xk, em.adjacency, terms, offsets, nodes, np.zeros(n), np.zeros(1, np.int64))
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
        for _ in range(1):  # one step: its sweeps already run thousands of parallel colour classes
            implicit_step(em, st, 0.01, rtol=1e-4)
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
        K.vbd_sweep(x, em.adjacency, terms, offsets, nodes, np.zeros(4), np.zeros(1, np.int64))
        assert x[3, 2] > 0.0
    assert x[3, 2] < 1e-3  # squashed as far as it goes, never through


def test_inverted_tet_is_pushed_back():
    """A single tet with one vertex pushed through the opposite face recovers its orientation."""
    em, X = one_tet_on_its_base()
    x = X.copy()
    x[3, 2] = -0.5  # inverted
    static_solve(em, x, rtol=1e-10, atol=0.0)
    assert x[3] == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)


def test_local_step_bookkeeping_matches_the_twins(deformed):
    """Which nodes a local step wakes first and after a sweep, its velocities and the loaded
    nodes, against NumPy: a held node, a half-held one, an orphan, a moving one, a loaded one."""
    from cutkit.relax import _adjacency_kernels as KA

    model, em, x = deformed
    n = em.n_nodes
    rng = np.random.default_rng(7)
    em.fixed[0] = True
    em.fixed[1, 2] = True
    degree = em.adj_degree.copy()
    degree[2] = 0  # an orphan: no tets
    v = np.zeros((n, 3))
    v[5] = [0.0, 3.0, 0.0]
    r2 = rng.uniform(0.0, 2e-6, n)
    r2[[0, 2, 9]] = 1.0  # out of balance, but held / orphaned / free
    h, tau2 = 0.02, 1e-6
    seeds = np.array([11, 11, 0], np.int64)
    movable_t, r2_t, wake_t = T.step_seeds(em.masses, em.fixed, degree, v, r2, h, tau2, seeds)
    movable, mark, r2_k = np.empty(n, bool), np.zeros(n, bool), r2.copy()
    wake = KA.step_seeds(KA.NodeKinds(em.masses, em.fixed, degree), v, r2_k, h, tau2, seeds, (movable, mark))
    np.testing.assert_array_equal(movable, movable_t)
    np.testing.assert_array_equal(r2_k, r2_t)
    np.testing.assert_array_equal(wake, wake_t)
    assert not mark.any() and {5, 9, 11} <= set(wake.tolist()) and 2 not in wake
    tets = em.tets[:em.n_elements]
    for t2 in (-1.0, tau2):
        got = KA.awake_after_sweep(em.adjacency, movable, r2_k, t2, wake, mark)
        np.testing.assert_array_equal(got, T.awake_after_sweep(tets, movable, r2_k, t2, wake))
        assert not mark.any()
    x0 = model.points
    out = np.empty((n, 3))
    KA.step_velocities(x, x0, em.fixed, h, out)
    np.testing.assert_array_equal(out, np.where(em.fixed, 0.0, (x - x0) / h))
    f = np.zeros((n, 3))
    f[[4, 7], [2, 0]] = [-1e-3, 2.0]
    np.testing.assert_array_equal(KA.loaded_nodes(f), [4, 7])
    # the tets around some nodes (a cut step's moved nodes), each once, against a search of the tet table
    for nodes in (np.array([3, 3, 8, 0], np.int64), np.zeros(0, np.int64)):
        want = np.flatnonzero(np.isin(tets, nodes).any(axis=1))
        np.testing.assert_array_equal(KA.tets_around(em.adjacency, nodes), want)


def test_rest_shapes_match_the_twin_with_prestrain_and_degenerate_tets(monkeypatch):
    """The kernel against NumPy's det and inv: random tets, one inverted, one flat, one a
    sliver just below MIN_ELEMENT_QUALITY; with and without a prestrain along a fibre."""
    from cutkit.relax._shape_kernels import corner_edge_inverses
    from cutkit.relax.elastic import MIN_ELEMENT_QUALITY

    rng = np.random.default_rng(11)
    X = rng.uniform(-2.0, 2.0, (40, 3))
    X[36:40] = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0.5, 0.0]]  # a flat tet
    tets = rng.integers(0, 36, (30, 4))
    tets = np.concatenate([tets, [[36, 37, 38, 39]], [[36, 38, 37, 0]]])  # flat; and one of either sign
    Xs = np.concatenate([X, [[0, 0, 1e-7]]])  # a sliver: quality about 2e-7
    tets_s = np.concatenate([tets, [[36, 37, 38, 40]]])
    p = rng.uniform(0.0, 0.2, tets_s.shape[0])
    f = rng.normal(size=(tets_s.shape[0], 3))
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    for pre, fib in ((None, None), (p, f)):
        want = T.rest_shape(Xs, tets_s, pre, fib, MIN_ELEMENT_QUALITY)
        for parallel_from in (1, 10**9):  # the thread pool's kernel and the calling thread's
            monkeypatch.setattr(elastic, "PARALLEL_MIN_TETS", parallel_from)
            got = rest_shape(Xs, tets_s, pre, fib)
            for g, w in zip(got, want):
                np.testing.assert_allclose(g, w, rtol=1e-10, atol=1e-12)
            assert got[1][-1] == 0.0 and got[1][-2] == 0.0 and np.all(got[0][-1] == 0.0)  # sliver, flat: no energy
    corners = Xs[tets_s]
    Tinv = np.zeros((len(tets_s), 3, 3))
    ok = corner_edge_inverses(corners, Tinv)
    D = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0]], 2)
    np.testing.assert_array_equal(ok, np.linalg.det(D) != 0)
    np.testing.assert_allclose(Tinv[ok], np.linalg.inv(D[ok]), rtol=1e-9, atol=1e-12)


def test_node_term_rows_match_the_twin():
    """The per-tet constants of a node update against NumPy's einsum: random rest shapes, one
    tet without volume (no 1 / 6V column), mixed Lame parameters."""
    from _twins_elastic import node_term_rows as twin

    from cutkit.relax._elastic_kernels import node_term_rows

    rng = np.random.default_rng(3)
    Dminv = rng.normal(size=(50, 3, 3))
    volume = rng.uniform(0.01, 2.0, 50)
    volume[7] = 0.0
    mu, lam = rng.uniform(1e-3, 1e-2, 50), rng.uniform(1e-2, 1e-1, 50)
    got = node_term_rows(Dminv, volume, mu, lam)
    np.testing.assert_allclose(got, twin(Dminv, volume, mu, lam), rtol=1e-14, atol=0.0)
    assert got[7].tolist() == [0.0] * 9


def test_copy_rows_matches_the_twin():
    """Rows copied into a fresh pool in another order (the rebase's layout): the kernel's slots are NumPy's."""
    from cutkit.relax import _adjacency_kernels as KA
    from cutkit.relax._elastic_kernels import Adjacency

    rng = np.random.default_rng(5)
    n = 15
    degree = rng.integers(0, 5, n).astype(np.int32)
    capacity = degree.astype(np.int64) + rng.integers(0, 3, n)
    start = np.concatenate([[0], np.cumsum(capacity)[:-1]]).astype(np.int64)
    pool = int(capacity.sum())
    slots = {"tets": rng.integers(0, 99, pool).astype(np.int32), "corner": rng.integers(0, 4, pool).astype(np.int8),
             "opposite": rng.integers(0, 99, (pool, 3)).astype(np.int32), "terms": rng.normal(size=(pool, 6))}
    nodes = rng.permutation(n)[:11].astype(np.int64)  # some rows are dropped
    new_cap = degree[nodes].astype(np.int64) + 2
    new_start = np.concatenate([[0], np.cumsum(new_cap)[:-1]]).astype(np.int64)
    size = int(new_cap.sum()) + 5
    want = T.copy_rows_twin(start, degree, slots, nodes, new_start, size)
    names = ("tets", "corner", "opposite", "terms")
    fresh = {k: np.zeros((size,) + slots[k].shape[1:], slots[k].dtype) for k in names}
    KA.copy_rows(Adjacency(start, degree, *(slots[k] for k in names)),
                 Adjacency(start, degree, *(fresh[k] for k in names)), nodes, new_start)
    for k in names:
        np.testing.assert_array_equal(fresh[k], want[k])


def test_make_room_matches_the_twin():
    """Rows moved to the pool's end for the slots new tets need: the kernel's starts, room and
    slots are NumPy's; a pool too small is left as it was and the end asked for is returned."""
    from cutkit.relax import _adjacency_kernels as KA
    from cutkit.relax._elastic_kernels import Adjacency

    rng = np.random.default_rng(2)
    n, used = 12, 0
    degree = rng.integers(0, 5, n).astype(np.int32)
    capacity = degree.astype(np.int64) + rng.integers(0, 3, n)
    start = np.concatenate([[0], np.cumsum(capacity)[:-1]]).astype(np.int64)
    used = int(capacity.sum())
    pool = used + 80
    slots = {"tets": rng.integers(0, 99, pool).astype(np.int32), "corner": rng.integers(0, 4, pool).astype(np.int8),
             "opposite": rng.integers(0, 99, (pool, 3)).astype(np.int32), "terms": rng.normal(size=(pool, 6))}
    for name in slots:
        slots[name][used:] = 0
    corners = rng.integers(0, n, 16).astype(np.int64)
    want = T.make_room_twin(start, degree, capacity, slots, corners, used, 8)
    adj = Adjacency(start.copy(), degree, *(slots[k].copy() for k in ("tets", "corner", "opposite", "terms")))
    cap = capacity.copy()
    end = KA.make_room(adj, cap, corners, used, 8, pool)
    assert end == want[3] and end > used
    np.testing.assert_array_equal(adj.start, want[0])
    np.testing.assert_array_equal(cap, want[1])
    for k, got in zip(("tets", "corner", "opposite", "terms"), adj[2:]):
        np.testing.assert_array_equal(got, want[2][k][:pool])
    # too small a pool: nothing moves, the end needed comes back
    adj2 = Adjacency(start.copy(), degree, *(slots[k].copy() for k in ("tets", "corner", "opposite", "terms")))
    cap2 = capacity.copy()
    assert KA.make_room(adj2, cap2, corners, used, 8, want[3] - 1) == -want[3] - 1
    np.testing.assert_array_equal(adj2.start, start)
    np.testing.assert_array_equal(cap2, capacity)


def test_rows_reserved_before_the_elements_are_the_rows_laid_out_after():
    # a rebase lays the rows out in sweep order before adding its elements (reserve_rows); the
    # pool must then hold what adding first and laying out afterwards (lay_out_rows) gives
    model = block(prestrain=0.05, shape=(4, 3, 2))
    built = build_element_model(model)
    fixed = np.zeros((model.n_points, 3), bool)
    fixed[::7] = True  # held nodes are not swept: their rows go after the colour classes
    mat = dict(mu=built.mu[:built.n_elements], lam=built.lam[:built.n_elements], density=np.full(model.n_tets, 1e-6))

    def fresh():
        em = elastic.ElementModel.empty(model.n_points, model.n_tets)
        em.fixed[:] = fixed
        em.colour[:] = built.colour
        return em

    after = fresh()
    after.add_elements(model.points, model.tets, mat["mu"], mat["lam"], mat["density"])
    after.lay_out_rows()
    before = fresh()
    before.reserve_rows(model.tets)
    before.add_elements(model.points, model.tets, mat["mu"], mat["lam"], mat["density"])
    assert before.adj_used == after.adj_used
    for name in ("adj_start", "adj_capacity", "adj_degree", "masses"):
        assert np.array_equal(getattr(before, name), getattr(after, name)), name
    used = after.adj_used
    for name in elastic.ADJACENCY_POOL:
        assert np.array_equal(getattr(before, name)[:used], getattr(after, name)[:used]), name
    assert all(np.array_equal(a, b) for a, b in zip(before.colour_classes(), after.colour_classes()))
    with pytest.raises(ValueError, match="without elements"):
        before.reserve_rows(model.tets)
    uncoloured = elastic.ElementModel.empty(model.n_points, model.n_tets)
    with pytest.raises(ValueError, match="coloured"):
        uncoloured.reserve_rows(model.tets)


def test_mass_shares_add_as_numpy_adds_them_in_order():
    """``add_mass_shares`` gives ``np.add.at``'s sums to the bit (the same additions in the same
    order), repeated corners and negative shares (a removal) included."""
    from cutkit.relax import _adjacency_kernels as KA

    rng = np.random.default_rng(3)
    tets = rng.integers(0, 40, size=(300, 4))
    share = rng.uniform(-1.0, 1.0, 300) * 10.0 ** rng.integers(-9, 3, 300)
    want = rng.uniform(0.0, 1.0, 40)
    got = want.copy()
    np.add.at(want, tets.ravel(), np.repeat(share, 4))
    KA.add_mass_shares(got, tets, share)
    np.testing.assert_array_equal(got, want)
