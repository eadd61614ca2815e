"""The average nodal pressure (ANP) tetrahedron: kernels against NumPy twins, derivatives against
finite differences, and its behaviour under homogeneous strain, cuts, prestress and crushing."""

import functools

import numpy as np
import pytest

import _twins_anp as T
from _tissues import with_cut_mesh
from cutkit.errors import InputError
from cutkit.mesh.geometry import tet_volumes
from cutkit.mesh.quality import signed_volumes
from cutkit.model.tetmodel import TetModel
from cutkit.relax import anp
from cutkit.relax.elastic import ElementModel, build_element_model
from cutkit.relax.equilibrium import static_solve
from cutkit.relax.vbd import elastic_energy
from _fem_reference import kuhn_box
from test_elastic_fem import E, solid

TIGHT = dict(rtol=1e-10, atol=1e-16, max_iterations=100)


def model(nu=0.45, cells=(2, 2, 1), L=(2.0, 2.0, 1.0), element="anp", smoothing=0.0):
    p, t = kuhn_box(np.array(L), cells)
    return p, t, build_element_model(TetModel.from_arrays(p, t, materials=solid(nu)), element=element,
                                     deviatoric_smoothing=smoothing)


def arrays(em):
    el = anp.active_elements(em)
    return el.tets, el.Dminv, el.volume, el.mu, el.lam


def wobbled(p, scale=0.05, seed=0):
    return p + scale * np.random.default_rng(seed).standard_normal(p.shape)


def hold_bottom(p, em):
    """Hold the nodes of z = 0 in all directions (they then carry no volume constraint) and one
    more node in x only (which still does); the held mask (n,)."""
    em.fixed[p[:, 2] < 1e-9] = True
    em.fixed[np.flatnonzero(p[:, 2] > 1e-9)[0], 0] = True
    return em.fixed.all(axis=1)


def cut_at_x1(p, t, em):
    """Duplicate the nodes of the plane x = 1 as a cut does: the tets on its right side removed and
    added again on new copies of those nodes.  Returns (rest positions (n + k, 3), the plane's
    nodes (k,), their copies (k,))."""
    right = np.flatnonzero(p[t].mean(axis=1)[:, 0] > 1.0)
    plane = np.flatnonzero(np.abs(p[:, 0] - 1.0) < 1e-9)
    new = em.add_nodes(plane.size)
    remap = np.arange(p.shape[0])
    remap[plane] = new
    X = np.concatenate([p, p[plane]])
    em.remove_elements(right)
    em.add_elements(X, remap[t[right]], em.mu[right], em.lam[right], np.full(right.size, 1e-9))
    return X, plane, new


def stiffen_half(p, em, factor=30.0):
    """A second material: the elements with their centroid at x > 1 get ``factor`` times the Lame
    constants, so the nodes of x = 1 have a patch in each (``anp.material_patches``)."""
    m = em.n_elements
    right = p[em.tets[:m]].mean(axis=1)[:, 0] > 1.0
    em.mu[:m][right] *= factor
    em.lam[:m][right] *= factor


@pytest.mark.parametrize("materials", [1, 2])
@pytest.mark.parametrize("held", [False, True])
@pytest.mark.parametrize("smoothing", [0.0, 0.7])
def test_kernels_match_their_numpy_twins(smoothing, held, materials):
    p, _, em = model(smoothing=smoothing)
    if materials == 2:
        stiffen_half(p, em)
    mask = hold_bottom(p, em) if held else None
    x = wobbled(p, 0.08)
    # squash one tet into the barrier band (J < 0.1) so its terms count too
    t0 = em.tets[0]
    x[t0[3]] = x[t0[0]] + 0.05 * (x[t0[3]] - x[t0[0]])
    assert anp.anp_energy(em, x) == pytest.approx(T.energy(x, *arrays(em), smoothing, mask), rel=1e-12)
    np.testing.assert_allclose(anp.anp_forces(em, x), T.forces(x, *arrays(em), smoothing, mask),
                               rtol=1e-10, atol=1e-14)


