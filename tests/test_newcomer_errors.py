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
    out = ro / ("out.h5" if name in FILE_OUTPUTS else "out")
    line = error_line({**FILE_OUTPUTS, **FOLDER_OUTPUTS}[name](inputs, out))
    assert line == f"cutkit: error: cannot write {out}: folder {ro} is not writable"


# ---- numbers and combinations that used to be accepted without a word


@pytest.mark.parametrize("cmd", ["segment", "build-model"])
@pytest.mark.parametrize("flag,value,expected", [
    ("--smooth", "-1", "--smooth must be a number of mm >= 0 (0: no smoothing), got -1"),
    ("--voxel-size", "0", "--voxel-size must be a positive number of mm, got 0"),
    ("--voxel-size", "-2", "--voxel-size must be a positive number of mm, got -2"),
])
def test_bad_sizes_are_refused(tmp_path, cmd, flag, value, expected):
    line = error_line([cmd, BLOCK, flag, value, "-o", tmp_path / "x.h5" if cmd == "build-model" else tmp_path / "x.nrrd"])
    assert line == f"cutkit: error: {expected}"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("cmd", ["segment", "build-model"])
def test_threshold_with_labels_is_a_conflict(tmp_path, cmd):
    out = tmp_path / ("x.h5" if cmd == "build-model" else "x.nrrd")
    line = error_line([cmd, BLOCK, "--labels", BLOCK, "--threshold", "1", "-o", out])
    assert line == "cutkit: error: --labels uses the label map as the segmentation; it cannot be combined with --threshold"


def test_build_model_writes_only_model_files(tmp_path):
    line = error_line(["build-model", BLOCK, "-o", tmp_path / "m.vtu"])
    assert line == (f"cutkit: error: {tmp_path / 'm.vtu'}: a model file ends in .h5; to get .vtu, write MODEL.h5 "
                    f"and run `cutkit export MODEL.h5 {tmp_path / 'm.vtu'}`")
    assert not (tmp_path / "m.vtu").exists()


def test_labels_are_resampled_as_segment_does(tmp_path):
    from cutkit.io.model_h5 import read_model

    code, _, r = run(["build-model", BLOCK, "--labels", BLOCK, "--voxel-size", "3", "--no-decimate",
                      "-o", tmp_path / "m.h5"])
    assert code == 0, r.output
    figures = read_model(tmp_path / "m.h5").provenance["stage_figures"]["segment"]
    # 20 x 12 x 10 voxels of 2 x 1.5 x 1 mm -> floor((n - 1) * s / 3) + 1 voxels of 3 mm
    assert figures["shape"] == [13, 6, 4]


def test_npy_without_spacing_is_reported(tmp_path):
    data = np.zeros((12, 12, 12), np.float32)
    data[3:9, 3:9, 3:9] = 100.0
    np.save(tmp_path / "v.npy", data)
    code, _, r = run(["segment", tmp_path / "v.npy", "--threshold", "50", "-o", tmp_path / "s.nrrd"])
    assert code == 0, r.output
    assert (f"warning: {tmp_path / 'v.npy'} stores no voxel size: taking 1 x 1 x 1 mm voxels "
            "(give --spacing SX,SY,SZ in mm)") in r.output
    code, _, r = run(["segment", tmp_path / "v.npy", "--threshold", "50", "--spacing", "1,1,1",
                      "-o", tmp_path / "s.nrrd"])
    assert code == 0 and "stores no voxel size" not in r.output


# ---- build-model: Otsu and label maps as input


def test_build_model_otsu(tmp_path):
    from cutkit.io.model_h5 import read_model

    data = np.zeros((14, 14, 14), np.float32)
    data[3:11, 3:11, 3:11] = 100.0
    np.save(tmp_path / "v.npy", data)
    code, _, r = run(["build-model", tmp_path / "v.npy", "--spacing", "1,1,1", "--otsu", "--no-decimate",
                      "-o", tmp_path / "m.h5"])
    assert code == 0, r.output
    m = read_model(tmp_path / "m.h5")
    assert m.provenance["recipe"]["segment"]["otsu"] is True
    assert set(np.unique(m.labels)) == {1}


def test_build_model_takes_a_label_map_as_input(tmp_path):
    from cutkit.io.model_h5 import read_model

    code, _, r = run(["build-model", BLOCK, "--no-decimate", "-o", tmp_path / "m.h5"])
    assert code == 0, r.output
    assert set(np.unique(read_model(tmp_path / "m.h5").labels)) == {1, 2}


# ---- messages that said the wrong thing


def test_missing_input_is_named(tmp_path):
    line = error_line(["build-model", tmp_path / "absent.nrrd", "-o", tmp_path / "m.h5"])
    assert line == f"cutkit: error: {tmp_path / 'absent.nrrd'}: no such file or folder"


def test_intensity_volume_without_rule_asks_for_one(tmp_path):
    line = error_line(["build-model", ROOT / "sample_volumes" / "knee_ct.nrrd", "-o", tmp_path / "m.h5"])
    assert line.endswith("no segmentation rule and the volume is not a label map: give --threshold, --otsu, "
                         "--channel, --labels or a recipe [segment] table")


