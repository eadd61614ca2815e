"""Median time per cut step (collision + subdivision + topology update).

Box meshes of about 10k, 100k and 1M tetrahedra are cut along a straight
incision with a slight wobble; the per-step cost should not depend on the
model size (all work is local to the blade).

    python benchmarks/cut.py [--json] [--sizes 10k,100k,1M] [--steps 200] [--model knee.h5] [--simulate knee.h5]
                             [--cold] [--no-fairing] [--no-smoothing]

``--model`` also cuts a model file (e.g. the demo's ``knee.h5``) along the
shipped incision (``sample_volumes/incision.csv``) and reports its step
times, whether the written mesh passes ``cutkit check``, and the end of the
stroke: the rebase of the cut mesh (``rebase_s``) and, within it, finding
the copies of edges and faces along the cut (``find_twins_s``), with the
cut-made tets' smallest dihedral angles (worst, p1, p5, median, and how
many are below 5 degrees).

``--no-fairing`` cuts the boxes and ``--model`` with ``fair_nodes=False``
(``cutkit.cutting.fairing``), ``--no-smoothing`` with ``smooth_vertices=False``
(``cutkit.cutting.smoothing``), for a comparison in one version of the code.

``--cold`` times a 40-step cut of a small box (8 x 8 x 8 cubes) in a fresh
interpreter twice: with an empty numba cache (``NUMBA_CACHE_DIR`` a new
folder: every kernel of the cut compiles) and again with that cache filled
(the kernels load): ``cold_s`` and ``warm_s``, import and mesh excluded.

``--simulate`` runs ``cutkit simulate`` on a model file with the shipped
incision (no frames, the default element model; a first run loads the
kernels) and reports the summary's ``cut_step_ms``: the cut step inside
``simulate`` (volume collision and subdivision at the proxy, then the hand-over
of the topology change to the tissue), median and p90, and the hand-over alone.
"""

import argparse
import json
import time

import numpy as np

SIZES = {"10k": (12, 12, 12), "100k": (26, 26, 25), "1M": (55, 55, 55)}


#: CutMesh options of the kinematic cuts (``--no-fairing`` sets fair_nodes=False, ``--no-smoothing``
#: smooth_vertices=False).
CUT_OPTIONS = {}


def bench(shape, steps):
    from cutkit.cutting import CutMesh, cut_step
    from cutkit.mesh.generate import box_mesh

    p, t = box_mesh(shape)
    t0 = time.perf_counter()
    cm = CutMesh(p, t, blade_length=4.0, **CUT_OPTIONS)
    setup = time.perf_counter() - t0
    nx, ny, nz = shape
    times = []
    # constant advance per step (0.1 cube), so every size sweeps the same area per step
    for i, x in enumerate(-0.5 + 0.1 * np.arange(steps)):
        tip = [x, ny / 2 + 0.37 + 0.2 * np.sin(0.3 * i), nz - 2.3]
        t1 = time.perf_counter()
        cut_step(cm, tip, [0.05, 0.02, 1.0])
        times.append(time.perf_counter() - t1)
    n_cut = len(cm.subtets)
    return {"tets": int(t.shape[0]), "setup_s": setup, "median_step_ms": 1e3 * float(np.median(times[5:])),
            "p90_step_ms": 1e3 * float(np.percentile(times[5:], 90)), "steps": steps,
            "cut_tets": n_cut, "new_tets_per_cut_tet": sum(len(v) for v in cm.subtets.values()) / max(n_cut, 1)}


def bench_model(path, trajectory):
    from cutkit.cutting import CutMesh, cut_step, finish_stroke, to_model
    from cutkit.cutting.rebase import find_twins, rebase
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.mesh.check import check_mesh
    from cutkit.mesh.quality import min_dihedral_angles

    m = read_model(path)
    traj = read_trajectory(trajectory)
    cm = CutMesh.from_model(m, blade_length=traj.blade_length, **CUT_OPTIONS)
    times = []
    for i in range(len(traj.t)):
        t1 = time.perf_counter()
        cut_step(cm, traj.tip[i], traj.a[i])
        times.append(time.perf_counter() - t1)
    finish_stroke(cm)  # the trajectory's end, as `cutkit cut` does
    w = to_model(cm, m)
    new = w.tets[w.cell_data["new_tet"] == 1]
    angles = min_dihedral_angles(w.points, new) if len(new) else np.full(1, np.nan)
    n_cut = len(cm.subtets)
    t1 = time.perf_counter()
    rebase(cm)
    rebase_s = time.perf_counter() - t1
    t1 = time.perf_counter()
    find_twins(cm)
    twins_s = time.perf_counter() - t1
    return {"tets": int(m.tets.shape[0]), "median_step_ms": 1e3 * float(np.median(times[5:])),
            "rebase_s": rebase_s, "find_twins_s": twins_s,
            "p90_step_ms": 1e3 * float(np.percentile(times[5:], 90)), "steps": len(times),
            "cut_tets": n_cut, "new_tets_per_cut_tet": len(new) / max(n_cut, 1),
            "worst_new_dihedral_deg": float(angles.min()),
            "new_dihedral_p1_p5_median_deg": [float(q) for q in np.percentile(angles, [1, 5, 50])],
            "new_tets_below_5_deg": int((angles < 5.0).sum()),
            "check_passed": bool(check_mesh(w.points, w.tets, w.labels).passed)}


