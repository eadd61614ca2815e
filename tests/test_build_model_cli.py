"""cutkit build-model end to end: a scalar CT volume by threshold, the knee recipe (as the demo builds it)."""

from pathlib import Path

import numpy as np
import pytest

from cutkit.cli.main import main
from cutkit.io.model_h5 import read_model
from cutkit.mesh.quality import min_dihedral_angles, signed_volumes

SAMPLES = Path(__file__).resolve().parents[1] / "sample_volumes"


def test_scalar_volume_by_threshold(tmp_path, capsys):
    out = tmp_path / "bone.h5"
    code = main(["build-model", str(SAMPLES / "knee_ct.nrrd"), "--threshold", "300:2000", "--voxel-size", "3",
                 "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    m = read_model(out)
    assert m.tets.shape[0] > 1000
    assert np.all(signed_volumes(m.points, m.tets) > 0)
    assert min_dihedral_angles(m.points, m.tets).min() > 1.0
    prov = m.provenance
    assert {"segment", "isovolume", "assign"} <= set(prov["stage_figures"])
    assert list(prov["recipe"]["segment"]["threshold"]) == [300.0, 2000.0]  # command-line parameters recorded
    import hashlib

    digest = hashlib.sha256((SAMPLES / "knee_ct.nrrd").read_bytes()).hexdigest()
    assert "sha256:" + digest in prov["inputs"].values()  # what sha256sum prints
    assert main(["check", str(out)]) == 0


def test_empty_threshold_is_one_line_error(tmp_path, capsys):
    code = main(["build-model", str(SAMPLES / "knee_ct.nrrd"), "--threshold", "90000", "-o", str(tmp_path / "m.h5")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "segmentation selects no voxel" in err[0]
    assert not (tmp_path / "m.h5").exists()


@pytest.mark.slow
def test_demo_build_is_reused_while_inputs_are_unchanged(tmp_path, demo_knee, monkeypatch):
    import shutil

    from cutkit.demo import build_or_reuse

    folder, _, report = demo_knee  # built once for the run, into an empty folder
    assert report
    for name in ("knee.h5", "knee.h5.key"):
        shutil.copy2(folder / name, tmp_path / name)
    path, reused, _ = build_or_reuse(tmp_path)
    assert reused and path == tmp_path / "knee.h5"
    m = read_model(path)
    assert sorted(np.unique(m.labels).tolist()) == [1, 2, 3, 4, 5]  # skin, fat, muscle, tendon, bone
    assert len(m.boundary.fixed_nodes) > 0 and len(m.prestress.label) == 2
    assert m.texture is not None and m.texcoords is not None
    assert main(["check", str(path)]) == 0
    stamp = path.stat().st_mtime_ns
    path2, reused2, _ = build_or_reuse(tmp_path)
    assert reused2 and path2 == path and path.stat().st_mtime_ns == stamp
    # a changed key (another version, recipe or volume) builds again: the build is called
    # (and stopped there; the whole build is the session fixture's, timed once per run)
    (tmp_path / "knee.h5.key").write_text("0" * 64 + "\n")

    class Built(Exception):
        pass

    def build(*args, **kwargs):
        raise Built

    monkeypatch.setattr("cutkit.build.run_build", build)
    with pytest.raises(Built):
        build_or_reuse(tmp_path)
