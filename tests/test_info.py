"""`cutkit info`: NaN count, label volumes in mm^3, orientation and frame, units, whole tables when piped."""

from pathlib import Path

import numpy as np
from click.testing import CliRunner

from cutkit.cli.info import orientation_code
from cutkit.cli.main import cli
from cutkit.io.model_h5 import write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model import MATERIAL_FIELDS, Materials, TetModel

BLOCK = str(Path(__file__).resolve().parents[1] / "sample_volumes" / "block_labels.nrrd")


def info(path):
    r = CliRunner().invoke(cli, ["info", str(path)])
    assert r.exit_code == 0, r.output
    return r.output


def test_volume_info_counts_nans(tmp_path):
    data = np.ones((4, 4, 4), np.float32)
    data[0, 0, :3] = np.nan
    np.save(tmp_path / "v.npy", data)
    assert "  NaN voxels: 3" in info(tmp_path / "v.npy").splitlines()


def test_label_volumes_in_mm3_and_the_frame():
    out = info(BLOCK)
    # 720 voxels of 2 x 1.5 x 1 mm
    assert any(line.split("│")[1:4] == [" 1     ", " 720    ", " 2160          "] for line in out.splitlines())
    assert "orientation LPS: voxel axes i, j, k point to left, posterior, superior; world frame LPS" in out
    assert "nibabel's RAS affine" in out


def test_orientation_code():
    assert orientation_code(np.eye(3)) == "LPS"
    assert orientation_code(np.diag([-1.0, -1.0, 1.0])) == "RAS"
    assert orientation_code(np.array([[0.0, 0, 1], [1, 0, 0], [0, -1, 0]])) == "PIL"


def test_materials_table_has_units_and_is_not_cut(tmp_path):
    p, t = box_mesh((2, 2, 2))
    row = dict(label=1, name="muscle", **{k: 0.3 for k in MATERIAL_FIELDS})
    write_model(tmp_path / "m.h5", TetModel.from_arrays(p, t, materials=Materials.from_rows([row])))
    out = info(tmp_path / "m.h5")
    header = next(line for line in out.splitlines() if "label" in line and "name" in line)
    last = list(MATERIAL_FIELDS)[-1]
    assert "E [Pa]" in header and "density [kg/m^3]" in header and last in header
