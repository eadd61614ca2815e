"""The linear solves of one projected Newton step on a model: what each way of solving costs.

Usage: python benchmarks/newton_linear.py --json --knee knee.h5 [--step 0.02] [--cholespy]

Builds the simulation's element model of MODEL.h5 (``ElasticTissue``), assembles the
Newton system of a backward Euler step of ``--step`` s from the model as built
(prestress, boundary conditions: the settle's first system) and solves it every way
:mod:`cutkit.relax.newton` could.  Prints one JSON object with ``--json``:

  dofs, entries                     size of the system (3 n, stored entries)
  inertia_over_stiffness_median     median over dofs of (m/h^2 + c m/h) / the Hessian's diagonal:
                                    near 0 the inertia does not condition the system (the step is
                                    as hard as a static solve); near 1 or above Jacobi is enough
  pattern_s, assemble_s             sparsity pattern (after a cut), projected Hessian values
  spmv_ms                           one product with the assembled matrix (scipy's scalar CSR)
  block_spmv_ms                     the same product on the symmetric block form the solver's CG
                                    uses (``cutkit.relax._block_cg_kernels``)
  cg.<preconditioner>               CG to a relative residual of 1e-2 (the Newton steps' inexact
                                    solve) and 1e-6: iterations, seconds, and the setup's seconds,
                                    for jacobi, block_jacobi (3 x 3 node blocks, scipy's products),
                                    block_kernel (the same in the solver's kernel: its setup is
                                    the gather into the block form and the inverses), amg (pyamg
                                    smoothed aggregation with the rigid-body modes, the ``linear="cg"`` path) and, where
                                    pypardiso is installed, an earlier factor (the factor of the
                                    Hessian of a state 10 um away, as reusing a step's factor
                                    across steps would)
  pardiso                           where pypardiso is installed: factorisation (analysis included)
                                    and one solve, seconds (MKL PARDISO, supernodal, MKL's threads)
  cholespy                          with ``--cholespy``: one factorisation and one solve, seconds
                                    (the ``linear="cholesky"`` path; minutes on the knee)

All timings are wall seconds of one run on this machine (NUMBA_NUM_THREADS and MKL's
threads as set in the environment); compare figures of one run with each other.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def _cg(A, r, make_preconditioner) -> dict:
    """CG with one preconditioner to 1e-2 and 1e-6: iterations and seconds, setup seconds."""
    from cutkit.relax.newton import pcg

    M, setup = _timed(make_preconditioner)
    out = {"setup_s": setup}
    for rtol in (1e-2, 1e-6):
        (d, its), t = _timed(lambda: pcg(A, r, M, rtol, 2000))
        out[f"rtol_{rtol:.0e}"] = {"iterations": int(its), "s": t}
    return out


class _FactorSolve:
    """``M @ v`` solves with a PARDISO factor (the preconditioner of an earlier system)."""

    def __init__(self, A):
        import pypardiso
        import scipy.sparse as sp

        self.upper = sp.triu(A, format="csr")
        self.upper.sort_indices()
        self.solver = pypardiso.PyPardisoSolver(mtype=2)  # real symmetric positive definite
        self.solver.factorize(self.upper)
        self.shape = A.shape

    def __matmul__(self, v):
        return self.solver.solve(self.upper, v)


def _block_kernel(A, r, pattern):
    """(one product in ms, CG as :func:`_cg` reports it) on the block form of the solver's kernel."""
    from cutkit.relax import _block_cg_kernels as KB
    from cutkit.relax.newton import block_system

    n = A.shape[0] // 3

    def setup():
        return block_system(A, pattern)

    setup()  # compiled (or loaded from the cache) outside the timings
    (blocks, inv), setup_s = _timed(setup)
    b, y, d, flag = r.reshape(n, 3).copy(), np.empty((n, 3)), np.empty((n, 3)), np.zeros(1, np.int64)
    import numba

    rows = numba.get_num_threads() > 1  # as the solver chooses (the same bits either way)
    KB.block_product(blocks, b, y)
    KB.block_product_rows(blocks, b, y)
    KB.block_pcg(blocks, inv, b, 0.5, 1, flag, d, rows)
    _, spmv = _timed(lambda: [KB.block_product(blocks, b, y) for _ in range(10)])
    _, spmv_rows = _timed(lambda: [KB.block_product_rows(blocks, b, y) for _ in range(10)])
    out = {"setup_s": setup_s, "rows_spmv_ms": 100.0 * spmv_rows, "threads": int(numba.get_num_threads())}
    for rtol in (1e-2, 1e-6):
        (_, its), t = _timed(lambda: KB.block_pcg(blocks, inv, b, rtol, 2000, flag, d, rows))
        out[f"rtol_{rtol:.0e}"] = {"iterations": int(its), "s": t}
    return 100.0 * spmv, out


