"""The analytic eigensystem of the stress Hessian (cutkit.relax._eigen_kernels) against LAPACK:
the rotation-variant SVD against numpy's, the projected 9x9 d2psi/dF2 against the exact one
clamped by eigh, on random, degenerate, inverted and barrier-band deformation gradients."""

import numpy as np
import pytest

import _twins_newton as T
from cutkit.relax import _eigen_kernels as KE
from cutkit.relax import _newton_kernels as KN

#: Projected matrices agree with eigh's to this, relative to the exact Hessian's largest entry,
#: wherever the two smallest |singular values| have a product >= 1e-10 |F|^2 (below that the
#: computed cof F, and with it the barrier's rank-one term, is itself uncertain at this level).
RTOL = 1e-9


def rotation(rng):
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def gradients():
    """(F, what) pairs: random, repeated and near-repeated singular values, inverted, flat,
    and J in the barrier band (0 < J < 0.1)."""
    rng = np.random.default_rng(29)
    out = [(rng.normal(size=(3, 3)), "random") for _ in range(40)]
    spectra = [(1, 1, 1), (2, 2, 2), (1, 1, 0.05), (1.3, 1.3, -0.7), (1, 1 + 1e-12, 1 - 1e-12), (2, 1, 1),
               (1, 1, 1e-6), (1, 0.3, 1e-4), (1, 1, -1), (1, -1, -1), (0.5, 0.2, 0.1), (1, 0.2, 0.2),
               (3, 1e-3, 1e-3), (1, 1, 0.099), (0.9, 0.5, 0.05), (1, 0.8, -1e-3), (1, 1, 0.0)]
    for sig in spectra:
        for _ in range(4):
            out.append((rotation(rng) @ np.diag(sig) @ rotation(rng).T, str(sig)))
    out.append((np.eye(3), "identity"))
    out.append((np.zeros((3, 3)), "zero"))
    out.append((np.diag([2.0, 1.0, 0.5]), "diagonal"))
    return out


CASES = gradients()


