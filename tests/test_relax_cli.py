"""``cutkit relax`` and the .vtu/.pvd series writer."""

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest
from click.testing import CliRunner
from test_relax import block

from cutkit.cli.main import cli
from cutkit.errors import InputError
from cutkit.io.model_h5 import write_model
from cutkit.io.series import SeriesWriter


def _pvd_files(path):
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def test_series_writer_keeps_a_valid_pvd_after_every_frame(tmp_path):
    tm = block(2, 2, 2)
    w = SeriesWriter(tmp_path, "run")
    for i in range(3):
        w.write(0.1 * i, tm.points + i, tm.tets, point_data={"displacement": np.full((tm.n_points, 3), float(i))})
        # an interrupted run still leaves a readable collection of the frames so far
        files = _pvd_files(tmp_path / "run.pvd")
        assert [f for _, f in files] == [f"frames/{k:04d}.vtu" for k in range(i + 1)]
    w.close()
    mesh = meshio.read(tmp_path / "frames" / "0002.vtu")
    np.testing.assert_allclose(mesh.points, tm.points + 2)
    np.testing.assert_array_equal(mesh.cells_dict["tetra"], tm.tets)
    assert [t for t, _ in _pvd_files(tmp_path / "run.pvd")] == pytest.approx([0.0, 0.1, 0.2])
    assert not [p for p in tmp_path.rglob(".*")]  # no temporary files left


def test_series_writer_rejects_mismatched_data(tmp_path):
    tm = block(2, 2, 2)
    with pytest.raises(InputError, match="point data 'u' has 3 rows, the mesh has 27 points"):
        SeriesWriter(tmp_path, "run").write(0.0, tm.points, tm.tets, point_data={"u": np.zeros((3, 3))})


def test_relax_command_settles_under_gravity(tmp_path):
    tm = block(3, 3, 2, damping=500.0)
    write_model(tmp_path / "m.h5", tm)
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["relax", str(tmp_path / "m.h5"), "--seconds", "0.2", "--fps", "10",
                                      "-o", str(out), "--gravity", "0,0,-9.81"])
    assert result.exit_code == 0, result.output
    files = _pvd_files(out / "relax.pvd")
    assert len(files) == 3 and files[-1][0] == pytest.approx(0.2)
    last = meshio.read(out / files[-1][1])
    disp = last.point_data["displacement"]
    assert set(last.point_data) == {"displacement", "velocity", "node_list"}
    # sags down; fixed bottom nodes stay put; fixed nodes are in no list
    bottom = tm.points[:, 2] == 0
    assert disp[~bottom, 2].min() < 0 and np.all(disp[bottom] == 0)
    assert np.all(last.point_data["node_list"][bottom] == -1)


def test_relax_command_reports_bad_arguments(tmp_path):
    write_model(tmp_path / "m.h5", block(2, 2, 2))
    result = CliRunner().invoke(cli, ["relax", str(tmp_path / "m.h5"), "--seconds", "-1", "-o", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert "--seconds must be a positive number, got -1.0" in result.output
    result = CliRunner().invoke(cli, ["relax", str(tmp_path / "m.h5"), "--seconds", "1", "-o", str(tmp_path / "o"),
                                      "--gravity", "0,-9.81"])
    assert result.exit_code == 2 and "--gravity must be three comma-separated numbers" in result.output
    result = CliRunner().invoke(cli, ["relax", str(tmp_path / "m.h5"), "--seconds", "1", "-o", str(tmp_path / "o"),
                                      "--lists", "0"])
    assert result.exit_code == 2 and "--lists must lie in 1..30, got 0" in result.output
    assert not (tmp_path / "o").exists()
