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
    assert "could not be cut" not in r.output  # a steady incision cuts every edge it meets


def test_cut_cli_reports_the_edges_the_blade_left_uncut(tmp_path):
    """A curved stroke with 1 mm tremor leaves the tissue with an edge deferred (two opposite cut edges
    alone in a tet, waiting for a linking cut that never comes); the edges the blade could not cut
    are reported, as many as the library counts (``CutMesh.edges_left_uncut``, checked against the
    crossed edges in tests/test_cut_properties.py)."""
    import re

    from _cut_paths import make_path

    from cutkit.cutting import CutMesh, cut_step
    from cutkit.cutting.step import rebase_if_left
    from cutkit.cutting.trajectory import Trajectory

    p, t = box_mesh((6, 3, 3))
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    poses = make_path("curved", np.random.default_rng(10), p.max(axis=0), tremor=1.0)
    tips, axes = np.array([q[0] for q in poses]), np.array([q[1] for q in poses])
    normals = np.cross(axes, [0.0, 1.0, 0.0])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    traj = Trajectory(t=np.arange(len(poses)) * 0.01, tip=tips, a=axes, n=normals, blade_length=5.0)
    write_trajectory(tmp_path / "f.csv", traj)
    r = CliRunner().invoke(command, [str(tmp_path / "m.h5"), "--trajectory", str(tmp_path / "f.csv"),
                                     "-o", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    cm = CutMesh(p, t, blade_length=5.0)
    for tip, a in zip(traj.tip, traj.a):
        cut_step(cm, tip, a)
        rebase_if_left(cm)
    assert cm.edges_left_uncut() > 0
    found = re.search(r"([0-9]+) edges? the blade met could not be cut", r.output.replace("\n", " "))
    assert found and int(found.group(1)) == cm.edges_left_uncut(), r.output
    # ... in one warning line naming each (up to 8) by its rest midpoint
    places = cm.uncut_edge_places()
    assert len(places) == cm.edges_left_uncut()
    named = re.findall(r"\(([-0-9.]+), ([-0-9.]+), ([-0-9.]+)\)", r.output.replace("\n", " "))
    assert len(named) == min(len(places), 8)
    np.testing.assert_allclose(np.array(named, float), places[:8], atol=0.006)


def test_cut_cli_a_second_stroke_crosses_the_first(tmp_path):
    """Two through-strokes in one trajectory, the blade lifted out between them: the second cuts
    the first's sub-tetrahedra (the cut is rebased when the blade has left), four pieces."""
    from _twins_cut import components

    from cutkit.cutting.trajectory import Trajectory

    p, t = box_mesh((6, 3, 3))
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    down = np.array([0.0, 0.0, -1.0])
    tips = [[x, 1.37, -0.5] for x in np.linspace(-0.5, 6.5, 15)]  # first stroke, through, along x
    tips += [[6.5, 1.37, 5.0], [2.37, -0.5, 5.0], [2.37, -0.5, -0.5]]  # lifted out, over, down beside
    tips += [[2.37, y, -0.5] for y in np.linspace(-0.5, 3.5, 9)[1:]]  # second stroke, along y
    tips = np.array(tips)
    k = len(tips)
    traj = Trajectory(t=np.arange(k) * 0.01, tip=tips, a=np.tile(down, (k, 1)),
                      n=np.tile([1.0, 0.0, 0.0], (k, 1)), blade_length=5.0)
    write_trajectory(tmp_path / "x.csv", traj)
    out = tmp_path / "out"
    r = CliRunner().invoke(command, [str(tmp_path / "m.h5"), "--trajectory", str(tmp_path / "x.csv"),
                                     "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "2 strokes" in r.output.replace("\n", " ")
    m = read_model(out / "model.h5")
    from cutkit.mesh.check import check_mesh
    from cutkit.mesh.quality import signed_volumes

    assert check_mesh(m.points, m.tets, m.labels).passed
    assert signed_volumes(m.points, m.tets).sum() == pytest.approx(6 * 3 * 3, rel=1e-12)
    assert components(m.tets) == 4
    on_cut = m.point_data["cut_surface_node"] == 1
    assert np.any(on_cut & (np.abs(m.points[:, 0] - 2.37) < 0.8)) and np.any(on_cut & (np.abs(m.points[:, 1] - 1.37) < 0.8))