def test_held_nodes_carry_no_volume_constraint():
    """A tet's volume goes to its free corners in equal parts; the free nodal volumes still add up
    to the volume of every tet with a free corner."""
    p, t, em = model()
    held = hold_bottom(p, em)
    nodal = anp.nodal_terms(em)
    assert np.all(nodal.pressure_volume[held] == 0.0) and np.all(nodal.pressure_volume[~held] > 0.0)
    some_free = (~held[t]).any(axis=1)
    assert nodal.pressure_volume.sum() == pytest.approx(em.volume[:em.n_elements][some_free].sum(), rel=1e-13)
    np.testing.assert_allclose(nodal.share, T.shares(t, held), rtol=0, atol=0)
    em.fixed[:] = False  # nothing held: the quarter split of Bonet & Burton
    np.testing.assert_array_equal(anp.nodal_terms(em).share, 0.25)


@pytest.mark.parametrize("materials", [1, 2])
@pytest.mark.parametrize("held", [False, True])
@pytest.mark.parametrize("smoothing", [0.0, 0.7])
def test_gradient_and_hessian_match_finite_differences(smoothing, held, materials):
    p, _, em = model(smoothing=smoothing)
    if materials == 2:
        stiffen_half(p, em)
    if held:
        hold_bottom(p, em)
    x = wobbled(p)
    f = anp.anp_forces(em, x)
    H = anp.anp_hessian(em, x, project=0).toarray()
    h = 1e-6
    g_fd = np.zeros(x.size)
    H_fd = np.zeros_like(H)
    for k in range(x.size):
        d = np.zeros(x.size)
        d[k] = h
        d = d.reshape(-1, 3)
        g_fd[k] = (anp.anp_energy(em, x + d) - anp.anp_energy(em, x - d)) / (2 * h)
        H_fd[:, k] = -(anp.anp_forces(em, x + d) - anp.anp_forces(em, x - d)).ravel() / (2 * h)
    np.testing.assert_allclose(-f.ravel(), g_fd, atol=1e-8 * np.abs(f).max())
    np.testing.assert_allclose(H, H_fd, atol=1e-7 * np.abs(H).max())
    # the projected Hessian is positive semi-definite and differs from the exact one only
    # in the element parts
    Hp = anp.anp_hessian(em, x, project=1).toarray()
    assert np.linalg.eigvalsh(Hp).min() > -1e-12 * np.abs(Hp).max()
    # projected through the analytic eigensystem as through LAPACK's eigh (the reference)
    from cutkit.relax._newton_kernels import CLAMP_EIGH

    np.testing.assert_allclose(Hp, anp.anp_hessian(em, x, project=CLAMP_EIGH).toarray(), rtol=0,
                               atol=1e-9 * np.abs(Hp).max())


def test_materials_keep_their_own_patches():
    """Where two materials meet, a node has one patch (nodal volume, bulk and shear weight) per
    material: patch a < n is node a's, the second material's patches follow; each material's
    patches hold its own volume."""
    p, t, em = model(cells=(4, 2, 1), L=(4.0, 2.0, 1.0))
    em.fixed[:] = False
    stiffen_half(p, em, 30.0)
    m, n = em.n_elements, em.n_nodes
    right = p[em.tets[:m]].mean(axis=1)[:, 0] > 1.0
    nodal = anp.nodal_terms(em)
    both = np.intersect1d(em.tets[:m][right], em.tets[:m][~right])  # nodes of both materials
    assert both.size > 0 and nodal.volume.shape == (n + both.size,)
    patch = nodal.patch
    assert not np.intersect1d(patch[right], patch[~right]).size  # no patch holds tets of both materials
    assert np.all(patch[~right] == em.tets[:m][~right])  # the first material keeps the node ids
    V = em.volume[:m]
    assert nodal.volume[np.unique(patch[right])].sum() == pytest.approx(V[right].sum(), rel=1e-13)
    assert nodal.volume[np.unique(patch[~right])].sum() == pytest.approx(V[~right].sum(), rel=1e-13)
    assert nodal.shear.sum() == pytest.approx((V * em.mu[:m]).sum(), rel=1e-13)
    # one material: the patches are the nodes
    _, t1, em1 = model()
    np.testing.assert_array_equal(anp.nodal_terms(em1).patch, t1)


