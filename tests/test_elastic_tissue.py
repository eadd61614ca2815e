"""The element tissue's handling of what a cut makes: tets born folded are opened where they are made."""

import numpy as np

from _tissues import with_cut_mesh
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import signed_volumes
from cutkit.model.tetmodel import Materials, TetModel
from cutkit.relax.elastic_tissue import ElasticTissue


def tissue(solver="hybrid", jitter=0.0):
    p, t = box_mesh((3, 3, 3), spacing=(1.0, 1.0, 1.0))
    p = p + np.random.default_rng(3).uniform(-jitter, jitter, p.shape)
    row = dict(label=1, name="m", E=30e3, poisson_ratio=0.45, density=1090.0, damping=8.0, F_enter=0.8,
               mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
               c_edge=1.0, c_shape=1.0)
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([row]))
    return with_cut_mesh(ElasticTissue(model, step_s=0.004, solver=solver), 10.0)


def interior_node(tis):
    x = tis.rest_positions
    return int(np.argmin(np.linalg.norm(x - x.mean(axis=0), axis=1)))


def test_lift_opens_a_folded_tet_and_keeps_the_others_open():
    tis = tissue()
    i = interior_node(tis)
    em = tis.em
    around = em.tets[em.tets_of(i)]
    rest = signed_volumes(tis.rest_positions, around)
    # push the node through the opposite face of one of its tets: that tet folds
    t = around[0]
    others = [a for a in t if a != i]
    centre = tis.positions[others].mean(axis=0)
    tis.positions[i] += 1.6 * (centre - tis.positions[i])
    J = signed_volumes(tis.positions, around) / rest
    assert J.min() < 0.0
    tis._lift(i, around, rest)
    J = signed_volumes(tis.positions, around) / rest
    assert J.min() > 0.0


def test_lift_moves_a_node_no_farther_than_its_tets_reach():
    """A folded tet whose face opposite the node is squashed near a line: the exact step that opens it
    is far longer than the tets (J barely depends on the node); the lift stops at UNFOLD_REACH of the
    distance to the farthest corner of the node's tets (a node was thrown 500 mm so), and what it
    leaves folded the relaxation opens."""
    from cutkit.relax.elastic_tissue import UNFOLD_REACH

    tis = tissue()
    i = interior_node(tis)
    em = tis.em
    around = em.tets[em.tets_of(i)][:1]  # the one tet the node is lifted for
    rest = signed_volumes(tis.rest_positions, around)
    a, b, c = [v for v in around[0] if v != i]
    x = tis.positions
    x[c] = x[a] + (x[b] - x[a]) * 0.5 + 1e-6 * (x[c] - x[a])  # the opposite face almost a segment
    x[i] += 1.6 * ((x[a] + x[b] + x[c]) / 3.0 - x[i])  # through it
    start = x[i].copy()
    reach = np.sqrt(((x[around.ravel()] - start) ** 2).sum(axis=1).max())
    assert signed_volumes(x, around)[0] < 0.0
    tis._lift(i, around, rest)
    assert 0.0 < np.linalg.norm(tis.positions[i] - start) <= UNFOLD_REACH * reach * (1 + 1e-12)


def test_unfold_never_takes_a_place_off_the_tissue():
    """A corner node folded inward, whose place before the step (as handed over) lies 500 mm out: far
    out every tet of a node on the surface opens, so a vote by the smallest volume ratio alone took
    it; candidates farther than the node's farthest tet corner are not looked at."""
    tis = tissue()
    x = tis.positions
    i = int(np.argmin(x.sum(axis=1)))  # the box's corner at its origin
    em = tis.em
    around = em.tets[em.tets_of(i)]
    centre = x[around.ravel()].mean(axis=0)
    out = (x[i] - centre) / np.linalg.norm(x[i] - centre)
    reach = np.sqrt(((x[around.ravel()] - x[i]) ** 2).sum(axis=1).max())
    x[i] = centre + (centre - x[i])  # pushed through its tets: all folded
    assert (signed_volumes(x, around) <= 0.0).any()
    tis._unfold(np.arange(em.n_elements), np.array([i]), (x[i] + 500.0 * out)[None])
    assert np.linalg.norm(tis.positions[i] - centre) < 2.0 * reach


