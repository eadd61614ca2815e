"""The element model against a linear P1 FEM on the same mesh (scikit-fem) and analytic answers.

At small strain the stable neo-Hookean energy is linear elasticity with the
same Lame parameters, and the element model's tetrahedra are the same
linear elements, so its converged static solution must match the linear
FEM's up to the (small) geometric nonlinearity.
"""

import numpy as np
import pytest

from cutkit.mesh.quality import signed_volumes
from cutkit.model.tetmodel import Materials, TetModel
from cutkit.relax.elastic import build_element_model
from cutkit.relax.equilibrium import static_solve
from cutkit.relax.vbd import elastic_forces
from _fem_reference import delaunay_box, kuhn_box, linear_fem

E_PA = 1.0e6  # 1 MPa
E = E_PA * 1e-6
#: Solve to far below the accuracy the comparisons ask for (projected Newton: a few dozen
#: iterations where vertex block descent needs 10^5 sweeps on the slender cantilever).
TIGHT = dict(rtol=1e-8, atol=1e-16, max_iterations=200)
#: The same equilibrium by vertex block descent's sweeps (test_settle_reaches_the_block_descent_equilibrium).
TIGHT_VBD = dict(rtol=1e-8, atol=1e-16, max_iterations=200000, chebyshev=0.9, solver="vbd")


def solid(nu):
    """Materials table of one solid with E = 1 MPa and Poisson ratio nu."""
    return Materials.from_rows([dict(label=1, name="solid", E=E_PA, poisson_ratio=nu, density=1000.0, damping=0.0,
                                     F_enter=1.0, mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8,
                                     alpha_static=0.1, alpha_dynamic=0.1, c_edge=1.0, c_shape=1.0)])


def element_model(points, tets, nu):
    return build_element_model(TetModel.from_arrays(points, tets, materials=solid(nu)))


def mesh(kind, L, cells):
    if kind == "kuhn":
        return kuhn_box(L, cells)
    return delaunay_box(L, float(np.min(np.asarray(L) / np.asarray(cells))))


def solve(points, tets, nu, fixed, prescribed, loads):
    em = element_model(points, tets, nu)
    em.fixed[:] = fixed
    em._classes = None
    x = points + np.where(fixed, prescribed, 0.0)
    info = static_solve(em, x, f_ext=loads, **TIGHT)
    assert info.converged, info
    return em, x


def solve_in_increments(points, tets, nu, fixed, prescribed, n=10):
    """Large prescribed displacements in n equal increments, as a nonlinear FEM applies them
    (the stable neo-Hookean energy is not convex: a 30 % jump at once crushes the layer under it)."""
    em = element_model(points, tets, nu)
    em.fixed[:] = fixed
    em._classes = None
    x = points.copy()
    for k in range(1, n + 1):
        x[fixed] = (points + prescribed * (k / n))[fixed]
        info = static_solve(em, x, **TIGHT)
        assert info.converged, info
    return em, x


def rel_l2(u, ref):
    return float(np.linalg.norm(u - ref) / np.linalg.norm(ref))


MESHES = ["kuhn", "delaunay"]
NUS = [0.3, 0.45]


@pytest.mark.parametrize("kind", MESHES)
@pytest.mark.parametrize("nu", NUS)
def test_bar_pulled_one_percent_has_young_modulus_and_poisson_ratio(kind, nu):
    L = np.array([10.0, 2.0, 2.0])
    p, t = mesh(kind, L, (10, 2, 2))
    tol = 1e-9
    fixed = np.zeros(p.shape, bool)
    fixed[:, 0] = (p[:, 0] < tol) | (p[:, 0] > L[0] - tol)  # ends slide on their planes
    fixed[:, 1] = p[:, 1] < tol  # symmetry planes
    fixed[:, 2] = p[:, 2] < tol
    eps = 0.01
    prescribed = np.zeros(p.shape)
    prescribed[p[:, 0] > L[0] - tol, 0] = eps * L[0]
    em, x = solve(p, t, nu, fixed, prescribed, np.zeros(p.shape))
    end = p[:, 0] > L[0] - tol
    reaction = -elastic_forces(em, x)[end, 0].sum()
    assert reaction == pytest.approx(E * L[1] * L[2] * eps, rel=0.03)
    side = p[:, 1] > L[1] - tol
    contraction = -((x - p)[side, 1] / L[1]).mean() / eps
    assert abs(contraction - nu) < 0.03
    ref = linear_fem(p, t, E, nu, fixed, prescribed, np.zeros(p.shape))
    assert rel_l2(x - p, ref) < 0.05


@pytest.mark.parametrize("kind", MESHES)
@pytest.mark.parametrize("nu", NUS)
def test_cantilever_under_tip_load_matches_linear_fem(kind, nu):
    L = np.array([10.0, 2.0, 2.0])
    p, t = mesh(kind, L, (10, 2, 2))
    tol = 1e-9
    fixed = np.zeros(p.shape, bool)
    fixed[p[:, 0] < tol] = True
    tip = p[:, 0] > L[0] - tol
    loads = np.zeros(p.shape)
    loads[tip, 2] = -4e-5 / tip.sum()  # 40 uN: tip deflection about 0.01 mm, far in the linear range
    em, x = solve(p, t, nu, fixed, np.zeros(p.shape), loads)
    ref = linear_fem(p, t, E, nu, fixed, np.zeros(p.shape), loads)
    assert rel_l2(x - p, ref) < 0.05
    assert (x - p)[tip, 2].mean() < 0  # it bends the way it is pushed