@pytest.mark.parametrize("nu", [0.45, 0.49])
def test_two_materials_against_p2(nu):
    """A soft block bonded to one 100 times stiffer (x > 2 of a 4 x 4 x 2 mm block on a held base)
    under a traction on the soft top: ANP with the nodes' deviatoric share against quadratic tets
    (scikit-fem P2, 3x the cells): within 6 % (measured 2.9 % at nu 0.45, 5.3 % at 0.49), at most a
    quarter of P1's error (24 %, 33 %).  One patch per node for both materials put the stiff
    material's shear into the soft side's smoothed part: 44 % too stiff (docs/relaxation.md)."""
    from _fem_reference import p2_composite_block_sag
    from cutkit.model.tetmodel import Materials

    B = _locking_benchmark()
    L, split, factor = B.BLOCK, 2.0, 100.0
    ref = p2_composite_block_sag(L, (12, 12, 6), E, nu, B.TRACTION, split, factor)
    p, t = kuhn_box(L, (4, 4, 2))
    row = dict(name="soft", E=B.E_PA, poisson_ratio=nu, density=1000.0, damping=0.0, F_enter=1.0, mu_static=1e-6,
               mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1, c_edge=1.0, c_shape=1.0)
    materials = Materials.from_rows([dict(row, label=1), dict(row, label=2, name="stiff", E=B.E_PA * factor)])
    labels = np.where(p[t].mean(axis=1)[:, 0] > split, 2, 1)
    soft_top = t[np.all(p[t][..., 0] < split + 1e-9, axis=1)]
    loads = np.zeros(p.shape)
    loads[:, 2] = B.face_loads(p, soft_top, 2, L[2], B.TRACTION)

    def sag(element, alpha):
        em = build_element_model(TetModel.from_arrays(p, t, labels, materials=materials), element=element,
                                 deviatoric_smoothing=alpha)
        em.fixed[p[:, 2] < 1e-9] = True
        x = p.copy()
        assert static_solve(em, x, f_ext=loads, **B.TIGHT).converged
        return float(((x - p)[:, 2] * loads[:, 2]).sum() / loads[:, 2].sum())

    err_anp = abs(sag("anp", anp.ANP_SMOOTHING) / ref - 1.0)
    err_nh = abs(sag("nh", 0.0) / ref - 1.0)
    assert err_anp <= 0.06 and err_anp <= 0.25 * err_nh, (err_anp, err_nh)


def test_hessian_couples_every_node_of_a_patch():
    p, t, em = model()
    H = anp.anp_hessian(em, wobbled(p), project=0)
    ring = np.zeros((p.shape[0],) * 2, bool)
    for a in range(4):
        for b in range(4):
            ring[t[:, a], t[:, b]] = True
    two_ring = (ring.astype(int) @ ring.astype(int)) > 0
    blocks = np.abs(H.toarray()).reshape(p.shape[0], 3, p.shape[0], 3).sum(axis=(1, 3)) > 0
    assert np.all(blocks <= two_ring)
    assert np.any(blocks & ~ring)  # the nodal terms reach past the nodes' own tets


@pytest.mark.parametrize("nu", [0.3, 0.45, 0.49])
def test_homogeneous_strain_has_the_neo_hookean_energy(nu):
    """Under a homogeneous F every nodal ratio is J: the split adds up to the stable neo-Hookean
    energy (mu/6 + K/2 = (lam + mu)/2), and at rest there is no force."""
    p, _, em = model(nu)
    assert np.abs(anp.anp_forces(em, p)).max() == 0.0
    F = np.array([[1.1, 0.05, 0.0], [0.02, 0.93, 0.03], [0.0, -0.04, 1.02]])
    x = p @ F.T
    nh = elastic_energy(build_element_model(TetModel.from_arrays(p, em.tets, materials=solid(nu))), x)
    assert anp.anp_energy(em, x) == pytest.approx(nh, rel=1e-12)


