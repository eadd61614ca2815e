"""simulate registers a blade that meets the tissue edge-first (whole-blade contact)."""

import numpy as np
import pytest

from cutkit.cutting.trajectory import Trajectory

#: A simulated cut (seconds on two cores).
pytestmark = pytest.mark.slow


def test_cleaver_with_the_tip_outside_enters_and_cuts(tmp_path):
    """The blade lies along x with its tip beyond the slab's end and moves into the y = 0 face.

    Neither the tip's path nor the first pose touches the tissue: only the
    swept quad does.
    """
    from test_simulate import slab

    from cutkit.simulate.run import SimulateOptions, simulate

    t = np.arange(0.0, 0.8, 0.01)
    y = -2.0 + 10.0 * t  # 8 mm into the slab by the end
    tip = np.stack([np.full_like(t, 36.0), y, np.full_like(t, 8.3)], axis=1)
    a = np.tile([1.0, 0.0, 0.0], (t.size, 1))
    n = np.tile([0.0, 1.0, 0.0], (t.size, 1))
    traj = Trajectory(t=t, tip=tip, a=a, n=n, blade_length=44.0)
    opt = SimulateOptions(fps=5.0, hold_s=0.1, settle_iterations=5, frames=False, write_model=False)
    summary = simulate(slab(0.15), traj, tmp_path / "out", opt)
    assert summary["counts"]["entries"] >= 1
    assert not any("never touches" in w for w in summary["warnings"])
    assert summary["cut_tets"] > 0
