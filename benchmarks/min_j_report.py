"""The per-step report of the smallest volume ratio: kept between steps against the whole pass.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/min_j_report.py --json --knee knee.h5 [--hold 0.5]

Runs ``cutkit simulate`` on the knee with the shipped incision (the blade lifted out and
resting outside for 1 s, ``benchmarks/live.py``'s ``strokes("one")``), then ``--hold`` s, and,
at every relaxation step, times the tissue's report
(``elastic_tissue.KeptVolumeRatios.extremes``) and the whole pass over every element
(``vbd.volume_ratio_extremes``) on the same state, back to back.  Reports the steps, whether
the two agreed at every step (they must, bit for bit), and the median, mean and total
milliseconds of each.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def measure(knee: str, hold_s: float) -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from live import strokes

    from cutkit.io.model_h5 import read_model
    from cutkit.relax.vbd import volume_ratio_extremes
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.relax.elastic_tissue import KeptVolumeRatios

    kept = KeptVolumeRatios.extremes
    rows = []

    def both(self, em, x, below, stop=None):
        t0 = time.perf_counter()
        out = kept(self, em, x, below, stop)
        t1 = time.perf_counter()
        whole = volume_ratio_extremes(em, x, below)
        rows.append((t1 - t0, time.perf_counter() - t1, out == whole))
        return out

    KeptVolumeRatios.extremes = both
    try:
        with tempfile.TemporaryDirectory() as d:
            simulate(read_model(knee), strokes("one"), Path(d) / "o",
                     SimulateOptions(frames=False, write_model=False, hold_s=hold_s))
    finally:
        KeptVolumeRatios.extremes = kept
    t = np.array([(a, b) for a, b, _ in rows]) * 1e3

    def stats(col):
        return {"median_ms": float(np.median(col)), "mean_ms": float(col.mean()), "total_ms": float(col.sum())}

    return {"steps": len(rows), "agree_every_step": all(ok for _, _, ok in rows), "kept": stats(t[:, 0]),
            "whole": stats(t[:, 1])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--knee", required=True, metavar="MODEL.h5")
    ap.add_argument("--hold", type=float, default=0.5, help="seconds simulated after the trajectory")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    out = measure(a.knee, a.hold)
    print(json.dumps(out, indent=2) if a.json else out)


if __name__ == "__main__":
    main()