def test_small_strain_modulus_is_youngs():
    """A bar pulled 0.1 % with free sides carries E A eps (the split keeps E and nu)."""
    L = np.array([4.0, 1.0, 1.0])
    p, t = kuhn_box(L, (8, 2, 2))
    em = build_element_model(TetModel.from_arrays(p, t, materials=solid(0.49)), element="anp")
    tol = 1e-9
    em.fixed[:, 0] = (p[:, 0] < tol) | (p[:, 0] > L[0] - tol)
    em.fixed[:, 1] = p[:, 1] < tol
    em.fixed[:, 2] = p[:, 2] < tol
    x = p.copy()
    end = p[:, 0] > L[0] - tol
    x[end, 0] += 1e-3 * L[0]
    assert static_solve(em, x, **TIGHT).converged
    reaction = -anp.anp_forces(em, x)[end, 0].sum()
    assert reaction == pytest.approx(E * L[1] * L[2] * 1e-3, rel=2e-3)
    contraction = -(x - p)[p[:, 1] > L[1] - tol, 1].mean() / L[1] / 1e-3
    assert contraction == pytest.approx(0.49, abs=0.01)


def test_a_cut_needs_nothing_special():
    """Nodes duplicated along a plane (as a cut does, by removing and re-adding the tets on one
    side with new nodes) get the nodal volumes of the tets that now hold them, and the two
    sides no longer feel each other."""
    p, t, em = model(cells=(2, 2, 2), L=(2.0, 2.0, 2.0))
    X, plane, new = cut_at_x1(p, t, em)
    nodal = anp.nodal_terms(em)
    el = anp.active_elements(em)
    live = el.volume > 0
    expected = np.bincount(el.tets[live].ravel(), np.repeat(tet_volumes(X, el.tets[live]) / 4, 4), minlength=X.shape[0])
    np.testing.assert_allclose(nodal.volume, expected, rtol=1e-12)
    assert np.all(nodal.volume[new] > 0) and np.all(nodal.volume[plane] > 0)
    x = X.copy()
    x[X[:, 0] > 1.0 + 1e-9] += [0.3, 0.0, 0.0]  # the right side moved away rigidly
    x[new] += [0.3, 0.0, 0.0]
    assert np.abs(anp.anp_forces(em, x)).max() < 1e-12 * E


def test_prestrained_block_relaxes_to_its_natural_shape():
    """A free block prestrained by 10 % along x (rest shape shortened, elastic.rest_shape) relaxes
    to 0.9 of its length with no energy left: the natural shape is the ANP model's rest shape."""
    L = np.array([2.0, 1.0, 1.0])
    p, t = kuhn_box(L, (4, 2, 2))
    m = t.shape[0]
    em = ElementModel.empty(p.shape[0], m)
    nu, mu = 0.45, E / 2.9
    em.add_elements(p, t, np.full(m, mu), np.full(m, 2 * mu * nu / (1 - 2 * nu)), np.full(m, 1e-9),
                    prestrain=np.full(m, 0.1), fibre=np.tile([1.0, 0.0, 0.0], (m, 1)))
    em.element = "anp"
    tol = 1e-9
    for c in range(3):
        em.fixed[:, c] = p[:, c] < tol  # symmetry planes
    em.recolour()
    x = p.copy()
    assert static_solve(em, x, **TIGHT).converged
    np.testing.assert_allclose(x[:, 0], 0.9 * p[:, 0], atol=1e-9)
    np.testing.assert_allclose(x[:, 1:], p[:, 1:], atol=1e-9)
    assert anp.anp_energy(em, x) < 1e-12 * E * L.prod()