def test_info_on_truncated_model(inputs):
    data = (inputs / "m.h5").read_bytes()
    (inputs / "t.h5").write_bytes(data[: len(data) // 2])
    line = error_line(["info", inputs / "t.h5"])
    assert line == f"cutkit: error: {inputs / 't.h5'}: cannot open model file (truncated)"


def test_cut_that_misses_the_tissue_says_so(inputs):
    traj = straight_incision([50.5, 1.37, 3.0], [55.5, 1.37, 3.0], [0, 0, -1.0], depth=1.5, approach=1.0,
                             press_time=0.05, cut_time=0.2, rate=50.0, blade_length=5.0)
    write_trajectory(inputs / "miss.csv", traj)
    code, _, r = run(["cut", inputs / "m.h5", "--trajectory", inputs / "miss.csv", "-o", inputs / "out"])
    assert code == 0, r.output
    assert "warning: the blade never cut the tissue: no tet was cut" in r.output
    assert "180.0 deg" not in r.output


def test_bad_spacing_prints_numbers(tmp_path):
    np.save(tmp_path / "v.npy", np.ones((4, 4, 4), np.float32))
    line = error_line(["segment", tmp_path / "v.npy", "--threshold", "0.5", "--spacing", "0,1,1.5",
                       "-o", tmp_path / "s.nrrd"])
    assert line == f"cutkit: error: {tmp_path / 'v.npy'}: spacing must be three positive numbers (got 0, 1, 1.5)"


@pytest.mark.parametrize("flag,value,expected", [
    ("--hold", "-1", "--hold must be a number >= 0, got -1"),
    ("--geometry-rate", "0", "--geometry-rate must be a positive number, got 0"),
    ("--geometry-rate", "5000", "--geometry-rate must be at most the haptic rate 1000 Hz, got 5000"),
])
def test_simulate_errors_name_the_flags(inputs, flag, value, expected):
    line = error_line(["simulate", inputs / "m.h5", "--trajectory", inputs / "c.csv", "-o", inputs / "o", flag, value])
    assert line == f"cutkit: error: {expected}"


def test_texture_without_registration_prints_no_nan(inputs):
    code, _, r = run(["texture", inputs / "m.h5", "--volume", BLOCK, "--register", "none", "-o", inputs / "t.h5"])
    assert code == 0, r.output
    assert "nan" not in r.output and "not registered" in r.output


def test_states_line_is_short():
    from cutkit.cli.simulate import states_line

    states = ["free", "touching", "cutting"] + ["resting", "cutting"] * 30
    assert states_line(states) == "states free, touching, cutting, resting (62 changes; every tick in forces.csv)"


def test_blade_length_help_does_not_promise_a_trajectory_blade():
    code, _, r = run(["simulate", "--help"])
    assert code == 0 and "the trajectory's)" not in r.output and "stores no blade size" in " ".join(r.output.split())


# ---- the clean-up's own change is reported, and thin structures are kept by default


def _thin_plates(tmp_path):
    data = np.zeros((24, 24, 24), np.float32)
    data[4:20, 4:20, 4:20] = 0.0
    for k in range(4, 20, 4):
        data[4:20, 4:20, k:k + 2] = 100.0  # plates two voxels thick, like white matter at 2 mm
    data[4:20, 4:6, 4:20] = 100.0  # joined by one wall
    np.save(tmp_path / "thin.npy", data)
    return tmp_path / "thin.npy"


def test_default_segmentation_keeps_thin_structures(tmp_path):
    path = _thin_plates(tmp_path)
    code, _, r = run(["segment", path, "--threshold", "50", "--spacing", "2,2,2", "-o", tmp_path / "s.nrrd"])
    assert code == 0, r.output
    assert "clean-up: 2304 voxels segmented, 2304 kept (+0.00 %)" in r.output
    assert "warning: the clean-up" not in r.output


def test_cleanup_loss_is_reported_and_warned(tmp_path):
    path = _thin_plates(tmp_path)
    code, _, r = run(["build-model", path, "--threshold", "50", "--spacing", "2,2,2", "--clean", "--no-decimate",
                      "-o", tmp_path / "m.h5"])
    assert code == 0, r.output
    text = " ".join(r.output.split())
    assert "clean-up change" in text and "-81.77 %" in text
    assert "warning: the clean-up changed the segmented volume by -" in text


def test_immutable_folder_is_one_line(tmp_path):
    """A real immutable folder (chattr +i), which even root cannot write; skipped where chattr is refused."""
    import shutil
    import subprocess

    d = tmp_path / "frozen"
    d.mkdir()
    if shutil.which("chattr") is None or subprocess.run(["chattr", "+i", str(d)], capture_output=True).returncode:
        pytest.skip("chattr +i is not available here")
    try:
        line = error_line(["segment", BLOCK, "-o", d / "x.nrrd"])
    finally:
        subprocess.run(["chattr", "-i", str(d)], capture_output=True)
    assert line == f"cutkit: error: cannot write {d / 'x.nrrd'}: folder {d} is not writable"
