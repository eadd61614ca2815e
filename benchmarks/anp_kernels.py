"""What one evaluation of the ANP element costs on a model: forces, energy, nodal terms and the
projected Newton matrix, against the default element's matrix.

Usage: python benchmarks/anp_kernels.py --model knee.h5 [--repeat 3] [--json]

Builds the element model of MODEL.h5 (``build_element_model``) once as P1 (``nh``), as plain ANP
and as ANP with the runtime's deviatoric smoothing (``anp.ANP_SMOOTHING``) and times, at the rest
positions, the best of ``--repeat`` calls after a first one (which compiles or loads the kernels):

  forces_s, energy_s     ``anp.anp_forces`` / ``anp.anp_energy`` (ANP only)
  nodal_terms_s          ``anp.nodal_terms`` summed afresh (what a change to the element set costs;
                         ANP only)
  matrix_s               ``NewtonSolver(em).matrix(X, free, 0, project=1)``: the projected Hessian
                         with its held rows, the sparsity pattern kept
  entries                stored entries of that matrix

with the thread count in ``threads`` (``NUMBA_NUM_THREADS``).  The ANP kernels make the same sums
on any thread count, so two runs with 1 and 2 threads time the same work.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def best_of(repeat: int, fn, *args) -> float:
    """Seconds of the fastest of ``repeat`` calls of fn(*args), after one untimed call."""
    fn(*args)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True, help="a model file (cutkit demo -o DIR: DIR/knee.h5)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)

    import numba

    from cutkit.io.model_h5 import read_model
    from cutkit.relax import anp
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.newton import NewtonSolver
    from cutkit.threads import configure_threads

    configure_threads(None)
    model = read_model(a.model)
    x = np.ascontiguousarray(model.points, np.float64)
    out = {"model": a.model, "tets": int(model.n_tets), "nodes": int(model.n_points),
           "threads": int(numba.get_num_threads()), "elements": []}
    for element, alpha in (("nh", 0.0), ("anp", 0.0), ("anp", anp.ANP_SMOOTHING)):
        em = build_element_model(model, element=element, deviatoric_smoothing=alpha)
        solver = NewtonSolver(em)
        free, zero = ~em.fixed, np.zeros(em.n_nodes)
        row = {"element": element, "deviatoric_smoothing": alpha,
               "matrix_s": best_of(a.repeat, solver.matrix, x, free, zero, 1),
               "entries": int(solver.matrix(x, free, zero, 1).nnz)}
        if element == "anp":
            row.update(forces_s=best_of(a.repeat, anp.anp_forces, em, x),
                       energy_s=best_of(a.repeat, anp.anp_energy, em, x),
                       nodal_terms_s=best_of(a.repeat, anp.nodal_terms, em))
        out["elements"].append(row)
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        for r in out["elements"]:
            extra = "".join(f", {k} {r[k]:.3f} s" for k in ("forces_s", "energy_s", "nodal_terms_s") if k in r)
            print(f"{r['element']:4s} alpha {r['deviatoric_smoothing']:.1f}: matrix {r['matrix_s']:.3f} s "
                  f"({r['entries']} entries){extra}  [{out['threads']} threads]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