def test_crushing_punch_inverts_no_tet():
    """A corner of a near-incompressible block pushed in by 40 % of its height: the barrier and
    the line search keep every tet upright."""
    L = np.array([2.0, 2.0, 1.0])
    p, t, em = model(0.49, cells=(4, 4, 2), L=L)
    tol = 1e-9
    em.fixed[p[:, 2] < tol] = True
    punch = (p[:, 2] > L[2] - tol) & (p[:, 0] < 0.5 + tol) & (p[:, 1] < 0.5 + tol)
    em.fixed[punch] = True
    x = p.copy()
    for k in range(1, 5):
        x[punch, 2] = L[2] - 0.1 * k * L[2]
        assert static_solve(em, x, rtol=1e-8, atol=1e-14, max_iterations=200).converged
    assert signed_volumes(x, t).min() > 0


def test_element_choice_is_checked():
    p, t = kuhn_box(np.ones(3), (1, 1, 1))
    with pytest.raises(InputError, match="element"):
        build_element_model(TetModel.from_arrays(p, t, materials=solid(0.3)), element="p2")
    p, _, em = model()
    with pytest.raises(InputError, match="newton"):
        static_solve(em, p.copy(), solver="vbd")
    _, _, nh = model(element="nh")
    with pytest.raises(InputError, match="newton"):
        static_solve(nh, p.copy(), solver="vbd", element="anp")
    assert nh.element == "nh"  # a refused solve changes nothing
    with pytest.raises(InputError, match="element"):
        static_solve(nh, p.copy(), element="p2")


def test_static_solve_takes_the_element_per_run():
    """The same model solved with element="anp" is the ANP model's equilibrium: a tip-loaded
    beam at nu 0.49 bends more than with the locking P1 element."""
    L = np.array([6.0, 1.0, 1.0])
    p, t = kuhn_box(L, (6, 1, 1))
    tips = []
    for element in ("nh", "anp"):
        em = build_element_model(TetModel.from_arrays(p, t, materials=solid(0.49)))
        em.fixed[p[:, 0] < 1e-9] = True
        f = np.zeros(p.shape)
        f[p[:, 0] > L[0] - 1e-9, 2] = -1e-6
        x = p.copy()
        assert static_solve(em, x, f, element=element, rtol=1e-7, atol=1e-16, max_iterations=100).converged
        assert em.element == element
        tips.append(-(x - p)[p[:, 0] > L[0] - 1e-9, 2].mean())
    assert tips[1] > 1.5 * tips[0]


def cut_slab(element, nu=0.45, smoothing=0.0):
    """A prestrained slab (10 % along y) cut along y = 1.37 by the newton steps of the tissue
    (``smoothing``: the ANP element's deviatoric smoothing)."""
    from cutkit.cutting import cut_step
    from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress
    from cutkit.relax.elastic_tissue import ElasticTissue
    from test_newton_tissue import ROW

    p, t = kuhn_box(np.array([6.0, 3.0, 3.0]), (6, 3, 3))
    ps = Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[0.0, 1.0, 0.0]]),
                   prestrain=np.array([0.1]))
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([dict(ROW, poisson_ratio=nu)]), prestress=ps,
                                 boundary=BoundaryConditions(fixed_nodes=np.flatnonzero(p[:, 2] == 0)))
    tis = with_cut_mesh(ElasticTissue(model, step_s=0.02, solver="newton", element=element), 1.6)
    tis.em.deviatoric_smoothing = smoothing
    tis.advance(np.zeros((tis.n_nodes, 3)), 0.1)
    for xb in np.linspace(-0.5, 6.5, 8):
        tis.apply_cut(cut_step(tis.cm, [xb, 1.37, 3.5], [0.0, 0.0, 1.0]))
        tis.advance(np.zeros((tis.n_nodes, 3)), tis.time + 0.02)
    tis.advance(np.zeros((tis.n_nodes, 3)), tis.time + 0.2)
    return tis


