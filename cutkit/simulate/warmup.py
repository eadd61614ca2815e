"""Compile (and cache) the numba kernels of decimation and simulation on a tiny model.

``cutkit demo`` runs this in a second process while the first one builds
the model: on a fresh installation numba compiles each kernel once (then
loads it from its cache), and this way the two cores compile side by side.
A live session runs it in process before its clock starts, so that no
kernel is first loaded (10-30 ms each) in the middle of a cut.

    python -m cutkit.simulate.warmup
"""

from __future__ import annotations

import subprocess
import sys
import tempfile

import numpy as np


def warm_up(outputs: bool = True, material_model: str | None = None) -> None:
    """Decimate and cut a small two-tissue slab (nothing is kept).

    Parameters
    ----------
    outputs : bool
        Also write frames and the cut model (their kernels).
    material_model : str, optional
        The tissue model to cut (``SimulateOptions.material_model``); default the model's.
    """
    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.cutting.trajectory import straight_incision
    from cutkit.decimate import decimate
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel
    from cutkit.simulate import SimulateOptions, simulate

    points, tets = box_mesh((8, 4, 6), spacing=(2.0, 2.0, 2.0))
    centre = points[tets].mean(axis=1)
    labels = np.where(centre[:, 1] < 2.0, 1, 3).astype(np.int32)  # a skin layer over muscle
    rows = [dict(label=1, name="skin", **DEFAULT_MATERIALS["skin"]),
            dict(label=3, name="muscle", **DEFAULT_MATERIALS["muscle"])]
    if outputs:
        decimate(TetModel.from_arrays(points, tets, labels, materials=Materials.from_rows(rows)), ratio=0.7)
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == 12.0))
    model = TetModel.from_arrays(points, tets, labels, materials=Materials.from_rows(rows),
                                 boundary=BoundaryConditions(fixed_nodes=ends),
                                 prestress=Prestress(label=np.array([3], np.int32),
                                                     fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                                                     prestrain=np.array([0.08])))
    traj = straight_incision([4.0, 0.0, 6.3], [12.0, 0.0, 6.3], inward=[0, 1, 0], depth=3.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    with tempfile.TemporaryDirectory() as d:
        simulate(model, traj, d, SimulateOptions(frames=outputs, fps=2, write_model=outputs, hold_s=0.05,
                                                 settle_iterations=2, material_model=material_model))


#: Kernel modules whose numba cache tells whether this installation has compiled the demo's
#: kernels: decimation, cutting and the default element model (caches are written on first use;
#: the springs' kernels compile only when a run asks for the springs).
CACHE_WITNESSES = ("decimate/_kernels.py", "cutting/_kernels_step.py", "relax/_elastic_kernels.py")


def kernels_compiled(root=None) -> bool | None:
    """Whether the numba kernels of this installation are in numba's cache (next to the sources).

    ``root`` is the package folder (default: this installation's ``cutkit``).

    False on a first run: the kernels compile then (minutes on two cores) and
    later runs load them.  None where the cache lives elsewhere
    (``NUMBA_CACHE_DIR``) or the package folder is not writable: unknown.
    """
    import os
    from pathlib import Path

    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    root = Path(__file__).resolve().parent.parent if root is None else Path(root)
    if not os.access(root, os.W_OK):
        return None
    for rel in CACHE_WITNESSES:
        src = root / rel
        if not any((src.parent / "__pycache__").glob(src.stem + ".*.nbi")):
            return False
    return True


def start_background() -> subprocess.Popen | None:
    """Run :func:`warm_up` in a quiet child process; None if it cannot start."""
    try:
        return subprocess.Popen([sys.executable, "-m", "cutkit.simulate.warmup"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        return None


if __name__ == "__main__":
    warm_up()
