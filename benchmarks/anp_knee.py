"""The demo knee's wound at equilibrium with each element: P1 (``nh``) and the average nodal pressure tet (``anp``).

Usage: python benchmarks/anp_knee.py --cut cutkit-demo/model.h5 [--rtol 1e-4] [--smoothing 0.7]
                                      [--nu 0.49] [--json]

The cut knee a run wrote (``cutkit demo``: the shipped incision; ``model.h5`` holds the cut mesh,
its rest positions and its final displacement) is solved to static equilibrium by Newton
(:func:`cutkit.relax.newton.newton_static`, the exact Hessian and the projected one where it is
indefinite) once with each element, both from the run's final state and to ``rtol`` of the model's
force scale (the out-of-balance force of its prestress in the rest configuration, P1's).  ``--nu``
sets every tissue's Poisson ratio (the knee's are 0.45, bone 0.3).

Prints per element: the wound's opening (the mean and largest distance between node copies that
coincide at rest), the smallest volume ratio J and the tets inverted at equilibrium, the Newton
iterations, conjugate-gradient iterations, whether it converged and the wall seconds; and the
largest distance between the two equilibria.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def coincident_pairs(X: np.ndarray) -> np.ndarray:
    """(p, 2) int64: every pair of nodes with the same rest position X (n, 3) (the cut's copies)."""
    _, group, counts = np.unique(X, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    pairs = []
    for g in np.flatnonzero(counts >= 2):
        nodes = np.flatnonzero(group == g)
        pairs += [(a, b) for i, a in enumerate(nodes) for b in nodes[i + 1:]]
    return np.array(pairs, np.int64).reshape(-1, 2)


def equilibrium(cut, element: str, smoothing: float, nu, x0: np.ndarray, atol: float, pairs: np.ndarray,
                rest_volume: np.ndarray) -> tuple[dict, np.ndarray]:
    """Static equilibrium of ``cut`` with ``element`` from x0 (n, 3) to ``atol`` N; (report, positions).
    ``pairs`` (p, 2) int64: :func:`coincident_pairs` of its rest points; ``rest_volume`` (m,): its tets'."""
    from cutkit.mesh.quality import signed_volumes
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.newton import NewtonSolver, newton_static

    em = build_element_model(cut, element=element, deviatoric_smoothing=smoothing, poisson_ratio=nu)
    x = x0.copy()
    solver = NewtonSolver(em)
    t0 = time.perf_counter()
    info = newton_static(em, x, rtol=0.0, atol=atol, max_iterations=100, solver=solver)
    wall = time.perf_counter() - t0
    J = signed_volumes(x, cut.tets) / rest_volume
    gap = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    return {"element": element, "deviatoric_smoothing": em.deviatoric_smoothing, "converged": bool(info.converged),
            "iterations": int(info.iterations), "cg_iterations": int(solver.counts["cg_iterations"]),
            "residual_N": float(info.residual), "wall_s": wall, "opening_mean_mm": float(gap.mean()),
            "opening_max_mm": float(gap.max()), "coincident_pairs": int(len(pairs)), "min_J": float(J.min()),
            "inverted_tets": int(np.count_nonzero(J <= 0.0))}, x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cut", required=True, help="a run's model.h5 (cutkit demo -o DIR: DIR/model.h5)")
    ap.add_argument("--rtol", type=float, default=1e-4, help="residual over the force scale each solve stops at")
    ap.add_argument("--smoothing", type=float, default=None,
                    help="ANP's deviatoric smoothing (default: the runtime's, cutkit.relax.anp.ANP_SMOOTHING)")
    ap.add_argument("--nu", type=float, default=None, help="every tissue's Poisson ratio (default: the model's)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)

    from cutkit.io.model_h5 import read_model
    from cutkit.mesh.quality import signed_volumes
    from cutkit.relax.anp import ANP_SMOOTHING, element_forces
    from cutkit.relax.elastic import build_element_model
    from cutkit.threads import configure_threads

    configure_threads(None)
    cut = read_model(a.cut)
    x0 = cut.points + cut.point_data["displacement"]
    p1 = build_element_model(cut, poisson_ratio=a.nu)
    scale = float(np.linalg.norm(element_forces(p1, cut.points)[~p1.fixed]))
    smoothing = ANP_SMOOTHING if a.smoothing is None else a.smoothing
    out = {"model": a.cut, "tets": int(cut.n_tets), "nodes": int(cut.n_points), "force_scale_N": scale,
           "rtol": a.rtol, "nu": a.nu, "elements": []}
    positions = []
    pairs, rest_volume = coincident_pairs(cut.points), signed_volumes(cut.points, cut.tets)
    for element, alpha in (("nh", 0.0), ("anp", smoothing)):
        report, x = equilibrium(cut, element, alpha, a.nu, x0, a.rtol * scale, pairs, rest_volume)
        out["elements"].append(report)
        positions.append(x)
    out["largest_distance_between_equilibria_mm"] = float(np.linalg.norm(positions[0] - positions[1], axis=1).max())
    nh, anp = out["elements"]
    out["anp_over_nh_opening"] = anp["opening_mean_mm"] / nh["opening_mean_mm"]
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        for r in out["elements"]:
            print(f"{r['element']:4s} opening {r['opening_mean_mm']:.4f} mm (max {r['opening_max_mm']:.3f}), "
                  f"min J {r['min_J']:.3f}, inverted {r['inverted_tets']}, {r['iterations']} Newton / "
                  f"{r['cg_iterations']} CG iterations, {r['wall_s']:.1f} s, converged {r['converged']}")
        print(f"ANP / P1 opening {out['anp_over_nh_opening']:.3f}; largest distance between the equilibria "
              f"{out['largest_distance_between_equilibria_mm']:.3f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