def test_unfold_leaves_a_mesh_without_folds_alone():
    tis = tissue()
    x0 = tis.positions.copy()
    tets = np.arange(tis.em.n_elements)
    placed = np.array([interior_node(tis)])
    tis._unfold(tets, placed, tis.positions[placed].copy())
    assert np.array_equal(tis.positions, x0)


def test_a_raised_stop_flag_leaves_the_step_untaken():
    """A cut waiting for the lock (the flag raised) before the first sweep ends: nothing moves, no time passes."""
    tis = tissue()
    f = np.zeros((tis.n_nodes, 3))
    f[interior_node(tis), 2] = 5.0
    x0, t0 = tis.positions.copy(), tis.time
    stop = np.ones(1, np.int64)
    assert tis.advance(f, t0 + 3 * tis.step_s, stop) == 0
    assert tis.time == t0 and np.array_equal(tis.positions, x0)
    stop[0] = 0
    assert tis.advance(f, t0 + 3 * tis.step_s, stop) > 0
    assert tis.time > t0 and not np.array_equal(tis.positions, x0)


def test_a_cut_waiting_at_the_end_of_a_step_leaves_its_smallest_volume_ratio_unmeasured():
    """The per-step report pass (the smallest J) does not make a waiting cut wait: a flag raised once
    the step is made leaves that step's min_J None (counted in steps_without_min_J), the step itself
    taken; the worst is taken over the steps measured."""
    class RaisedAfterTheStep(ElasticTissue):
        def _sweep_step(self, f_ext, loaded, atol, stop):
            out = super()._sweep_step(f_ext, loaded, atol, stop)
            if stop is not None and self.step_log["min_J"]:
                stop[0] = 1
            return out

    tis = tissue()
    tis.__class__ = RaisedAfterTheStep
    f = np.zeros((tis.n_nodes, 3))
    f[interior_node(tis), 2] = 5.0
    stop = np.zeros(1, np.int64)
    tis.advance(f, tis.time + tis.step_s + 1e-9, stop)  # one step, measured
    assert tis.advance(f, tis.time + tis.step_s + 1e-9, stop) > 0  # taken, its report pass stopped
    rep = tis.relax_report()
    assert rep["count"] == 2 and rep["min_J"][1] is None and rep["steps_without_min_J"] == 1
    assert rep["min_J_worst"] == rep["min_J"][0] < 1.0


def test_the_sweep_kernel_reads_the_stop_flag_before_each_colour_class():
    from cutkit.relax import _elastic_kernels as K
    from cutkit.relax.vbd import _node_terms

    tis = tissue()
    em = tis.em
    x = tis.positions.copy()
    f = np.zeros((em.n_nodes, 3))
    f[:, 2] = 1.0
    terms = _node_terms(em, x, tis.step_s, f, None, x.copy())
    offsets, nodes = em.colour_classes()
    assert K.vbd_sweep(x, em.adjacency, terms, offsets, nodes, np.zeros(em.n_nodes),
                       np.ones(1, np.int64)) == 0
    assert np.array_equal(x, tis.positions)
    assert K.vbd_sweep(x, em.adjacency, terms, offsets, nodes, np.zeros(em.n_nodes),
                       np.zeros(1, np.int64)) == offsets.size - 1
    assert not np.array_equal(x, tis.positions)


def test_a_held_node_keeps_no_residual_from_before():
    """A node held (or left without tets by a cut) after its last sweep does not keep later steps from converging.

    Its last residual stayed in the sum: on the demo knee one orphan kept 1.4 N
    (the step tolerance 0.28 N) and every later step ran to the sweep cap.
    """
    from cutkit.relax.vbd import local_step

    tis = tissue()
    em = tis.em
    i = interior_node(tis)
    em.fixed[i] = True
    em._classes = None
    r2 = np.zeros(em.n_nodes)
    r2[i] = 1.4 ** 2
    info = local_step(em, tis.state, tis.step_s, np.zeros((em.n_nodes, 3)), r2, np.zeros(0, np.int64),
                      atol=0.28, max_iterations=50)
    assert info.converged and info.iterations <= 1 and r2[i] == 0.0


