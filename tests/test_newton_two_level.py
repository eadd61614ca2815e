"""The two-level preconditioner of the Newton solver's conjugate gradients
(:func:`cutkit.relax.newton.coarse_space`, :mod:`cutkit.relax._coarse_kernels`) against a NumPy twin
that builds the coarse basis W as a matrix: E = W^T A W, the correction W E^-1 W^T r, the aggregates a
crack splits, and conjugate gradients that reach scipy's direct solution in fewer iterations."""

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _fem_reference import kuhn_box  # noqa: E402
from test_newton import _block_system, cut_slab, model_of  # noqa: E402

from cutkit.relax import _block_cg_kernels as KB  # noqa: E402
from cutkit.relax import _coarse_kernels as KC  # noqa: E402
from cutkit.relax.elastic import build_element_model  # noqa: E402
from cutkit.relax.newton import (COARSE_MIN_TURNING_NODES, NewtonSolver, block_system, cell_aggregates,  # noqa: E402
                                 coarse_space)


def basis_twin(c, n):
    """(3n, 6k) W written out: each node's translations, then e_m x rel (m = x, y, z) where its
    aggregate turns, zero at held dofs and at nodes without an aggregate."""
    k = int(c.agg.max()) + 1
    W = np.zeros((3 * n, 6 * k))
    for i in range(n):
        a = c.agg[i]
        if a < 0:
            continue
        for m in range(3):
            W[3 * i + m, 6 * a + m] = 1.0
            if c.turns[i]:
                e = np.zeros(3)
                e[m] = 1.0
                W[3 * i:3 * i + 3, 6 * a + 3 + m] = np.cross(e, c.rel[i])
        W[3 * i:3 * i + 3] *= c.free[i][:, None]
    return W


def bent_bar():
    """A 40 x 2 x 2 mm bar (Kuhn cells of 1 mm) held at x = 0, bent, and the projected Newton
    matrix of a step there (a small inertia on the diagonal) in block form: a soft, slender body
    whose bending block Jacobi converges slowest on."""
    p, t = kuhn_box((40.0, 2.0, 2.0), (40, 2, 2))
    em = build_element_model(model_of(p, t))
    em.fixed[p[:, 0] == 0] = True
    em._classes = None
    x = p.copy()
    x[:, 2] -= 0.002 * p[:, 0] ** 2
    free = ~em.fixed
    solver = NewtonSolver(em)
    A = solver.matrix(x, free, np.full(em.n_nodes, 1e-3), 1)
    blocks, inv = block_system(A, solver.pattern())
    return em, x, free, A, blocks, inv


def test_galerkin_product_and_correction_match_the_twin():
    em, x, free, A, blocks, inv = bent_bar()
    c = coarse_space(blocks, x, free)
    assert c is not None
    n = em.n_nodes
    k = int(c.agg.max()) + 1
    assert k > 1 and (c.agg[~free.any(axis=1)] == -1).all() and (c.agg[free.any(axis=1)] >= 0).all()
    assert np.array_equal(c.turns[c.agg >= 0] > 0, np.bincount(c.agg[c.agg >= 0])[c.agg[c.agg >= 0]] >= COARSE_MIN_TURNING_NODES)
    W = basis_twin(c, n)
    E = W.T @ (A @ W)
    E[np.diag(E) == 0.0, np.diag(E) == 0.0] = 1.0
    np.testing.assert_allclose(KC.galerkin(blocks, c, k, np.zeros(1, np.int64)), E, rtol=1e-10, atol=1e-12 * np.abs(E).max())
    np.testing.assert_allclose(c.inv @ E, np.eye(6 * k), atol=1e-8)
    r = np.random.default_rng(5).normal(size=(n, 3))
    z = np.zeros((n, 3))
    KC.add_correction(c, r, z)
    want = W @ (np.linalg.solve(E, W.T @ r.ravel()))
    np.testing.assert_allclose(z.ravel(), want, rtol=1e-9, atol=1e-12 * np.abs(want).max())


