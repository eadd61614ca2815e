"""Pinned results: what the runtime computes on fixed inputs, to the last bit.

Each case cuts (and, for ``simulate``, relaxes) a fixed model along a fixed
incision and compares with the figures stored in ``tests/data/pinned/``:
the tets cut and the relaxation's counts exactly, the final topology
exactly, the final positions bit for bit as they were computed on this kind
of processor (``positions``: a sha256 per processor, the name and features
the kernels are compiled for; the arrays in the ``.npz``).  Another kind of
processor rounds the last bits differently (its BLAS and NumPy's SIMD
paths, fused multiply-adds), and a long run carries the difference on: a
processor with no pins of its own is held to the nearest pinned positions
within :data:`CROSS_CPU_ATOL_MM` of its case, the difference measured
between an Intel Xeon and an AMD EPYC.
A restructuring must leave every case as it is; a change meant to move a
result (a new solver, a new cut rule) writes the pins again with

    python tests/test_pinned_results.py --write [--knee FOLDER] [CASE ...]

(``--knee``: a folder where ``cutkit demo`` built ``knee.h5``, reused).

and says in its commit which cases moved and by how much.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

PINS = Path(__file__).parent / "data" / "pinned"
#: Final positions on a processor with no pins of its own: at most this far from the nearest pinned
#: ones, mm, by case (default :data:`CROSS_CPU_DEFAULT_MM`).  Measured between an Intel Xeon and an
#: AMD EPYC: 0 to 2e-14 mm, the knee's neo-Hookean run 9.7e-8 mm, the knee's springs 0.61 mm (their
#: per-node explicit steps carry a rounding difference through 2,095 passes of a cut that is the same
#: tet for tet).  A change that moves a result on a pinned processor fails bit for bit.
CROSS_CPU_ATOL_MM = {"knee_simulate_neohookean": 1e-5, "knee_simulate_springs": 2.0}
CROSS_CPU_DEFAULT_MM = 1e-9

#: The slab of the short simulated incision (tests/test_simulate.py): 32 x 12 x 16 mm, 2 mm cells.
SLAB_SHAPE, SLAB_H = (16, 6, 8), 2.0


def _slab_model():
    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel

    points, tets = box_mesh(SLAB_SHAPE, spacing=(SLAB_H,) * 3)
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == SLAB_SHAPE[2] * SLAB_H))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    return TetModel.from_arrays(
        points, tets, materials=Materials.from_rows([row]), boundary=BoundaryConditions(fixed_nodes=ends),
        prestress=Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                            prestrain=np.array([0.15])))


def _slab_incision():
    from cutkit.cutting.trajectory import straight_incision

    return straight_incision([6.0, 0.0, 8.3], [26.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                             press_time=0.3, cut_time=0.6, rate=100)


def _knee(tmp):
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.demo import build_or_reuse, demo_inputs

    path, _, _ = build_or_reuse(tmp / "knee")
    return read_model(path), read_trajectory(demo_inputs()[1])


def _cut(model, traj) -> dict:
    """A kinematic cut as ``cutkit cut`` makes it: the rest positions and tets of the cut mesh."""
    from cutkit.cutting import CutMesh, cut_step, to_model
    from cutkit.cutting.step import finish_stroke, rebase_if_left

    cm = CutMesh.from_model(model, blade_length=traj.blade_length)
    for i in range(len(traj.t)):
        cut_step(cm, traj.tip[i], traj.a[i])
        rebase_if_left(cm)
    finish_stroke(cm)  # the trajectory's end
    m = to_model(cm, model)
    return {"counts": {"tets": int(m.tets.shape[0]), "new_tets": int(m.cell_data["new_tet"].sum())},
            "positions": m.points, "tets": m.tets}


def _simulate(model, traj, material_model, out) -> dict:
    """A ``simulate`` run (no frames, no pictures: they never change what is simulated)."""
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions, simulate

    s = simulate(model, traj, out, SimulateOptions(material_model=material_model, frames=False, hold_s=0.5))
    m = read_model(out / "model.h5")
    counts = {"cut_tets": int(s["cut_tets"]), "tets": int(m.tets.shape[0])}
    counts.update({k: int(v) for k, v in s["counts"].items() if k.startswith("relax_")})
    return {"counts": counts, "positions": m.points + m.point_data["displacement"], "tets": m.tets}


#: case -> (needs the knee, the run)
CASES = {
    "slab_cut": (False, lambda tmp: _cut(_slab_model(), _slab_incision())),
    "slab_simulate_neohookean": (False, lambda tmp: _simulate(_slab_model(), _slab_incision(), "neohookean",
                                                              tmp / "out")),
    "slab_simulate_springs": (False, lambda tmp: _simulate(_slab_model(), _slab_incision(), "springs",
                                                           tmp / "out")),
    "knee_cut": (True, lambda tmp: _cut(*_knee(tmp))),
    "knee_simulate_neohookean": (True, lambda tmp: _simulate(*_knee(tmp), "neohookean", tmp / "out")),
    "knee_simulate_springs": (True, lambda tmp: _simulate(*_knee(tmp), "springs", tmp / "out")),
}


def fingerprint(result: dict) -> dict:
    """Counts and sha256 of the final tets and positions (float64, C order) of one case."""
    x = np.ascontiguousarray(result["positions"], np.float64)
    t = np.ascontiguousarray(result["tets"], np.int64)
    return {"counts": result["counts"], "n_points": int(x.shape[0]),
            "tets_sha256": hashlib.sha256(t.tobytes()).hexdigest(),
            "positions_sha256": hashlib.sha256(x.tobytes()).hexdigest()}


def host_cpu() -> str:
    """The processor the kernels are compiled for: its name and a hash of its features (llvmlite's)."""
    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features().flatten()
    return f"{llvm.get_host_cpu_name()}-{hashlib.sha256(features.encode()).hexdigest()[:12]}"


def write_pins(names, tmp: Path, knee_folder: Path | None) -> None:
    """Run each case and pin its result for this processor.  The pins of other processors are kept
    where this processor's result is unchanged (a restructuring), and dropped where it moved."""
    PINS.mkdir(parents=True, exist_ok=True)
    cpu = host_cpu()
    for name in names:
        case_dir = tmp / name
        case_dir.mkdir(parents=True, exist_ok=True)
        if knee_folder is not None:
            (case_dir / "knee").symlink_to(knee_folder.resolve(), target_is_directory=True)
        result = CASES[name][1](case_dir)
        pin = fingerprint(result)
        sha = pin.pop("positions_sha256")
        old = json.loads((PINS / f"{name}.json").read_text()) if (PINS / f"{name}.json").exists() else {}
        arrays = dict(np.load(PINS / f"{name}.npz")) if (PINS / f"{name}.npz").exists() else {}
        kept = old.get("positions", {}) if old.get("positions", {}).get(cpu) == sha else {}
        pin["positions"] = {**kept, cpu: sha}
        arrays = {k: arrays[k] for k in kept if k in arrays}
        arrays[cpu] = np.asarray(result["positions"], np.float64)
        (PINS / f"{name}.json").write_text(json.dumps(pin, indent=1) + "\n")
        np.savez_compressed(PINS / f"{name}.npz", **arrays)
        print(name, pin["counts"], "processors pinned:", sorted(pin["positions"]))


def _params():
    return [pytest.param(name, marks=[pytest.mark.slow, pytest.mark.knee] if knee else [], id=name)
            for name, (knee, _) in CASES.items()]


@pytest.mark.parametrize("name", _params())
def test_pinned_result(name, tmp_path, request):
    if CASES[name][0]:
        knee_folder = request.getfixturevalue("demo_knee")[0]
        (tmp_path / "knee").symlink_to(knee_folder, target_is_directory=True)
    pinned = json.loads((PINS / f"{name}.json").read_text())
    result = CASES[name][1](tmp_path)
    got = fingerprint(result)
    assert got["counts"] == pinned["counts"]
    assert got["n_points"] == pinned["n_points"]
    assert got["tets_sha256"] == pinned["tets_sha256"]
    if got["positions_sha256"] in pinned["positions"].values():
        return  # bit for bit as on a pinned processor
    cpu = host_cpu()
    x = np.asarray(result["positions"], np.float64)
    arrays = np.load(PINS / f"{name}.npz")
    if cpu in pinned["positions"]:
        diff = float(np.abs(x - arrays[cpu]).max())
        raise AssertionError(f"final positions moved by up to {diff:.3e} mm on this processor ({cpu})")
    diff = min(float(np.abs(x - arrays[k]).max()) for k in pinned["positions"])
    atol = CROSS_CPU_ATOL_MM.get(name, CROSS_CPU_DEFAULT_MM)
    assert diff <= atol, f"final positions {diff:.3e} mm from the nearest pinned processor's (no pins for {cpu})"


if __name__ == "__main__":
    import tempfile

    args = sys.argv[1:]
    if "--write" not in args:
        sys.exit("usage: python tests/test_pinned_results.py --write [--knee FOLDER] [CASE ...]")
    args.remove("--write")
    knee = None
    if "--knee" in args:
        k = args.index("--knee")
        knee = Path(args[k + 1])
        del args[k:k + 2]
    with tempfile.TemporaryDirectory() as d:
        write_pins(args or list(CASES), Path(d), knee)