def test_laying_out_the_rows_in_sweep_order_changes_no_result():
    """The pool written again colour by colour: the rows follow the sweep order and a sweep gives the same bits."""
    from cutkit.relax import _elastic_kernels as K
    from cutkit.relax.elastic import ElementModel
    from cutkit.relax.vbd import _node_terms

    tis = tissue()
    cm = tis.cm
    em = ElementModel.empty(tis.n_nodes, cm.orig_tets.shape[0])  # rows in node order, as added
    em.add_elements(cm._X[:tis.n_nodes], cm.orig_tets, tis.mu, tis.lam, tis.density)
    em.recolour()
    x = tis.positions + np.random.default_rng(3).normal(scale=0.05, size=tis.positions.shape)
    terms = _node_terms(em, x, tis.step_s, np.zeros((em.n_nodes, 3)), None, x.copy())
    offsets, nodes = em.colour_classes()
    rows_before = [sorted(em.tets_of(i).tolist()) for i in range(em.n_nodes)]
    assert not np.all(np.diff(em.adj_start[nodes]) > 0)
    xa = x.copy()
    K.vbd_sweep(xa, em.adjacency, terms, offsets, nodes, np.zeros(em.n_nodes), np.zeros(1, np.int64))
    em.lay_out_rows()
    assert [sorted(em.tets_of(i).tolist()) for i in range(em.n_nodes)] == rows_before
    assert np.all(np.diff(em.adj_start[nodes]) > 0)  # sweep order is pool order
    xb = x.copy()
    K.vbd_sweep(xb, em.adjacency, terms, offsets, nodes, np.zeros(em.n_nodes), np.zeros(1, np.int64))
    assert np.array_equal(xa, xb) and not np.array_equal(xa, x)