@pytest.mark.parametrize("kind", MESHES)
@pytest.mark.parametrize("nu", NUS)
def test_confined_compression_under_a_punch_matches_linear_fem(kind, nu):
    L = np.array([4.0, 4.0, 4.0])
    p, t = mesh(kind, L, (4, 4, 4))
    tol = 1e-9
    fixed = np.zeros(p.shape, bool)
    fixed[:, 0] = (p[:, 0] < tol) | (p[:, 0] > L[0] - tol)  # walls of the confining box
    fixed[:, 1] = (p[:, 1] < tol) | (p[:, 1] > L[1] - tol)
    fixed[:, 2] = p[:, 2] < tol
    punch = (p[:, 2] > L[2] - tol) & (np.abs(p[:, 0] - 2.0) < 1.0 + tol) & (np.abs(p[:, 1] - 2.0) < 1.0 + tol)
    fixed[punch, 2] = True
    prescribed = np.zeros(p.shape)
    prescribed[punch, 2] = -0.01 * L[2]
    em, x = solve(p, t, nu, fixed, prescribed, np.zeros(p.shape))
    ref = linear_fem(p, t, E, nu, fixed, prescribed, np.zeros(p.shape))
    assert rel_l2(x - p, ref) < 0.05


def uniaxial_lateral_stretch(a, nu):
    """Lateral stretch b of the stable neo-Hookean solid under uniaxial stress at axial stretch a.

    The lateral first Piola-Kirchhoff stress mu b + ((lam + mu)(J - 1) - mu) J / b with
    J = a b^2 vanishes (bisection on b in (0, 2)).
    """
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    lo, hi = 1e-3, 2.0

    def g(b):
        J = a * b * b
        return mu * b + ((lam + mu) * (J - 1) - mu) * J / b

    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(lo) * g(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("kind", MESHES)
def test_block_compressed_by_thirty_percent_keeps_every_tet_and_its_volume(kind):
    nu = 0.45
    L = np.array([4.0, 4.0, 4.0])
    p, t = mesh(kind, L, (4, 4, 4))
    tol = 1e-9
    fixed = np.zeros(p.shape, bool)
    for c in range(3):
        fixed[:, c] = p[:, c] < tol  # frictionless symmetry planes
    top = p[:, 2] > L[2] - tol
    fixed[top, 2] = True
    prescribed = np.zeros(p.shape)
    prescribed[top, 2] = -0.3 * L[2]
    em, x = solve_in_increments(p, t, nu, fixed, prescribed)
    vol = signed_volumes(x, t)
    assert vol.min() > 0.0
    b = uniaxial_lateral_stretch(0.7, nu)
    expected = 0.7 * b * b - 1.0
    change = vol.sum() / signed_volumes(p, t).sum() - 1.0
    assert abs(change - expected) < 0.02
    # the homogeneous answer is in the elements' space: every node where it belongs
    assert np.allclose(x[:, 0], p[:, 0] * b, atol=1e-6)


def test_clamped_block_squeezed_by_thirty_percent_does_not_invert():
    """Both faces clamped (no sliding): the bulging block keeps every tet positive."""
    p, t = kuhn_box([4.0, 4.0, 4.0], (4, 4, 4))
    tol = 1e-9
    fixed = np.zeros(p.shape, bool)
    bottom, top = p[:, 2] < tol, p[:, 2] > 4.0 - tol
    fixed[bottom | top] = True
    prescribed = np.zeros(p.shape)
    prescribed[top, 2] = -1.2
    em, x = solve_in_increments(p, t, 0.45, fixed, prescribed)
    assert signed_volumes(x, t).min() > 0.0


@pytest.mark.parametrize("kind", MESHES)
def test_linear_stiffness_is_scikit_fem_stiffness(kind):
    """The settle's small-strain stiffness is the P1 linear-elasticity matrix, entry for entry."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from cutkit.relax.settle import linear_stiffness

    p, t = mesh(kind, [3.0, 2.0, 2.0], (3, 2, 2))
    em = element_model(p, t, 0.45)
    K = linear_stiffness(em).toarray()
    basis = skfem.Basis(skfem.MeshTet(p.T.copy(), t.T.copy()), skfem.ElementVector(skfem.ElementTetP1()))
    ref = skfem.asm(linear_elasticity(*lame_parameters(E, 0.45)), basis).toarray()
    order = np.stack([basis.nodal_dofs[c] for c in range(3)], axis=1).ravel()  # our dof 3 i + c
    np.testing.assert_allclose(K, ref[np.ix_(order, order)], atol=1e-12 * np.abs(ref).max())


def test_settle_reaches_the_block_descent_equilibrium():
    """Newton with the linear stiffness and vertex block descent find the same prestressed equilibrium."""
    from cutkit.model.tetmodel import Prestress
    from cutkit.relax.settle import settle_static

    p, t = kuhn_box([6.0, 3.0, 3.0], (6, 3, 3))
    model = TetModel.from_arrays(p, t, materials=solid(0.45), prestress=Prestress(
        label=np.array([1], np.int32), fibre_direction=np.array([[1.0, 0.0, 0.0]]), prestrain=np.array([0.08])))
    em = build_element_model(model)
    em.fixed[(p[:, 0] == 0) | (p[:, 0] == 6.0)] = True
    em._classes = None
    x_newton, x_vbd = p.copy(), p.copy()
    info = settle_static(em, x_newton, rtol=1e-9)
    assert info.converged and info.iterations <= 20
    assert static_solve(em, x_vbd, **TIGHT_VBD).converged
    assert np.abs(x_newton - x_vbd).max() < 1e-6
    assert np.abs(x_newton - p).max() > 0.01  # the prestress did move it
