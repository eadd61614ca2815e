"""The hybrid solver: vertex block descent steps that stall at their sweep cap are finished by a local
Newton polish, converged on the whole model's true residual, at the state a minimiser written here
reaches, no tet ever inverted; a step the sweeps finish alone is untouched."""

import numpy as np
import pytest

from _tissues import with_cut_mesh
from _fem_reference import kuhn_box, trust_region_minimum
from _twins_elastic import deformation_gradients
from cutkit.errors import CutkitError
from cutkit.mesh.quality import signed_volumes
from cutkit.model.tetmodel import BoundaryConditions, Materials, TetModel
from cutkit.relax.hybrid import polish_step
from cutkit.relax.vbd import elastic_forces, local_step
from cutkit.simulate import SimulateOptions
from cutkit.relax.elastic_tissue import ElasticTissue

ROW = dict(label=1, name="m", E=30e3, poisson_ratio=0.45, density=1090.0, damping=8.0, F_enter=0.8,
           mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
           c_edge=1.0, c_shape=1.0)
H = 0.02


def pressed(solver, load, rest_rtol=None):
    """A 3 x 3 x 2 mm block held at its base, one top node pressed down by ``load`` N (a load that
    stays the same, so the hybrid's steps after the first rest unless ``rest_rtol`` is None)."""
    p, t = kuhn_box((3.0, 3.0, 2.0), (3, 3, 2))
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW]),
                                 boundary=BoundaryConditions(fixed_nodes=np.flatnonzero(p[:, 2] == 0)))
    tis = with_cut_mesh(ElasticTissue(model, step_s=H, solver=solver, rest_rtol=rest_rtol), 1.0)
    tis.em.forget_colour_classes()
    f = np.zeros_like(p)
    f[int(np.flatnonzero(p[:, 2] == 2.0)[4])] = [0.0, 0.0, -load]
    return tis, f


def true_residual(em, x, x0, v0, f, h=H):
    """N: the backward Euler residual's norm over the free dofs, written out here."""
    m = em.masses[:, None]
    r = elastic_forces(em, x) + f - m / h ** 2 * (x - x0 - h * v0) - em.damping[:, None] * m / h * (x - x0)
    return float(np.linalg.norm(r[~em.fixed & (em.adj_degree > 0)[:, None]]))


def test_steps_that_stall_the_sweeps_end_converged_and_no_tet_ever_inverts(monkeypatch):
    """0.3 N on one node crushes a tet into the barrier band (J ~ 4e-3): every sweep step ends at
    its cap; with the polish every step ends within its tolerance, and no Newton iterate inverts a tet."""
    import cutkit.relax.hybrid as HY

    vbd, f = pressed("vbd", 0.3)
    hyb, _ = pressed("hybrid", 0.3)
    lowest = []
    search = HY.line_search

    def watched(problem, x, d, r, res):
        out = search(problem, x, d, r, res)
        m = hyb.em.n_elements  # every tet of the model, at every accepted iterate
        lowest.append(np.linalg.det(deformation_gradients(x, hyb.em.tets[:m], hyb.em.Dminv[:m])).min())
        return out

    monkeypatch.setattr(HY, "line_search", watched)
    vbd.advance(f, 10 * H)
    assert vbd.relax_report()["not_converged"] == 10  # the case stalls the sweeps
    atol = hyb.step_rtol * hyb.force_scale
    for _ in range(10):
        x0, v0 = hyb.positions.copy(), hyb.velocities.copy()
        hyb.advance(f, hyb.time + H)
        assert true_residual(hyb.em, hyb.positions, x0, v0, f) <= atol
        np.testing.assert_array_equal(hyb.velocities[~hyb.em.fixed], ((hyb.positions - x0) / H)[~hyb.em.fixed])
        assert signed_volumes(hyb.positions, hyb.cm.tets).min() > 0
    rep = hyb.relax_report()
    assert rep["not_converged"] == 0 and rep["worst_relative_residual"] <= rep["rtol"]
    J_last = signed_volumes(hyb.positions, hyb.cm.tets) / signed_volumes(hyb.rest_positions, hyb.cm.tets)
    assert len(rep["min_J"]) == 10 and rep["min_J"][-1] == pytest.approx(J_last.min(), rel=1e-9)
    assert rep["min_J_worst"] == min(rep["min_J"]) and rep["crushed_J"] == 1e-3
    assert rep["steps_with_crushed_tets"] == sum(1 for j in rep["min_J"] if j < 1e-3)
    assert rep["polished_steps"] >= 1 and rep["polish_iterations_total"] == hyb.counts["newton_iterations"] > 0
    assert len(rep["polish_iterations"]) == rep["count"] == 10 and rep["polish_calls"] >= rep["polished_steps"]
    assert {"total", "assembly", "factorisation"} <= set(rep["polish_s"])
    J = signed_volumes(hyb.positions, hyb.cm.tets) / signed_volumes(hyb.rest_positions, hyb.cm.tets)
    assert J.min() < 0.01  # a tet in the barrier band
    assert lowest and min(lowest) > 0.0


