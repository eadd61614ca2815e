"""Simulated/wall time ratio of ``cutkit simulate`` (the paper's Fig. 1 tasks on one clock).

Models: the knee demo model (built with pipelines/knee.toml, or --knee FILE)
and prestressed slabs of about 100k and 1M tetrahedra, each cut by a
straight 30 mm incision across its fibres.  Frames, pictures and the model
file are not written: the ratio is that of haptics + collision/cut +
relaxation.  Each model runs with the default element model (stable
neo-Hookean, vertex block descent) and with the paper's springs; baseline
of the springs in the same process: a single node list (every node at the
finest step dt0, no adaptive step-size control).

    python benchmarks/simulate.py [--json] [--sizes knee,100k,1M] [--knee knee.h5] [--no-baseline]
                                  [--materials neohookean,springs]

Writes one JSON object (``--json``) or a table.
"""

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

#: Slab shapes (cubes of 2 mm, six tets each).
SLABS = {"100k": (32, 16, 32), "1M": (64, 32, 80)}


def slab_model(shape):
    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel

    points, tets = box_mesh(shape, spacing=(2.0, 2.0, 2.0))
    zmax = shape[2] * 2.0
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == zmax))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    return TetModel.from_arrays(points, tets, materials=Materials.from_rows([row]),
                                boundary=BoundaryConditions(fixed_nodes=ends),
                                prestress=Prestress(label=np.array([1], np.int32),
                                                    fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                                                    prestrain=np.array([0.08])))


def slab_incision(shape):
    from cutkit.cutting.trajectory import straight_incision

    xm, zm = shape[0], shape[2]  # mid-x, mid-z in mm (2 mm cubes)
    return straight_incision([xm - 15.0, 0.0, zm + 0.3], [xm + 15.0, 0.0, zm + 0.3], inward=[0, 1, 0],
                             depth=6.0, approach=3.0, press_time=0.3, cut_time=1.5, rate=100)


def knee():
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.demo import build_or_reuse, demo_inputs

    out = os.path.join(tempfile.gettempdir(), "cutkit-bench-knee")
    path, _, _ = build_or_reuse(out)
    return read_model(path), read_trajectory(demo_inputs()[1])


def run(model, traj, material_model="neohookean", n_lists=None):
    from cutkit.simulate import SimulateOptions, simulate

    opt = SimulateOptions(frames=False, write_model=False, png=False, hold_s=0.5, material_model=material_model)
    if n_lists is not None:
        opt.n_lists = n_lists
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        s = simulate(model, traj, d, opt)
        total = time.perf_counter() - t0
    t = s["time_per_task_s"]
    return {
        "tets": s["tets_initial"], "nodes": s["nodes_initial"], "cut_tets": s["cut_tets"],
        "new_tets_per_cut_tet": s["new_tets_per_cut_tet"], "simulated_s": s["simulated_s"],
        "loop_wall_s": s["wall_s"], "simulated_per_wall": s["simulated_per_wall"],
        "setup_s": t["setup"] + t["settle"], "total_wall_s": total,
        "haptics_s": t["haptics"], "collision_and_cut_s": t["collision_and_cut"], "relaxation_s": t["relaxation"],
        "relax_passes_or_sweeps": s["counts"]["relax_passes"], "n_lists": s["options"]["n_lists"],
        "cut_opening_mean_mm": s["cut_opening_mm"]["final_mean"], "inverted_tets": s["inverted_tets_deformed"],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--sizes", default="knee,100k,1M")
    ap.add_argument("--knee", help="use this knee model instead of building pipelines/knee.toml")
    ap.add_argument("--no-baseline", action="store_true", help="skip the single-list baseline runs")
    ap.add_argument("--materials", default="neohookean,springs",
                    help="material models to run (the springs' baseline runs only with springs)")
    args = ap.parse_args(argv)
    import numba

    from cutkit.simulate.warmup import warm_up

    # every kernel loaded (compiled, on a fresh cache) before any clock starts: steady-state figures
    materials = args.materials.split(",")
    for material_model in materials:
        warm_up(outputs=False, material_model=material_model)
    result = {"machine": {"cpus": os.cpu_count(), "numba_threads": numba.get_num_threads()}, "runs": {}}
    for size in args.sizes.split(","):
        if size == "knee":
            if args.knee:
                from cutkit.cutting.trajectory import read_trajectory
                from cutkit.io.model_h5 import read_model
                from cutkit.demo import demo_inputs
                model, traj = read_model(args.knee), read_trajectory(demo_inputs()[1])
            else:
                model, traj = knee()
        elif size in SLABS:
            model, traj = slab_model(SLABS[size]), slab_incision(SLABS[size])
        else:
            sys.exit(f"unknown size {size!r} (knee, {', '.join(SLABS)})")
        entry = {}
        if "neohookean" in materials:
            entry["neohookean"] = run(model, traj)
        if "springs" in materials:
            entry["adaptive"] = run(model, traj, "springs")
        if not args.no_baseline and size != "1M" and "springs" in materials:
            entry["single_list_baseline"] = run(model, traj, "springs", n_lists=1)
            entry["speedup_of_adaptive_lists"] = (entry["single_list_baseline"]["loop_wall_s"]
                                                 / entry["adaptive"]["loop_wall_s"])
        result["runs"][size] = entry
        if not args.json and "neohookean" in entry:
            a = entry["neohookean"]
            print(f"{size:>5}: {a['tets']} tets, simulated/wall {a['simulated_per_wall']:.2f} "
                  f"(relax {a['relaxation_s']:.1f} s, cut {a['collision_and_cut_s']:.1f} s, "
                  f"haptics {a['haptics_s']:.2f} s for {a['simulated_s']:.1f} s simulated)", flush=True)
    if args.json:
        print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
