"""What a new user meets first: unwritable outputs, bad options, misleading messages.

Every user error is one line ``cutkit: error: ...`` and exit status 2,
reported before any work is done.
"""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cutkit.cli.main import cli
from cutkit.cutting.trajectory import straight_incision, write_trajectory
from cutkit.io.model_h5 import write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import TetModel

ROOT = Path(__file__).resolve().parents[1]
BLOCK = str(ROOT / "sample_volumes" / "block_labels.nrrd")


def run(args):
    r = CliRunner().invoke(cli, [str(a) for a in args])
    return r.exit_code, r.stderr if hasattr(r, "stderr") else r.output, r


def error_line(args):
    code, _, r = run(args)
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    lines = [ln for ln in r.output.splitlines() if ln.startswith("cutkit: error:")]
    assert code == 2, r.output
    assert len(lines) == 1, r.output
    return lines[0]


@pytest.fixture
def inputs(tmp_path):
    p, t = box_mesh((6, 3, 3))
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    traj = straight_incision([0.5, 1.37, 3.0], [5.5, 1.37, 3.0], [0, 0, -1.0], depth=1.5, approach=1.0,
                             press_time=0.05, cut_time=0.2, rate=50.0, blade_length=5.0)
    write_trajectory(tmp_path / "c.csv", traj)
    (tmp_path / "afile").write_text("not a folder\n")
    (tmp_path / "r.toml").write_text("[materials.1]\nname = 'fat'\n")
    return tmp_path


# the output's parent is a regular file: no user (root included) can write there
FILE_OUTPUTS = {
    "build-model": lambda d, o: ["build-model", BLOCK, "--labels", BLOCK, "-o", o],
    "segment": lambda d, o: ["segment", BLOCK, "-o", o],
    "isovolume": lambda d, o: ["isovolume", BLOCK, "-o", o],
    "decimate": lambda d, o: ["decimate", d / "m.h5", "--ratio", "0.5", "-o", o],
    "import": lambda d, o: ["import", ROOT / "tests" / "absent.vtu", "-o", o],
    "export": lambda d, o: ["export", d / "m.h5", o],
    "assign": lambda d, o: ["assign", d / "m.h5", "--recipe", d / "r.toml", "-o", o],
    "texture": lambda d, o: ["texture", d / "m.h5", "--volume", BLOCK, "--register", "none", "-o", o],
}
FOLDER_OUTPUTS = {
    "simulate": lambda d, o: ["simulate", d / "m.h5", "--trajectory", d / "c.csv", "-o", o],
    "cut": lambda d, o: ["cut", d / "m.h5", "--trajectory", d / "c.csv", "-o", o],
    "relax": lambda d, o: ["relax", d / "m.h5", "--seconds", "0.1", "-o", o],
    "demo": lambda d, o: ["demo", "-o", o],
}


@pytest.mark.parametrize("name", sorted(FILE_OUTPUTS))
def test_unwritable_output_file_is_one_line(inputs, name):
    out = inputs / "afile" / "out.h5"
    line = error_line(FILE_OUTPUTS[name](inputs, out))
    assert line == f"cutkit: error: cannot write {out}: {inputs / 'afile'} is a file, not a folder"


@pytest.mark.parametrize("name", sorted(FOLDER_OUTPUTS))
def test_unwritable_output_folder_is_one_line(inputs, name):
    out = inputs / "afile" / "OUT"
    line = error_line(FOLDER_OUTPUTS[name](inputs, out))
    assert line == f"cutkit: error: cannot write {out}: {inputs / 'afile'} is a file, not a folder"
    assert not out.exists()


@pytest.mark.parametrize("name", ["build-model", "decimate", "simulate", "demo"])
def test_read_only_folder_is_reported_before_the_work(inputs, monkeypatch, name):
    # tests may run as root, which ignores permission bits: make os.access say "read-only"
    import os

    ro = inputs / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if Path(p) == ro and mode & os.W_OK else real(p, mode, **kw))
    import cutkit.build

    def no_work(*a, **k):  # the build must not start
        raise AssertionError("work started before the output was checked")

    monkeypatch.setattr(cutkit.build, "run_build", no_work)
    args = {**FILE_OUTPUTS, **FOLDER_OUTPUTS}[name](inputs, ro / "out")
    line = error_line(args)
    assert line == f"cutkit: error: cannot write {ro / 'out'}: folder {ro} is not writable"
