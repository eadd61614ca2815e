"""Benchmark of the haptic scalpel: kernel step time and the 1 kHz service over loopback.

    .venv/bin/python benchmarks/haptics.py --seconds 5 --json

starts ``cutkit haptics serve`` on a free port, drives it with the bench
device loop, and prints one JSON object (the ``cutkit haptics bench``
figures plus ``step_us_p50`` / ``step_us_p99``, the time of one scalpel
step called from Python, dispatch included).
"""

from __future__ import annotations

import argparse
import json
import time

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--priority", choices=["normal", "high", "realtime"], default="high")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from cutkit.haptics.client import run_bench, spawned_server
    from cutkit.haptics.priority import raise_priority

    us = kernel_step_times()
    with spawned_server("--priority", args.priority) as (host, port, _):
        got = raise_priority(args.priority)
        result = run_bench(host, port, args.seconds)
    result.update(priority=got, step_us_p50=float(np.percentile(us, 50)), step_us_p99=float(np.percentile(us, 99)))
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in result.items():
            print(f"{k:28s} {v:.4g}" if isinstance(v, float) else f"{k:28s} {v}")


if __name__ == "__main__":
    main()
