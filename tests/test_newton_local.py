"""Local Newton (NewtonSolver's region_rings): each iteration solves where the model is out of balance,
yet a step ends only on the whole model's residual, at the state a whole-model minimiser written here
reaches."""

import numpy as np
import pytest

from _fem_reference import kuhn_box, trust_region_minimum
from _twins_elastic import deformation_gradients
from cutkit.errors import InputError
from cutkit.model.tetmodel import Materials, TetModel
from cutkit.relax.elastic import ElementState, build_element_model
from cutkit.relax.newton import NewtonSolver, newton_region, newton_step
from cutkit.relax.vbd import elastic_forces

ROW = dict(label=1, name="m", E=30e3, poisson_ratio=0.45, density=1090.0, damping=8.0, F_enter=0.8,
           mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
           c_edge=1.0, c_shape=1.0)
H = 0.02


def block():
    """A bar held at its base, at rest, and a point load on one top corner."""
    p, t = kuhn_box((8.0, 2.0, 2.0), (8, 2, 2))
    em = build_element_model(TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW])))
    em.fixed[p[:, 2] == 0] = True
    em._classes = None
    f = np.zeros_like(p)
    corner = int(np.argmax(p[:, 0] + p[:, 1] + p[:, 2]))
    f[corner] = [0.0, 0.0, -0.01]  # N: a dent of about a tenth of a mm
    return p, em, f


def reference_step(em, x0, f, h):
    """One backward Euler step from rest, minimised over every free dof at once by scipy's
    trust-region Newton (_fem_reference): no region, no solver under test."""
    m = em.masses[:, None]
    return trust_region_minimum(em, x0, f, ~em.fixed, ki=m / h ** 2, kd=em.damping[:, None] * m / h,
                                gtol=1e-12, maxiter=200)


def test_a_local_newton_step_reaches_the_whole_models_step():
    p, em, f = block()
    st = ElementState(p.copy(), np.zeros_like(p))
    solver = NewtonSolver(em, region_rings=1)
    atol = 1e-10 * np.linalg.norm(f)
    info = newton_step(em, st, H, f, atol=atol, solver=solver)
    # converged on the residual of the whole model, recomputed here
    x, m = st.positions, em.masses[:, None]
    r = elastic_forces(em, x) + f - (m / H ** 2 + em.damping[:, None] * m / H) * (x - p)
    assert info.converged and np.linalg.norm(r[~em.fixed]) == pytest.approx(info.residual, rel=1e-6, abs=1e-14)
    assert info.residual <= atol
    # the first iterations solved a region, not the whole bar
    n_free = np.count_nonzero(~em.fixed)
    assert solver.counts["local_iterations"] >= 1
    assert 0 < min(d for d in solver.region_log if d) < n_free / 4
    ref = reference_step(em, p.copy(), f, H)
    assert np.linalg.norm(x - ref) <= 1e-6 * np.linalg.norm(ref - p)
    assert np.linalg.det(deformation_gradients(x, em.tets[:em.n_elements], em.Dminv[:em.n_elements])).min() > 0


def test_a_local_solve_stops_only_on_the_whole_models_residual():
    """A load far from the region's seed: a residual spread thin over the whole bar keeps the solve
    going (widening, or whole-model iterations) until all of it is below the tolerance."""
    p, em, f = block()
    f[:] = 0.0
    f[~em.fixed[:, 0], 2] = -1e-3  # a little weight on every free node
    st = ElementState(p.copy(), np.zeros_like(p))
    solver = NewtonSolver(em, region_rings=0)
    info = newton_step(em, st, H, f, atol=1e-9, solver=solver)
    x, m = st.positions, em.masses[:, None]
    r = elastic_forces(em, x) + f - (m / H ** 2 + em.damping[:, None] * m / H) * (x - p)
    assert info.converged and np.linalg.norm(r[~em.fixed]) <= 1e-9


def test_the_region_leaves_out_at_most_the_stated_residual():
    rng = np.random.default_rng(0)
    n = 30
    r = rng.normal(size=(n, 3)) * rng.exponential(size=(n, 1)) ** 3
    free = np.ones((n, 3), bool)
    ptr = np.arange(n + 1)  # a chain: node i's neighbour is i + 1
    idx = np.minimum(np.arange(n) + 1, n - 1)
    out = 0.3 * np.linalg.norm(r)
    region = newton_region(r, free, ptr, idx, out, 0)
    assert np.linalg.norm(r[~region]) <= out
    # smallest such set: dropping its weakest node breaks the bound
    weakest = np.flatnonzero(region)[np.argmin(np.linalg.norm(r[region], axis=1))]
    less = region.copy()
    less[weakest] = False
    assert np.linalg.norm(r[~less]) > out
    grown = newton_region(r, free, ptr, idx, out, 1)
    assert np.array_equal(grown, region | np.isin(np.arange(n), idx[region]))


def test_bad_rings_are_refused():
    p, em, f = block()
    with pytest.raises(InputError, match="region_rings"):
        NewtonSolver(em, region_rings=-1)


@pytest.mark.parametrize("project", [0, 1])
def test_the_region_matrix_is_the_whole_matrix_on_the_region(project):
    p, em, f = block()
    x = p + np.random.default_rng(1).normal(scale=0.05, size=p.shape)
    solver = NewtonSolver(em)
    region = np.zeros(em.n_nodes, bool)
    region[(p[:, 0] >= 5) & (p[:, 2] >= 1)] = True
    sub = ~em.fixed & region[:, None]
    dofs = np.flatnonzero(sub.ravel())
    add = em.masses / H ** 2
    whole = solver.matrix(x, sub, add, project)[dofs][:, dofs].toarray()
    part = solver.region_matrix(x, sub, region, add, project)[dofs][:, dofs].toarray()
    assert np.allclose(part, whole, rtol=1e-12, atol=1e-12 * np.abs(whole).max())
