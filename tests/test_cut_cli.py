"""End-to-end test of ``cutkit cut``."""

import numpy as np
from click.testing import CliRunner

from cutkit.cli.cut import command
from cutkit.cutting.trajectory import straight_incision, write_trajectory
from cutkit.io.model_h5 import read_model, write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import TetModel


def test_cut_cli(tmp_path):
    p, t = box_mesh((6, 3, 3))
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    traj = straight_incision([0.5, 1.37, 3.0], [5.5, 1.37, 3.0], [0, 0, -1.0], depth=1.5, approach=1.0,
                             press_time=0.05, cut_time=0.2, rate=50.0, blade_length=5.0)
    write_trajectory(tmp_path / "c.csv", traj)
    out = tmp_path / "out"
    r = CliRunner().invoke(command, [str(tmp_path / "m.h5"), "--trajectory", str(tmp_path / "c.csv"),
                                     "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert (out / "cut.pvd").exists()
    frames = sorted((out / "frames").glob("*.vtu"))
    assert len(frames) == len(traj.t)
    m = read_model(out / "model.h5")
    assert m.tets.shape[0] > t.shape[0]
    assert m.cell_data["new_tet"].sum() > 0 and m.point_data["new_node"].sum() > 0
