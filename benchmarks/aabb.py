"""Benchmark of the surface AABB hierarchy (paper 4.1).

On icosphere surfaces (radius 40 mm) of about 80k and 1.3M triangles:
build time; refit after a small local deformation vs a full rebuild;
segment queries vs brute force over all triangles; how many refits a
small jitter of every node triggers with and without tolerance boxes; and
the blade's entry test (``blade_entry``, what a live session makes for every
pose of a blade outside the tissue) for a 10 mm blade hovering 13 mm
outside, still and moving (``entry_us``, microseconds a call, best of 5 x
1,000 calls).

Usage::

    python benchmarks/aabb.py [--json] [--levels 6 8] [--s-tol 0.05]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np


def icosphere(level: int, radius: float):
    import pyvista as pv

    s = pv.Icosphere(radius=radius, nsub=level)
    return np.ascontiguousarray(s.points, dtype=np.float64), np.ascontiguousarray(
        s.faces.reshape(-1, 4)[:, 1:], dtype=np.int64
    )


def best_of(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def entry_cost(bvh, pts, radius: float) -> dict:
    """Microseconds a ``blade_entry`` call takes for a 10 mm blade pointing at the sphere from 13 mm
    outside: still, and moving 0.01 mm a call (best of 5 x 1,000 calls)."""
    from cutkit.collision import blade_entry

    a = np.array([0.0, 0.0, -1.0])
    tip = np.array([0.0, 0.0, radius + 13.0])
    moved = tip + np.array([0.01, 0.0, 0.0])
    out = {}
    for key, p1 in (("still", tip), ("moving", moved)):
        def calls(p1=p1):
            for _ in range(1000):
                blade_entry(bvh, pts, tip, tip - 10.0 * a, p1, p1 - 10.0 * a)

        out[key] = best_of(calls, 5) * 1e3
    return out


def run(level: int, s_tol: float, radius: float = 40.0, seed: int = 0) -> dict:
    from cutkit.collision import SurfaceBVH

    rng = np.random.default_rng(seed)
    pts, faces = icosphere(level, radius)
    res = {"level": level, "triangles": int(len(faces)), "nodes": int(len(pts)), "s_tol_mm": s_tol}
    edge = np.linalg.norm(pts[faces[:, 1]] - pts[faces[:, 0]], axis=1).mean()
    res["mean_edge_mm"] = float(edge)

    t0 = time.perf_counter()
    bvh = SurfaceBVH.build(pts, faces, s_tol=s_tol)
    res["build_s"] = time.perf_counter() - t0
    res["tree_nodes"] = bvh.n_nodes

    # small local deformation: a 1 mm bump over a 5 mm patch (about what a
    # scalpel pressing on the skin does in one step)
    centre = pts[0]
    d = np.linalg.norm(pts - centre, axis=1)
    bumped = pts + (np.clip(1 - d / 5.0, 0, None) * 1.0)[:, None] * (pts / radius)
    res["bump_nodes"] = int((d < 5.0).sum())

    def refit_bump():
        b = SurfaceBVH.build(pts, faces, s_tol=s_tol)
        b.reset_counters()
        t = time.perf_counter()
        b.update(bumped)
        return time.perf_counter() - t, b.refit_counts

    times = [refit_bump() for _ in range(3)]
    res["refit_bump_s"] = min(t for t, _ in times)
    res["refit_bump_counts"] = times[0][1]
    res["rebuild_s"] = best_of(lambda: SurfaceBVH.build(bumped, faces, s_tol=s_tol), 1)

    # queries: blade segments (20 mm) and tip path segments (1 mm) through
    # random points of the surface
    k = 200
    w = rng.dirichlet([1.0, 1.0, 1.0], k)
    at = np.einsum("ki,kij->kj", w, pts[faces[rng.integers(0, len(faces), k)]])
    dirs = rng.normal(size=(k, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    for name, length in (("blade_20mm", 20.0), ("tip_path_1mm", 1.0)):
        p0 = at - 0.5 * length * dirs
        p1 = at + 0.5 * length * dirs
        t = time.perf_counter()
        n_hits = sum(len(bvh.query_segment(pts, a, b)) for a, b in zip(p0, p1))
        res[f"query_{name}_us"] = (time.perf_counter() - t) / k * 1e6
        kb = 20
        t = time.perf_counter()
        n_brute = sum(len(bvh.query_segment(pts, a, b, brute_force=True)) for a, b in zip(p0[:kb], p1[:kb]))
        res[f"brute_{name}_us"] = (time.perf_counter() - t) / kb * 1e6
        res[f"hits_{name}_per_query"] = n_hits / k
        hits_sub = sum(len(bvh.query_segment(pts, a, b)) for a, b in zip(p0[:kb], p1[:kb]))
        assert hits_sub == n_brute, "hierarchy and brute force disagree"

    # jitter: every node moves by up to `jitter` per step, a random walk of
    # `steps` steps; count refits with and without tolerance boxes
    jitter, steps = 0.01, 10
    walk = pts.copy()
    with_tol = SurfaceBVH.build(pts, faces, s_tol=s_tol)
    without = SurfaceBVH.build(pts, faces, s_tol=0.0)
    tt = {"with": 0.0, "without": 0.0}
    for _ in range(steps):
        walk = walk + rng.uniform(-jitter, jitter, walk.shape)
        for key, b in (("with", with_tol), ("without", without)):
            t = time.perf_counter()
            b.update(walk)
            tt[key] += time.perf_counter() - t
    res["entry_us"] = entry_cost(bvh, pts, radius)
    res["jitter"] = {
        "per_step_mm": jitter,
        "steps": steps,
        "with_tolerance": with_tol.refit_counts,
        "without_tolerance": without.refit_counts,
        "update_with_tolerance_s_per_step": tt["with"] / steps,
        "update_without_tolerance_s_per_step": tt["without"] / steps,
    }
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print JSON only")
    ap.add_argument("--levels", type=int, nargs="+", default=[6, 8], help="icosphere subdivision levels")
    ap.add_argument("--s-tol", type=float, default=0.05, help="tolerance box half size, mm")
    args = ap.parse_args(argv)

    # compile (or load the cached kernels) before timing
    t = time.perf_counter()
    run(1, args.s_tol)
    warm = time.perf_counter() - t
    results = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "warmup_s": warm,
        "runs": [run(level, args.s_tol) for level in args.levels],
    }
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"warm-up (compile or cache load): {warm:.2f} s")
    for r in results["runs"]:
        j = r["jitter"]
        print(f"\nicosphere level {r['level']}: {r['triangles']:,} triangles, mean edge {r['mean_edge_mm']:.3f} mm, s_tol {r['s_tol_mm']} mm")
        print(f"  build                      {r['build_s']:.3f} s ({r['tree_nodes']:,} tree nodes)")
        print(f"  refit after 1 mm bump      {r['refit_bump_s'] * 1e3:.2f} ms ({r['bump_nodes']} nodes moved; {r['refit_bump_counts']})")
        print(f"  full rebuild               {r['rebuild_s']:.3f} s")
        for name in ("blade_20mm", "tip_path_1mm"):
            print(f"  query {name:<14}       {r[f'query_{name}_us']:.1f} us   brute force {r[f'brute_{name}_us']:.0f} us"
                  f"   ({r[f'hits_{name}_per_query']:.2f} hits/query)")
        e = r["entry_us"]
        print(f"  entry test, blade outside  {e['still']:.1f} us still, {e['moving']:.1f} us moving")
        print(f"  jitter {j['per_step_mm']} mm x {j['steps']} steps: with tolerance {j['with_tolerance']}"
              f" ({j['update_with_tolerance_s_per_step'] * 1e3:.2f} ms/step)")
        print(f"  {'':>32}without tolerance {j['without_tolerance']}"
              f" ({j['update_without_tolerance_s_per_step'] * 1e3:.2f} ms/step)")


if __name__ == "__main__":
    main()
