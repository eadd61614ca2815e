"""The projected Hessian of projected Newton: LAPACK's 9x9 eigh against the analytic eigensystem.

Usage: python benchmarks/projected_hessian.py --json --knee knee.h5 [--cut model.h5] [--batch 100000]

Times, back to back in one process and in turns (``--repeats`` rounds, the fastest of each
kept), the assembly of the knee's elastic Hessian (``cutkit.relax._newton_kernels.assemble_hessian``)
exact, projected by eigh (``CLAMP_EIGH``) and projected by the analytic eigensystem (``CLAMP``):

  knee       the model as built (prestress and held nodes: the settle's first state)
  cut        with ``--cut`` (a ``simulate``/``demo`` output's model.h5): the cut knee's final state
  batch      ``--batch`` random deformation gradients (normal entries: most are indefinite),
             one ``stress_hessian`` each, per element microseconds

Each entry: seconds (us per element for the batch) of exact, eigh and analytic, the element
count and ``eigh_over_analytic``.  Prints one JSON object
with ``--json``.  All timings are wall seconds on this machine (NUMBA_NUM_THREADS as set).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from numba import njit

from cutkit.relax._newton_kernels import stress_hessian


@njit(cache=True)
def _batch(Fs, mu, lam, project):
    P = np.empty((3, 3))
    H = np.empty((9, 9))
    acc = 0.0
    for t in range(Fs.shape[0]):
        stress_hessian(Fs[t], mu, lam, project, P, H)
        acc += H[0, 0]
    return acc


def _fastest(fns: dict, repeats: int) -> dict:
    """Each of ``fns`` run ``repeats`` times in turns: the fastest wall seconds of each."""
    best = {k: np.inf for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t)
    return best


def _assembly(em, x, repeats: int) -> dict:
    from cutkit.relax import _elastic_kernels as KE
    from cutkit.relax import _newton_kernels as KN
    from cutkit.relax.newton import NewtonSolver

    solver = NewtonSolver(em)
    m = em.n_elements
    pat, el = solver.pattern(), KE.Elements(em.tets[:m], em.Dminv[:m], em.volume[:m], em.mu[:m], em.lam[:m])
    data = np.empty(pat.indices.shape[0])
    modes = {"exact_s": KN.EXACT, "eigh_s": KN.CLAMP_EIGH, "analytic_s": KN.CLAMP}
    fns = {k: (lambda p=p: KN.assemble_hessian(x, el, pat, p, data)) for k, p in modes.items()}
    for fn in fns.values():  # compile
        fn()
    out = _fastest(fns, repeats)
    out["elements"] = int(np.count_nonzero(el.volume > 0))
    out["eigh_over_analytic"] = out["eigh_s"] / out["analytic_s"]
    return out


def _batch_times(n: int, repeats: int) -> dict:
    from cutkit.relax import _newton_kernels as KN

    Fs = np.random.default_rng(0).normal(size=(n, 3, 3))
    modes = {"exact_us": KN.EXACT, "eigh_us": KN.CLAMP_EIGH, "analytic_us": KN.CLAMP}
    fns = {k: (lambda p=p: _batch(Fs, 1.0, 10.0, p)) for k, p in modes.items()}
    for fn in fns.values():
        fn()
    out = {k: 1e6 * v / n for k, v in _fastest(fns, repeats).items()}
    out["elements"] = n
    out["eigh_over_analytic"] = out["eigh_us"] / out["analytic_us"]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--knee", metavar="MODEL.h5", help="cutkit demo's knee.h5")
    ap.add_argument("--cut", metavar="MODEL.h5", help="a simulate output's model.h5 (the cut knee)")
    ap.add_argument("--batch", type=int, default=100000, help="random deformation gradients (0: none)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    from cutkit.io.model_h5 import read_model
    from cutkit.relax.elastic import build_element_model, initial_element_state

    out = {}
    if args.batch:
        out["batch"] = _batch_times(args.batch, args.repeats)
    if args.knee:
        km = read_model(args.knee)
        out["knee"] = _assembly(build_element_model(km), initial_element_state(km).positions, args.repeats)
    if args.cut:
        cm = read_model(args.cut)
        out["cut"] = _assembly(build_element_model(cm), cm.points + cm.point_data["displacement"], args.repeats)
    print(json.dumps(out, indent=1 if args.json else None))


if __name__ == "__main__":
    main()
