"""What following an earlier wound costs a cut step after a rebase (cutkit/cutting/following.py).

A Kuhn box of 30 x 30 x 20 cells (108,000 tets) is cut through in x by a
40 mm blade 12 mm deep, the blade lifted out (a rebase), then cut again
(a) along the same line 2 mm deeper (every step reaches past the wound, so
nothing is followed: the cost is the test alone), and after another rebase
(b) across the first cut at right angles.  Each is run with following on
and off, alternated ``--repeat`` times; it prints the median wall time of
a step of (a) and (b), ms, and the edges followed.

    python benchmarks/cut_following.py [--repeat 2] [--json]
"""

import argparse
import json
import time

import numpy as np


def run(follow: bool) -> dict:
    from cutkit.cutting import CutMesh, cut_step
    from cutkit.mesh.generate import box_mesh

    p, t = box_mesh((30, 30, 20))
    cm = CutMesh(p, t, blade_length=40.0, follow_wounds=follow)
    a = np.array([0.0, 0.05, -1.0]) / np.hypot(0.05, 1.0)
    for x in np.linspace(-1.0, 31.0, 60):
        cut_step(cm, np.array([x, 15.3, 8.0]), a)
    cm.rebase()
    deeper, across = [], []
    for x in np.linspace(-1.0, 31.0, 60):
        t0 = time.perf_counter()
        cut_step(cm, np.array([x, 15.32, 6.0]), a)
        deeper.append(time.perf_counter() - t0)
    cm.rebase()
    b = np.array([0.05, 0.0, -1.0]) / np.hypot(0.05, 1.0)
    for y in np.linspace(-1.0, 31.0, 60):
        t0 = time.perf_counter()
        cut_step(cm, np.array([12.3, y, 8.0]), b)
        across.append(time.perf_counter() - t0)
    return {"tets": int(len(t)), "deeper_median_step_ms": 1e3 * float(np.median(deeper)),
            "across_median_step_ms": 1e3 * float(np.median(across)), "edges_followed": int(cm.edges_followed())}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    run(True)  # loads the kernels
    out = {"on": [], "off": []}
    for _ in range(args.repeat):
        out["on"].append(run(True))
        out["off"].append(run(False))
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for key, rows in out.items():
            for r in rows:
                print(key, r)


if __name__ == "__main__":
    main()
