"""The Newton matrix's pattern carried over cuts (cutkit.relax.hessian_pattern) equals a full build
and a NumPy twin, array for array, after each change."""

import numpy as np

from _tissues import with_cut_mesh
from _fem_reference import kuhn_box
from cutkit.cutting import cut_step
from cutkit.relax import _newton_kernels as KN
from cutkit.relax import hessian_pattern
from cutkit.relax.hessian_pattern import HessianPattern
from cutkit.relax.newton import NewtonSolver
from test_newton import model_of
from cutkit.relax.elastic import build_element_model
from cutkit.relax.elastic_tissue import ElasticTissue


def twin_pattern(tets, volume, n):
    """The node rows and element blocks, the obvious way: a node's row is itself and every corner
    of the active elements it is a corner of, sorted; a block is its column's place in the row."""
    rows = [{i} for i in range(n)]
    for t, v in zip(tets, volume):
        if v > 0:
            for i in t:
                rows[i].update(int(j) for j in t)
    ptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])])
    idx = np.concatenate([sorted(r) for r in rows]).astype(np.int64)
    blocks = np.full((len(tets), 4, 4), -1, np.int64)
    for k, (t, v) in enumerate(zip(tets, volume)):
        if v > 0:
            for a in range(4):
                row = list(idx[ptr[t[a]]:ptr[t[a] + 1]])
                blocks[k, a] = [ptr[t[a]] + row.index(j) for j in t]
    return ptr, idx, blocks


def full_pattern(em):
    m = em.n_elements
    tets, volume = em.tets[:m], em.volume[:m]
    ptr, idx, _ = KN.node_neighbours(tets, volume, em.n_nodes, np.zeros(1, np.int64))
    blocks, _ = KN.element_blocks(tets, volume, ptr, idx, np.zeros(1, np.int64))
    return KN.Pattern(ptr, idx, blocks, *KN.scalar_pattern(ptr, idx))


def assert_same(pattern, em):
    full = full_pattern(em)
    for name in KN.Pattern._fields:
        np.testing.assert_array_equal(getattr(pattern, name), getattr(full, name), err_msg=name)
    m = em.n_elements
    ptr, idx, blocks = twin_pattern(em.tets[:m], em.volume[:m], em.n_nodes)
    np.testing.assert_array_equal(pattern.node_ptr, ptr)
    np.testing.assert_array_equal(pattern.node_idx, idx)
    np.testing.assert_array_equal(pattern.element_blocks, blocks)


def box_model():
    p, t = kuhn_box((4.0, 3.0, 3.0), (4, 3, 3))
    return p, build_element_model(model_of(p, t))


def test_each_kind_of_change_is_carried_over_as_a_full_build_would_make_it():
    """Elements taken out, new nodes with new elements, an element's corners rewritten in place,
    one put back, inactive ones appended: each time the kept pattern is updated (no full build)
    and equals a full build and the twin."""
    p, em = box_model()
    store = HessianPattern(em)
    assert_same(store.get(), em)
    rng = np.random.default_rng(4)
    mu, lam, rho = em.mu[:1], em.lam[:1], np.ones(1)
    X = p.copy()

    def add(tets, ids=None):
        nonlocal X
        tets = np.asarray(tets, np.int64).reshape(-1, 4)
        k = tets.shape[0]
        em.add_elements(X, tets, np.repeat(mu, k), np.repeat(lam, k), np.repeat(rho, k), ids=ids)

    gone = rng.choice(em.n_elements, 5, replace=False)
    corners = np.unique(em.tets[gone])
    em.remove_elements(gone)
    store.changed()
    assert_same(store.get(), em)
    assert store.elements_changed == 5 and store.rows_rebuilt == corners.size  # only their corners' rows
    # two new nodes near an element's corners, and two elements on them
    t0 = em.tets[[i for i in range(em.n_elements) if em.volume[i] > 0][0]].copy()
    new = X[t0[:2]] + 0.1
    X = np.vstack([X, new])
    em.add_nodes(2)
    n0 = em.n_nodes - 2
    add([[t0[0], t0[1], t0[2], n0], [n0, t0[1], t0[2], n0 + 1]])
    store.changed()
    assert_same(store.get(), em)
    # an element's corners rewritten in place (a slot reused for another tet)
    k = int(gone[0])
    add([[t0[0], t0[2], t0[3], n0 + 1]], ids=np.array([k]))
    store.changed()
    assert_same(store.get(), em)
    # inactive slots appended past the end: the pattern grows its element blocks, rows as they were
    em.remove_elements(np.array([em.n_elements - 1]))
    store.changed()
    assert_same(store.get(), em)
    assert store.builds == 1 and store.updates == 4


def test_a_cut_slab_keeps_its_pattern_from_cut_to_cut(monkeypatch):
    """A blade drawn through a slab in 15 steps: after every step the tissue's kept pattern (the one
    its Newton solvers share) equals a full build of the cut model (updated every time, however
    much of this small slab a step touched)."""
    monkeypatch.setattr(hessian_pattern, "FULL_BUILD_FRACTION", 1.0)
    p, t = kuhn_box((6.0, 3.0, 3.0), (6, 3, 3))
    tis = with_cut_mesh(ElasticTissue(model_of(p, t), step_s=0.02), 1.6)
    solver = NewtonSolver(tis.em, pattern=tis.hessian_pattern)
    assert_same(solver.pattern(), tis.em)
    for xb in np.linspace(-0.5, 6.5, 15):
        tis.apply_cut(cut_step(tis.cm, [xb, 1.37, 3.5], [0.0, 0.0, 1.0]))
        solver.reset()
        assert_same(solver.pattern(), tis.em)
    assert tis.em.n_nodes > tis.cm.n_orig_points  # the blade cut
    assert tis.hessian_pattern.builds == 1 and tis.hessian_pattern.updates >= 10


def test_a_waiting_cut_stops_an_update_and_the_next_call_makes_it():
    p, em = box_model()
    store = HessianPattern(em)
    before = store.get()
    em.remove_elements(np.array([3, 7]))
    store.changed()
    assert store.get(np.ones(1, np.int64)) is None
    assert store.get(np.zeros(1, np.int64)) is not before
    assert_same(store.get(), em)
    assert store.builds == 1 and store.updates == 1


def test_an_unchanged_model_keeps_the_same_pattern_object():
    p, em = box_model()
    store = HessianPattern(em)
    first = store.get()
    store.changed()
    assert store.get() is first and store.updates == 0


def test_a_live_tissue_at_rest_makes_its_pattern_while_idle_and_an_offline_one_does_not():
    """Resting steps already in balance have nothing to do: in a live session (a stop flag given) they
    make the matrix pattern then, so that the resting step after the next stroke only updates it;
    offline (no flag) nothing is made that no step needs."""
    p, t = kuhn_box((4.0, 3.0, 3.0), (4, 3, 3))
    for stop, builds in ((np.zeros(1, np.int64), 1), (None, 0)):
        tis = with_cut_mesh(ElasticTissue(model_of(p, t), step_s=0.02), 1.6)
        tis.advance(np.zeros((tis.n_nodes, 3)), 0.1, stop)
        assert tis.counts["resting_steps"] > 0
        assert tis.hessian_pattern.builds == builds
        if builds:
            assert_same(tis.hessian_pattern.get(), tis.em)