def test_a_crack_splits_the_aggregates_it_crosses(monkeypatch):
    """On the cut slab, with cells that span the blade's plane, the nodes on the two sides of the
    crack are never in one aggregate (no node is joined to one across it, so the wound's opening is
    in the coarse space), while below the crack, where the tissue is whole, aggregates span it."""
    monkeypatch.setattr("cutkit.relax.newton.COARSE_CELLS", 4)
    tis = cut_slab()
    em = tis.em
    x = tis.positions.copy()
    A, blocks, inv, solver = _block_system(em, x)
    free = ~em.fixed
    c = coarse_space(blocks, x, free)
    assert c is not None
    side = x[:, 1] > 1.37  # the blade's plane
    split = 0
    for a in range(int(c.agg.max()) + 1):
        members = np.flatnonzero(c.agg == a)
        near = members[np.abs(x[members, 1] - 1.37) < 0.6]
        upper = x[near, 2] > 1.5  # where the cut reached
        sides = set(side[near[upper]].tolist())
        assert len(sides) <= 1, a
        split += len(set(side[members].tolist())) > 1
    assert split > 0  # below the crack an aggregate spans both sides (the tissue is whole there)


def test_two_level_conjugate_gradients_reach_the_direct_solution_in_fewer_iterations():
    """The same right-hand side to 1e-10: the two-level solve equals scipy's direct one, its
    preconditioner is symmetric, and it takes far fewer iterations than block Jacobi on the slender
    bar (186 against 58 here)."""
    em, x, free, A, blocks, inv = bent_bar()
    c = coarse_space(blocks, x, free)
    n = em.n_nodes
    b = np.random.default_rng(7).normal(size=(n, 3)) * free
    flag = np.zeros(1, np.int64)
    d1, d2 = np.empty((n, 3)), np.empty((n, 3))
    s1, its_bj = KB.block_pcg(blocks, inv, b, 1e-10, 5000, flag, d1, False)
    s2, its_two = KB.block_pcg(blocks, inv, b, 1e-10, 5000, flag, d2, False, c)
    assert s1 == s2 == KB.CG_DONE
    direct = spla.spsolve(A.tocsc(), b.ravel())
    for d in (d1, d2):
        np.testing.assert_allclose(d.ravel(), direct, rtol=1e-7, atol=1e-8 * np.abs(direct).max())
    assert its_two < 0.5 * its_bj, (its_two, its_bj)
    r1, r2 = np.random.default_rng(8).normal(size=(2, n, 3))
    z1, z2 = np.zeros((n, 3)), np.zeros((n, 3))
    KC.add_correction(c, r2, z1)
    KC.add_correction(c, r1, z2)
    assert np.sum(r1 * z1) == pytest.approx(np.sum(r2 * z2), rel=1e-11)


def test_a_waiting_cut_stops_the_coarse_space_and_the_iteration_is_abandoned():
    """With the halt flag up, coarse_space returns None without finishing E, and the two-level
    solver's linear solve gives up (None), as its conjugate gradients do."""
    em, x, free, A, blocks, inv = bent_bar()
    up = np.ones(1, np.int64)
    assert coarse_space(blocks, x, free, up) is None
    assert coarse_space(blocks, x, free, np.zeros(1, np.int64)) is not None
    solver = NewtonSolver(em, linear="cg", preconditioner="two_level")
    solver.matrix(x, free, np.full(em.n_nodes, 1e-3), 1)
    r = np.ones(3 * em.n_nodes) * free.ravel()
    assert solver._solve_linear(A, r, x, free, 1e-6, up) is None
    d = solver._solve_linear(A, r, x, free, 1e-10, np.zeros(1, np.int64))
    np.testing.assert_allclose(d, spla.spsolve(A.tocsc(), r), rtol=1e-7, atol=1e-8 * np.abs(d).max())


def test_aggregates_are_the_connected_pieces_of_each_cell():
    """``cell_aggregates`` against scipy's connected components of the same graph (the matrix's
    blocks between movable nodes of one cell), numbered by first node as it does."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    em, x, free, A, blocks, inv = bent_bar()
    n = em.n_nodes
    rng = np.random.default_rng(2)
    cell = rng.integers(0, 6, n).astype(np.int64)
    movable = free.any(axis=1)
    agg, k = cell_aggregates(blocks, cell, movable)
    rows = np.repeat(np.arange(n), np.diff(blocks.ptr))
    keep = movable[rows] & movable[blocks.col] & (cell[rows] == cell[blocks.col])
    graph = coo_matrix((np.ones(keep.sum()), (rows[keep], blocks.col[keep])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    want, seen = np.full(n, -1), {}
    for i in np.flatnonzero(movable):
        want[i] = seen.setdefault(label[i], len(seen))
    assert k == len(seen) > 6 and np.array_equal(agg, want)