def reference_step(em, x0, v0, f, h=H):
    """One backward Euler step from (x0, v0) minimised over every free dof at once by scipy's
    trust-region Newton (_fem_reference), from x0: no solver under test."""
    free = ~em.fixed
    m = em.masses[:, None]
    return trust_region_minimum(em, x0, f, free, ki=m / h ** 2, kd=em.damping[:, None] * m / h,
                                y=np.where(free, x0 + h * v0, x0), gtol=1e-11, maxiter=300)


def test_a_polished_step_is_the_backward_euler_step_of_a_reference_minimiser():
    """The sweeps stop at their cap on a crushing load; the polish of the same step, to a tight
    tolerance, reaches the minimiser of the step's potential that scipy finds (to 1e-6 mm)."""
    tis, f = pressed("vbd", 0.1)
    em, st = tis.em, tis.state
    x0, v0 = st.positions.copy(), st.velocities.copy()
    sweeps = local_step(em, st, H, f, np.zeros(em.n_nodes), np.arange(em.n_nodes), atol=1e-12, max_iterations=50)
    assert not sweeps.converged and sweeps.iterations == 50
    atol = 1e-9
    info, r = polish_step(em, st, x0, v0, H, f, atol=atol)
    assert info.converged and info.iterations > 0
    assert true_residual(em, st.positions, x0, v0, f) == pytest.approx(info.residual, rel=1e-6, abs=1e-12)
    assert info.residual <= atol and np.linalg.norm(r) == pytest.approx(info.residual, rel=1e-12)
    ref = reference_step(em, x0, v0, f)
    assert np.abs(st.positions - ref).max() <= 1e-6
    assert np.abs(ref - x0).max() > 1.0  # the step moved the loaded node by millimetres
    np.testing.assert_array_equal(st.velocities[~em.fixed], ((st.positions - x0) / H)[~em.fixed])


def test_a_step_the_polish_cannot_take_is_finished_on_the_whole_model(monkeypatch):
    """Where the out-of-balance region is more than a polish factorises (here: any region at all), the
    step is finished by whole-model projected Newton: it ends within its tolerance (1e-3 of the force
    scale), within 2 um of the minimiser of the step's potential that scipy finds from the same start
    (the step moves the loaded node by 11 mm), and is counted."""
    import cutkit.relax.hybrid as HY

    monkeypatch.setattr(HY, "CHOLESKY_MAX_DOFS", 0)  # the polish gives up before its first iteration
    hyb, f = pressed("hybrid", 0.1)
    hyb.step_max_iterations = 2  # the sweeps stop far from the step's end
    hyb.step_rtol = 1e-3
    x0, v0 = hyb.positions.copy(), hyb.velocities.copy()
    hyb.advance(f, H)
    rep = hyb.relax_report()
    assert rep["whole_model_finishes"] == 1 and rep["not_converged"] == 0
    assert rep["polish_iterations"] == [hyb.counts["newton_iterations"]] and hyb.counts["newton_iterations"] > 0
    assert true_residual(hyb.em, hyb.positions, x0, v0, f) <= 1e-3 * hyb.force_scale
    ref = reference_step(hyb.em, x0, v0, f)
    assert np.abs(hyb.positions - ref).max() <= 2e-3 and np.abs(ref - x0).max() > 10.0
    np.testing.assert_array_equal(hyb.velocities[~hyb.em.fixed], ((hyb.positions - x0) / H)[~hyb.em.fixed])
    assert signed_volumes(hyb.positions, hyb.cm.tets).min() > 0


