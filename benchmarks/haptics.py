"""Benchmark of the haptic scalpel: kernel step time and the 1 kHz service over loopback.

    .venv/bin/python benchmarks/haptics.py --seconds 5 --json

starts ``cutkit haptics serve`` on a free port, drives it with the bench
device loop, and prints one JSON object (the ``cutkit haptics bench``
figures plus ``step_us_p50`` / ``step_us_p99``, the time of one scalpel
step called from Python, dispatch included).  ``--with-relaxation`` runs a
spring relaxation of a 48k-tet grid on every core in another process during
the bench (``relaxation_beside: true``): the rate the service keeps while
the tissue relaxes beside it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def kernel_step_times(n: int = 20000) -> np.ndarray:
    from cutkit.scalpel import N_OUT, Control, ScalpelParams, ScalpelState, enter, step

    p = ScalpelParams().array()
    s, c, out, f = ScalpelState(), Control(), np.zeros(N_OUT), np.zeros(3)
    enter(s, (0, 0, 0), (0, 0, 1), (0, 0, 0))
    rng = np.random.default_rng(0)
    tips = s.proxy + rng.uniform(-1, 3, (n, 1)) * np.array([1.0, 0.0, 0.0]) + rng.normal(0, 0.3, (n, 3))
    step(p, s, c, f, out)
    times = np.empty(n)
    clock = time.perf_counter_ns
    for i in range(n):
        c.tip[:] = tips[i]
        t0 = clock()
        step(p, s, c, f, out)
        times[i] = clock() - t0
    return times * 1e-3


RELAX_LOAD = """
import sys, time
sys.path.insert(0, {tests!r})
from _twins_relax import kuhn_grid
from cutkit.model.tetmodel import BoundaryConditions, TetModel
from test_relax import materials
from cutkit.relax import Control, build_spring_model, initial_state, step
import numpy as np
pts, tets = kuhn_grid(20, 20, 20, 2.0)
tm = TetModel.from_arrays(pts, tets, materials=materials(damping=5.0),
                          boundary=BoundaryConditions(fixed_nodes=np.flatnonzero(pts[:, 2] == 0)))
sm = build_spring_model(tm); st = initial_state(sm); ctl = Control(gravity=np.array([0.0, 0.0, -9806.65]))
print("loaded", flush=True)
while True:
    step(sm, st, ctl, 1e-4, gauss_seidel=True)
"""


@contextlib.contextmanager
def relaxation_beside():
    """A spring relaxation sweeping in another process (compiled and running) for the duration."""
    tests = str(Path(__file__).resolve().parents[1] / "tests")
    load = subprocess.Popen([sys.executable, "-c", RELAX_LOAD.format(tests=tests)], stdout=subprocess.PIPE, text=True)
    try:
        if load.stdout.readline().strip() != "loaded":
            raise RuntimeError("the relaxation beside the bench did not start")
        yield
    finally:
        load.kill()
        load.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--priority", choices=["normal", "high", "realtime"], default="high")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--with-relaxation", action="store_true", help="run a 48k-tet relaxation beside the bench")
    args = ap.parse_args()

    from cutkit.haptics.client import run_bench, spawned_server
    from cutkit.haptics.priority import raise_priority

    us = kernel_step_times()
    load = relaxation_beside() if args.with_relaxation else contextlib.nullcontext()
    with load, spawned_server("--priority", args.priority) as (host, port, _):
        got = raise_priority(args.priority)
        result = run_bench(host, port, args.seconds)
    result.update(priority=got, relaxation_beside=args.with_relaxation, step_us_p50=float(np.percentile(us, 50)), step_us_p99=float(np.percentile(us, 99)))
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in result.items():
            print(f"{k:28s} {v:.4g}" if isinstance(v, float) else f"{k:28s} {v}")


if __name__ == "__main__":
    main()
