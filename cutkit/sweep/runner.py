"""Run a sweep on Dask: an embedded local cluster by default, an existing cluster by address.

The main process loads the models once, sends each to every worker once
(``Client.scatter(..., broadcast=True)``), submits one task per run and
records each row as it arrives (:class:`~cutkit.sweep.results.ResultsTable`).
A run that raises is a failed row; a worker that dies has its runs
rescheduled by Dask on the other workers; an interrupt cancels what is
left and leaves a valid table.
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from cutkit.errors import InputError
from cutkit.sweep.results import ResultsTable
from cutkit.sweep.spec import SweepSpec, load_spec, run_incision
from cutkit.sweep.worker import FIGURES, one_line

#: Environment of the embedded cluster's workers: one numba (and BLAS) thread each.
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1"}
#: Dask settings of the embedded cluster's workers.  Runs are long and
#: CPU-bound, so everything a worker does beside them is made rare: the
#: statistical profiler (a stack sample every 10 ms) is off, the event loop's
#: tick check, the system and memory monitors and the GIL sampler wake
#: seldom or never (each wake-up takes the GIL from the run), and glibc keeps
#: freed memory instead of trimming it at 64 KiB (the run allocates and frees
#: the same large arrays every step).  Measured by ``benchmarks/sweep.py``:
#: a run's CPU time in a worker went from 6 % above the same run in a plain
#: process to within 1 % of it.
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": 256 * 2**20,
}


@dataclass
class SweepReport:
    """What :func:`run_sweep` did.

    Attributes
    ----------
    total : int
        Runs in the spec (distinct keys).
    skipped : int
        Runs with a result already (``resume``).
    ran : int
        Runs finished now (ok or failed).
    failed : int
        Of those, failed.
    wall_s : float
        Seconds from the first submission to the last result.
    workers : int
        Workers of the cluster at the start.
    out_dir : Path
    """

    total: int = 0
    skipped: int = 0
    ran: int = 0
    failed: int = 0
    wall_s: float = 0.0
    workers: int = 0
    out_dir: Path = field(default_factory=Path)


def local_cluster(n_workers: int | None = None):
    """An embedded ``LocalCluster``: one worker process per core, one thread and one numba thread each.

    Parameters
    ----------
    n_workers : int, optional
        Default: the cores this process may run on.
    """
    from dask.distributed import LocalCluster

    from cutkit.threads import available_cores

    n = available_cores() if n_workers is None else int(n_workers)
    if n < 1:
        raise InputError(f"workers must be a whole number >= 1, got {n_workers}")
    import dask

    with dask.config.set(WORKER_CONFIG):  # the nannies hand their configuration to the workers
        return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, env=dict(WORKER_ENV),
                            dashboard_address=":0", silence_logs=logging.ERROR,
                            preload=["cutkit.sweep._worker_setup"])


def run_sweep(spec: SweepSpec | str | Path, out_dir, *, scheduler: str | None = None, client=None,
              n_workers: int | None = None, resume: bool = False, retry_failed: bool = False,
              on_event: Callable[[str, dict], None] | None = None, before_run=None) -> SweepReport:
    """Run every run of a sweep spec and write the results table.

    Parameters
    ----------
    spec : SweepSpec or path-like
    out_dir : path-like
        ``results.parquet``, ``results.csv`` and ``runs/<key>/`` go here.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); without
        it (and without ``client``) an embedded :func:`local_cluster` runs
        the sweep and is closed at the end.
    client : dask.distributed.Client, optional
        A client to use as it is (left open).
    n_workers : int, optional
        Workers of the embedded cluster.
    resume : bool
        Skip every run whose key already has a result in ``out_dir``.
        Without it, a folder that holds results is refused.
    retry_failed : bool
        With ``resume``, run failed runs again.
    on_event : callable(kind, info), optional
        ``("start", {"total", "todo", "skipped", "workers"})`` once, then
        ``("result", {"row", "done", "failed", "todo"})`` per finished run.
        An exception it raises (KeyboardInterrupt included) stops the sweep
        like an interrupt: the table keeps every finished run.
    before_run : callable(run), optional
        Called on the worker before each run (a test hook).

    Returns
    -------
    SweepReport

    Raises
    ------
    InputError
        A bad spec, or results in ``out_dir`` without ``resume``.
    """
    if not isinstance(spec, SweepSpec):
        spec = load_spec(spec)
    out_dir = Path(out_dir)
    table = ResultsTable(out_dir, spec.param_names)
    if table.load() and not resume:
        raise InputError(f"{out_dir}: holds the results of an earlier sweep; add --resume to continue it, "
                         "or choose another folder")
    loaded = spec.resolve()

    runs, seen = [], set()
    for run in spec.runs:
        if run.key not in seen:
            seen.add(run.key)
            runs.append(run)
    finished = {k for k, r in table.rows.items() if r.get("status") == "ok" or not retry_failed}
    todo = [r for r in runs if r.key not in finished]
    report = SweepReport(total=len(runs), skipped=len(runs) - len(todo), out_dir=out_dir)

    own_cluster = None
    if client is None:
        from dask.distributed import Client

        if scheduler is None:
            own_cluster = local_cluster(n_workers)
            client = Client(own_cluster)
        else:
            try:
                client = Client(scheduler, timeout=30)
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError(f"cannot reach the Dask scheduler at {scheduler}: {one_line(exc)}") from None
        own_client = True
    else:
        own_client = False
    futures = []
    t0 = time.perf_counter()
    try:
        report.workers = len(client.scheduler_info().get("workers", {}))
        if on_event:
            on_event("start", {"total": report.total, "todo": len(todo), "skipped": report.skipped,
                               "workers": report.workers})
        if not todo:
            table.flush()
            return report
        # each model goes to every worker once; the runs refer to it
        needed = sorted({r.model for r in todo})
        model_futures = {name: client.scatter(loaded["models"][name], broadcast=True, hash=False)
                         for name in needed}
        out_root = str(out_dir.resolve())
        nonce = uuid.uuid4().hex[:8]  # a run cancelled by an earlier interrupt may still be running
        by_future = {}
        for run in todo:
            payload = {"key": run.key, "model": run.model, "trajectory": run.trajectory, "params": run.params,
                       "options": spec.options, "threads": spec.threads_per_run,
                       "trajectory_data": loaded["trajectories"][run.trajectory]}
            if payload["trajectory_data"] is None:
                payload["incision"] = run_incision(spec, run)
            from cutkit.sweep.worker import run_one

            fut = client.submit(run_one, model_futures[run.model], payload, out_root, before_run,
                                key=f"cutkit-run-{run.key}-{nonce}", pure=False, retries=spec.retries)
            futures.append(fut)
            by_future[fut.key] = run
        from dask.distributed import as_completed

        for fut in as_completed(futures):
            run = by_future[fut.key]
            try:
                row = fut.result()
            except Exception as exc:  # the task itself failed (e.g. its worker died too often)
                row = _failed_row(run, one_line(exc))
            table.add(row)
            report.ran += 1
            report.failed += row["status"] != "ok"
            if on_event:
                on_event("result", {"row": row, "done": report.ran, "failed": report.failed, "todo": len(todo)})
    finally:
        report.wall_s = time.perf_counter() - t0
        pending = [f for f in futures if not f.done()]
        if pending:
            try:
                client.cancel(pending)
            except Exception:  # noqa: BLE001 - the interrupt matters more than a failed cancel
                pass
        table.flush()
        if own_client:
            client.close()
        if own_cluster is not None:
            own_cluster.close()
    return report


def _failed_row(run, error: str) -> dict:
    row = {"key": run.key, "model": run.model, "trajectory": run.trajectory, **run.params, "status": "failed",
           "error": error}
    row.update({k: None for k in FIGURES})
    row["worker"] = ""
    return row
