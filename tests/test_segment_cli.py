"""The ``cutkit segment`` command."""

from pathlib import Path

import numpy as np
from click.testing import CliRunner

from cutkit.cli.main import cli
from cutkit.volumes import read_volume

SAMPLES = Path(__file__).resolve().parents[1] / "sample_volumes"


def test_segment_ct_threshold_writes_labels_and_summary(tmp_path):
    out = tmp_path / "bone.nrrd"
    res = CliRunner().invoke(cli, ["segment", str(SAMPLES / "knee_ct.nrrd"), "-o", str(out), "--threshold", "300:2000"])
    assert res.exit_code == 0, res.output
    seg = read_volume(out)
    ct = read_volume(SAMPLES / "knee_ct.nrrd")
    assert seg.data.dtype == np.uint8 and set(np.unique(seg.data)) == {0, 1}
    np.testing.assert_allclose(seg.affine, ct.affine)
    n = int(np.count_nonzero(seg.data))
    assert f"{n}" in res.output and f"{n * 1.5 ** 3:.1f}" in res.output


def test_segment_npy_with_spacing_and_voxel_size(tmp_path):
    data = np.zeros((10, 10, 10), np.float32)
    data[2:8, 2:8, 2:8] = 1.0
    np.save(tmp_path / "v.npy", data)
    out = tmp_path / "s.npz"
    res = CliRunner().invoke(cli, ["segment", str(tmp_path / "v.npy"), "-o", str(out), "--threshold", "0.5",
                                   "--spacing", "2,2,2", "--voxel-size", "1"])
    assert res.exit_code == 0, res.output
    seg = read_volume(out)
    np.testing.assert_allclose(seg.spacing, 1.0)
    assert seg.shape == (19, 19, 19)


def test_segment_empty_is_a_one_line_error(tmp_path):
    out = tmp_path / "e.nrrd"
    res = CliRunner().invoke(cli, ["segment", str(SAMPLES / "knee_ct.nrrd"), "-o", str(out), "--threshold", "5000"])
    assert res.exit_code == 2
    assert "error: segmentation selects no voxel (threshold 5000:; values range" in res.output
    assert not out.exists()


def test_segment_bad_threshold(tmp_path):
    res = CliRunner().invoke(cli, ["segment", str(SAMPLES / "knee_ct.nrrd"), "-o", str(tmp_path / "x.nrrd"),
                                   "--threshold", "9:1"])
    assert res.exit_code == 2
    assert "--threshold must be LOW, LOW:HIGH or :HIGH with LOW <= HIGH (got '9:1')" in res.output


def test_segment_integer_label_volume_is_used_as_is(tmp_path):
    out = tmp_path / "l.nrrd"
    res = CliRunner().invoke(cli, ["segment", str(SAMPLES / "block_labels.nrrd"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    np.testing.assert_array_equal(read_volume(out).data, read_volume(SAMPLES / "block_labels.nrrd").data)