@pytest.mark.parametrize("F, what", CASES, ids=[w for _, w in CASES])
def test_rotation_svd_matches_numpy(F, what):
    U, sig, V = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
    KE.rotation_svd(F, U, sig, V)
    _, st, _ = T.rotation_svd(F)
    scale = max(np.abs(F).max(), 1.0)
    assert np.allclose(U @ U.T, np.eye(3), atol=1e-14) and np.allclose(V @ V.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(U) == pytest.approx(1.0) and np.linalg.det(V) == pytest.approx(1.0)
    assert np.allclose(U @ np.diag(sig) @ V.T, F, atol=1e-14 * scale)
    assert np.allclose(sig, st, atol=1e-14 * scale)  # sorted, the sign of det F on the last


def test_symmetric_eigen3_matches_eigh():
    rng = np.random.default_rng(3)
    lam, Q = np.empty(3), np.empty((3, 3))
    for A in [np.diag([1.0, 1.0, 2.0]), np.ones((3, 3)), np.zeros((3, 3))] + [
            (lambda M: M + M.T)(rng.normal(size=(3, 3)) * [1, 1e-8, 1e8]) for _ in range(50)]:
        KE.symmetric_eigen3(A.copy(), lam, Q)
        assert np.allclose(Q.T @ Q, np.eye(3), atol=1e-14)
        assert np.allclose((Q * lam) @ Q.T, A, atol=1e-14 * max(np.abs(A).max(), 1.0))
        assert np.allclose(np.sort(lam), np.linalg.eigvalsh(A), atol=1e-14 * max(np.abs(A).max(), 1.0))


def kernel_hessian(F, mu, lam, project):
    P, H = np.empty((3, 3)), np.empty((9, 9))
    KN.stress_hessian(F, mu, lam, project, P, H)
    return H


@pytest.mark.parametrize("F, what", CASES, ids=[w for _, w in CASES])
@pytest.mark.parametrize("factor", [1, 2])
def test_projection_matches_eigh(F, what, factor):
    """Clamped (1) and reflected (2): equal to eigh's projection of the same exact Hessian, positive
    semi-definite, and the exact Hessian itself where that has no negative eigenvalue."""
    sig = np.sort(np.abs(np.linalg.svd(F, compute_uv=False)))
    for mu, lam in [(1.0, 1.0), (3.0, 1e3)]:  # nu 0.25 and 0.4985
        H0 = kernel_hessian(F, mu, lam, KN.EXACT)
        H = kernel_hessian(F, mu, lam, KN.CLAMP if factor == 1 else KN.ABSOLUTE)
        He = kernel_hessian(F, mu, lam, KN.CLAMP_EIGH if factor == 1 else KN.ABSOLUTE_EIGH)
        scale = np.abs(H0).max()
        w0 = np.linalg.eigvalsh(H0)
        if w0.min() >= 0:
            assert np.array_equal(H, H0)
        if sig[0] * sig[1] < 1e-10 * max(sig[2], 1.0) ** 2:
            continue
        ref = T.clamp_negative(H0, factor)
        assert np.abs(H - ref).max() <= RTOL * scale, what
        assert np.abs(He - ref).max() <= RTOL * scale, what
        assert np.linalg.eigvalsh(H).min() >= -RTOL * scale
        assert np.array_equal(H, H.T) or np.abs(H - H.T).max() <= 1e-15 * scale


def test_projection_against_the_twin_in_the_barrier_band():
    """The twin's own exact Hessian (det by LAPACK, cof by cross products) clamped by eigh, for J
    across the barrier band down to 1e-6: the analytic projection is that to RTOL."""
    rng = np.random.default_rng(5)
    for J in [0.099, 0.05, 1e-2, 1e-4, 1e-6, -0.3]:
        for _ in range(5):
            F = rotation(rng) @ np.diag([1.1, 0.9, J / 0.99]) @ rotation(rng).T
            _, ref = T.stress_hessian(F, 2.0, 20.0, 1)
            H = kernel_hessian(F, 2.0, 20.0, KN.CLAMP)
            assert np.abs(H - ref).max() <= RTOL * np.abs(ref).max()


def test_eigenvalues_are_the_exact_hessians():
    """The modes' eigenvalues are H's: the smallest returned equals eigh's smallest."""
    rng = np.random.default_rng(11)
    for _ in range(30):
        F = rng.normal(size=(3, 3))
        J = np.linalg.det(F)
        mu, lam = 1.5, 7.0
        k = lam + mu
        db, ddb = T.barrier_derivatives(J, k)
        H0 = kernel_hessian(F, mu, lam, KN.EXACT)
        smallest = KE.project_stress_hessian(F, mu, k + ddb, k * (J - 1) - mu + db, 1.0, H0.copy())
        assert smallest == pytest.approx(np.linalg.eigvalsh(H0).min(), abs=1e-12 * np.abs(H0).max())


def test_assembled_matrix_moves_only_within_the_tolerance():
    """The Newton matrix of a randomly deformed block with a tet crushed into the barrier band: the
    analytic projection against eigh's, assembled."""
    from _fem_reference import kuhn_box
    from cutkit.model.tetmodel import Materials, TetModel
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.newton import NewtonSolver

    p, t = kuhn_box((3.0, 2.0, 2.0), (3, 2, 2))
    row = dict(label=1, name="m", E=30e3, poisson_ratio=0.45, density=1090.0, damping=8.0, F_enter=0.8,
               mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
               c_edge=1.0, c_shape=1.0)
    em = build_element_model(TetModel.from_arrays(p, t, materials=Materials.from_rows([row])))
    x = p + np.random.default_rng(7).normal(scale=0.4, size=p.shape)
    n = em.n_nodes
    solver = NewtonSolver(em)
    free, add = np.ones((n, 3), bool), np.zeros(n)
    A = solver.matrix(x, free, add, KN.CLAMP).toarray()
    Ae = solver.matrix(x, free, add, KN.CLAMP_EIGH).toarray()
    A0 = solver.matrix(x, free, add, KN.EXACT).toarray()
    assert not np.array_equal(A, A0)  # some elements were projected
    assert np.abs(A - Ae).max() <= RTOL * np.abs(A0).max()