def test_a_step_the_sweeps_finish_is_the_same_to_the_bit_with_the_hybrid():
    """A light load: the sweeps converge within their cap, the polish is never called, and the
    hybrid's states equal vertex block descent's bit for bit."""
    vbd, f = pressed("vbd", 0.002)
    hyb, _ = pressed("hybrid", 0.002)
    for k in range(1, 6):
        vbd.advance(f, k * H)
        hyb.advance(f, k * H)
        np.testing.assert_array_equal(hyb.positions, vbd.positions)
        np.testing.assert_array_equal(hyb.velocities, vbd.velocities)
    rep = hyb.relax_report()
    assert rep["not_converged"] == 0 and rep["polish_iterations"] == [0] * 5 and rep["polished_steps"] == 0
    assert rep["iterations"] == vbd.relax_report()["iterations"]
    assert rep["relative_residual"] == vbd.relax_report()["relative_residual"]
    assert "polish_iterations" not in vbd.relax_report()


def test_the_hybrid_is_a_solver_choice_and_the_polish_checks_its_input():
    SimulateOptions(solver="hybrid").check()
    with pytest.raises(CutkitError):
        SimulateOptions(solver="hybrid", element="anp").check()
    tis, f = pressed("hybrid", 0.1)
    x0 = tis.positions.copy()
    with pytest.raises(CutkitError, match="x0 must have shape"):
        polish_step(tis.em, tis.state, x0[:-1], np.zeros_like(x0), H, f, atol=1e-3)
    with pytest.raises(CutkitError, match="atol"):
        polish_step(tis.em, tis.state, x0, np.zeros_like(x0), H, f, atol=0.0)
    with pytest.raises(CutkitError, match="rings"):
        polish_step(tis.em, tis.state, x0, np.zeros_like(x0), H, f, atol=1e-3, rings=-1)


@pytest.mark.parametrize("iterations", [1, 2, 3, 5])
def test_a_polish_cut_short_never_hands_on_more_residual_than_it_was_given(iterations):
    """However few iterations it may make, the polish ends at its iterate of least residual (the
    sweeps' end included), with that residual and its velocities, every tet upright.  (0.3 N: the
    first iteration lowers G but raises the residual from 0.47 to 2.2 N, the third from 0.41 to 0.63 N.)"""
    tis, f = pressed("vbd", 0.3)
    em, st = tis.em, tis.state
    x0, v0 = st.positions.copy(), st.velocities.copy()
    local_step(em, st, H, f, np.zeros(em.n_nodes), np.arange(em.n_nodes), atol=1e-12, max_iterations=50)
    xs = st.positions.copy()
    info, r = polish_step(em, st, x0, v0, H, f, atol=1e-9, max_iterations=iterations)
    assert info.residual <= info.initial_residual
    if iterations == 1:  # its only iterate was worse: the sweeps' end stands
        np.testing.assert_array_equal(st.positions, xs)
    assert true_residual(em, st.positions, x0, v0, f) == pytest.approx(info.residual, rel=1e-9)
    np.testing.assert_array_equal(st.velocities[~em.fixed], ((st.positions - x0) / H)[~em.fixed])
    assert signed_volumes(st.positions, tis.cm.tets).min() > 0


