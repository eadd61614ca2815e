"""End-to-end test of ``cutkit cut``."""

import numpy as np
import pytest
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


def test_cut_cli_writes_no_orphan_node_and_reports_the_written_angle(tmp_path):
    import re

    import meshio

    from cutkit.mesh.check import check_mesh
    from cutkit.mesh.quality import min_dihedral_angles

    p, t = box_mesh((6, 3, 3))
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    traj = straight_incision([0.5, 1.37, 3.0], [5.5, 1.37, 3.0], [0, 0, -1.0], depth=1.5, approach=1.0,
                             press_time=0.05, cut_time=0.2, rate=50.0, blade_length=5.0)
    write_trajectory(tmp_path / "c.csv", traj)
    out = tmp_path / "out"
    r = CliRunner().invoke(command, [str(tmp_path / "m.h5"), "--trajectory", str(tmp_path / "c.csv"),
                                     "-o", str(out)])
    assert r.exit_code == 0, r.output
    m = read_model(out / "model.h5")
    rep = check_mesh(m.points, m.tets, m.labels)
    assert rep.passed, rep.failed
    assert np.unique(m.tets).size == m.points.shape[0]
    for f in sorted((out / "frames").glob("*.vtu")):
        mesh = meshio.read(f)
        assert np.unique(mesh.cells_dict["tetra"]).size == mesh.points.shape[0], f.name
    worst = float(re.search(r"worst new dihedral ([0-9.]+) deg", r.output.replace("\n", " ")).group(1))
    new = m.tets[m.cell_data["new_tet"] == 1]
    assert worst == pytest.approx(min_dihedral_angles(m.points, new).min(), abs=0.06)