@pytest.mark.parametrize("smoothing", [0.0, anp.ANP_SMOOTHING])
def test_the_tissue_cuts_with_anp_and_inverts_no_tet(smoothing):
    tis = cut_slab("anp", smoothing=smoothing)
    assert tis.em.deviatoric_smoothing == smoothing
    rep = tis.relax_report()
    assert rep["not_converged"] == 0 and rep["worst_relative_residual"] <= rep["rtol"]
    assert tis.em.n_nodes > tis.cm.n_orig_points
    assert signed_volumes(tis.positions, tis.cm.tets).min() > 0


def _locking_benchmark():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "element_locking.py"
    spec = importlib.util.spec_from_file_location("element_locking", path)
    B = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(B)
    return B


@functools.lru_cache(maxsize=None)
def _p2_references(nu, ref):
    """(cantilever deflection, block force) of the P2 reference at ``ref`` times the base cells: the
    same for both mesh kinds, so solved once per process (a file's tests run on one worker)."""
    from _fem_reference import p2_block_reaction, p2_cantilever

    B = _locking_benchmark()
    return (p2_cantilever(B.CANTILEVER, (10 * ref, 2 * ref, 2 * ref), E, nu, B.TRACTION),
            p2_block_reaction(B.BLOCK, (4 * ref, 4 * ref, 2 * ref), E, nu, B.STRAIN))


def _locking_ratios(nu, kind, size=1, ref=2, elements=("nh", "anp", f"anp:{anp.ANP_SMOOTHING}")):
    """cutkit's cantilever deflection and block force over the P2 reference at ``ref`` times the
    base cells, for each element, on the meshes of benchmarks/element_locking.py at ``size``."""
    B = _locking_benchmark()
    ref_c, ref_b = _p2_references(nu, ref)
    pc, tc = B.mesh(kind, B.CANTILEVER, (10 * size, 2 * size, 2 * size))
    pb, tb = B.mesh(kind, B.BLOCK, (4 * size, 4 * size, 2 * size))
    return {e: (B.cantilever(pc, tc, nu, e) / ref_c, B.block(pb, tb, nu, e) / ref_b) for e in elements}


@pytest.mark.parametrize("kind", ["kuhn", "delaunay"])
def test_anp_locks_far_less_than_p1_against_a_p2_reference(kind):
    """Against quadratic tets (scikit-fem P2, linear elasticity, refined mesh): at nu 0.3 ANP is
    no worse than P1; at 0.45 and 0.49, where P1's cantilever is 32-87 % off and its block's
    force 52-324 % too high, ANP's error is at most 70 % of P1's, and with the nodes' deviatoric
    share within 5 % (benchmarks/element_locking.py has the refinement)."""
    for nu in (0.3, 0.45, 0.49):
        r = _locking_ratios(nu, kind)
        for q in range(2):
            err_nh, err_anp = abs(r["nh"][q] - 1.0), abs(r["anp"][q] - 1.0)
            assert err_anp <= (1.0 if nu == 0.3 else 0.7) * err_nh, (nu, q, r)
            # the nodes' deviatoric share removes the bending stiffness too: never worse than ANP,
            # and the cantilever within 5 % already at these ~100 nodes up to nu 0.45
            err_s = abs(r[f"anp:{anp.ANP_SMOOTHING}"][q] - 1.0)
            assert err_s <= min(err_anp, err_nh), (nu, q, r)
            # within 5 % already at these ~100 nodes, except the nu 0.49 cantilever (10-15 % stiff
            # here, within 5 % once refined: test_within_five_percent_of_p2_once_refined)
            if q == 1 or nu <= 0.45:
                assert err_s <= 0.05, (nu, q, r)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["kuhn", "delaunay"])
def test_within_five_percent_of_p2_once_refined(kind):
    """Issue 32's bound: on the once-refined meshes (size 2, ~500 nodes) ANP with the nodes'
    deviatoric share is within 5 % of P2 (3x the base cells) on the cantilever and the bonded
    block at nu 0.49, where P1 is 47-69 % (cantilever) and 85-105 % (block) off.  The faster
    test_anp_locks_far_less_than_p1_against_a_p2_reference covers nu 0.3-0.45 and the block."""
    r = _locking_ratios(0.49, kind, size=2, ref=3, elements=(f"anp:{anp.ANP_SMOOTHING}",))
    for q in range(2):
        assert abs(r[f"anp:{anp.ANP_SMOOTHING}"][q] - 1.0) <= 0.05, (q, r)