def test_forces_at_some_nodes_equal_the_twins_and_the_whole_models_sums():
    """forces_at sums what node_forces sums for the nodes it is given, and both equal the NumPy
    twin's -dW/dx (a crushed block: the barrier is in the sums)."""
    from _twins_elastic import forces as forces_twin
    from cutkit.relax import _elastic_kernels as KE

    tis, f = pressed("vbd", 0.3)
    tis.advance(f, 3 * H)
    em, x = tis.em, tis.positions
    nodes = np.array([0, 5, 17, int(np.argmin(x[:, 2]))], np.int64)
    out = np.empty((nodes.size, 3))
    KE.forces_at(x, em.adjacency, nodes, out)
    whole = elastic_forces(em, x)
    np.testing.assert_array_equal(out, whole[nodes])
    m = em.n_elements
    twin = forces_twin(x, em.tets[:m], em.Dminv[:m], em.volume[:m], em.mu[:m], em.lam[:m])
    np.testing.assert_allclose(out, twin[nodes], rtol=1e-9, atol=1e-12 * np.abs(twin).max())


def test_the_polish_residual_kept_row_by_row_equals_the_whole_models():
    """The residual the polish keeps (rows of the region's nodes summed again after each iteration)
    equals the whole model's residual recomputed from scratch at the final positions."""
    tis, f = pressed("vbd", 0.3)
    em, st = tis.em, tis.state
    x0, v0 = st.positions.copy(), st.velocities.copy()
    local_step(em, st, H, f, np.zeros(em.n_nodes), np.arange(em.n_nodes), atol=1e-12, max_iterations=50)
    info, r = polish_step(em, st, x0, v0, H, f, atol=1e-9, max_iterations=4)
    assert info.iterations == 4
    m, x = em.masses[:, None], st.positions
    full = elastic_forces(em, x) + f - m / H ** 2 * (x - x0 - H * v0) - em.damping[:, None] * m / H * (x - x0)
    full[em.fixed] = 0.0
    np.testing.assert_allclose(r, full, rtol=0, atol=1e-12 * np.abs(full).max())


def test_resting_steps_go_on_to_the_rest_tolerance_once_the_blade_has_left(monkeypatch):
    """Resting steps under a load (the blade's) are solved to REST_FIRST_RTOL of the force scale; the
    step the load is taken off in rests too, solved to REST_UNLOADED_FIRST_RTOL; the resting steps of
    the unloaded tissue after it go on to the rest tolerance."""
    import cutkit.relax.newton as newton
    from cutkit.relax.elastic_tissue import REST_FIRST_RTOL, REST_SWEEPS, REST_UNLOADED_FIRST_RTOL
    from cutkit.relax.vbd import DEFAULT_ATOL_N

    asked, swept = [], []
    solve = newton.rest_step

    def recorded(*args, **kw):
        asked.append(kw["atol"])
        swept.append(kw["sweeps"])
        return solve(*args, **kw)

    monkeypatch.setattr(newton, "rest_step", recorded)
    hyb, f = pressed("hybrid", 0.1, rest_rtol=1e-9)
    scale, none = hyb.force_scale, np.zeros_like(f)
    for k, load in enumerate([f, f, f, none, none], start=1):  # the load taken off at the fourth step
        hyb.advance(load, k * H)
    x0, v0 = hyb.positions.copy(), hyb.velocities.copy()
    hyb.advance(none, 6 * H)
    loaded, left = REST_FIRST_RTOL * scale, REST_UNLOADED_FIRST_RTOL * scale
    tight = max(1e-9 * scale, DEFAULT_ATOL_N)
    assert asked == pytest.approx([loaded, loaded, left, tight, tight], rel=1e-15)
    assert swept == [REST_SWEEPS, REST_SWEEPS, 0, REST_SWEEPS, REST_SWEEPS]  # none where the blade just left
    assert true_residual(hyb.em, hyb.positions, x0, v0, none) <= DEFAULT_ATOL_N
    rep = hyb.relax_report()
    assert rep["resting"] == [False, True, True, True, True, True]
    assert rep["relative_residual"][3] <= REST_UNLOADED_FIRST_RTOL
    assert (rep["rest_first_rtol"], rep["rest_unloaded_first_rtol"]) == (REST_FIRST_RTOL, REST_UNLOADED_FIRST_RTOL)


