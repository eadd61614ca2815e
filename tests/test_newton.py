"""Projected Newton (cutkit.relax.newton): kernels against twins and finite differences, solves against
a reference minimiser written here (scipy's trust-region Newton on the energy), the barrier's invariant."""

import numpy as np
import pytest

import _twins_newton as T
from _tissues import with_cut_mesh
from _fem_reference import kuhn_box, trust_region_minimum
from _twins_elastic import deformation_gradients
from cutkit.cutting import cut_step
from cutkit.errors import InputError
from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel
from cutkit.relax import _newton_kernels as KN
from cutkit.relax.elastic import ElementState, build_element_model
from cutkit.relax.newton import PRECONDITIONERS, NewtonSolver, newton_static, newton_step, node_block_inverse
from cutkit.relax.vbd import elastic_energy, elastic_forces
from cutkit.relax.elastic_tissue import ElasticTissue

ROW = dict(label=1, name="m", E=30e3, poisson_ratio=0.45, density=1090.0, damping=8.0, F_enter=0.8,
           mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
           c_edge=1.0, c_shape=1.0)


def model_of(p, t, prestrain=0.0, fibre=(1.0, 0.0, 0.0), fixed=None):
    ps = Prestress(label=np.array([1], np.int32), fibre_direction=np.array([fibre]), prestrain=np.array([prestrain]))
    boundary = BoundaryConditions(fixed_nodes=np.zeros(0, np.int64) if fixed is None else np.flatnonzero(fixed))
    return TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW]), prestress=ps, boundary=boundary)


def arrays(em):
    m = em.n_elements
    return em.tets[:m], em.Dminv[:m], em.volume[:m], em.mu[:m], em.lam[:m]


@pytest.fixture
def deformed():
    """A block under random displacements with one tet crushed into the barrier band (J = 0.04)."""
    p, t = kuhn_box((3.0, 2.0, 2.0), (3, 2, 2))
    em = build_element_model(model_of(p, t, prestrain=0.05))
    x = p + np.random.default_rng(3).normal(scale=0.1, size=p.shape)
    q = em.tets[0]
    nrm = np.cross(x[q[2]] - x[q[1]], x[q[3]] - x[q[1]])
    nrm /= np.linalg.norm(nrm)
    J = np.linalg.det(deformation_gradients(x, em.tets[:1], em.Dminv[:1]))[0]
    x[q[0]] -= (1.0 - 0.04 / J) * np.dot(x[q[0]] - x[q[1]], nrm) * nrm  # J is affine in one corner
    return em, x


@pytest.mark.parametrize("project", [0, 1])
def test_element_terms_match_the_twin(deformed, project):
    em, x = deformed
    ids = np.arange(em.n_elements)
    g, H = np.zeros((ids.size, 12)), np.zeros((ids.size, 12, 12))
    KN.element_terms(x, em.elements, ids, project, g, H)
    gt, Ht = T.element_terms(x, *arrays(em), project)
    assert np.allclose(g, gt, rtol=1e-10, atol=1e-14)
    assert np.allclose(H, Ht, rtol=1e-9, atol=1e-12 * np.abs(Ht).max())
    J = np.linalg.det(deformation_gradients(x, *arrays(em)[:2]))
    assert J.min() == pytest.approx(0.04)  # the barrier term is in the comparison


