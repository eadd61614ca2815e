"""End to end: ``cutkit simulate --scalpel fracture`` on the small slab of tests/test_simulate.py."""

import csv
import json

import numpy as np
import pytest

from cutkit.cli.main import main
from cutkit.cutting.trajectory import straight_incision, write_trajectory
from cutkit.io.model_h5 import write_model
from test_simulate import slab

#: One simulated cut (tens of seconds on two cores); tests/test_scalpel_fracture.py covers the force model fast.
pytestmark = pytest.mark.slow

J_C = 200.0  # liver-like, J/m^2
DEPTH = 5.0  # mm


def test_fracture_scalpel_cuts_the_slab_at_J_c_times_depth(tmp_path):
    model = slab(0.15)
    model.materials.values["J_c"][:] = J_C
    write_model(tmp_path / "slab.h5", model)
    traj = straight_incision([6.0, 0.0, 8.3], [26.0, 0.0, 8.3], inward=[0, 1, 0], depth=DEPTH, approach=3.0,
                             press_time=0.3, cut_time=0.6, rate=100)
    write_trajectory(tmp_path / "cut.csv", traj)
    out = tmp_path / "out"
    assert main(["simulate", str(tmp_path / "slab.h5"), "--trajectory", str(tmp_path / "cut.csv"), "-o", str(out),
                 "--fps", "5", "--hold", "0.1", "--scalpel", "fracture"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["options"]["scalpel"] == "fracture"
    assert s["cut_tets"] > 20 and s["tets_final"] > s["tets_initial"]
    with open(out / "forces.csv") as f:
        rows = list(csv.DictReader(f))
    states = [r["state"] for r in rows]
    assert "cutting" in states and "static" in states
    # while the crack advances at full depth the blade pays J_c per crack area: over whole sawtooth periods
    # the mean force is J_c * depth, the depth counted from where the blade entered (the first static tick:
    # the settled slab's face lies a little outside y = 0)
    force = np.array([[float(r[c]) for c in ("F_ext_x", "F_ext_y", "F_ext_z")] for r in rows])
    tip_y = np.array([float(r["tip_y"]) for r in rows])
    depth = tip_y.max() - tip_y[states.index("static")]
    assert 0.7 * DEPTH < depth <= DEPTH
    cutting = np.flatnonzero(np.array(states) == "cutting")
    steady = slice(cutting[len(cutting) // 2], cutting[-1])
    mean = float(np.linalg.norm(force[steady], axis=1).mean())
    assert mean == pytest.approx(J_C * 1e-3 * depth, rel=0.15)