def test_a_resting_step_is_the_backward_euler_step_of_a_reference_minimiser(monkeypatch):
    """Under a load that stays, every step after the first rests: a few whole-model sweeps, then Newton
    on the whole model; to a tight rest tolerance it is the minimiser scipy finds, no tet inverts.  The step
    stops at the solvers' floor of 1e-7 N (DEFAULT_ATOL_N), which leaves 2.7e-6 mm on this block's
    softest direction: hence 1e-5 mm (the reference's residual is 4e-13 N).  (The first resting step
    is asked the rest tolerance itself here: REST_FIRST_RTOL 0.)"""
    import cutkit.relax.elastic_tissue as ET
    from cutkit.relax.vbd import DEFAULT_ATOL_N

    monkeypatch.setattr(ET, "REST_FIRST_RTOL", 0.0)
    hyb, f = pressed("hybrid", 0.1, rest_rtol=1e-9)
    hyb.advance(f, H)  # the first step: no last load to compare with
    x0, v0 = hyb.positions.copy(), hyb.velocities.copy()
    hyb.advance(f, 2 * H)
    assert true_residual(hyb.em, hyb.positions, x0, v0, f) <= DEFAULT_ATOL_N
    ref = reference_step(hyb.em, x0, v0, f)
    assert true_residual(hyb.em, ref, x0, v0, f) <= 1e-11
    assert np.abs(hyb.positions - ref).max() <= 1e-5
    assert np.abs(ref - x0).max() > 1e-3  # the first step left it out of balance: the resting one moved
    np.testing.assert_array_equal(hyb.velocities[~hyb.em.fixed], ((hyb.positions - x0) / H)[~hyb.em.fixed])
    rep = hyb.relax_report()
    from cutkit.relax.elastic_tissue import REST_SMOOTHING_SWEEPS, REST_SWEEPS

    assert rep["resting"] == [False, True] and rep["resting_steps"] == 1
    assert rep["polish_iterations"][1] > 0 and rep["rest_rtol"] == 1e-9
    # the sweeps could not reach 1e-9: Newton finished, with at most REST_SMOOTHING_SWEEPS after each iteration
    assert REST_SWEEPS <= rep["iterations"][1] <= REST_SWEEPS + REST_SMOOTHING_SWEEPS * rep["polish_iterations"][1]
    assert signed_volumes(hyb.positions, hyb.cm.tets).min() > 0


def test_resting_steps_end_within_the_rest_tolerance_and_a_balanced_one_costs_no_iteration():
    """The default rest tolerance (tighter than a cutting step's): each resting step's true
    residual, written out here, is within it; once in balance a step makes no Newton iteration and
    the tissue is at rest."""
    from cutkit.relax.elastic_tissue import REST_RTOL
    from cutkit.relax.vbd import DEFAULT_ATOL_N

    hyb, f = pressed("hybrid", 0.3, rest_rtol=REST_RTOL)
    atol = max(REST_RTOL * hyb.force_scale, DEFAULT_ATOL_N)
    assert atol < hyb.step_rtol * hyb.force_scale
    for k in range(1, 7):
        x0, v0 = hyb.positions.copy(), hyb.velocities.copy()
        hyb.advance(f, k * H)
        if k > 1:
            assert true_residual(hyb.em, hyb.positions, x0, v0, f) <= atol
        assert signed_volumes(hyb.positions, hyb.cm.tets).min() > 0
    rep = hyb.relax_report()
    assert rep["not_converged"] == 0 and rep["resting_steps"] == 5
    assert rep["polish_iterations"][-1] == 0 and np.all(hyb.velocities == 0.0)
    assert max(rep["relative_residual"][1:]) <= REST_RTOL


def test_a_cut_or_a_new_load_ends_the_rest_and_the_rest_tolerance_is_checked():
    hyb, f = pressed("hybrid", 0.1, rest_rtol=1e-3)
    hyb.advance(f, H)
    hyb.advance(f, 2 * H)
    hyb.advance(1.5 * f, 3 * H)  # the blade moved: its load changed
    hyb._cut_since_step = True  # what a cut that added or removed tets leaves for the next step
    hyb.advance(1.5 * f, 4 * H)
    hyb.advance(1.5 * f, 5 * H)
    g = 1.5 * f
    g[1, 0] += 1e-9  # a still blade's load settles: a change within the rest tolerance still rests
    hyb._seeds.append(np.array([0], np.int64))  # a cut step that only moved nodes
    hyb.advance(g, 6 * H)
    assert hyb.relax_report()["resting"] == [False, True, False, False, True, True]
    p, t = kuhn_box((1.0, 1.0, 1.0), (1, 1, 1))
    model = TetModel.from_arrays(p, t, materials=Materials.from_rows([ROW]))
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(CutkitError, match="rest_rtol must be a positive number or None"):
            ElasticTissue(model, step_s=H, solver="hybrid", rest_rtol=bad)