def test_simulate_takes_the_element():
    from click.testing import CliRunner

    from cutkit.cli.main import cli
    from cutkit.simulate import SimulateOptions
    from cutkit.relax.elastic_tissue import ElasticTissue

    out = CliRunner().invoke(cli, ["simulate", "--help"])
    assert out.exit_code == 0 and "--element" in out.output
    SimulateOptions(element="anp").check()
    with pytest.raises(InputError, match="newton"):
        SimulateOptions(element="anp", solver="vbd").check()
    with pytest.raises(InputError, match="element"):
        SimulateOptions(element="p2").check()
    p, t = kuhn_box(np.ones(3), (1, 1, 1))
    with pytest.raises(InputError, match="newton"):
        ElasticTissue(TetModel.from_arrays(p, t, materials=solid(0.45)), step_s=0.02, solver="vbd", element="anp")



def test_a_run_takes_the_smoothing_that_meets_the_bound_unless_told():
    """`--element anp` is ANP with ANP_SMOOTHING (the share the locking tests hold to 5 %); the share is
    the run's to choose, and only with ANP."""
    from cutkit.simulate import SimulateOptions
    from cutkit.simulate.tissues import make_tissue

    p, t = kuhn_box(np.ones(3), (1, 1, 1))
    m = TetModel.from_arrays(p, t, materials=solid(0.45))
    for given, want in ((None, anp.ANP_SMOOTHING), (0.0, 0.0), (0.3, 0.3)):
        tis = make_tissue(m, None, "neohookean", SimulateOptions(element="anp", deviatoric_smoothing=given))
        assert tis.em.element == "anp" and tis.em.deviatoric_smoothing == want
    assert make_tissue(m, None, "neohookean", SimulateOptions()).em.deviatoric_smoothing == 0.0
    with pytest.raises(InputError, match="needs element anp"):
        SimulateOptions(deviatoric_smoothing=0.5).check()
    with pytest.raises(InputError, match=r"must lie in \[0, 1\), got 1.0"):
        SimulateOptions(element="anp", deviatoric_smoothing=1.0).check()


def test_a_kept_newton_solver_follows_the_element():
    from cutkit.relax.newton import NewtonSolver

    _, _, em = model(element="nh")
    solver = NewtonSolver(em)
    one_ring = solver.pattern().node_idx.size
    em.element = "anp"
    assert solver.pattern().node_idx.size > one_ring


def test_the_kept_nodal_terms_follow_every_change_of_the_elements():
    """anp.cached_nodal_terms (what forces, energy and Hessian use) against anp.nodal_terms computed
    afresh, field by field, bit for bit: at the start, after stiffening half the elements in place,
    after holding nodes, after a cut that removes and re-adds elements with new nodes, and for a
    second model; the forces through the kept terms equal those of a fresh model at every stage."""
    p, t, em = model(cells=(2, 2, 2), L=(2.0, 2.0, 2.0), smoothing=0.7)
    x = wobbled(p)

    def same():
        el = anp.active_elements(em)
        kept, fresh = anp.cached_nodal_terms(em, el), anp.nodal_terms(em, el)
        for a, b in zip(kept, fresh):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert anp.cached_nodal_terms(em, el) is kept  # nothing changed: the same terms

    same()
    first = anp.anp_forces(em, x[:em.n_nodes])
    stiffen_half(p, em)
    same()
    assert not np.array_equal(anp.anp_forces(em, x[:em.n_nodes]), first)
    hold_bottom(p, em)
    same()
    cut_at_x1(p, t, em)
    same()
    other = model(cells=(2, 2, 1))[2]
    el = anp.active_elements(other)
    np.testing.assert_array_equal(anp.cached_nodal_terms(other, el).volume, anp.nodal_terms(other, el).volume)
    same()


