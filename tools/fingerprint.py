"""Fingerprint of cutkit's results: sha256 (first 16 hex digits) of the final arrays of a few short runs.

Run it before and after a change that must not move any result (a
restructuring) and compare the lines: a kinematic ``cutkit cut`` of a small
slab, ``isovolume`` + ``decimate`` of ``sample_volumes/block_labels.nrrd`` and
a cut of the decimated block, and a short ``simulate`` on a small prestressed
slab with each material model (positions and tets of the last frame, the
forces file, and the summary without its wall-clock figures).

Usage (from the repository root; a few minutes on two cores)::

    NUMBA_NUM_THREADS=1 python tools/fingerprint.py OUT_DIR [REPO_ROOT] [slab,block,springs,neohookean]
"""

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from cutkit.assign.defaults import DEFAULT_MATERIALS
from cutkit.cli.main import main
from cutkit.cutting.trajectory import straight_incision, write_trajectory
from cutkit.io.model_h5 import read_model, write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel


TIMING_KEYS = ("model", "wall_s", "simulated_per_wall", "simulated_per_wall_without_output", "time_per_task_s",
               "cut_step_ms")


def h(*arrays):
    s = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        s.update(str(a.dtype).encode() + str(a.shape).encode())
        s.update(a.tobytes())
    return s.hexdigest()[:16]


def run(args):
    code = main([str(a) for a in args])
    assert code in (0, None), (args, code)


def cut_case(d, name, model_path, p0, p1, inward, depth, blade_length):
    traj = straight_incision(p0, p1, inward, depth=depth, approach=1.0, press_time=0.05, cut_time=0.2,
                             rate=50.0, blade_length=blade_length)
    write_trajectory(d / f"{name}.csv", traj)
    out = d / f"{name}_out"
    run(["cut", model_path, "--trajectory", d / f"{name}.csv", "-o", out])
    m = read_model(out / "model.h5")
    print(f"cut {name}: tets={m.tets.shape[0]} nodes={m.points.shape[0]} "
          f"points={h(m.points)} tets={h(m.tets)}", flush=True)


def sim_case(d, name, material):
    shape, H = (8, 4, 6), 2.0
    points, tets = box_mesh(shape, spacing=(H, H, H))
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == shape[2] * H))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    model = TetModel.from_arrays(
        points, tets, materials=Materials.from_rows([row]),
        boundary=BoundaryConditions(fixed_nodes=ends),
        prestress=Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                            prestrain=np.array([0.15])))
    write_model(d / f"{name}.h5", model)
    traj = straight_incision([3.0, 0.0, 6.3], [13.0, 0.0, 6.3], inward=[0, 1, 0], depth=4.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    write_trajectory(d / f"{name}.csv", traj)
    out = d / f"{name}_out"
    run(["simulate", d / f"{name}.h5", "--trajectory", d / f"{name}.csv", "-o", out, "--fps", "10",
         "--hold", "0.1", "--material-model", material])
    import meshio

    frames = sorted((out / "frames").glob("*.vtu"))
    last = meshio.read(frames[-1])
    s = json.loads((out / "summary.json").read_text())
    for k in TIMING_KEYS:  # wall-clock figures and the input path vary from run to run
        s.pop(k, None)
    forces = (out / "forces.csv").read_bytes() if (out / "forces.csv").exists() else b""
    print(f"simulate {name} ({material}): frames={len(frames)} tets={last.cells_dict['tetra'].shape[0]} "
          f"points={h(last.points)} tets={h(last.cells_dict['tetra'])} "
          f"forces={hashlib.sha256(forces).hexdigest()[:16]} "
          f"summary={hashlib.sha256(json.dumps(s, sort_keys=True).encode()).hexdigest()[:16]}", flush=True)


if __name__ == "__main__":
    d = Path(sys.argv[1])
    d.mkdir(parents=True, exist_ok=True)
    root = Path(sys.argv[2]) if len(sys.argv) > 2 else Path(".")
    only = sys.argv[3].split(",") if len(sys.argv) > 3 else ["slab", "block", "springs", "neohookean"]
    if "slab" in only:
        p, t = box_mesh((6, 3, 3))
        write_model(d / "slab.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
        cut_case(d, "slab", d / "slab.h5", [0.5, 1.37, 3.0], [5.5, 1.37, 3.0], [0, 0, -1.0], 1.5, 5.0)
    if "block" in only:
        run(["isovolume", root / "sample_volumes" / "block_labels.nrrd", "-o", d / "block_iso.h5"])
        iso = read_model(d / "block_iso.h5")
        print(f"isovolume block: tets={iso.tets.shape[0]} points={h(iso.points)} tets={h(iso.tets)}", flush=True)
        run(["decimate", d / "block_iso.h5", "-o", d / "block_dec.h5", "--ratio", "0.3"])
        dec = read_model(d / "block_dec.h5")
        print(f"decimate block: tets={dec.tets.shape[0]} points={h(dec.points)} tets={h(dec.tets)} "
              f"labels={h(dec.labels)}", flush=True)
        lo, hi = dec.points.min(axis=0), dec.points.max(axis=0)
        mid = 0.5 * (lo + hi)
        cut_case(d, "block", d / "block_dec.h5", [lo[0] + 0.2 * (hi[0] - lo[0]), mid[1] + 0.37, hi[2] + 0.5],
                 [hi[0] - 0.2 * (hi[0] - lo[0]), mid[1] + 0.37, hi[2] + 0.5], [0, 0, -1.0],
                 0.3 * (hi[2] - lo[2]), 0.6 * (hi[2] - lo[2]))
    for mat in ("springs", "neohookean"):
        if mat in only:
            sim_case(d, f"sim_{mat}", mat)