def bench_simulate(path, trajectory):
    import tempfile
    from pathlib import Path

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions, simulate

    model, traj = read_model(path), read_trajectory(trajectory)
    for _ in range(2):  # the first run loads the kernels
        with tempfile.TemporaryDirectory() as d:
            s = simulate(model, traj, Path(d), SimulateOptions(fps=10, frames=False, write_model=False))
    c = s["cut_step_ms"]
    return {"tets": int(s["tets_initial"]), "cut_tets": int(s["cut_tets"]), "cut_steps": c["n"],
            "median_step_ms": c["median"], "p90_step_ms": c["p90"], "handover_median_ms": c["handover_median"],
            "handover_p90_ms": c["handover_p90"], "new_tets_per_cut_tet": s["new_tets"] / max(s["cut_tets"], 1)}


_COLD_CUT = """
import time, numpy as np
from cutkit.cutting import CutMesh, cut_step
from cutkit.mesh.generate import box_mesh
cm = CutMesh(*box_mesh((8, 8, 8)), blade_length=4.0)
t0 = time.perf_counter()
for x in np.linspace(-0.5, 6.0, 40):
    cut_step(cm, np.array([x, 3.3 + 0.2 * np.sin(x), 3.1]), np.array([0.0, 0.0, 1.0]))
print(time.perf_counter() - t0)
"""


def bench_cold():
    """Seconds of a small cut with every kernel compiled (empty cache) and then loaded."""
    import os
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = [float(subprocess.run([sys.executable, "-c", _COLD_CUT], env=env, check=True, capture_output=True,
                                    text=True).stdout.split()[-1]) for _ in range(2)]
    return {"cold_s": out[0], "warm_s": out[1]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--sizes", default="10k,100k,1M")
    ap.add_argument("--steps", type=int, default=110)
    ap.add_argument("--model", default=None, help="also cut this model file along --trajectory")
    ap.add_argument("--trajectory", default="sample_volumes/incision.csv")
    ap.add_argument("--simulate", default=None, help="also time the cut steps of `cutkit simulate` on this model")
    ap.add_argument("--cold", action="store_true", help="also time a small cut with an empty numba cache")
    ap.add_argument("--no-fairing", action="store_true", help="cut the boxes and --model with fair_nodes=False")
    ap.add_argument("--no-smoothing", action="store_true",
                    help="cut the boxes and --model with smooth_vertices=False")
    args = ap.parse_args()
    if args.no_fairing:
        CUT_OPTIONS["fair_nodes"] = False
    if args.no_smoothing:
        CUT_OPTIONS["smooth_vertices"] = False
    res = {s: bench(SIZES[s], args.steps) for s in args.sizes.split(",") if s}
    if args.cold:
        res["cold"] = bench_cold()
    if args.model:
        res[args.model] = bench_model(args.model, args.trajectory)
    if args.simulate:
        res["simulate " + args.simulate] = bench_simulate(args.simulate, args.trajectory)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        for s, r in res.items():
            if s == "cold":
                print(f" cold: a 40-step cut {r['cold_s']:.1f} s compiling, {r['warm_s']:.2f} s with the kernels cached")
                continue
            print(f"{s:>5}: {r['tets']} tets, median step {r['median_step_ms']:.2f} ms, "
                  f"p90 {r['p90_step_ms']:.2f} ms, {r['new_tets_per_cut_tet']:.1f} tets per cut tet"
                  + (f", check {'passed' if r['check_passed'] else 'FAILED'}" if "check_passed" in r else ""))


if __name__ == "__main__":
    main()