def test_gradient_and_hessian_are_the_energy_derivatives(deformed):
    """Element gradients summed are -elastic_forces (checked against differences of elastic_energy in
    test_elastic); the exact Hessian is the central difference of the gradient, barrier tet included."""
    em, x = deformed
    n = em.n_nodes
    ids = np.arange(em.n_elements)
    g, H = np.zeros((ids.size, 12)), np.zeros((ids.size, 12, 12))
    KN.element_terms(x, em.elements, ids, 0, g, H)
    grad = np.zeros((n, 3))
    np.add.at(grad, em.tets[:em.n_elements].ravel(), g.reshape(-1, 3))
    assert np.allclose(grad, -elastic_forces(em, x), rtol=1e-9, atol=1e-15)
    h = 1e-5
    for i, c in [(int(em.tets[0, 0]), 2), (5, 0), (11, 1)]:
        e = [elastic_energy(em, np.where((np.arange(n) == i)[:, None] & (np.arange(3) == c), x + s * h, x))
             for s in (-1, 1)]
        assert (e[1] - e[0]) / (2 * h) == pytest.approx(grad[i, c], rel=1e-6, abs=1e-12)
    A = NewtonSolver(em, hessian="exact").matrix(x, np.ones((n, 3), bool), np.zeros(n), 0).toarray()
    fd = np.zeros((3 * n, 3 * n))
    for k in range(3 * n):
        xp, xm = x.copy(), x.copy()
        xp.ravel()[k] += h
        xm.ravel()[k] -= h
        fd[:, k] = -(elastic_forces(em, xp) - elastic_forces(em, xm)).ravel() / (2 * h)
    assert np.allclose(A, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_projected_hessian_is_semidefinite_and_exact_where_that_is(deformed):
    em, x = deformed
    ids = np.arange(em.n_elements)
    H0, H1 = np.zeros((ids.size, 12, 12)), np.zeros((ids.size, 12, 12))
    g = np.zeros((ids.size, 12))
    KN.element_terms(x, em.elements, ids, 0, g, H0)
    KN.element_terms(x, em.elements, ids, 1, g, H1)
    w1 = np.linalg.eigvalsh(H1)
    assert w1.min() > -1e-10 * np.abs(w1).max()
    psd = np.linalg.eigvalsh(H0).min(axis=1) > 0  # 12x12 of an element: 6 rigid zero modes at best
    assert np.allclose(H0[psd], H1[psd], atol=1e-9 * np.abs(H0).max())


@pytest.mark.parametrize("project", [0, 1])
def test_assembled_matrix_matches_the_twin(deformed, project):
    em, x = deformed
    n = em.n_nodes
    fixed = np.zeros((n, 3), bool)
    fixed[:4] = True
    fixed[7, 1] = True
    add = np.linspace(1.0, 2.0, n)
    A = NewtonSolver(em).matrix(x, ~fixed, add, project)
    assert np.all(np.diff(A.indices[A.indptr[3]:A.indptr[4]]) > 0)  # columns sorted in each row
    At = T.assembled(x, *arrays(em), project, fixed.ravel(), np.where(fixed, 0.0, np.repeat(add, 3).reshape(n, 3)
                                                                      ).ravel())
    assert np.allclose(A.toarray(), At, rtol=1e-9, atol=1e-12 * np.abs(At).max())


@pytest.mark.parametrize("project", [0, 1])
def test_elements_with_every_dof_held_are_left_out_of_the_assembly_and_the_matrix_is_the_same(deformed, project):
    """The elements none of whose dofs is free (the block's low layer held) write only rows and
    columns the constraint clears: assembled without them, the matrix is the same to the bit."""
    from cutkit.relax.newton import reaching_free_dofs

    em, x = deformed
    n = em.n_nodes
    free = np.ones((n, 3), bool)
    free[x[:, 2] < 1.2] = False  # the nodes at z = 0 and z = 1 (displaced by about 0.1 mm)
    free[np.flatnonzero(~free.any(axis=1))[0], 2] = True  # one of them free along z: its elements stay
    solver = NewtonSolver(em)
    el = solver._elements()
    left_out = (el.volume > 0) & (reaching_free_dofs(el, free).volume == 0)
    assert 0 < np.count_nonzero(left_out) < np.count_nonzero(el.volume > 0)
    assert np.all(~free[el.tets[left_out]].any(axis=(1, 2)))  # none of their dofs is free
    add = np.linspace(1.0, 2.0, n)
    A = solver.matrix(x, free, add, project)
    pat = solver.pattern()
    whole = np.empty(pat.indices.shape[0])
    KN.assemble_hessian(x, el, pat, project, whole)
    B = solver._constrained(whole, free, add)
    assert np.array_equal(A.data, B.data)


def test_step_bound_matches_the_twin(deformed):
    em, x = deformed
    rng = np.random.default_rng(5)
    for scale in (0.05, 0.3, 1.0):
        d = rng.normal(scale=scale, size=x.shape)
        a = KN.step_bound(x, d, em.elements, 1.0)
        at = T.step_bound(x, d, em.tets[:em.n_elements], em.volume[:em.n_elements], 1.0)
        assert a == pytest.approx(at, rel=1e-9)
        if a <= 1.0:  # just before the bound every upright element is upright, just after one is not
            J = np.linalg.det(deformation_gradients(x + (1 - 1e-9) * a * d, *arrays(em)[:2]))
            assert J.min() > 0 and np.linalg.det(deformation_gradients(x + (1 + 1e-6) * a * d,
                                                                     *arrays(em)[:2])).min() < 0


# ---------------------------------------------------------------- solves against a reference

def reference_minimum(em, x0, f, free):
    """The static minimiser of W - f.x by scipy's trust-region Newton (_fem_reference)."""
    return trust_region_minimum(em, x0, f, free, gtol=1e-11, maxiter=500)


def cantilever():
    p, t = kuhn_box((20.0, 3.0, 3.0), (10, 2, 2))
    em = build_element_model(model_of(p, t))
    em.fixed[p[:, 0] == 0] = True
    em._classes = None
    f = np.zeros_like(p)
    tip = p[:, 0] == 20.0
    f[tip, 2] = -0.004 / tip.sum()  # N: the linear answer would be 55 mm down, past the bar's length
    return p, em, f, tip


@pytest.mark.slow
def test_static_newton_matches_the_reference_on_a_cantilever_by_default():
    p, em, f, tip = cantilever()
    x = p.copy()
    info = newton_static(em, x, f_ext=f)  # defaults
    assert info.converged and info.residual <= max(1e-6 * info.initial_residual, 1e-7)
    assert -x[tip, 2].mean() > 0.3 * 20.0  # large deflection
    ref = reference_minimum(em, p.copy(), f, ~em.fixed)
    u, ur = x - p, ref - p
    assert np.linalg.norm(u - ur) <= 1e-4 * np.linalg.norm(ur)


def cut_slab():
    """A prestressed slab (fibres across the cut, base held) cut half way down by a blade."""
    p, t = kuhn_box((6.0, 3.0, 3.0), (6, 3, 3))
    model = model_of(p, t, prestrain=0.1, fibre=(0.0, 1.0, 0.0), fixed=p[:, 2] == 0)
    tis = with_cut_mesh(ElasticTissue(model, step_s=0.02), 1.6)
    for xb in np.linspace(-0.5, 6.5, 15):
        tis.apply_cut(cut_step(tis.cm, [xb, 1.37, 3.5], [0.0, 0.0, 1.0]))
    return tis


def test_static_newton_matches_the_reference_on_a_cut_slab():
    tis = cut_slab()
    em = tis.em
    assert em.n_nodes > tis.cm.n_orig_points  # the cut made nodes
    x0 = tis.positions.copy()
    free = ~em.fixed & (em.adj_degree > 0)[:, None]
    x = x0.copy()
    info = newton_static(em, x, rtol=1e-10, atol=0.0)
    assert info.converged
    ref = reference_minimum(em, x0, np.zeros_like(x0), free)
    assert np.linalg.norm(x - ref) <= 1e-4 * np.linalg.norm(ref - tis.rest_positions)
    # the cut opened: its two sides moved apart across the fibres
    assert np.linalg.norm(x - tis.rest_positions, axis=1).max() > 0.05


def test_implicit_steps_converge_on_the_true_residual():
    p, em, f, tip = cantilever()
    st = ElementState(p.copy(), np.zeros_like(p))
    solver = NewtonSolver(em)
    h, m = 0.02, em.masses[:, None]
    for _ in range(5):
        x0, v0 = st.positions.copy(), st.velocities.copy()
        info = newton_step(em, st, h, f, atol=1e-9, solver=solver)
        assert info.converged
        x = st.positions  # the residual of backward Euler, recomputed here
        r = elastic_forces(em, x) + f - m / h ** 2 * (x - x0 - h * v0) - em.damping[:, None] * m / h * (x - x0)
        assert np.linalg.norm(r[~em.fixed]) == pytest.approx(info.residual, rel=1e-6, abs=1e-15)
        assert info.residual <= 1e-9
    assert solver.counts["pattern_builds"] == 1  # the pattern is kept between steps


def test_a_solve_that_stops_early_says_so_with_its_residual():
    p, em, f, tip = cantilever()
    x = p.copy()
    info = newton_static(em, x, f_ext=f, rtol=1e-12, atol=0.0, max_iterations=2)
    assert not info.converged and info.iterations == 2
    r = (elastic_forces(em, x) + f)[~em.fixed]
    assert info.residual == pytest.approx(np.linalg.norm(r), rel=1e-12)
    assert info.residual > 1e-12 * info.initial_residual


@pytest.mark.parametrize("hessian", ["auto", "projected"])
def test_a_crushing_point_load_never_inverts_a_tet(hessian, monkeypatch):
    """A node pushed into the held base by ten times E over a face: no iterate of any step inverts a tet."""
    import cutkit.relax.newton as N

    p, t = kuhn_box((3.0, 3.0, 2.0), (3, 3, 2))
    em = build_element_model(model_of(p, t))
    em.fixed[p[:, 2] == 0] = True
    top = int(np.flatnonzero(p[:, 2] == 2.0)[4])
    f = np.zeros_like(p)
    f[top, 2] = -0.3
    lowest = []
    search = N.line_search

    def watched(problem, x, d, r, res, g0=None):
        out = search(problem, x, d, r, res, g0)
        lowest.append(np.linalg.det(deformation_gradients(x, *arrays(em)[:2])).min())
        return out

    monkeypatch.setattr(N, "line_search", watched)
    st = ElementState(p.copy(), np.zeros_like(p))
    solver = NewtonSolver(em, hessian=hessian)
    for _ in range(20):
        newton_step(em, st, 0.01, f, atol=1e-9, solver=solver)
    assert min(lowest) > 0.0
    assert st.positions[top, 2] < 0.5 * p[top, 2]  # the load did squash the block


def test_the_line_search_says_when_the_inversion_bound_cut_its_first_trial_short():
    """One tet whose apex a direction drives through its base at step length 1/2: the first trial is
    0.9 of that (cut short, and the tet stays upright); a direction a tenth as long is not cut."""
    import cutkit.relax.newton as N

    p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([[0, 1, 2, 3]])
    em = build_element_model(model_of(p, t))
    free = np.ones_like(p, bool)
    terms = N._free_terms(em, p, None, None, None)
    problem = N._Potential(em, terms, free, NewtonSolver(em)._elements())
    for scale, short in ((1.0, True), (0.1, False)):
        x = p.copy()
        d = np.zeros_like(p)
        d[3, 2] = -2.0 * scale  # apex to z = 0 at a = 1/2 (scale 1)
        r = d.copy()  # a descent direction's residual: slope > 0
        moved, _, _, cut_short = N.line_search(problem, x, d, r, float(np.linalg.norm(r)))
        assert cut_short is short
        assert np.linalg.det(deformation_gradients(x, em.tets[:1], em.Dminv[:1]))[0] > 0.0


def test_an_iteration_after_a_step_cut_short_solves_its_system_loosely_and_the_steps_still_converge(monkeypatch):
    """The crushing load below on the conjugate-gradient path: every linear solve that follows a line
    search the inversion bound cut short runs to at least BOUNDED_CG_RTOL, others tighter (the usual
    tolerance); every step still ends on the true residual's tolerance with no tet inverted."""
    import cutkit.relax.newton as N

    p, t = kuhn_box((3.0, 3.0, 2.0), (3, 3, 2))
    em = build_element_model(model_of(p, t))
    em.fixed[p[:, 2] == 0] = True
    f = np.zeros_like(p)
    f[int(np.flatnonzero(p[:, 2] == 2.0)[4]), 2] = -0.3
    events, search, solve_linear = [], N.line_search, NewtonSolver._solve_linear

    def watched_search(*args, **kw):
        out = search(*args, **kw)
        events.append(("search", out[3]))
        return out

    def watched_solve(self, A, r, x, free, rtol, halt=None):
        events.append(("solve", rtol))
        return solve_linear(self, A, r, x, free, rtol, halt)

    monkeypatch.setattr(N, "line_search", watched_search)
    monkeypatch.setattr(NewtonSolver, "_solve_linear", watched_solve)
    st = ElementState(p.copy(), np.zeros_like(p))
    solver = NewtonSolver(em, linear="cg", hessian="projected")
    for _ in range(10):
        events.append(("step", None))
        assert newton_step(em, st, 0.01, f, atol=1e-6, solver=solver).converged
        assert np.linalg.det(deformation_gradients(st.positions, *arrays(em)[:2])).min() > 0.0
    after_short = [b[1] for a, b in zip(events, events[1:]) if a == ("search", True) and b[0] == "solve"]
    after_long = [b[1] for a, b in zip(events, events[1:]) if a == ("search", False) and b[0] == "solve"]
    assert after_short and min(after_short) >= N.BOUNDED_CG_RTOL
    assert after_long and min(after_long) < N.BOUNDED_CG_RTOL  # the rule is selective


def test_no_oversolving_stops_each_linear_solve_at_its_share_of_the_tolerance(monkeypatch):
    """NewtonSolver's ``no_oversolve``: an iteration from residual res (the true one, written here)
    solves its system to no_oversolve * atol / res where that is looser than cg_rtol (never looser
    than CG_RTOL_MAX); a larger factor solves more loosely and the step still ends within atol by the
    residual written here.  A factor outside (0, 1] is refused by name."""
    import cutkit.relax.newton as N

    p, em, f, tip = cantilever()
    h, seen = 0.02, []
    atol = 1e-4 * float(np.linalg.norm(_step_residual(em, p, p, h, f)))
    solve_linear = NewtonSolver._solve_linear

    def watched(self, A, r, x, free, rtol, halt=None):
        res = float(np.linalg.norm(_step_residual(em, x, p, h, f)))
        seen.append((self.no_oversolve, rtol, min(N.CG_RTOL_MAX, max(self.cg_rtol, self.no_oversolve * atol / res))))
        return solve_linear(self, A, r, x, free, rtol, halt)

    monkeypatch.setattr(NewtonSolver, "_solve_linear", watched)
    for factor in (0.5, 1.0):
        st = ElementState(p.copy(), np.zeros_like(p))
        solver = NewtonSolver(em, linear="cg", cg_rtol=1e-3, no_oversolve=factor)
        assert newton_step(em, st, h, f, atol=atol, max_iterations=30, solver=solver).converged
        assert float(np.linalg.norm(_step_residual(em, st.positions, p, h, f))) <= atol
    for factor, rtol, want in seen:
        assert rtol == pytest.approx(want, rel=1e-6)
    last = {factor: rtol for factor, rtol, _ in seen}
    assert last[1.0] > 1e-3 and last[0.5] > 1e-3  # the last solve of each was loosened ...
    assert last[1.0] > last[0.5]  # ... the more so by the larger factor
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(InputError, match=r"no_oversolve must be in \(0, 1\]"):
            NewtonSolver(em, no_oversolve=bad)


@pytest.mark.parametrize("preconditioner", PRECONDITIONERS)
def test_the_cg_solves_reach_the_same_static_answer(preconditioner):
    """Preconditioned CG (what models above CHOLESKY_MAX_DOFS use) against the factorisation."""
    p, em, f, tip = cantilever()
    f = 0.25 * f
    x_chol, x_cg = p.copy(), p.copy()
    assert newton_static(em, x_chol, f_ext=f, rtol=1e-10, atol=0.0, solver=NewtonSolver(em, linear="cholesky")).converged
    cg = NewtonSolver(em, linear="cg", preconditioner=preconditioner)
    info = newton_static(em, x_cg, f_ext=f, rtol=1e-10, atol=0.0, max_iterations=200, solver=cg)
    assert info.converged and cg.counts["cg_iterations"] > 0 and cg.counts["factorisations"] == 0
    assert np.abs(x_cg - x_chol).max() <= 1e-6 * np.abs(x_chol - p).max()


def test_a_looser_inner_tolerance_reaches_the_same_answer_with_fewer_cg_iterations_a_solve():
    """cg_rtol (inexact Newton, the hybrid's resting steps take 0.1) changes the work of each linear
    solve, not where the outer iterations stop: the same static answer as the factorisation's."""
    p, em, f, tip = cantilever()
    f = 0.25 * f
    x_chol = p.copy()
    assert newton_static(em, x_chol, f_ext=f, rtol=1e-10, atol=0.0, solver=NewtonSolver(em, linear="cholesky")).converged
    per_solve = {}
    for rtol in (1e-2, 0.1):
        x = p.copy()
        cg = NewtonSolver(em, linear="cg", cg_rtol=rtol)
        info = newton_static(em, x, f_ext=f, rtol=1e-10, atol=0.0, max_iterations=200, solver=cg)
        assert info.converged and np.abs(x - x_chol).max() <= 1e-6 * np.abs(x_chol - p).max()
        per_solve[rtol] = cg.counts["cg_iterations"] / info.iterations
    assert per_solve[0.1] < per_solve[1e-2]
    for bad in (0.0, 1.0, float("nan")):
        with pytest.raises(InputError, match="cg_rtol must be in"):
            NewtonSolver(em, cg_rtol=bad)


class FlagInCG(NewtonSolver):
    """A solver whose stop flag ((1,) int64) is set as its ``solve``-th conjugate-gradient solve
    starts (a cut that starts waiting while that solve runs); the kernel reads it there."""

    def __init__(self, em, flag, solve):
        super().__init__(em, linear="cg")
        self.flag, self.solve_at, self.solves = flag, solve, 0

    def _block_cg(self, A, r, rtol, halt=None, x=None, free=None):
        self.solves += 1
        if self.solves == self.solve_at:
            self.flag[0] = 1
        return super()._block_cg(A, r, rtol, halt, x, free)


def test_a_waiting_cut_stops_the_conjugate_gradients_and_the_iteration_is_abandoned():
    """The stop flag is read inside the conjugate gradients too: set while the first Newton
    iteration's system is solved, the step is not taken (state unchanged); while the second's, the
    step ends at the first iterate, exactly where a step of one iteration ends."""
    p, em, f, tip = cantilever()
    f = 0.25 * f

    def step(max_iterations, solver, stop=None):
        st = ElementState(p.copy(), np.zeros_like(p))
        info = newton_step(em, st, 0.02, f, atol=0.0, max_iterations=max_iterations, solver=solver, stop=stop)
        return info, st

    _, one = step(1, NewtonSolver(em, linear="cg"))
    flag = np.zeros(1, np.int64)
    info, st = step(5, FlagInCG(em, flag, 1), flag)
    assert not info.taken and info.iterations == 0 and np.array_equal(st.positions, p) and st.time == 0.0
    flag = np.zeros(1, np.int64)
    solver = FlagInCG(em, flag, 2)
    info, st = step(5, solver, flag)
    assert info.taken and info.iterations == 1 and not info.converged
    np.testing.assert_array_equal(st.positions, one.positions)


def test_a_waiting_cut_stops_the_assembly_and_the_resting_sweeps():
    """The flag is read by the pattern's build, between the assembly's chunks of elements and by a
    resting step's whole-model sweeps: up, no pattern is kept, no matrix is made (None) and a resting
    step moves nothing and takes no time; down, the matrix is the one made without a flag."""
    from cutkit.relax.newton import rest_step

    p, em, f, tip = cantilever()
    solver = NewtonSolver(em)
    free, add = np.ones((em.n_nodes, 3), bool), np.ones(em.n_nodes)
    up = np.ones(1, np.int64)
    assert solver.pattern(up) is None and solver.counts["pattern_builds"] == 0
    assert solver.matrix(p, free, add, 1, up) is None and solver.counts["pattern_builds"] == 0
    assert solver.pattern() is not None and solver.counts["pattern_builds"] == 1
    assert solver.matrix(p, free, add, 1, up) is None  # the pattern kept, the assembly stopped
    A, B = solver.matrix(p, free, add, 1), solver.matrix(p, free, add, 1, np.zeros(1, np.int64))
    assert np.array_equal(A.data, B.data) and np.array_equal(A.indices, B.indices)
    st = ElementState(p.copy(), np.zeros_like(p))
    info, swept = rest_step(em, st, 0.02, f, atol=0.0, sweeps=3, max_iterations=2, solver=NewtonSolver(em),
                            stop=np.ones(1, np.int64))
    assert not info.taken and swept == 0 and np.array_equal(st.positions, p) and st.time == 0.0


def test_a_solve_with_a_cut_already_waiting_evaluates_nothing(monkeypatch):
    """Raised before the solve begins, the flag ends it before its first residual (a pass over every
    element that the waiting cut would wait for): not taken, nothing moved, no residual evaluated."""
    from cutkit.relax import newton as N

    p, em, f, tip = cantilever()
    calls = []
    residual = N._Potential.residual
    monkeypatch.setattr(N._Potential, "residual", lambda self, x: calls.append(1) or residual(self, x))
    st = ElementState(p.copy(), np.zeros_like(p))
    info = N.newton_step(em, st, 0.02, f, atol=0.0, max_iterations=2, solver=NewtonSolver(em),
                         stop=np.ones(1, np.int64))
    assert not info.taken and calls == [] and np.array_equal(st.positions, p) and st.time == 0.0
    info = N.newton_step(em, st, 0.02, f, atol=0.0, max_iterations=1, solver=NewtonSolver(em),
                         stop=np.zeros(1, np.int64))
    assert info.taken and len(calls) >= 2 and st.time == 0.02  # down: the step as ever


def _step_residual(em, x, x0, h, f):
    """(n, 3) N: the backward Euler residual at x of a step of h s from x0 at rest, written here
    (elastic forces and load less inertia and damping, 0 at held dofs)."""
    m = em.masses[:, None]
    r = elastic_forces(em, x) + f - m / (h * h) * (x - x0) - em.damping[:, None] * m / h * (x - x0)
    r[em.fixed] = 0.0
    return r


def test_a_resting_step_sweeps_between_its_newton_iterations_and_ends_on_the_true_residual():
    """rest_step's smoothing: sweeps after a Newton iteration that leaves the step out of balance.
    With and without them the step ends within atol by the residual written here, at the same
    positions (to what atol leaves), and the sweeps spare Newton iterations, never add one."""
    from cutkit.relax.newton import rest_step

    p, em, f, tip = cantilever()
    h = 0.02
    atol = 1e-7 * float(np.linalg.norm(_step_residual(em, p, p, h, f)))
    runs = {}
    for smoothing in (0, 5):
        st = ElementState(p.copy(), np.zeros_like(p))
        info, swept = rest_step(em, st, h, f, atol=atol, sweeps=0, max_iterations=30, solver=NewtonSolver(em),
                                smoothing=smoothing)
        true = float(np.linalg.norm(_step_residual(em, st.positions, p, h, f)))
        assert info.converged and true <= atol and true == pytest.approx(info.residual, rel=1e-6)
        np.testing.assert_allclose(st.velocities, (st.positions - p) / h)
        runs[smoothing] = (st.positions, info.iterations, swept)
    assert runs[0][2] == 0 and runs[5][2] > 0
    assert runs[5][1] < runs[0][1]
    moved = float(np.abs(runs[0][0] - p).max())
    assert moved > 1.0 and np.abs(runs[5][0] - runs[0][0]).max() <= 1e-6 * moved


def test_a_smoother_that_moves_the_iterate_never_hides_the_residual_it_leaves():
    """NewtonSolver.solve's smoother is called only while the residual is above atol, and the
    residual the solve reports is the one at the positions it ends at (evaluated afresh after the
    smoother), not the one the last Newton iteration left."""
    import cutkit.relax.newton as N

    p, em, f, tip = cantilever()
    h = 0.02
    terms = N._free_terms(em, p, h, f, None, p.copy())
    free = ~em.fixed
    calls = []

    def push(x):  # a bad smoother: it moves every free node 1 um along x
        calls.append(float(np.linalg.norm(_step_residual(em, x, p, h, f))))
        x[free[:, 0], 0] += 1e-3
        return True

    x = p.copy()
    info = NewtonSolver(em).solve(x, terms, atol=1e-12, max_iterations=3, smoother=push)
    assert len(calls) == info.iterations == 3 and not info.converged
    assert info.residual == pytest.approx(float(np.linalg.norm(_step_residual(em, x, p, h, f))), rel=1e-9)
    x = p.copy()
    loose = 10.0 * float(np.linalg.norm(_step_residual(em, p, p, h, f)))
    calls.clear()
    assert NewtonSolver(em).solve(x, terms, atol=loose, smoother=push).converged and calls == []


def _held_matrix(em, x):
    """The projected Newton matrix of (em, x) with a few held dofs (scipy CSR), and its solver."""
    n = em.n_nodes
    fixed = np.zeros((n, 3), bool)
    fixed[:2] = True
    fixed[7, 1] = True
    solver = NewtonSolver(em)
    return solver.matrix(x, ~fixed, np.linspace(1.0, 2.0, n), 1), solver


def _block_system(em, x):
    """A Newton matrix of (em, x) with held dofs (scipy CSR), and its block form and inverse
    diagonal blocks (:mod:`cutkit.relax._block_cg_kernels`)."""
    from cutkit.relax.newton import block_system

    A, solver = _held_matrix(em, x)
    blocks, inv = block_system(A, solver.pattern())
    assert inv is not None
    return A, blocks, inv, solver


def test_block_form_products_equal_the_scalar_matrix(deformed):
    """The symmetric block form (upper blocks used twice) multiplies like scipy's CSR of the same
    matrix, and its inverse diagonal blocks are node_block_inverse's."""
    from cutkit.relax import _block_cg_kernels as KB

    em, x = deformed
    A, blocks, inv, solver = _block_system(em, x)
    p = np.random.default_rng(5).normal(size=(em.n_nodes, 3))
    y = np.empty_like(p)
    KB.block_product(blocks, p, y)
    np.testing.assert_allclose(y.ravel(), A @ p.ravel(), rtol=1e-12, atol=1e-12 * np.abs(A @ p.ravel()).max())
    M = node_block_inverse(A, solver.pattern())
    np.testing.assert_allclose(M @ p.ravel(), np.einsum("iab,ib->ia", inv, p).ravel(), rtol=1e-10,
                               atol=1e-12 * np.abs(M @ p.ravel()).max())


def test_the_row_parallel_product_and_cg_are_the_same_bits_as_the_scatter_on_any_thread_count(deformed):
    """block_product_rows adds each row's terms in block_product's order: the same bits; block_pcg
    with either product, on one thread or two, gives the same iterations and solution to the bit."""
    import numba

    from cutkit.relax import _block_cg_kernels as KB

    em, x = deformed
    A, blocks, inv, solver = _block_system(em, x)
    n = em.n_nodes
    rng = np.random.default_rng(11)
    p = rng.normal(size=(n, 3))
    y, z = np.empty_like(p), np.empty_like(p)
    KB.block_product(blocks, p, y)
    KB.block_product_rows(blocks, p, z)
    assert np.array_equal(y, z) and np.abs(y).max() > 0
    b = rng.normal(size=(n, 3))
    runs = []
    before = numba.get_num_threads()
    try:
        for threads in sorted({1, min(2, numba.config.NUMBA_NUM_THREADS)}):
            numba.set_num_threads(threads)
            for rows in (False, True):
                d = np.empty((n, 3))
                runs.append((KB.block_pcg(blocks, inv, b, 1e-10, 500, np.zeros(1, np.int64), d, rows), d))
    finally:
        numba.set_num_threads(before)
    (status, its), d0 = runs[0]
    assert status == KB.CG_DONE and 0 < its < 500
    for out, d in runs[1:]:
        assert out == (status, its) and np.array_equal(d, d0)


def test_block_cg_equals_the_scalar_twin_and_reads_its_halt_flag(deformed):
    """block_pcg against pcg (NumPy, scipy's products, the same preconditioner): the same
    iterations and solution to rounding; with its flag set it makes no iteration and says so."""
    from cutkit.relax import _block_cg_kernels as KB
    from cutkit.relax.newton import block_system, pcg

    em, x = deformed
    A, blocks, inv, solver = _block_system(em, x)
    n = em.n_nodes
    b = np.random.default_rng(3).normal(size=(n, 3))
    b[:2] = 0.0
    b[7, 1] = 0.0
    d = np.empty((n, 3))
    assert KB.block_pcg(blocks, inv, b, 1e-8, 500, np.ones(1, np.int64), d, False) == (KB.CG_HALTED, 0)
    status, its = KB.block_pcg(blocks, inv, b, 1e-8, 500, np.zeros(1, np.int64), d, False)
    twin, twin_its = pcg(A, b.ravel(), node_block_inverse(A, solver.pattern()), 1e-8, 500)
    assert status == KB.CG_DONE and its == twin_its and 0 < its < 500
    np.testing.assert_allclose(d.ravel(), twin, rtol=1e-8, atol=1e-10 * np.abs(twin).max())
    assert np.linalg.norm(b.ravel() - A @ d.ravel()) <= 1.01e-8 * np.linalg.norm(b)
    A.data[solver.pattern().diagonal[3 * 5 + 1]] *= -1.0  # an indefinite diagonal block
    assert block_system(A, solver.pattern())[1] is None


def test_block_jacobi_inverts_each_nodes_diagonal_block(deformed):
    """node_block_inverse against the 3 x 3 diagonal blocks of the dense matrix, inverted one by one."""
    em, x = deformed
    n = em.n_nodes
    A, solver = _held_matrix(em, x)
    M = node_block_inverse(A, solver.pattern()).toarray()
    dense = A.toarray()
    expected = np.zeros_like(dense)
    for i in range(n):
        b = slice(3 * i, 3 * i + 3)
        expected[b, b] = np.linalg.inv(dense[b, b])
    assert np.allclose(M, expected, rtol=1e-10, atol=1e-14 * np.abs(expected).max())
    A.data[solver.pattern().diagonal[3 * 5 + 1]] *= -1.0  # one indefinite block: no preconditioner
    assert node_block_inverse(A, solver.pattern()) is None


def test_an_unknown_preconditioner_is_refused(deformed):
    em, _ = deformed
    with pytest.raises(InputError, match="preconditioner must be one of"):
        NewtonSolver(em, preconditioner="ilu")


def test_a_static_solve_is_the_same_to_the_bit_whatever_blas_threads_the_process_has():
    """Above 10,000 dofs the solve runs conjugate gradients, whose dot products and norms a
    threaded BLAS sums in an order set by its thread count; the solver runs BLAS on one thread
    (cutkit.threads.one_blas_thread), so a 2-core and a 1-core process give the same iterates."""
    from threadpoolctl import threadpool_limits

    p, t = kuhn_box((20.0, 14.0, 14.0), (20, 14, 14))  # 4,725 nodes: 13,500 free dofs, solved by CG
    runs = []
    for blas_threads in (2, 1):
        em = build_element_model(model_of(p, t, prestrain=0.1))
        em.fixed[p[:, 2] == 0] = True
        x = p.copy()
        with threadpool_limits(limits=blas_threads, user_api="blas"):
            info = newton_static(em, x, rtol=1e-8)
        runs.append((x, info.iterations))
    assert runs[0][1] == runs[1][1] > 0
    assert np.array_equal(runs[0][0], runs[1][0])


def test_the_assembly_is_the_same_to_the_bit_at_any_thread_count_and_chunk(monkeypatch):
    """The Hessians are computed in parallel blocks, a chunk at a time, and added in element order:
    one thread or two, one chunk or many, the matrix is the same to the bit, and it equals the
    element Hessians (element_terms) added one by one in a dense matrix."""
    import numba
    import scipy.sparse as sp

    from cutkit.relax import _elastic_kernels as KE

    p, t = kuhn_box((3.0, 2.0, 2.0), (4, 3, 3))
    em = build_element_model(model_of(p, t, prestrain=0.05))
    x = p + np.random.default_rng(4).normal(scale=0.05, size=p.shape)
    solver = NewtonSolver(em)
    m = em.n_elements
    pat, el = solver.pattern(), KE.Elements(em.tets[:m], em.Dminv[:m], em.volume[:m], em.mu[:m], em.lam[:m])
    out = []
    for threads, chunk in ((1, KN.ASSEMBLY_CHUNK), (min(2, numba.config.NUMBA_NUM_THREADS), 7)):
        numba.set_num_threads(threads)
        monkeypatch.setattr(KN, "ASSEMBLY_CHUNK", chunk)
        data = np.empty(pat.indices.shape[0])
        KN.assemble_hessian(x, el, pat, KN.CLAMP, data)
        out.append(data)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(out[0], out[1])
    grads, hessians = np.empty((m, 12)), np.empty((m, 12, 12))
    KN.element_terms(x, el, np.arange(m), KN.CLAMP, grads, hessians)
    dense = np.zeros((3 * em.n_nodes, 3 * em.n_nodes))
    for e in range(m):
        dofs = (3 * el.tets[e][:, None] + np.arange(3)).ravel()
        dense[np.ix_(dofs, dofs)] += hessians[e]
    A = sp.csr_matrix((out[0], pat.indices, pat.indptr), shape=dense.shape).toarray()
    np.testing.assert_allclose(A, dense, rtol=1e-12, atol=1e-12 * np.abs(dense).max())


def test_the_warm_up_runs_the_conjugate_gradients_kernel():
    """The run side's warm-up (before a live session's clock starts) solves by the block CG kernel too:
    the warm-up slab is small enough to factorise, a knee's resting steps are not."""
    from cutkit.simulate.warmup import warm_up_conjugate_gradients

    assert warm_up_conjugate_gradients() > 0


def test_every_kernel_that_takes_the_stop_flag_reads_it_atomically():
    """A live cut raises the flag from another thread; a plain load may be read once and kept for
    the whole kernel (LLVM assumes no other thread writes without atomics: the pattern build ran
    55 ms past a raised flag).  Every kernel that takes the flag reads it by an atomic load, in its
    serial part and in its parallel loops' bodies."""
    import numba

    from cutkit.relax import _block_cg_kernels as KB
    from cutkit.relax import _elastic_kernels as KE
    from cutkit.relax.newton import rest_step
    from cutkit.relax.vbd import kept_volume_ratios

    p, em, f, tip = cantilever()
    solver = NewtonSolver(em, linear="cg", preconditioner="block_jacobi")
    st = ElementState(p.copy(), np.zeros_like(p))
    rest_step(em, st, 0.02, f, atol=1e-9, sweeps=1, max_iterations=1, solver=solver, stop=np.zeros(1, np.int64))
    m = em.tets.shape[0]
    kept_volume_ratios(em, st.positions, np.full((em.n_nodes, 3), np.nan), np.empty(0, np.int64), np.ones(m, bool),
                       np.ones(m), 0.5, np.zeros(1, np.int64))
    kernels = {"node_neighbours": KN.node_neighbours, "element_blocks": KN.element_blocks,
               "vbd_sweep": KE.vbd_sweep, "refresh_volume_ratios": KE.refresh_volume_ratios,
               "block_pcg": KB.block_pcg}
    for name, kernel in kernels.items():
        assert kernel.signatures, name
        # cached code has no IR to read: compile the same function afresh, with the same options
        options = {k: v for k, v in kernel.targetoptions.items() if k not in ("cache", "nopython")}
        fresh = numba.njit(**options)(kernel.py_func)
        for sig in kernel.signatures:
            fresh.compile(sig)
            assert "load atomic" in fresh.inspect_llvm(sig), name
