"""The rebase at a stroke's end on a cut model: its wall time, and how it splits between its parts.

Usage: python benchmarks/rebase.py --json --model knee.h5 [--repeat 3]

Runs ``simulate`` on the shipped incision (``sample_volumes/incision.csv``) with the blade lifted
out along its axis at the end, so the stroke ends and the session rebases (the rebase a live
session runs in its own thread while the next stroke's poses wait), then rebases the same session
``--repeat`` times more (each a full rebase of the same mesh, without the cut's sub-tets).
Reports, per rebase, the wall time of :meth:`Session.rebase` and of its parts: the cut mesh's
(``CutMesh.rebase``: a fresh cut state, its faces, edges and twins), the tissue's (the element
model built again on the new numbering; the default element tissue) and the rest (surface collision, hierarchies, hooks).
Set ``NUMBA_NUM_THREADS`` as the run to compare with; run two commits back to back.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from live import lifted  # noqa: E402


def _timed(cls, name: str, log: list):
    """Wrap ``cls.name`` so that each call appends its wall time (s) to ``log``."""
    original = getattr(cls, name)

    def timed(self, *a, **k):
        t0 = time.perf_counter()
        out = original(self, *a, **k)
        log.append(time.perf_counter() - t0)
        return out

    setattr(cls, name, timed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True, help="A model file (the demo knee: cutkit-demo/knee.h5).")
    ap.add_argument("--trajectory", default=str(Path(__file__).resolve().parents[1] / "sample_volumes/incision.csv"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from cutkit.cutting.cutmesh import CutMesh
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.relax.elastic_tissue import ElasticTissue
    from cutkit.simulate.session import Session

    logs = {"total": [], "cut_mesh": [], "tissue": []}
    sessions = []
    original = Session.rebase

    def rebase(self):
        sessions.append(self)
        t0 = time.perf_counter()
        out = original(self)
        logs["total"].append(time.perf_counter() - t0)
        return out

    Session.rebase = rebase
    _timed(CutMesh, "rebase", logs["cut_mesh"])
    _timed(ElasticTissue, "rebase", logs["tissue"])
    model = read_model(args.model)
    with tempfile.TemporaryDirectory() as tmp:
        simulate(model, lifted(read_trajectory(args.trajectory), out_mm=15.0, lift_s=0.2), Path(tmp) / "out",
                 SimulateOptions(frames=False, hold_s=0.05, write_model=False))
        if not sessions:
            raise SystemExit("the stroke did not end inside the run: no rebase to time")
        session = sessions[0]
        first = {k: v[0] for k, v in logs.items() if v}
        for _ in range(args.repeat):
            session.rebase()
    again = {k: v[-args.repeat:] for k, v in logs.items()}
    rest = [t - c - s for t, c, s in zip(again["total"], again["cut_mesh"], again["tissue"])]
    result = {"model": args.model, "tets": int(session.store.orig_tets.shape[0]), "tissue": type(session.tis).__name__,
              "first_rebase_s": first,
              "rebase_s": {k: float(np.median(v)) for k, v in again.items()} | {"rest": float(np.median(rest))},
              "rebase_s_all": again}
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in result["rebase_s"].items():
            print(f"rebase.{k:10s} {v * 1e3:8.1f} ms (median of {args.repeat})")


if __name__ == "__main__":
    main()