def knee_linear(path: str, step_s: float, cholespy: bool) -> dict:
    import scipy.sparse as sp

    from cutkit.io.model_h5 import read_model
    from cutkit.relax.newton import NewtonSolver, _free_terms, _Potential, node_block_inverse
    from cutkit.relax.elastic_tissue import ElasticTissue

    tis = ElasticTissue(read_model(path), step_s=step_s, solver="newton")
    em, x0 = tis.em, tis.state.positions.copy()
    terms = _free_terms(em, x0, step_s, None, None, x0)
    free = ~terms.fixed & (em.adj_degree > 0)[:, None]
    solver = NewtonSolver(em)
    add = terms.inertia + terms.damping
    _, pattern_s = _timed(solver.pattern)
    A, assemble_s = _timed(lambda: solver.matrix(x0, free, add, 1))
    r = _Potential(em, terms, free, solver._elements()).residual(x0).ravel()
    _, spmv = _timed(lambda: [A @ r for _ in range(10)])
    out = {"dofs": int(A.shape[0]), "entries": int(A.nnz), "step_s": step_s,
           "inertia_over_stiffness_median": float(np.median(np.repeat(add, 3)[free.ravel()] / A.diagonal()[free.ravel()])),
           "pattern_s": pattern_s, "assemble_s": assemble_s, "spmv_ms": 100.0 * spmv}
    cg = {"jacobi": _cg(A, r, lambda: sp.diags(1.0 / A.diagonal()).tocsr()),
          "block_jacobi": _cg(A, r, lambda: node_block_inverse(A, solver.pattern()))}
    out["block_spmv_ms"], cg["block_kernel"] = _block_kernel(A, r, solver.pattern())

    def amg():
        solver._build_amg(A, x0, free)
        return solver._preconditioner(A)

    cg["amg"] = _cg(A, r, amg)
    try:
        import pypardiso  # noqa: F401
    except ImportError:
        pypardiso = None
    if pypardiso is not None:
        factor, factor_s = _timed(lambda: _FactorSolve(A))
        d, solve_s = _timed(lambda: factor @ r)
        out["pardiso"] = {"factor_s": factor_s, "solve_s": solve_s,
                          "relative_residual": float(np.linalg.norm(A @ d - r) / np.linalg.norm(r))}
        x1 = x0 + np.where(free, 0.01 * np.random.default_rng(0).standard_normal(x0.shape), 0.0)
        A1 = solver.matrix(x1, free, add, 1)
        cg["earlier_factor"] = _cg(A1, r, lambda: factor)
        cg["earlier_factor"]["setup_s"] = factor_s
    if cholespy:
        import cholespy as cp

        L, factor_s = _timed(lambda: cp.CholeskySolverD(A.shape[0], A.indptr.astype(np.int32),
                                                        A.indices.astype(np.int32), A.data, cp.MatrixType.CSR))
        d = np.zeros_like(r)
        _, solve_s = _timed(lambda: L.solve(r, d))
        out["cholespy"] = {"factor_s": factor_s, "solve_s": solve_s}
    out["cg"] = cg
    return out


def cut_to_residual(knee: str, cut: str, rtol: float, preconditioners=None) -> dict:
    """Static projected Newton from a cut model's state (a ``simulate`` output's model.h5) to ``rtol``
    of the knee's force scale, with each CG preconditioner: wall seconds, Newton and CG iterations."""
    from cutkit.io.model_h5 import read_model
    from cutkit.relax.elastic import build_element_model, initial_element_state
    from cutkit.relax.newton import PRECONDITIONERS, NewtonSolver, newton_static
    from cutkit.relax.vbd import elastic_forces

    km = read_model(knee)
    ek, sk = build_element_model(km), initial_element_state(km)
    scale = float(np.linalg.norm(elastic_forces(ek, sk.positions)[~ek.fixed]))
    cm = read_model(cut)
    em = build_element_model(cm)
    x0 = cm.points + cm.point_data["displacement"]
    free = ~em.fixed & (em.adj_degree > 0)[:, None]
    out = {"force_scale_N": scale, "dofs": 3 * em.n_nodes, "rtol": rtol,
           "start_relative_residual": float(np.linalg.norm(elastic_forces(em, x0)[free]) / scale)}
    for name in preconditioners or PRECONDITIONERS:
        x = x0.copy()
        solver = NewtonSolver(em, linear="cg", preconditioner=name)
        info, wall = _timed(lambda: newton_static(em, x, rtol=0.0, atol=rtol * scale, solver=solver))
        out[name] = {"wall_s": wall, "newton_iterations": int(info.iterations), "converged": bool(info.converged),
                     "relative_residual": float(np.linalg.norm(elastic_forces(em, x)[free]) / scale), **solver.counts}
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--knee", required=True, metavar="MODEL.h5")
    ap.add_argument("--step", type=float, default=0.02, help="backward Euler step, s (simulate's default)")
    ap.add_argument("--cholespy", action="store_true", help="time one cholespy factorisation too (slow)")
    ap.add_argument("--cut", metavar="MODEL.h5", help="a simulate output's model.h5 of the knee: static Newton "
                    "from its state to --rtol of the knee's force scale with each preconditioner, instead")
    ap.add_argument("--rtol", type=float, default=1e-3)
    ap.add_argument("--preconditioners", default="amg,block_jacobi", help="with --cut: which, comma-separated")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.cut:
        out = cut_to_residual(args.knee, args.cut, args.rtol, args.preconditioners.split(","))
    else:
        out = knee_linear(args.knee, args.step, args.cholespy)
    print(json.dumps(out, indent=None if args.json else 2))


if __name__ == "__main__":
    main()