def test_material_patches_match_their_numpy_twin():
    """Random materials (up to 5 at a node, mu ties with different lam), inactive elements."""
    rng = np.random.default_rng(4)
    p, t = kuhn_box(np.array([3.0, 2.0, 2.0]), (3, 2, 2))
    volume = np.where(rng.random(len(t)) < 0.1, 0.0, 1.0)
    mu = rng.choice([1.0, 2.0, 2.0, 5.0], len(t))
    lam = rng.choice([3.0, 4.0], len(t))
    one = np.ones(len(t))
    for m_, l_ in ((one, one), (mu, lam)):
        got, want = anp.material_patches(t, volume, m_, l_, len(p)), T.material_patches(t, volume, m_, l_, len(p))
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1] == want[1]
    assert anp.material_patches(t, volume, one, one, len(p))[1] == len(p)
    assert anp.material_patches(t, volume, mu, lam, len(p))[1] > len(p)
    assert anp.material_patches(t, np.zeros(len(t)), mu, lam, len(p))[1] == len(p)


def test_patch_members_match_their_numpy_twin():
    """Each patch's members are its tets' distinct nodes in the order the tets meet them; each
    node's row lists the members that are that node, in patch order (what forces and Hessian
    rows gather); checked on two materials with held nodes and a cut."""
    p, t, em = model(cells=(2, 2, 2), L=(2.0, 2.0, 2.0), smoothing=0.7)
    hold_bottom(p, em)
    X = cut_at_x1(p, t, em)[0]
    el = anp.active_elements(em)
    back = X[el.tets].mean(axis=1)[:, 1] > 1.0  # a second material across the cut
    em.mu[:el.tets.shape[0]][back] *= 30.0
    el = anp.active_elements(em)
    nt = anp.nodal_terms(em, el)
    assert nt.node_ptr.size - 1 > em.n_nodes  # the nodes of y = 1 have a second patch
    members, slots = [], []
    for a in range(nt.node_ptr.size - 1):
        tets = el.tets[nt.node_tets[nt.node_ptr[a]:nt.node_ptr[a + 1]]]
        nodes = list(dict.fromkeys(tets.ravel().tolist()))
        members.append(nodes)
        slots += [[nodes.index(i) for i in row] for row in tets]
        assert nt.member_node[nt.member_ptr[a]:nt.member_ptr[a + 1]].tolist() == nodes
        assert (nt.member_patch[nt.member_ptr[a]:nt.member_ptr[a + 1]] == a).all()
    np.testing.assert_array_equal(nt.tet_slot, np.array(slots).reshape(-1, 4))
    for i in range(em.n_nodes):
        rows = nt.row_member[nt.row_ptr[i]:nt.row_ptr[i + 1]]
        want = [(a, nodes.index(i)) for a, nodes in enumerate(members) if i in nodes]
        assert [(nt.member_patch[s], s - nt.member_ptr[nt.member_patch[s]]) for s in rows] == want


def test_forces_energy_and_hessian_are_the_same_on_any_thread_count():
    """The patches' sums are made by one block each and gathered by node rows in patch order: one
    and two threads give the same bits (forces, energy, the projected Hessian)."""
    import numba

    p, t, em = model(cells=(4, 3, 3), L=(2.0, 1.5, 1.5), smoothing=0.7)
    stiffen_half(p, em)
    x = wobbled(p, 0.03)
    runs = []
    before = numba.get_num_threads()
    try:
        for threads in sorted({1, min(2, numba.config.NUMBA_NUM_THREADS)}):
            numba.set_num_threads(threads)
            runs.append((anp.anp_forces(em, x), anp.anp_energy(em, x), anp.anp_hessian(em, x, project=1).data))
    finally:
        numba.set_num_threads(before)
    for f, e, h in runs[1:]:
        assert np.array_equal(f, runs[0][0]) and e == runs[0][1] and np.array_equal(h, runs[0][2])
    assert np.abs(runs[0][2]).max() > 0
