"""The progressive record: optional, and compressed where it is kept."""

from pathlib import Path

import h5py
import numpy as np
from click.testing import CliRunner

from cutkit.cli.main import cli
from cutkit.io.model_h5 import read_model, write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import TetModel

BLOCK = str(Path(__file__).resolve().parents[1] / "sample_volumes" / "block_labels.nrrd")


def run(*args):
    r = CliRunner().invoke(cli, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    return r


def test_build_model_leaves_the_record_out_unless_asked(tmp_path):
    run("build-model", BLOCK, "--ratio", "0.5", "-o", tmp_path / "a.h5")
    run("build-model", BLOCK, "--ratio", "0.5", "--keep-record", "-o", tmp_path / "b.h5")
    assert "progressive" not in read_model(tmp_path / "a.h5").extra
    rec = read_model(tmp_path / "b.h5").extra["progressive"]
    assert rec["tets0"].shape[0] > read_model(tmp_path / "b.h5").n_tets
    with h5py.File(tmp_path / "b.h5") as f:
        tets0 = f["cutkit/extra/progressive/tets0"]
        assert tets0.compression == "gzip" and tets0.shuffle
    assert (tmp_path / "a.h5").stat().st_size < (tmp_path / "b.h5").stat().st_size


def test_decimate_keeps_the_record_unless_told(tmp_path):
    p, t = box_mesh((6, 6, 6))
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    run("decimate", tmp_path / "m.h5", "--ratio", "0.5", "-o", tmp_path / "d.h5")
    run("decimate", tmp_path / "m.h5", "--ratio", "0.5", "--no-record", "-o", tmp_path / "n.h5")
    assert "progressive" in read_model(tmp_path / "d.h5").extra
    assert "progressive" not in read_model(tmp_path / "n.h5").extra
    r = CliRunner().invoke(cli, ["decimate", str(tmp_path / "n.h5"), "--level", "1", "-o", str(tmp_path / "x.h5")])
    assert r.exit_code == 2 and "cutkit build-model --keep-record" in r.output


def test_compressed_record_reads_back_exactly(tmp_path):
    p, t = box_mesh((12, 12, 12))
    rng = np.random.default_rng(0)
    extra = {"progressive": {"tets0": t.copy(), "points0": p + rng.normal(size=p.shape)}}
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32), extra=extra))
    back = read_model(tmp_path / "m.h5").extra["progressive"]
    np.testing.assert_array_equal(back["tets0"], t)
    np.testing.assert_array_equal(back["points0"], extra["progressive"]["points0"])
