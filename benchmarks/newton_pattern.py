"""The Newton matrix's pattern after a stroke: updated where the cut was, against a full build.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/newton_pattern.py --json --knee knee.h5 [--repeat 5]

Runs ``cutkit simulate`` on the knee with the shipped incision (``benchmarks/live.py``'s
``strokes("one")``).  The tissue's kept pattern (``cutkit.relax.hessian_pattern``) is made on
the uncut model before the first cut; when the stroke ends, before its rebase renumbers the
nodes, the cut model's pattern is made ``--repeat`` times each way, back to back, on the same
model: updated from the uncut one (what a live session's first resting step after a stroke
does) and built in full.  Reports whether the two agree array for array, the nodes the stroke
touched, and the median milliseconds of each and their ratio.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def measure(knee: str, repeat: int) -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from live import strokes

    from cutkit.io.model_h5 import read_model
    from cutkit.relax.hessian_pattern import HessianPattern
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.relax.elastic_tissue import ElasticTissue

    result = {}
    apply_delta, rebase = ElasticTissue.apply_delta, ElasticTissue.rebase

    def first_delta(self, delta):
        if "uncut" not in result:
            result["uncut"] = HessianPattern(self.em)
            result["uncut"].get()  # the uncut model's pattern, kept as a live session keeps it
        return apply_delta(self, delta)

    def at_stroke_end(self, old_of_new):
        if "update_ms" not in result:
            result.update(_both_ways(self.em, result["uncut"], repeat, HessianPattern))
        return rebase(self, old_of_new)

    ElasticTissue.apply_delta, ElasticTissue.rebase = first_delta, at_stroke_end
    try:
        with tempfile.TemporaryDirectory() as d:
            simulate(read_model(knee), strokes("one"), Path(d) / "o",
                     SimulateOptions(frames=False, write_model=False, hold_s=0.0))
    finally:
        ElasticTissue.apply_delta, ElasticTissue.rebase = apply_delta, rebase
    result.pop("uncut")
    return result


def _both_ways(em, uncut, repeat: int, HessianPattern) -> dict:
    """Time an update of a copy of ``uncut`` to ``em`` and a full build, in turns (an update makes
    new arrays, so a shallow copy keeps ``uncut`` as it was)."""
    updates, builds, same = [], [], True
    for _ in range(repeat):
        kept = copy.copy(uncut)
        kept.changed()
        t0 = time.perf_counter()
        a = kept.get()
        t1 = time.perf_counter()
        b = HessianPattern(em).get()
        t2 = time.perf_counter()
        updates.append(t1 - t0)
        builds.append(t2 - t1)
        same &= kept.updates == 1 and all(np.array_equal(x, y) for x, y in zip(a, b))
    update_ms, build_ms = 1e3 * float(np.median(updates)), 1e3 * float(np.median(builds))
    return {"nodes": int(em.n_nodes), "elements": int(em.n_elements), "elements_changed": kept.elements_changed,
            "nodes_touched": kept.rows_rebuilt, "same_arrays": bool(same),
            "update_ms": update_ms, "build_ms": build_ms, "build_over_update": build_ms / update_ms}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--knee", required=True, metavar="MODEL.h5")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    out = measure(a.knee, a.repeat)
    print(json.dumps(out, indent=2) if a.json else out)


if __name__ == "__main__":
    main()