def test_the_step_the_load_is_taken_off_in_rests_even_when_the_blade_cut_on_its_way_out():
    """A cut since the last step ends the rest, except in the step the blade's load goes to zero in:
    that step is solved on the whole model, to REST_UNLOADED_FIRST_RTOL by a residual written here; a
    cut while nothing loads the tissue still makes a step that does not rest."""
    from cutkit.relax.elastic_tissue import REST_UNLOADED_FIRST_RTOL

    hyb, f = pressed("hybrid", 0.1, rest_rtol=1e-6)
    none = np.zeros_like(f)
    hyb.advance(f, H)
    hyb.advance(f, 2 * H)
    hyb._cut_since_step = True  # the blade's last pose in the tissue cut
    x0, v0 = hyb.positions.copy(), hyb.velocities.copy()
    hyb.advance(none, 3 * H)  # ... and the next one is out: no load
    assert true_residual(hyb.em, hyb.positions, x0, v0, none) <= REST_UNLOADED_FIRST_RTOL * hyb.force_scale
    hyb.advance(none, 4 * H)
    hyb._cut_since_step = True  # a cut with no load before or after it
    hyb.advance(none, 5 * H)
    assert hyb.relax_report()["resting"] == [False, True, True, True, False]


def test_what_is_written_does_not_change_a_hybrid_run_with_resting_steps(tmp_path):
    """The hybrid's resting steps depend on the load and the cuts, never on the frames: a run
    writing 1 frame a second and one writing 30 cut the same model and write the same forces."""
    from test_settle_cache import _result, prestressed_block

    from cutkit.cutting.trajectory import straight_incision
    from cutkit.simulate import simulate

    model = prestressed_block()
    traj = straight_incision([3.0, 0.0, 4.3], [13.0, 0.0, 4.3], inward=[0, 1, 0], depth=3.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    fps = 1.0
    runs = {}
    for rate in (fps, 30.0):
        out = tmp_path / f"fps{rate:g}"
        runs[rate] = simulate(model, traj, out, SimulateOptions(fps=rate, hold_s=0.3, solver="hybrid"))
    assert runs[30.0]["relax_steps"]["resting_steps"] > 0 and runs[30.0]["frames"] > runs[fps]["frames"]
    assert runs[fps]["relax_steps"]["relative_residual"] == runs[30.0]["relax_steps"]["relative_residual"]
    for a, b in zip(_result(tmp_path / f"fps{fps:g}"), _result(tmp_path / "fps30")):
        if isinstance(a, str):
            assert a == b
        else:
            np.testing.assert_array_equal(a, b)  # to the bit


def test_the_kept_volume_ratios_report_what_the_whole_pass_reports_at_every_step_of_a_cut(monkeypatch, tmp_path):
    """The per-step smallest J comes from ratios kept between steps and computed again only where a
    node moved or a cut removed or added an element: through a cut, its hold and the tissue's
    unfolding of new tets, at every step it equals the whole pass over every element, bit for bit."""
    from test_settle_cache import prestressed_block

    from cutkit.cutting.trajectory import straight_incision
    from cutkit.relax.vbd import volume_ratio_extremes
    from cutkit.simulate import simulate
    from cutkit.relax.elastic_tissue import KeptVolumeRatios

    kept = KeptVolumeRatios.extremes
    seen = []

    def both(self, em, x, below, stop=None):
        out = kept(self, em, x, below, stop)
        seen.append((out, volume_ratio_extremes(em, x, below), int(self.mark.sum())))
        return out

    monkeypatch.setattr(KeptVolumeRatios, "extremes", both)
    traj = straight_incision([3.0, 0.0, 4.3], [13.0, 0.0, 4.3], inward=[0, 1, 0], depth=3.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    s = simulate(prestressed_block(), traj, tmp_path / "o", SimulateOptions(frames=False, hold_s=0.2, solver="hybrid"))
    assert s["cut_tets"] > 0 and len(seen) == s["relax_steps"]["count"] > 20
    for out, whole, left in seen:
        assert out == whole and left == 0
    assert min(j for (j, _), _, _ in seen) < 1.0  # the cut deforms the tissue: the report is not trivial


def test_prepare_resting_builds_the_pattern_the_resting_steps_then_keep():
    """``prepare_resting`` (a live session calls it before its clock starts) builds the Newton
    matrix's pattern once; the resting steps after it use that pattern without building it again,
    and a tissue solved by sweeps alone builds none."""
    hyb, f = pressed("hybrid", 0.1, rest_rtol=1e-9)
    assert hyb.hessian_pattern.builds == 0
    hyb.prepare_resting()
    assert hyb.hessian_pattern.builds == 1
    for k in range(1, 4):
        hyb.advance(f, k * H)
    assert hyb.relax_report()["resting"] == [False, True, True]
    assert hyb.relax_report()["polish_iterations"][1] > 0  # a resting step solved by Newton
    assert (hyb.hessian_pattern.builds, hyb.hessian_pattern.updates) == (1, 0)
    vbd, _ = pressed("vbd", 0.1)
    vbd.prepare_resting()
    assert vbd.hessian_pattern.builds == 0


def test_a_step_a_waiting_cut_ends_early_is_not_converged_and_its_residual_not_evaluated(monkeypatch):
    """The flag raised as a step's sweeps end (a cut arrives): the step is taken (its sweeps moved the
    nodes), counted not converged, its true residual not evaluated (a pass over every element the cut
    would wait for: no residual is asked for with the flag up) and reported as None; the same for a
    resting step; the closing line says so."""
    import cutkit.relax.elastic_tissue as ET
    import cutkit.relax.newton as N
    from cutkit.simulate.run import relax_steps_line

    tis, f = pressed("hybrid", 0.05, rest_rtol=1e-4)
    flag = np.zeros(1, np.int64)
    evaluated = []
    residual = ET.ElasticTissue._residual
    monkeypatch.setattr(ET.ElasticTissue, "_residual",
                        lambda self, *a: evaluated.append(int(flag[0])) or residual(self, *a))
    sweeps, rest = ET.local_step, N.rest_step

    def cut_arrives(step):
        def then(*a, **k):
            out = step(*a, **k)
            flag[0] = 1
            return out
        return then

    monkeypatch.setattr(ET, "local_step", cut_arrives(sweeps))
    x0 = tis.positions.copy()
    tis.advance(f, H, stop=flag)
    rep = tis.relax_report()
    assert rep["count"] == 1 and rep["relative_residual"] == [None] and rep["steps_without_residual"] == 1
    assert rep["not_converged"] == 1 and 1 not in evaluated and not np.array_equal(tis.positions, x0)
    assert relax_steps_line(rep).endswith("a waiting cut ended it early, its residual not evaluated")
    # the next step rests (the same load): a cut ends it after its sweeps
    monkeypatch.setattr(ET, "local_step", sweeps)
    monkeypatch.setattr(N, "rest_step", cut_arrives(rest))
    flag[0] = 0
    tis.advance(f, 2 * H, stop=flag)
    rep = tis.relax_report()
    assert rep["count"] == 2 and rep["resting"][-1] and rep["relative_residual"] == [None, None]
    assert rep["steps_without_residual"] == 2 and rep["not_converged"] == 2 and 1 not in evaluated
    # unstopped steps as ever: evaluated, and the worst residual is over them alone
    monkeypatch.setattr(N, "rest_step", rest)
    flag[0] = 0
    tis.advance(f, 5 * H, stop=flag)
    rep = tis.relax_report()
    assert rep["count"] == 5 and all(r is not None for r in rep["relative_residual"][2:]) and 0 in evaluated
    assert rep["worst_relative_residual"] == max(rep["relative_residual"][2:])
