"""Local Newton against whole-model Newton on the demo incision: per-step wall, regions, iterations.

Usage: python benchmarks/newton_local.py --json --knee knee.h5 [--rings none,2] [--rows N] [--hold S]

For each ``--rings`` value (``none``: every iteration solves the whole model; k: the local solve of
``NewtonSolver(region_rings=k)``, set through ``elastic_tissue.NEWTON_REGION_RINGS``) runs
``simulate`` with ``--solver newton`` on the first ``--rows`` trajectory rows of the demo incision
(all by default) and a ``--hold`` hold, and reports: simulated/wall, steps and steps not converged
(on the whole model's true residual), the worst step residual over the force scale, each Newton
solve's wall time (median, p95, max), iterations per step, local and whole-model iterations and
the local regions' dofs (median, max).  Run the variants back to back on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def run(model, traj, rings, hold_s: float) -> dict:
    import tempfile
    from pathlib import Path

    from cutkit.relax import newton
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.relax import elastic_tissue as et

    solvers, walls = [], []
    original_solve, original_make = newton.NewtonSolver.solve, et.ElasticTissue._newton_solver

    def timed_solve(self, *a, **k):
        t0 = time.perf_counter()
        info = original_solve(self, *a, **k)
        walls.append(time.perf_counter() - t0)
        print(f"solve {len(walls)}: {walls[-1]:.3f} s, {info.iterations} iterations, residual {info.residual:.3g} N, "
              f"regions {self.region_log[-info.iterations:] if info.iterations else []}", file=sys.stderr, flush=True)
        return info

    def kept_solver(self):
        s = original_make(self)
        solvers.append(s)
        return s

    et.NEWTON_REGION_RINGS = rings
    newton.NewtonSolver.solve, et.ElasticTissue._newton_solver = timed_solve, kept_solver
    try:
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            s = simulate(model, traj, Path(d), SimulateOptions(fps=10, frames=False, hold_s=hold_s, solver="newton"))
            wall = time.perf_counter() - t0
    finally:
        newton.NewtonSolver.solve, et.ElasticTissue._newton_solver = original_solve, original_make
        et.NEWTON_REGION_RINGS = None
    rs = s["relax_steps"]
    step_walls = np.array(walls[-rs["count"]:]) if rs["count"] else np.zeros(1)  # the settle's solves come first
    regions = np.array([d for sv in solvers for d in sv.region_log if d] or [0])
    counts = {k: int(sum(sv.counts[k] for sv in solvers)) for k in solvers[0].counts} if solvers else {}
    return {"rings": rings, "simulated_per_wall": s["simulated_per_wall"], "simulate_wall_s": wall,
            "steps": rs["count"], "steps_not_converged": rs["not_converged"],
            "worst_step_relative_residual": rs["worst_relative_residual"], "rtol": rs["rtol"],
            "iterations_per_step_median": float(np.median(rs["iterations"] or [0])),
            "iterations_per_step_max": int(max(rs["iterations"] or [0])),
            "step_wall_s": {"median": float(np.median(step_walls)), "p95": float(np.percentile(step_walls, 95)),
                            "max": float(step_walls.max()), "total": float(step_walls.sum())},
            "region_dofs": {"median": float(np.median(regions)), "max": int(regions.max())},
            "counts": counts, "cut_tets": s["cut_tets"], "opening_mm": s["cut_opening_mm"]["final_mean"],
            "inverted_tets_deformed": s["inverted_tets_deformed"], "warnings": s["warnings"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--knee", required=True, help="the demo's knee.h5")
    ap.add_argument("--rings", default="none,2", help="comma-separated: none or a ring count")
    ap.add_argument("--rows", type=int, default=0, help="first trajectory rows only (0: all)")
    ap.add_argument("--hold", type=float, default=0.0, help="hold after the incision, s")
    args = ap.parse_args(argv)
    import dataclasses

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.demo import demo_inputs
    from cutkit.io.model_h5 import read_model

    traj = read_trajectory(demo_inputs()[1])
    if args.rows:
        k = args.rows
        traj = dataclasses.replace(traj, t=traj.t[:k], tip=traj.tip[:k], a=traj.a[:k], n=traj.n[:k])
    model = read_model(args.knee)
    out = {"rows": len(traj), "hold_s": args.hold, "runs": []}
    for r in args.rings.split(","):
        out["runs"].append(run(model, traj, None if r == "none" else int(r), args.hold))
    if args.json:
        json.dump(out, sys.stdout, indent=1)
        print()
    else:
        for r in out["runs"]:
            print(r)


if __name__ == "__main__":
    main()
