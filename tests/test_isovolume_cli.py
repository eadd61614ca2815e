"""The ``cutkit isovolume`` command (volume reading stubbed where the reader is not under test)."""

import numpy as np
from click.testing import CliRunner

import cutkit.volumes
from cutkit.cli.main import cli
from cutkit.io.model_h5 import read_model
from cutkit.volumes import Volume


def _labels():
    labels = np.zeros((9, 8, 7), np.int16)
    labels[2:7, 2:6, 1:6] = 1
    labels[3:6, 3:5, 2:5] = 2
    return labels


def test_isovolume_command_writes_the_model_and_a_summary(tmp_path, monkeypatch):
    vol = Volume(_labels(), spacing=(0.5, 0.5, 1.0))
    monkeypatch.setattr(cutkit.volumes, "read_volume", lambda path: vol, raising=False)
    out = tmp_path / "model.h5"
    result = CliRunner().invoke(cli, ["isovolume", "labels.nrrd", "-o", str(out)])
    assert result.exit_code == 0, result.output
    model = read_model(out)
    assert set(np.unique(model.labels)) == {1, 2}
    assert f"{model.n_tets} tets" in result.output
    assert "volume per label" in result.output and "dihedral min" in result.output


def test_isovolume_command_empty_label_map_is_a_one_line_error(tmp_path, monkeypatch):
    monkeypatch.setattr(cutkit.volumes, "read_volume", lambda path: Volume(np.zeros((4, 4, 4), np.uint8)), raising=False)
    out = tmp_path / "model.h5"
    result = CliRunner().invoke(cli, ["isovolume", "empty.nrrd", "-o", str(out)])
    assert result.exit_code == 2
    assert result.output.strip() == "cutkit: error: isovolume: nothing to mesh, no voxel with a tissue label > 0"
    assert not out.exists()
