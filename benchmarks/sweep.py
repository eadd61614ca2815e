"""Runs per hour of ``cutkit sweep`` against the same runs in a plain loop in one process.

Model: the generated slab of ``cutkit.sweep.slab_model`` (16 x 6 x 8 cubes,
4,608 tets, about the 5k-tet slab of a parameter study), cut by a short
generated incision across its fibres; each run varies F_enter and E.  Both
sides run the same function (:func:`cutkit.sweep.worker.run_one`) with the
sweep's options (no frames, no model file) and are warmed up first (numba
compilation and cache loading are not counted; the cluster's start-up is
reported on its own).

* loop: the runs one after another in this process, one numba thread;
* sweep: the same runs on an embedded LocalCluster of ``--workers``
  worker processes (one thread, one numba thread each), through
  :func:`cutkit.sweep.run_sweep` (results table included).

The per-run overhead of Dask is ``(workers * sweep wall - sum of the runs'
own wall) / runs``: the time per run a worker spends outside the run.  On a
machine whose cores other work shares, the wall times measure the share
each process got; ``projected_on_free_cores`` therefore also gives the
rates the runs' CPU times allow (loop: one run's CPU time per run; sweep:
``workers`` runs at a time, each its CPU time plus Dask's overhead).

    python benchmarks/sweep.py [--json] [--runs 40] [--workers 2]

Writes one JSON object (``--json``) or a few lines.
"""

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

SPEC = """
[sweep]
name = "benchmark"

[options]
material_model = "springs"
hold_s = 0.1
settle_iterations = 20

[[models]]
name = "slab"
slab = {{ shape = [16, 6, 8] }}

[[trajectories]]
name = "across"
incision = {{ start = [6.0, -1.0, 8.3], end = [26.0, -1.0, 8.3], depth = 4.0, speed = 40.0, press_time = 0.15 }}

[product]
material.muscle.F_enter = {f_enter}
material.muscle.E = [20000.0, 30000.0]
"""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--runs", type=int, default=40, help="runs on each side (even)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)

    from cutkit.sweep import load_spec, local_cluster, run_sweep
    from cutkit.sweep.spec import run_incision
    from cutkit.sweep.worker import run_one
    from cutkit.threads import configure_threads

    configure_threads(1)
    tmp = Path(tempfile.mkdtemp(prefix="cutkit-bench-sweep-"))
    n_f = max(1, args.runs // 2)
    f_enter = [round(0.2 + 0.05 * i, 3) for i in range(n_f)]
    (tmp / "sweep.toml").write_text(SPEC.format(f_enter=f_enter))
    spec = load_spec(tmp / "sweep.toml")
    loaded = spec.resolve()
    model = loaded["models"]["slab"]
    n_tets = int(model.tets.shape[0])

    def payload(run):
        return {"key": run.key, "model": run.model, "trajectory": run.trajectory, "params": run.params,
                "options": spec.options, "threads": 1, "trajectory_data": None, "incision": run_incision(spec, run)}

    # ---- plain loop in this process
    run_one(model, payload(spec.runs[0]), str(tmp / "warm"))  # compile / load caches
    t0 = time.perf_counter()
    loop_rows = [run_one(model, payload(run), str(tmp / "loop")) for run in spec.runs]
    loop_wall = time.perf_counter() - t0
    assert all(r["status"] == "ok" for r in loop_rows), [r["error"] for r in loop_rows if r["status"] != "ok"]

    # ---- the same runs on a local cluster
    from dask.distributed import Client

    t0 = time.perf_counter()
    cluster = local_cluster(args.workers)
    client = Client(cluster)
    start_s = time.perf_counter() - t0
    try:
        # warm every worker up (numba caches) with runs of another sweep folder
        warm = [client.submit(run_one, model, payload(spec.runs[0]), str(tmp / f"warm{i}"), pure=False,
                              workers=[w], allow_other_workers=False)
                for i, w in enumerate(client.scheduler_info()["workers"])]
        client.gather(warm)
        warm_s = time.perf_counter() - t0 - start_s
        report = run_sweep(spec, tmp / "sweep", client=client)
    finally:
        client.close()
        cluster.close()
    import pyarrow.parquet as pq

    rows = pq.read_table(tmp / "sweep" / "results.parquet").to_pylist()
    assert len(rows) == len(spec.runs) and all(r["status"] == "ok" for r in rows)
    run_wall = sum(r["wall_s"] for r in rows)
    run_cpu = sum(r["cpu_s"] for r in rows)
    loop_cpu = sum(r["cpu_s"] for r in loop_rows)
    n = len(rows)
    result = {
        "model_tets": n_tets,
        "runs": n,
        "workers": args.workers,
        "cores": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "loop": {"wall_s": loop_wall, "runs_per_hour": n / loop_wall * 3600, "mean_run_s": loop_wall / n,
                 "mean_run_cpu_s": loop_cpu / n},
        "sweep": {"wall_s": report.wall_s, "runs_per_hour": n / report.wall_s * 3600,
                  "mean_run_s_in_worker": run_wall / n, "mean_run_cpu_s_in_worker": run_cpu / n,
                  "cluster_start_s": start_s, "worker_warmup_s": warm_s},
        "speedup": loop_wall / report.wall_s,
        "dask_overhead_per_run_s": (args.workers * report.wall_s - run_wall) / n,
        # on free cores a run takes its CPU time; each worker adds Dask's overhead per run
        "projected_on_free_cores": {
            "loop_runs_per_hour": 3600 / (loop_cpu / n),
            "sweep_runs_per_hour": args.workers * 3600 / (run_cpu / n + (args.workers * report.wall_s - run_wall) / n),
        },
        "same_results": _same(loop_rows, rows),
    }
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        print()
    else:
        print(f"{n} runs on a {n_tets}-tet slab: loop {result['loop']['runs_per_hour']:.0f}/h, "
              f"sweep on {args.workers} workers {result['sweep']['runs_per_hour']:.0f}/h "
              f"(x{result['speedup']:.2f}); Dask overhead {result['dask_overhead_per_run_s'] * 1e3:.0f} ms per run; "
              f"cluster start {start_s:.1f} s, warm-up {warm_s:.1f} s")


def _same(loop_rows, sweep_rows) -> bool:
    """Whether the loop and the sweep measured the same figures for every run."""
    keys = ("peak_force_N", "mean_cut_force_N", "cut_tets", "opening_mm", "inverted_tets", "volume_change")
    by_key = {r["key"]: r for r in sweep_rows}
    return all(all(by_key[r["key"]][k] == r[k] for k in keys) for r in loop_rows)


if __name__ == "__main__":
    main()
