"""Relaxation throughput (paper section 5): spring updates per second, 1M-tet sweep, adaptive lists.

Usage: python benchmarks/relax.py [--json] [--big N] [--small N] [--knee MODEL.h5] [--knee-simulate MODEL.h5]
       python benchmarks/relax.py --json --knee-simulate knee.h5 --solvers newton,vbd [--hold 1.0]
       python benchmarks/relax.py --json --knee-simulate knee.h5 --solvers vbd,hybrid --repeat 2 --no-to-residual
       python benchmarks/relax.py --json --knee-simulate head.h5 --trajectory head_cut.csv --solvers vbd,hybrid --lift --static

Prints one JSON object with ``--json``:
  spring_updates_per_s                  semi-implicit Jacobi sweep (numba, all threads), spring ends per s
  numpy_baseline_spring_updates_per_s   vectorised NumPy explicit step on the same mesh, same process
  speedup_vs_numpy
  sweep_ms_1m_tets                      one Jacobi sweep of all nodes of a ~1M-tet Kuhn grid, ms
  gauss_seidel_sweep_ms_1m_tets         the same as a coloured parallel Gauss-Seidel sweep
  adaptive_steps_per_s_100k_tets        finest steps dt_0 of simulated time per wall second,
                                        adaptive node lists, local load on a ~100k-tet grid
  adaptive_update_fraction_100k_tets    node updates of the adaptive run / those of a uniform run at dt_0
  element_sweep_ms_1m_tets              one vertex block descent sweep of the element model, same grid
  element_over_spring_sweep             element sweep / spring Gauss-Seidel sweep (goal <= 3)
  knee (with --knee MODEL.h5): wall time to a relative residual of 1e-4 of the settle problem
  (prestress and boundary conditions, from rest), for the element model (projected Newton, the
  hybrid's settle; modified Newton with AMG-CG, the vbd solver's; vertex block descent)
  and the springs (uniform Gauss-Seidel steps and adaptive node lists), and the sweeps or node
  updates each took: the equal-accuracy comparison of docs/relaxation.md; and ``simulate``'s
  simulated/wall on it with the shipped incision, for both material models (knee.simulate), and
  for the element model over the incision shifted by 0 .. 5 um (``--knee-paths``; the cut follows the tissue, so
  the work changes from path to path).  ``--knee-simulate MODEL.h5`` runs knee.simulate alone;
  with ``--solvers newton,vbd`` it instead runs the demo incision and a ``--hold`` with each element
  solver (knee.solvers: steps not converged, worst step residual, simulated/wall, the final
  out-of-balance force over the force scale, the opening) and the wall time each takes to bring
  the cut knee to 1e-3 of its force scale (knee.solvers.to_residual; ``--no-to-residual`` leaves
  that out).  ``--repeat N`` runs the solvers in turn N times (keys ``vbd``, ``hybrid``, ``vbd#2``,
  ...: back to back on a shared machine); each run reports ``relaxation_wall_s`` and, for the
  hybrid, ``polish_iterations_total``, ``polished_steps``, ``polish_calls`` and ``polish_s`` (the
  polishes' wall seconds, in all and by part).  ``--static`` adds to each run a static projected
  Newton solve of its cut model from its final state to 1e-3 of the force scale (``static``: the
  mean distance between node copies coincident at rest before and after, how far nodes move).
  Each run of ``--solvers`` also reports ``newton_rest_steps``: for every resting step that made a
  Newton iteration (``cutkit.relax.newton.rest_step``), its wall seconds, Newton iterations, CG
  iterations and sweeps.  ``--rest-smoothing N`` sets the sweeps a resting step makes between its
  Newton iterations (``cutkit.relax.elastic_tissue.REST_SMOOTHING_SWEEPS``; 0: none) for a
  before/after on the same machine.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time

import numpy as np

from cutkit.model.tetmodel import MATERIAL_FIELDS, BoundaryConditions, Materials, TetModel
from cutkit.relax import Control, build_spring_model, initial_state
from cutkit.relax import _kernels as K
from cutkit.relax.adaptive import NodeLists
from cutkit.relax.integrate import advance_nodes, colour_classes
from cutkit.relax.run import explicit_time_limit

_KUHN = np.array([[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]])


def kuhn_grid(nx, ny, nz, h=1.0):
    """Box of nx ny nz cubes, six positively oriented tets each."""
    ii, jj, kk = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    points = np.stack([ii, jj, kk], -1).reshape(-1, 3) * float(h)
    ci, cj, ck = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    nid = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k  # noqa: E731
    corners = np.stack([nid(ci + (c & 1), cj + ((c >> 1) & 1), ck + ((c >> 2) & 1)) for c in range(8)], 1)
    tets = corners[:, _KUHN].reshape(-1, 4)
    p = points[tets]
    det = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    tets[det < 0] = tets[det < 0][:, [0, 2, 1, 3]]
    return points, tets


def block_model(n_cubes_side, nz=None, damping=200.0):
    nz = nz or n_cubes_side
    pts, tets = kuhn_grid(n_cubes_side, n_cubes_side, nz, 1.0)
    row = {k: 0.0 for k in MATERIAL_FIELDS}
    row.update(label=1, name="tissue", E=1e4, density=1000.0, damping=damping)
    fixed = np.flatnonzero(pts[:, 2] == 0)
    return TetModel.from_arrays(pts, tets, materials=Materials.from_rows([row]),
                                boundary=BoundaryConditions(fixed_nodes=fixed))


def numpy_explicit_step(x, v, springs, rest, k, mass, dt):
    """Vectorised NumPy symplectic Euler step (the baseline)."""
    d = x[springs[:, 1]] - x[springs[:, 0]]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    fs = (k * (length - rest) / length)[:, None] * d
    f = np.zeros_like(x)
    for c in range(3):
        f[:, c] = np.bincount(springs[:, 0], fs[:, c], minlength=len(x)) - np.bincount(springs[:, 1], fs[:, c], minlength=len(x))
    v = v + dt * f / mass[:, None]
    return x + dt * v, v


def best_of(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def element_sweep(tm) -> dict:
    """One vertex block descent sweep of the element model over all free nodes, ms (best of 5)."""
    from cutkit.relax import _elastic_kernels as EK
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.vbd import _node_terms

    em = build_element_model(tm, poisson_ratio=0.45)
    rng = np.random.default_rng(0)
    x = tm.points + rng.normal(scale=1e-3, size=tm.points.shape) * ~em.fixed
    terms = _node_terms(em, x, 0.01, None, None, x.copy())
    offsets, nodes = em.colour_classes()
    r2 = np.zeros(em.n_nodes)

    def sweep():
        EK.vbd_sweep(x, em.adjacency, terms, offsets, nodes, r2, np.zeros(1, np.int64))

    sweep()
    return {"element_sweep_ms_1m_tets": best_of(sweep, 5) * 1e3, "element_colours": int(offsets.shape[0] - 1)}


#: The shipped incision is also run shifted by k * 1 um along x, k = 1 .. KNEE_PATHS - 1: the cut
#: depends on the relaxed tissue, so a shift far below any tolerance changes the cut and the
#: relaxation's work after it (docs/relaxation.md, "Simulate on the knee").
KNEE_PATHS = 6


def knee_simulate(model, paths: int = KNEE_PATHS) -> dict:
    """``cutkit simulate``'s simulated/wall on the model with the shipped incision, for both material
    models (no frames written; the settle is not in the ratio), and for the element model the
    same over ``paths`` incisions shifted by a micrometre each."""
    import dataclasses
    import tempfile
    from pathlib import Path

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.demo import demo_inputs

    traj = read_trajectory(demo_inputs()[1])

    def run(name, trajectory):
        with tempfile.TemporaryDirectory() as d:
            s = simulate(model, trajectory, Path(d), SimulateOptions(fps=10, frames=False, material_model=name))
        return {"simulated_per_wall": s["simulated_per_wall"], "time_per_task_s": s["time_per_task_s"],
                "cut_tets": s["cut_tets"], "inverted_tets_deformed": s["inverted_tets_deformed"],
                "sweeps": s["counts"].get("relax_sweeps"), "steps_capped": s["counts"].get("relax_steps_not_converged"),
                "opening_mm": s["cut_opening_mm"]["final_mean"], "cut_step_ms_median": s["cut_step_ms"]["median"]}

    res = {name: run(name, traj) for name in ("neohookean", "springs")}
    shifted = [res["neohookean"]] + [run("neohookean", dataclasses.replace(traj, tip=traj.tip + [1e-3 * k, 0.0, 0.0]))
                                     for k in range(1, paths)]
    ratio = np.array([r["simulated_per_wall"] for r in shifted])
    res["neohookean_shifted_paths"] = {
        "shift_mm": [1e-3 * k for k in range(paths)], "runs": shifted,
        "simulated_per_wall_median": float(np.median(ratio)), "simulated_per_wall_min": float(ratio.min()),
        "simulated_per_wall_max": float(ratio.max()),
        "sweeps_median": float(np.median([r["sweeps"] for r in shifted])),
        "steps_capped_median": float(np.median([r["steps_capped"] for r in shifted]))}
    return res


def knee_solvers(model, solvers=("newton", "vbd"), hold_s: float = 1.0, rtol: float = 1e-3,
                 cap_s: float = 600.0, trajectory=None, repeat: int = 1, to_residual: bool = True,
                 static: bool = False, lift: bool = False, static_rtol: float = 1e-5,
                 rest_rtol: float | None = None, from_closed: bool = False) -> dict:
    """The demo incision with each element solver (``SimulateOptions.solver``) and a ``hold_s`` hold:
    steps not converged, worst step residual, simulated/wall, the final out-of-balance force over
    the force scale, the opening; then, on the cut model the first solver left, the wall time each
    solver takes to bring it to ``rtol`` of the force scale (static; vertex block descent with
    Chebyshev acceleration, stopped after ``cap_s``).

    ``lift``: the blade is drawn out of the wound before the hold (``live.lifted``), so the hold has
    no load and the final out-of-balance force (the elastic forces alone) is the model's own; with
    the blade left in, that figure counts the blade's load too, and ``last_step_relative_residual``
    (the step's own, load included) is the one to read.  ``static`` solves to ``static_rtol``."""
    import tempfile
    from pathlib import Path

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.vbd import elastic_forces
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.demo import demo_inputs

    traj = trajectory if trajectory is not None else read_trajectory(demo_inputs()[1])
    if lift:
        from live import lifted

        traj = lifted(traj)
    out, cut = {}, None
    runs = [(name, name if k == 0 else f"{name}#{k + 1}") for k in range(repeat) for name in solvers]
    for name, key in runs:
        with tempfile.TemporaryDirectory() as d, timed_rest_steps() as rest_steps:
            t0 = time.perf_counter()
            s = simulate(model, traj, Path(d), SimulateOptions(fps=10, frames=False, hold_s=hold_s, solver=name,
                                                               rest_rtol=rest_rtol))
            wall = time.perf_counter() - t0
            cm = read_model(Path(d) / "model.h5")
        rs = s["relax_steps"]
        em = build_element_model(cm)
        x = cm.points + cm.point_data["displacement"]
        free = ~em.fixed & (em.adj_degree > 0)[:, None]
        out[key] = {"steps": rs["count"], "steps_not_converged": rs["not_converged"],
                     "worst_step_relative_residual": rs["worst_relative_residual"],
                     "last_step_relative_residual": rs["relative_residual"][-1] if rs["relative_residual"] else None,
                     "min_J_worst": rs.get("min_J_worst"), "steps_with_crushed_tets": rs.get("steps_with_crushed_tets"),
                     "iterations_total": rs["iterations_total"], "force_scale_N": rs["force_scale_N"],
                     "final_out_of_balance_relative": float(np.linalg.norm(elastic_forces(em, x)[free])
                                                            / rs["force_scale_N"]),
                     "simulated_per_wall": s["simulated_per_wall"], "simulate_wall_s": wall,
                     "time_per_task_s": s["time_per_task_s"], "cut_tets": s["cut_tets"],
                     "opening_mm": s["cut_opening_mm"]["final_mean"], "settle": s["settle"],
                     "inverted_tets_deformed": s["inverted_tets_deformed"], "warnings": s["warnings"],
                     "relaxation_wall_s": s["time_per_task_s"]["relaxation"], "newton_rest_steps": rest_steps,
                     **{k: rs[k] for k in ("polish_iterations_total", "polished_steps", "polish_calls", "polish_s",
                                           "resting_steps", "rest_rtol") if k in rs}}
        if static:
            out[key]["static"] = static_reference(em, cm.points, x, static_rtol * rs["force_scale_N"])
        if cut is None:
            cut = (em, x, rs["force_scale_N"], cm)
    if not to_residual:
        return out
    em, x0, scale, cut_model = cut
    out["to_residual"] = _to_residual(em, x0, scale, rtol, cap_s)
    if from_closed:
        out["to_residual_from_closed"] = _to_residual(em, closed_wound(model, cut_model), scale, rtol, cap_s)
    return out


@contextlib.contextmanager
def timed_rest_steps():
    """A list that gets, for each resting step that makes a Newton iteration while the context is open,
    ``{"wall_s", "newton_iterations", "cg_iterations", "sweeps"}`` (``cutkit.relax.newton.rest_step``
    wrapped: the runtime imports it where it calls it)."""
    from cutkit.relax import newton

    steps, plain = [], newton.rest_step

    def timed(em, state, h, f_ext, **kw):
        cg, t0 = kw["solver"].counts["cg_iterations"], time.perf_counter()
        info, swept = plain(em, state, h, f_ext, **kw)
        if info.iterations:
            steps.append({"wall_s": time.perf_counter() - t0, "newton_iterations": int(info.iterations),
                          "cg_iterations": int(kw["solver"].counts["cg_iterations"] - cg), "sweeps": int(swept)})
        return info, swept

    newton.rest_step = timed
    try:
        yield steps
    finally:
        newton.rest_step = plain


def closed_wound(model, cut_model) -> np.ndarray:
    """(n, 3) float64: the cut model's nodes where the settled, uncut ``model`` has their rest points
    (its settle, as ``simulate`` makes it, cached): the wound closed, every cut-made tet the affine image
    of its rest shape inside its original tet, so no tet is inverted and the whole opening is left to
    solve.  Each node's rest point is found among the original tets (those of the 64 nearest centroids)."""
    from scipy.spatial import cKDTree

    from cutkit.simulate import SimulateOptions
    from cutkit.simulate.session import settle
    from cutkit.simulate.tissues import make_tissue

    opt = SimulateOptions()
    tis = make_tissue(model, None, "neohookean", opt)
    settle(tis, "neohookean", opt, [])
    settled, rest, tets = tis.positions[: model.n_points], model.points, model.tets
    x = np.empty_like(cut_model.points)
    dist, same = cKDTree(rest).query(cut_model.points)
    exact = dist <= 1e-9 * float(np.ptp(rest))  # an original node (or a copy of one)
    x[exact] = settled[same[exact]]
    q = cut_model.points[~exact]
    corners = rest[tets]
    _, near = cKDTree(corners.mean(axis=1)).query(q, k=64)
    c = corners[near]  # (m, 64, 4, 3)
    T = np.einsum("nkij->nkji", c[:, :, 1:] - c[:, :, :1])  # (m, 64, 3, 3): edge vectors as columns
    lam = np.linalg.solve(T, (q[:, None, :] - c[:, :, 0])[..., None])[..., 0]
    bary = np.concatenate([1.0 - lam.sum(-1, keepdims=True), lam], axis=-1)  # (m, 64, 4)
    best = np.argmax(bary.min(-1), axis=1)
    rows = np.arange(q.shape[0])
    b = bary[rows, best]
    if b.size and b.min() < -1e-6:
        raise RuntimeError(f"a node's rest point lies outside every original tet near it ({b.min():.2e})")
    x[~exact] = np.einsum("nk,nkj->nj", b, settled[tets[near[rows, best]]])
    return x


def _to_residual(em, x0: np.ndarray, scale: float, rtol: float, cap_s: float) -> dict:
    """Wall time of a static Newton solve and of Chebyshev-accelerated vertex block descent from x0 (n, 3)
    to ``rtol`` of the force scale (N), the sweeps stopped after ``cap_s``."""
    from cutkit.relax.newton import NewtonSolver, newton_static
    from cutkit.relax.vbd import _node_terms, elastic_forces, iterate

    free = ~em.fixed & (em.adj_degree > 0)[:, None]
    atol = rtol * scale
    to = {"rtol": rtol, "start_relative": float(np.linalg.norm(elastic_forces(em, x0)[free]) / scale)}
    x = x0.copy()
    t0 = time.perf_counter()
    solver = NewtonSolver(em)
    info = newton_static(em, x, rtol=0.0, atol=atol, solver=solver)
    to["newton"] = {"wall_s": time.perf_counter() - t0, "iterations": info.iterations, "converged": info.converged,
                    "relative": float(np.linalg.norm(elastic_forces(em, x)[free]) / scale), **solver.counts}
    x = x0.copy()
    terms = _node_terms(em, x, None, None, None)
    t0, sweeps, info = time.perf_counter(), 0, None
    while time.perf_counter() - t0 < cap_s:
        info = iterate(em, x, terms, rtol=0.0, atol=atol, max_iterations=200, chebyshev=0.9)
        sweeps += info.iterations
        if info.converged:
            break
    to["vbd_chebyshev"] = {"wall_s": time.perf_counter() - t0, "sweeps": sweeps, "converged": bool(info.converged),
                           "relative": float(np.linalg.norm(elastic_forces(em, x)[free]) / scale)}
    to["vbd_over_newton"] = to["vbd_chebyshev"]["wall_s"] / to["newton"]["wall_s"]
    return to


def static_reference(em, X, x, atol: float) -> dict:
    """A static projected Newton solve of the cut model from a run's final state x to ``atol`` N (the
    equilibrium the run's state relaxes to): the mean distance between node copies that coincide at
    rest (X; the cut's duplicated nodes) before and after, mm, and how far the nodes move to it."""
    from anp_knee import coincident_pairs
    from cutkit.relax.newton import NewtonSolver, newton_static

    pairs = coincident_pairs(X)
    xs = x.copy()
    t0 = time.perf_counter()
    info = newton_static(em, xs, rtol=0.0, atol=atol, solver=NewtonSolver(em))
    move = np.linalg.norm(xs - x, axis=1)

    def opening(y):
        return float(np.linalg.norm(y[pairs[:, 0]] - y[pairs[:, 1]], axis=1).mean()) if len(pairs) else 0.0

    return {"wall_s": time.perf_counter() - t0, "iterations": info.iterations, "converged": bool(info.converged),
            "coincident_pairs": int(len(pairs)), "opening_mm": opening(x), "static_opening_mm": opening(xs),
            "move_max_mm": float(move.max()), "move_p99_mm": float(np.percentile(move, 99))}


def slab_solvers(hold_s: float = 1.0, solvers=("newton", "vbd"), **runs) -> dict:
    """knee_solvers on the prestressed slab of tests/test_simulate.py (16 x 6 x 8 cubes of 2 mm,
    4,608 tets, muscle, 15 % prestrain across the cut) with its 20 mm incision, 5 mm deep
    (``runs``: knee_solvers' ``repeat`` and ``to_residual``)."""
    import sys
    from pathlib import Path

    from cutkit.cutting.trajectory import straight_incision

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from test_simulate import slab

    traj = straight_incision([6.0, 0.0, 8.3], [26.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                             press_time=0.3, cut_time=0.6, rate=100)
    return knee_solvers(slab(0.15), solvers, hold_s=hold_s, trajectory=traj, **runs)


def gmsh_slab_solvers(hold_s: float = 1.0, solvers=("newton", "vbd"), **runs) -> dict:
    """slab_solvers on gmsh's Delaunay mesh of the same 32 x 12 x 16 mm slab (mesh size 2 mm; an
    imported mesh: no grid, no Kuhn split), muscle, 15 % prestrain along z, the z ends held."""
    import sys
    from pathlib import Path

    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.cutting.trajectory import straight_incision

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from _fem_reference import delaunay_box

    points, tets = delaunay_box(np.array([32.0, 12.0, 16.0]), 2.0)
    ends = np.flatnonzero((np.abs(points[:, 2]) < 1e-9) | (np.abs(points[:, 2] - 16.0) < 1e-9))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    from cutkit.model.tetmodel import Prestress

    model = TetModel.from_arrays(points, tets, materials=Materials.from_rows([row]),
                                 boundary=BoundaryConditions(fixed_nodes=ends),
                                 prestress=Prestress(label=np.array([1], np.int32),
                                                     fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                                                     prestrain=np.array([0.15])))
    traj = straight_incision([6.0, 0.0, 8.3], [26.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                             press_time=0.3, cut_time=0.6, rate=100)
    out = knee_solvers(model, solvers, hold_s=hold_s, trajectory=traj, **runs)
    out["mesh"] = {"points": int(points.shape[0]), "tets": int(tets.shape[0])}
    return out


def knee_to_residual(model, rtol: float) -> dict:
    """Wall time and work to bring the settle problem to ``rtol`` with each model and schedule."""
    from cutkit.relax import spring_forces
    from cutkit.relax.elastic import build_element_model, initial_element_state
    from cutkit.relax.equilibrium import static_solve
    from cutkit.relax.vbd import elastic_forces
    from cutkit.relax.newton import newton_static
    from cutkit.relax.settle import settle_static

    res = {"tets": model.n_tets, "rtol": rtol}
    em = build_element_model(model)
    st = initial_element_state(model)
    static_solve(em, st.positions.copy(), max_iterations=2, solver="vbd")  # compile
    free = ~em.fixed
    for name in ("element_projected_newton", "element_newton_amg", "element_vbd"):
        x = st.positions.copy()
        t0 = time.perf_counter()
        if name == "element_vbd":
            info = static_solve(em, x, rtol=rtol, atol=0.0, max_iterations=2000, chebyshev=0.9, solver="vbd")
        elif name == "element_projected_newton":  # the hybrid's and the newton solver's settle
            info = newton_static(em, x, rtol=rtol, atol=0.0)
        else:  # the vbd solver's settle: modified Newton with the linear stiffness, AMG-CG
            info = settle_static(em, x, rtol=rtol)
        wall = time.perf_counter() - t0
        r0 = np.linalg.norm(elastic_forces(em, st.positions)[free])
        res[name] = {"wall_s": wall, "iterations": info.iterations, "converged": info.converged,
                     "relative_residual_exact": float(np.linalg.norm(elastic_forces(em, x)[free]) / r0)}
        if wall > 600:
            break

    sm = build_spring_model(model)
    free = ~sm.fixed

    def relative(stt):
        return float(np.linalg.norm(spring_forces(sm, stt.positions)[free]) / r0)

    r0 = float(np.linalg.norm(spring_forces(sm, sm.rest_positions)[free]))
    dt0 = explicit_time_limit(sm)
    for name, n_lists in (("springs_uniform", 1), ("springs_adaptive", 6)):
        stt = initial_state(sm)
        lists = NodeLists(sm, stt, dt0, n_lists, displacement_tolerance=1e-4 * float(np.mean(sm.rest_length)))
        t0 = time.perf_counter()
        t_sim, reached = 0.0, relative(stt)
        while reached > rtol and time.perf_counter() - t0 < 300:
            t_sim += 64 * dt0
            lists.advance(None, t_sim)
            reached = relative(stt)
        res[name] = {"wall_s": time.perf_counter() - t0, "node_updates": int(stt.n_updates.sum()),
                     "simulated_s": t_sim, "relative_residual": reached, "converged": reached <= rtol}
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--big", type=int, default=55, help="cubes per side of the ~1M-tet grid (55 -> 998k tets)")
    ap.add_argument("--small", type=int, default=26, help="cubes per side of the ~100k-tet grid (26 -> 105k tets)")
    ap.add_argument("--knee", help="model file for the equal-accuracy comparison (e.g. cutkit-demo/knee.h5)")
    ap.add_argument("--rtol", type=float, default=1e-4, help="relative residual of the equal-accuracy comparison")
    ap.add_argument("--knee-simulate", metavar="MODEL", help="only simulate's simulated/wall on this model (knee.simulate)")
    ap.add_argument("--solvers", default=None,
                    help="with --knee-simulate: compare these element solvers (e.g. newton,vbd) instead")
    ap.add_argument("--hold", type=float, default=1.0, help="hold after the incision of --solvers, s")
    ap.add_argument("--trajectory", metavar="CSV",
                    help="with --knee-simulate and --solvers: this incision instead of the shipped one "
                         "(another model, e.g. an MRI head; docs/relaxation.md)")
    ap.add_argument("--repeat", type=int, default=1, help="with --solvers: run them in turn this many times")
    ap.add_argument("--static", action="store_true",
                    help="with --solvers: a static Newton solve from each run's final state (its opening)")
    ap.add_argument("--lift", action="store_true",
                    help="with --solvers: draw the blade out before the hold (a hold without load)")
    ap.add_argument("--static-rtol", type=float, default=1e-5,
                    help="with --static: the static solve's residual over the force scale")
    ap.add_argument("--rest-rtol", type=float, default=None,
                    help="with --solvers: the resting steps' tolerance (simulate --rest-rtol; default the runtime's)")
    ap.add_argument("--vbd-cap", type=float, default=600.0,
                    help="with --solvers: seconds the sweeps of to_residual may take (then not converged)")
    ap.add_argument("--to-rtol", type=float, default=1e-3,
                    help="with --solvers: the force-scale fraction of to_residual (default 1e-3)")
    ap.add_argument("--from-closed", action="store_true",
                    help="with --solvers: also bring the cut knee to 1e-3 from its wound closed "
                         "(to_residual_from_closed: the settled uncut knee at the cut nodes' rest points)")
    ap.add_argument("--no-to-residual", action="store_true",
                    help="with --solvers: leave out the static solves of the cut knee to 1e-3 (to_residual)")
    ap.add_argument("--slab-solvers", action="store_true",
                    help="the --solvers comparison on tests/test_simulate.py's prestressed slab")
    ap.add_argument("--gmsh-slab-solvers", action="store_true",
                    help="the --solvers comparison on gmsh's Delaunay mesh of the same slab (an imported mesh)")
    ap.add_argument("--knee-paths", type=int, default=KNEE_PATHS,
                    help="incisions of knee.simulate, each shifted by 1 um more (the stalls vary from path to path)")
    ap.add_argument("--rest-smoothing", type=int, default=None,
                    help="with --solvers: sweeps between a resting step's Newton iterations (default the runtime's)")
    args = ap.parse_args(argv)
    if args.rest_smoothing is not None:
        from cutkit.relax import elastic_tissue

        elastic_tissue.REST_SMOOTHING_SWEEPS = args.rest_smoothing
    out = {}
    slabs = {"gmsh_slab": (args.gmsh_slab_solvers, gmsh_slab_solvers), "slab": (args.slab_solvers, slab_solvers)}
    for key, (asked, solve) in slabs.items():
        if asked:
            names = tuple(args.solvers.split(",")) if args.solvers else ("newton", "vbd")
            out[key] = {"solvers": solve(args.hold, names, repeat=args.repeat, to_residual=not args.no_to_residual,
                                         static=args.static, lift=args.lift, static_rtol=args.static_rtol,
                                         rest_rtol=args.rest_rtol)}
            return _print(out, args.json)
    if args.knee_simulate:
        from cutkit.io.model_h5 import read_model

        if args.solvers:
            from cutkit.cutting.trajectory import read_trajectory

            traj = read_trajectory(args.trajectory) if args.trajectory else None
            out["knee"] = {"solvers": knee_solvers(read_model(args.knee_simulate), tuple(args.solvers.split(",")),
                                                   hold_s=args.hold, repeat=args.repeat, trajectory=traj,
                                                   to_residual=not args.no_to_residual, static=args.static,
                                                   lift=args.lift, static_rtol=args.static_rtol,
                                                   from_closed=args.from_closed, rtol=args.to_rtol,
                                                   rest_rtol=args.rest_rtol,
                                                   cap_s=args.vbd_cap)}
            return _print(out, args.json)
        out["knee"] = {"simulate": knee_simulate(read_model(args.knee_simulate), args.knee_paths)}
        return _print(out, args.json)

    tm = block_model(args.big)
    sm = build_spring_model(tm)
    st = initial_state(sm)
    rng = np.random.default_rng(0)
    st.positions += rng.normal(scale=1e-3, size=st.positions.shape) * ~sm.fixed[:, None]
    nodes = sm.free_nodes
    f = np.zeros((sm.n_nodes, 3))
    g = np.array([0.0, 0.0, -9806.65])
    dt = explicit_time_limit(sm)
    ends = int(sm.adj_offsets[nodes + 1].sum() - sm.adj_offsets[nodes].sum())
    out["n_tets_big"] = tm.n_tets
    out["n_nodes_big"] = sm.n_nodes
    out["n_springs_big"] = sm.n_springs
    t = [0.0]

    def jacobi():
        t[0] += dt
        advance_nodes(sm, st, nodes, t[0], f, g, K.MODE_AXIAL, None)

    jacobi()
    sweep = best_of(jacobi, 10)
    out["sweep_ms_1m_tets"] = sweep * 1e3
    out["spring_updates_per_s"] = ends / sweep
    classes = colour_classes(sm, nodes)

    def gs():
        t[0] += dt
        advance_nodes(sm, st, nodes, t[0], f, g, K.MODE_AXIAL, classes)

    gs()
    out["gauss_seidel_sweep_ms_1m_tets"] = best_of(gs, 5) * 1e3
    out.update(element_sweep(tm))
    out["element_over_spring_sweep"] = out["element_sweep_ms_1m_tets"] / out["gauss_seidel_sweep_ms_1m_tets"]
    x, v = st.positions.copy(), st.velocities.copy()
    np_step = best_of(lambda: numpy_explicit_step(x, v, sm.springs, sm.rest_length, sm.stiffness, sm.masses, dt), 3)
    # the NumPy step touches every spring once (both ends): 2 s spring-end updates
    out["numpy_baseline_spring_updates_per_s"] = 2 * sm.n_springs / np_step
    out["speedup_vs_numpy"] = out["spring_updates_per_s"] / out["numpy_baseline_spring_updates_per_s"]
    del sm, st, tm

    tm = block_model(args.small)
    sm = build_spring_model(tm)
    dt0 = explicit_time_limit(sm)
    pts = tm.points
    f = np.zeros((sm.n_nodes, 3))
    top = np.flatnonzero((pts[:, 2] == args.small) & (np.abs(pts[:, 0] - args.small / 2) <= 2)
                        & (np.abs(pts[:, 1] - args.small / 2) <= 2))
    f[top, 2] = -1e-3 / len(top)
    control = Control(external_forces=f)
    st = initial_state(sm)
    lists = NodeLists(sm, st, dt0, 6, displacement_tolerance=1e-5)
    lists.advance(control, 8 * dt0)  # warm-up (compile) and settle the lists
    n_steps = 400
    t0 = time.perf_counter()
    lists.advance(control, (8 + n_steps) * dt0)
    wall = time.perf_counter() - t0
    out["n_tets_small"] = tm.n_tets
    out["adaptive_steps_per_s_100k_tets"] = n_steps / wall
    out["adaptive_update_fraction_100k_tets"] = float(st.n_updates.sum() / ((8 + n_steps) * len(sm.free_nodes)))
    out["adaptive_list_sizes"] = [int(len(x)) for x in lists.node_lists]
    if args.knee:
        from cutkit.io.model_h5 import read_model

        out["knee"] = knee_to_residual(read_model(args.knee), args.rtol)
        out["knee"]["simulate"] = knee_simulate(read_model(args.knee), args.knee_paths)
    import numba

    out["threads"] = numba.get_num_threads()
    _print(out, args.json)


def _print(out: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(out))
    else:
        for key, val in out.items():
            print(f"{key:40s} {val:.4g}" if isinstance(val, float) else f"{key:40s} {val}")


if __name__ == "__main__":
    main()