def test_removing_elements_leaves_the_rows_a_fresh_build_has():
    """A cut takes elements out of the node rows: every node's row then holds exactly what a model
    built without them holds (tet, corner, other corners, terms; the order of the rest kept), and
    the masses agree to rounding; a node left with no tet has mass exactly 0.  Built a few
    elements at a time from a pool with no room, the rows are the same."""
    from cutkit.relax.elastic import ElementModel

    tis = tissue()
    cm = tis.cm
    n, m = tis.n_nodes, cm.orig_tets.shape[0]
    gone = np.random.default_rng(4).choice(m, m // 5, replace=False)
    lone = cm.orig_tets[gone[0], 0]
    gone = np.union1d(gone, np.flatnonzero((cm.orig_tets == lone).any(axis=1)))  # every tet of one node
    keep = np.setdiff1d(np.arange(m), gone)

    def build(ids):
        em = ElementModel.empty(n, m)
        em.add_elements(cm._X[:n], cm.orig_tets[ids], tis.mu[ids], tis.lam[ids], tis.density[ids], ids=ids)
        return em

    cut, fresh = build(np.arange(m)), build(keep)
    # added a few at a time into a pool with no room: the rows move and the pool grows, same rows
    grown = ElementModel.empty(n, 1)
    for ids in np.array_split(keep, 9):
        grown.add_elements(cm._X[:n], cm.orig_tets[ids], tis.mu[ids], tis.lam[ids], tis.density[ids], ids=ids)
    cut.remove_elements(gone)

    def row(em, i):
        s, d = em.adj_start[i], em.adj_degree[i]
        return [(int(t), int(c), em.adj_opposite[s + k].tolist(), em.adj_terms[s + k].tolist())
                for k, (t, c) in enumerate(zip(em.adj_tets[s:s + d], em.adj_corner[s:s + d]))]

    assert all(row(cut, i) == row(fresh, i) == row(grown, i) for i in range(n))
    assert grown.adj_tets.shape[0] >= grown.adj_used >= 4 * keep.size
    np.testing.assert_allclose(cut.masses, fresh.masses, rtol=1e-12, atol=1e-30)
    orphans = np.flatnonzero(fresh.adj_degree[:n] == 0)
    assert lone in orphans and np.all(cut.masses[orphans] == 0.0)


def test_the_kept_forces_are_the_whole_models_at_every_step_of_a_cut(monkeypatch, tmp_path):
    # a step's true residual reads the kept elastic forces (KeptForces): summed again only where the
    # step moved nodes or a cut changed tets; at every call they must be the whole pass's, bit for bit
    from test_simulate import slab

    from cutkit.cutting.trajectory import straight_incision
    from cutkit.relax.vbd import elastic_forces
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.relax import elastic_tissue
    from cutkit.relax.elastic_tissue import KeptForces

    # every change summed in part, however large (on this small slab a step often wakes a quarter)
    monkeypatch.setattr(elastic_tissue, "KEPT_FORCES_WHOLE_SHARE", 1.0)
    calls = {"kept": 0, "whole": 0}
    get, whole = KeptForces.get, KeptForces._whole

    def checked_get(self, em, x):
        f = get(self, em, x)
        assert np.array_equal(f, elastic_forces(em, x))
        calls["kept"] += 1
        return f

    def counted_whole(self, em, x):
        calls["whole"] += 1
        return whole(self, em, x)

    monkeypatch.setattr(KeptForces, "get", checked_get)
    monkeypatch.setattr(KeptForces, "_whole", counted_whole)
    traj = straight_incision([6.0, 0.0, 8.3], [16.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                             press_time=0.2, cut_time=0.2, rate=100)
    # the hybrid: its sweeps' steps and its polished steps both read the kept forces
    summary = simulate(slab(), traj, tmp_path / "run", SimulateOptions(frames=False, hold_s=0.1, solver="hybrid",
                                                                     write_model=False))
    assert summary["cut_tets"] > 0 and summary["relax_steps"]["polish_calls"] > 0
    assert calls["kept"] > 20 and calls["whole"] <= 2  # summed whole at the first step (and a rebase)


def test_at_rest_after_a_resting_step_in_balance_only_with_the_hybrid_and_newton():
    """at_rest: the hybrid's or Newton's last step rested within its tolerance (a live session starts
    a stroke's rebase then); never before a step, never with the sweeps alone."""
    for solver in ("hybrid", "newton", "vbd"):
        tis = tissue(solver)
        assert not tis.at_rest()
        f = np.zeros((tis.n_nodes, 3))
        f[interior_node(tis), 2] = -1e-4  # a small load, held: the steps after the first rest
        tis.advance(f, tis.time + tis.step_s)
        assert not tis.at_rest()  # the first step cannot rest: no load before it to compare with
        tis.advance(f, tis.time + 3 * tis.step_s)
        assert tis.at_rest() == (solver != "vbd")
        assert tis.counts.get("resting_steps", 0) >= (solver != "vbd")


def test_an_unloaded_model_takes_a_one_percent_strain_as_its_force_scale():
    """Without prestress or a prescribed displacement the model's as-built forces are rounding
    (about 1e-16 N); its force scale is then that of a 1 % strain of every tet (the NumPy twin of
    the forces at 1.01 times the rest shape), so a step's tolerance is a force, and a loaded step
    converges instead of chasing rounding to its cap."""
    import _twins_elastic as T

    tis = tissue("newton", jitter=0.2)  # off the grid: the as-built forces are rounding, not exactly 0
    em, n = tis.em, tis.n_nodes
    X = tis.rest_positions
    Dminv, volume, _ = T.rest_shape(X, em.tets[:em.n_elements])
    m = em.n_elements
    as_built = np.linalg.norm(T.forces(X, em.tets[:m], Dminv, volume, em.mu[:m], em.lam[:m]))
    strained = np.linalg.norm(T.forces(1.01 * X, em.tets[:m], Dminv, volume, em.mu[:m], em.lam[:m]))
    assert as_built < 1e-9 * strained
    assert abs(tis.force_scale - strained) <= 1e-9 * strained
    f = np.zeros((n, 3))
    f[interior_node(tis), 2] = 0.05 * strained
    tis.advance(f, tis.time + 2 * tis.step_s)
    rep = tis.relax_report()
    assert rep["not_converged"] == 0 and rep["worst_relative_residual"] <= rep["rtol"], rep
