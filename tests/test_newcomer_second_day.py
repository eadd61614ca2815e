"""A newcomer's second day (issue 33): the bad-input matrix, each case one exact line, its exit status
and what is (not) left on disk."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cutkit.assign.defaults import DEFAULT_MATERIALS
from cutkit.cli.main import cli
from cutkit.cutting.trajectory import straight_incision, write_trajectory
from cutkit.io.model_h5 import read_model, write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import BoundaryConditions, Materials, TetModel

ROOT = Path(__file__).resolve().parents[1]
BLOCK = str(ROOT / "sample_volumes" / "block_labels.nrrd")


def run(args):
    r = CliRunner().invoke(cli, [str(a) for a in args])
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    return r.exit_code, r.output


def error_line(args, code=2):
    got, output = run(args)
    lines = [ln for ln in output.splitlines() if ln.startswith("cutkit: error:")]
    assert got == code, output
    assert len(lines) == 1, output
    return lines[0]


def slab(materials=True, shape=(6, 3, 3)):
    """A small box of tets (label 1), held at x = 0, with muscle as its material."""
    p, t = box_mesh(shape)
    rows = [dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])] if materials else []
    return TetModel.from_arrays(p, t, labels=np.ones(len(t), np.int32),
                                materials=Materials.from_rows(rows) if rows else Materials.empty(),
                                boundary=BoundaryConditions(fixed_nodes=np.flatnonzero(p[:, 0] == 0)))


@pytest.fixture
def d(tmp_path):
    write_model(tmp_path / "m.h5", slab())
    write_model(tmp_path / "bare.h5", slab(materials=False))
    traj = straight_incision([0.5, 1.37, 3.0], [5.5, 1.37, 3.0], [0, 0, -1.0], depth=1.5, approach=1.0,
                             press_time=0.05, cut_time=0.2, rate=50.0, blade_length=5.0)
    write_trajectory(tmp_path / "c.csv", traj)
    return tmp_path


def listing(folder):
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*"))


# ---- 1. a non-empty output folder is refused unless --overwrite

FOLDER_COMMANDS = {
    "simulate": lambda d, o: ["simulate", d / "m.h5", "--trajectory", d / "c.csv", "-o", o, "--hold", "0",
                              "--fps", "5"],
    "cut": lambda d, o: ["cut", d / "m.h5", "--trajectory", d / "c.csv", "-o", o],
    "relax": lambda d, o: ["relax", d / "m.h5", "--seconds", "0.01", "--fps", "100", "-o", o],
}


@pytest.mark.parametrize("name", sorted(FOLDER_COMMANDS))
def test_non_empty_output_folder_is_refused(d, name):
    out = d / "out"
    out.mkdir()
    (out / "0032.vtu").write_text("an earlier run's frame\n")
    line = error_line(FOLDER_COMMANDS[name](d, out))
    assert line == (f"cutkit: error: {out}: the output folder is not empty (0032.vtu); give --overwrite to "
                    f"replace the outputs of an earlier `cutkit {name}` there, or another folder")
    assert listing(out) == ["0032.vtu"]


@pytest.mark.parametrize("name", sorted(FOLDER_COMMANDS))
def test_overwrite_replaces_only_the_commands_own_outputs(d, name):
    out = d / "out"
    code, output = run(FOLDER_COMMANDS[name](d, out))
    assert code == 0, output
    frames = sorted((out / "frames").glob("*.vtu"))
    stale = out / "frames" / "9999.vtu"
    stale.write_bytes(frames[-1].read_bytes())  # as if an earlier run had been longer
    (out / "notes.txt").write_text("mine\n")
    code, output = run(FOLDER_COMMANDS[name](d, out) + ["--overwrite"])
    assert code == 0, output
    assert not stale.exists()  # nothing of the earlier run mixes with this one
    assert (out / "notes.txt").read_text() == "mine\n"  # what cutkit did not write stays
    assert sorted((out / "frames").glob("*.vtu")) == frames


def test_overwrite_never_removes_an_input(d):
    out = d / "out"
    out.mkdir()
    model = out / "model.h5"
    model.write_bytes((d / "m.h5").read_bytes())
    line = error_line(["simulate", model, "--trajectory", d / "c.csv", "-o", out, "--overwrite"])
    assert line == (f"cutkit: error: {model}: an input of this run is one of the outputs --overwrite would "
                    f"replace in {out}; move it or write to another folder")
    assert listing(out) == ["model.h5"]


def test_sweep_offers_resume_and_overwrite(d):
    out = d / "sw"
    out.mkdir()
    (out / "results.csv").write_text("key\n")
    (d / "s.toml").write_text("name = 'x'\n")
    line = error_line(["sweep", d / "s.toml", "-o", out])
    assert line == (f"cutkit: error: {out}: the output folder is not empty (results.csv); give --resume to "
                    "continue the earlier sweep there, --overwrite to replace the outputs of an earlier "
                    "`cutkit sweep` there, or another folder")
    line = error_line(["sweep", d / "s.toml", "-o", out, "--resume", "--overwrite"])
    assert line == "cutkit: error: --resume continues the earlier sweep, --overwrite replaces it; give one"
    assert listing(out) == ["results.csv"]


def test_demo_folder_is_reused_and_a_foreign_one_refused(tmp_path):
    from cutkit.demo import demo_outputs

    out = tmp_path / "demo"
    out.mkdir()
    for name in ("knee.h5", "knee.h5.key", "cut.pvd", "forces.csv"):
        (out / name).write_text("x\n")
    (out / "pictures").mkdir()
    (out / "pictures" / "0054_cut.png").write_text("x\n")
    # the demo's own folder: its earlier run goes, its built model stays for reuse
    assert sorted(p.name for p in demo_outputs(out)) == ["cut.pvd", "forces.csv", "pictures"]
    (out / "mine.txt").write_text("x\n")
    line = error_line(["demo", "-o", out])
    assert line == (f"cutkit: error: {out}: the output folder is not empty (cut.pvd, forces.csv, knee.h5 (+3 "
                    "more)); give --overwrite to replace the outputs of an earlier `cutkit demo` there, or "
                    "another folder")
    assert sorted(p.name for p in demo_outputs(out, overwrite=True)) == ["cut.pvd", "forces.csv", "pictures"]
    assert (out / "mine.txt").exists() and (out / "knee.h5").exists()


# ---- 7. refusals leave no folder; an imported mesh is told to get materials


def test_model_without_materials_names_assign(d):
    out = d / "out"
    line = error_line(["simulate", d / "bare.h5", "--trajectory", d / "c.csv", "-o", out])
    assert line == (f"cutkit: error: {d / 'bare.h5'}: the model has no materials yet; give them with "
                    f"`cutkit assign {d / 'bare.h5'} --recipe R.toml -o MODEL.h5` (docs/recipes.md)")
    assert not out.exists()


def test_relax_names_assign_too(d):
    line = error_line(["relax", d / "bare.h5", "--seconds", "0.01", "-o", d / "out"])
    assert line == (f"cutkit: error: {d / 'bare.h5'}: the model has no materials yet; give them with "
                    f"`cutkit assign {d / 'bare.h5'} --recipe R.toml -o MODEL.h5` (docs/recipes.md)")
    assert not (d / "out").exists()


def test_model_with_a_label_without_material():
    from cutkit.errors import InputError
    from cutkit.simulate.run import preflight

    m = slab()
    m.labels[:3] = 4  # a model file refuses this on reading; a model built in a script may have it
    with pytest.raises(InputError) as err:
        preflight(m, "two.h5")
    assert str(err.value) == ("two.h5: the model has no material for tet label 4; give them with "
                              "`cutkit assign two.h5 --recipe R.toml -o MODEL.h5` (docs/recipes.md)")


def test_import_says_what_to_run_next(d):
    import meshio

    p, t = box_mesh((2, 2, 2))
    meshio.write(d / "sphere.vtu", meshio.Mesh(p, [("tetra", t)]))
    code, output = run(["import", d / "sphere.vtu", "-o", d / "s.h5"])
    assert code == 0, output
    text = " ".join(output.split())
    assert (f"the model has no materials yet: give them with `cutkit assign {d / 's.h5'} --recipe R.toml "
            "-o MODEL.h5` (docs/recipes.md), then `cutkit simulate`") in text


def test_failed_run_leaves_no_empty_folder(d, monkeypatch):
    import cutkit.simulate
    from cutkit.errors import InputError

    def refuse(model, traj, out_dir, *a, **k):
        (Path(out_dir) / "frames").mkdir(parents=True)  # the folders made, then a refusal
        raise InputError("refused inside the run")

    monkeypatch.setattr(cutkit.simulate, "simulate", refuse)
    (d / "new").mkdir()
    out = d / "new" / "out"
    line = error_line(FOLDER_COMMANDS["simulate"](d, out))
    assert line == "cutkit: error: refused inside the run"
    assert not out.exists() and (d / "new").exists()  # what was there before stays


# ---- 5. simulate refuses a mesh that fails the cheap checks


def test_simulate_refuses_a_flat_tet(d):
    m = slab()
    m.points = m.points.copy()
    t0 = m.tets[0]
    m.points[t0[3]] = m.points[t0[0]] + 0.5 * (m.points[t0[1]] - m.points[t0[0]])  # a zero-volume tet
    write_model(d / "flat.h5", m)
    line = error_line(["simulate", d / "flat.h5", "--trajectory", d / "c.csv", "-o", d / "out"])
    assert line.startswith(f"cutkit: error: {d / 'flat.h5'}: fails the mesh check \"positive orientation\" (")
    assert line.endswith(f"); run `cutkit check {d / 'flat.h5'}`")
    assert not (d / "out").exists()


# ---- 3. memory: refused in one line before anything is written


def test_simulate_refuses_a_model_that_does_not_fit(d, monkeypatch):
    import cutkit.simulate.run as run_module

    monkeypatch.setattr(run_module, "available_memory_bytes", lambda: 100 << 20)
    line = error_line(["simulate", d / "m.h5", "--trajectory", d / "c.csv", "-o", d / "out"])
    n = read_model(d / "m.h5").n_tets
    need = run_module.simulate_memory_bytes(n, read_model(d / "m.h5").n_points)
    assert line == (f"cutkit: error: {d / 'm.h5'}: {n:,} tets need about {need / 2**30:.1f} GiB to simulate, "
                    f"0.1 GiB is available; decimate it first (`cutkit decimate {d / 'm.h5'} --ratio R "
                    "-o SMALLER.h5`)")
    assert not (d / "out").exists()


def test_available_memory_is_read():
    from cutkit.simulate.run import available_memory_bytes

    got = available_memory_bytes()
    assert got is None or got > 0


# ---- 8. SIGTERM takes Ctrl-C's path: a valid recording and summary, exit 143


def _wait_for(cond, proc, timeout_s=600.0):
    """Poll ``cond`` (no timing assertion: a generous bound for a loaded machine)."""
    import time

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.05)
    return False


@pytest.mark.slow
def test_sigterm_leaves_a_valid_recording(d):
    out = d / "out"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "cutkit.cli.main", "simulate", str(d / "m.h5"),
                             "--trajectory", str(d / "c.csv"), "-o", str(out), "--hold", "600", "--fps", "20"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    try:
        # a frame after the settle: the run is in its loop
        started = _wait_for(lambda: len(list((out / "frames").glob("*.vtu"))) >= 3, proc)
        assert started, proc.communicate()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert err.decode().strip().splitlines()[-1] == "cutkit: terminated"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert (out / "forces.csv").read_text().startswith("t,state,")
    pvd = (out / "cut.pvd").read_text()
    assert pvd.rstrip().endswith("</VTKFile>")
    assert pvd.count("<DataSet") == len(list((out / "frames").glob("*.vtu")))


@pytest.mark.slow
def test_sigterm_ends_a_live_session_with_its_recording(d):
    out = d / "live"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "cutkit.cli.main", "live", str(d / "m.h5"), "-o", str(out),
                             "--trajectory", str(d / "c.csv"), "--speed", "0.001", "--no-window",
                             "--seconds", "600"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    try:
        line = proc.stdout.readline()  # the session prints one line once its clock runs
        assert line.decode().strip() == "cutkit live: running", (line, proc.stderr.read() if proc.poll() else "")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert err.decode().strip().splitlines()[-1] == "cutkit: terminated"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and (out / "forces.csv").is_file()
    # the poses acted on so far (none to write when the signal came before a second pose)
    assert (out / "trajectory.csv").is_file() == summary["live"]["trajectory_recorded"]


def test_sigterm_is_raised_as_an_interrupt(monkeypatch):
    """In process: the handler raises Terminated (a KeyboardInterrupt) and the command exits 143."""
    import click

    from cutkit.cli import main as main_module

    @click.command("term")
    def term():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs at the next bytecode of the main thread
            pass
        raise AssertionError("SIGTERM did not stop the command")

    monkeypatch.setattr(main_module._TableGroup, "get_command", lambda self, ctx, name: term)
    before = signal.getsignal(signal.SIGTERM)
    assert main_module.main(["term"]) == 143
    assert signal.getsignal(signal.SIGTERM) == before



def test_sigterm_dropped_in_a_finalizer_is_sent_again(monkeypatch):
    """A SIGTERM that lands while Python runs a ``__del__`` has its Terminated printed and dropped
    there; the command line sends the signal again, so the command still ends with 143."""
    import click

    from cutkit.cli import main as main_module

    class Finalized:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs here, inside the finalizer
                pass

    @click.command("term")
    def term():
        Finalized()  # dropped at once: its __del__ runs now
        # the signal sent again (by a timer thread, 10 ms on) arrives in here; a bound for a loaded
        # machine, not a timing: the loop ends when the signal comes
        t_end = time.monotonic() + 60.0
        while time.monotonic() < t_end:
            time.sleep(0.001)
        raise AssertionError("SIGTERM was lost in the finalizer")

    monkeypatch.setattr(main_module._TableGroup, "get_command", lambda self, ctx, name: term)
    hook = sys.unraisablehook
    assert main_module.main(["term"]) == 143
    assert sys.unraisablehook is hook


# ---- 9. user text is never rich markup


def test_bracketed_names_pass_through_every_command(tmp_path):
    # "a[/]b" is a folder "a[" holding "]b": the path's text holds a closing tag "[/]" (rich raises
    # on it) and then a style "[bold]" (rich would swallow it)
    d = tmp_path / "a[/]b" / "m[bold]x"
    d.mkdir(parents=True)
    seg, mesh, model = d / "s[1].nrrd", d / "m[bold]x.h5", d / "cut[final].h5"
    steps = [
        (["segment", BLOCK, "-o", seg], [f"-> {seg}"]),
        (["isovolume", seg, "-o", mesh], [f"-> {mesh}"]),
        (["info", mesh], [f"model {mesh}"]),
        (["check", mesh], [f"check {mesh}"]),
        (["export", mesh, d / "e[x].vtu"], [f"-> {d / 'e[x].vtu'}"]),
        (["assign", mesh, "--recipe", d / "r[1].toml", "-o", model], [f"-> {model}"]),
        (["trajectory", "--model", model, "--start", "4,6,10", "--end", "12,6,10", "--depth", "2",
          "-o", d / "cut[final].csv"], [f"{d / 'cut[final].csv'}: "]),
        (["cut", model, "--trajectory", d / "cut[final].csv", "-o", d / "o[ut]"], [f"-> {d / 'o[ut]'}/cut.pvd"]),
        (["relax", model, "--seconds", "0.01", "--fps", "100", "-o", d / "r[/]"], [f"-> {d / 'r[/]'}/relax.pvd"]),
        (["simulate", model, "--trajectory", d / "cut[final].csv", "-o", d / "s[/]im", "--hold", "0.05"],
         [f"ParaView: open {d / 's[/]im'}/cut.pvd"]),
        (["render", d / "s[/]im", "--size", "160x120"], [f"picture: {d / 's[/]im'}/pictures/"]),
        (["decimate", mesh, "--ratio", "0.5", "-o", d / "d[x].h5"], [f"-> {d / 'd[x].h5'}"]),
        (["texture", mesh, "--volume", BLOCK, "-o", d / "t[x].h5"], [f"-> {d / 't[x].h5'}"]),
        (["import", d / "e[x].vtu", "-o", d / "i[x].h5"], [f"-> {d / 'i[x].h5'}"]),
        (["build-model", BLOCK, "--no-decimate", "-o", d / "b[bold].h5"],
         [f"build-model -> {d / 'b[bold].h5'}", "add a [boundary] table"]),
    ]
    (d / "r[1].toml").write_text("[[materials]]\nlabel = 1\nname = 'muscle'\n\n[[materials]]\nlabel = 2\n"
                                 "name = 'fat'\n\n[boundary]\nfixed_labels = [2]\n")
    for args, expected in steps:
        code, output = run(args)
        assert code == 0, (args, output)
        text = " ".join(output.split())
        for e in expected:
            assert e in text, (args, output)


# ---- 2. assign: labels the model lacks, defaults it took


def test_assign_refuses_labels_the_model_does_not_have(d):
    (d / "r.toml").write_text("[[materials]]\nlabel = 7\nname = 'fat'\n\n[boundary]\nfixed_labels = [9]\n")
    line = error_line(["assign", d / "m.h5", "--recipe", d / "r.toml", "-o", d / "a.h5"])
    assert line == ("cutkit: error: the recipe names labels 7 (materials); 9 (boundary.fixed_labels) that no tet "
                    "of the model has; the model's labels: 1")
    assert not (d / "a.h5").exists()


def test_assign_says_which_defaults_an_unknown_tissue_took(d):
    (d / "r.toml").write_text("[[materials]]\nlabel = 1\nname = 'brain'\n")
    code, output = run(["assign", d / "m.h5", "--recipe", d / "r.toml", "-o", d / "a.h5"])
    assert code == 0, output
    lines = [ln for ln in output.splitlines() if ln.startswith("warning:")]
    assert lines == ["warning: material 'brain' (label 1) is not one of cutkit's tissues (skin, fat, muscle, "
                     "tendon, bone): it takes the generic soft tissue's (muscle's) defaults for every field "
                     "(E = 30000, poisson_ratio = 0.45, density = 1090)"]
    (d / "r.toml").write_text("[[materials]]\nlabel = 1\nname = 'brain'\nE = 1000.0\npoisson_ratio = 0.49\n"
                              "density = 1040.0\n")
    code, output = run(["assign", d / "m.h5", "--recipe", d / "r.toml", "-o", d / "a.h5"])
    assert code == 0 and "E = " not in output
    assert "defaults for damping, F_enter" in " ".join(output.split())


# ---- 3. build-model states its decimation and warns about size


def test_build_model_states_the_default_and_warns_about_size(tmp_path, monkeypatch):
    import cutkit.cli.build_model as bm

    code, output = run(["build-model", "--help"])
    assert "there is no decimation" in " ".join(output.split())
    monkeypatch.setattr(bm, "SIZE_WARN_TETS", 1000)
    code, output = run(["build-model", BLOCK, "-o", tmp_path / "m.h5"])
    assert code == 0, output
    n = read_model(tmp_path / "m.h5").n_tets
    text = " ".join(output.split())
    assert f"decimation: none (no --ratio and no recipe [decimate] table): all {n} isovolume tets kept" in text
    assert f"warning: {n:,} tets (above 1,000): `cutkit simulate` would need about" in text
    assert "--ratio" in text.split("(above 1,000)")[1]


# ---- 10. messages that misled


def test_isovolume_names_the_missing_label(tmp_path):
    line = error_line(["isovolume", BLOCK, "--label", "9", "-o", tmp_path / "m.h5"])
    assert line == "cutkit: error: isovolume: no voxel has label 9; the label map has labels 1, 2"
    assert not (tmp_path / "m.h5").exists()


@pytest.mark.parametrize("cmd", ["info", "segment"])
def test_empty_volume_file(tmp_path, cmd):
    (tmp_path / "e.nrrd").write_bytes(b"")
    args = [cmd, tmp_path / "e.nrrd"] + (["-o", tmp_path / "s.nrrd"] if cmd == "segment" else [])
    line = error_line(args)
    assert line == f"cutkit: error: {tmp_path / 'e.nrrd'}: the file is empty (0 bytes), not a nrrd volume"
    assert listing(tmp_path) == ["e.nrrd"]


def test_trajectory_zero_inward(tmp_path):
    line = error_line(["trajectory", "--start", "0,0,0", "--end", "10,0,0", "--inward", "0,0,0",
                       "-o", tmp_path / "t.csv"])
    assert line == "cutkit: error: incision: inward must be a non-zero direction, got 0,0,0"
    assert not (tmp_path / "t.csv").exists()


def test_trajectory_far_from_the_model(d):
    line = error_line(["trajectory", "--model", d / "m.h5", "--start", "800,1,1", "--end", "810,1,1",
                       "-o", d / "t.csv"])
    assert line == ("cutkit: error: incision: start 800,1,1 is 794 mm from the model's surface (the model spans "
                    "0..6, 0..3, 0..3 mm in x, y, z); give points on or near its skin")
    line = error_line(["trajectory", "--model", d / "m.h5", "--start", "3,1,3.2", "--end", "3,1,3.3",
                       "-o", d / "t.csv"])
    assert line == ("cutkit: error: incision: start and end both move to the model's surface point 3,1,3; give "
                    "points farther apart")
    assert not (d / "t.csv").exists()


@pytest.mark.parametrize("field,value,expected", [
    ("E", "0.0", "E must be a positive number, got 0"),
    ("E", "-5.0", "E must be a positive number, got -5"),
    ("density", "0.0", "density must be a positive number, got 0"),
    ("damping", "-1.0", "damping must be a number >= 0, got -1"),
])
def test_material_numbers_in_one_wording(d, field, value, expected):
    (d / "r.toml").write_text(f"[[materials]]\nlabel = 1\nname = 'fat'\n{field} = {value}\n")
    line = error_line(["assign", d / "m.h5", "--recipe", d / "r.toml", "-o", d / "a.h5"])
    assert line == f"cutkit: error: {d / 'r.toml'}: [[materials]] #1: {expected}"


@pytest.mark.parametrize("args,what", [
    (lambda d: ["info", d / "no.h5"], "no.h5: no such file or folder"),
    (lambda d: ["check", d / "no.h5"], "no.h5: no such file"),
    (lambda d: ["import", d / "no.msh", "-o", d / "x.h5"], "no.msh: no such file"),
    (lambda d: ["assign", d / "m.h5", "--recipe", d / "no.toml", "-o", d / "x.h5"], "no.toml: no such file"),
    (lambda d: ["simulate", d / "no.h5", "--trajectory", d / "c.csv", "-o", d / "o"], "no.h5: no such file"),
    (lambda d: ["simulate", d / "m.h5", "--trajectory", d / "no.csv", "-o", d / "o"], "no.csv: no such file"),
    (lambda d: ["segment", d / "no.nrrd", "-o", d / "x.nrrd"], "no.nrrd: no such file or folder"),
    (lambda d: ["build-model", d / "no.nrrd", "-o", d / "x.h5"], "no.nrrd: no such file or folder"),
    (lambda d: ["render", d / "no"], "no: no such folder"),
])
def test_missing_inputs_in_one_wording(d, args, what):
    before = listing(d)
    line = error_line(args(d))
    assert line == f"cutkit: error: {d}/{what}"
    assert listing(d) == before


def test_decimate_checks_its_numbers_before_any_progress(d):
    code, output = run(["decimate", d / "m.h5", "--ratio", "1.5", "-o", d / "x.h5"])
    assert code == 2
    assert output.strip() == "cutkit: error: --ratio must be the fraction of tets to keep, in (0, 1], got 1.5"
    code, output = run(["decimate", d / "m.h5", "--ratio", "0.5", "--min-dihedral", "75", "-o", d / "x.h5"])
    assert output.strip() == "cutkit: error: --min-dihedral must lie in [0, 70) degrees, got 75"
    assert not (d / "x.h5").exists()


def test_simulate_miss_gives_extents(d):
    traj = straight_incision([50.5, 1.37, 3.0], [55.5, 1.37, 3.0], [0, 0, -1.0], depth=1.5, approach=1.0,
                             press_time=0.05, cut_time=0.1, rate=50.0, blade_length=5.0)
    write_trajectory(d / "miss.csv", traj)
    code, output = run(["simulate", d / "m.h5", "--trajectory", d / "miss.csv", "-o", d / "o", "--hold", "0"])
    assert code == 0, output
    text = " ".join(output.split())
    assert ("warning: the trajectory never touches the tissue: no cut (the model spans 0..6, 0..3, 0..3 mm in "
            "x, y, z; the trajectory 50.5..55.5, 1.37..1.37, ") in text


# ---- 13. drift


def test_model_format_doc_matches_the_writer():
    from cutkit.io.model_h5 import SCHEMA_VERSION
    from cutkit.model.tetmodel import MATERIAL_FIELDS

    text = (ROOT / "docs" / "model-format.md").read_text()
    assert f"| attr `schema_version` | int64 | | {SCHEMA_VERSION} " in text
    for name in MATERIAL_FIELDS:
        assert f"`{name}`" in text or f"materials/{name}`" in text or f", `{name}`" in text, name


def test_every_haptics_and_texture_option_has_help():
    import click

    from cutkit.cli import haptics, texture

    for cmd in [haptics.command.commands["bench"], haptics.command.commands["play"], texture.command]:
        for p in cmd.params:
            if isinstance(p, click.Option) and p.name != "threads":
                assert p.help, (cmd.name, p.name)


def test_texture_without_segmentation_does_not_warn(d):
    code, output = run(["texture", d / "m.h5", "--volume", BLOCK, "-o", d / "t.h5"])
    assert code == 0, output
    assert "warning" not in output and "not registered" in output
    code, output = run(["texture", d / "m.h5", "--volume", BLOCK, "--register", "rigid", "-o", d / "t.h5"])
    assert "warning: --register rigid needs --segmentation; registering with 'none'" in output


def test_simulate_and_demo_take_the_same_frame_rate():
    texts = [" ".join(run([cmd, "--help"])[1].split()) for cmd in ("simulate", "demo")]
    assert all("[default: 10.0]" in t.split("--fps")[1][:400] for t in texts), texts


@pytest.mark.slow
def test_pictures_are_in_the_summary_and_the_legend_names_the_material(d):
    from cutkit.render import read_folder

    out = d / "out"
    code, output = run(FOLDER_COMMANDS["simulate"](d, out) + ["--png"])
    assert code == 0, output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["options"]["png"] is True and summary["pictures"]
    assert all((out / p).is_file() for p in summary["pictures"])
    assert read_folder(out).label_names == {1: "muscle"}


# ---- 4. decimation never leaves a mesh that fails `cutkit check`


def _thin_folded_sheet():
    """A sheet one to two voxels thick folded onto itself, its sides touching (like white matter):
    the band around a level set of smoothed noise, seeded."""
    from scipy import ndimage

    from cutkit.isovolume import isovolume
    from cutkit.volumes.volume import Volume

    n = 16
    f = ndimage.gaussian_filter(np.random.default_rng(1).standard_normal((n, n, n)), 1.2)
    band = np.abs(f) < 0.06
    band[:2] = band[-2:] = False
    band[:, :2] = band[:, -2:] = False
    band[:, :, :2] = band[:, :, -2:] = False
    return isovolume(Volume(band.astype(np.uint8), spacing=np.array([1.0, 1.0, 1.0])))


@pytest.mark.slow
def test_decimation_leaves_no_hanging_node(monkeypatch):
    import importlib

    from cutkit.decimate import decimate
    from cutkit.mesh.check import check_mesh

    m = _thin_folded_sheet()
    assert check_mesh(m.points, m.tets).passed
    d = decimate(m, ratio=0.1)
    rep = check_mesh(d.points, d.tets)
    assert rep.passed, rep.failed
    # the phantom needs the rule: without it a node hangs
    module = importlib.import_module("cutkit.decimate.decimate")
    monkeypatch.setattr(module, "_boundary_grid",
                        lambda p, t, h: (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(8)))
    d = decimate(m, ratio=0.1)
    assert check_mesh(d.points, d.tets).failed == ["no hanging node (conforming)"]


@pytest.mark.slow
def test_demo_twice_into_its_folder(tmp_path, monkeypatch):
    """`cutkit demo -o X` twice: the second run reuses the build and replaces the first run's outputs;
    a folder with other files in it is refused (a small recipe stands in for the knee)."""
    import functools

    import cutkit.demo as demo_module
    import cutkit.demo.warmup as warmup
    import cutkit.simulate as simulate_module

    (tmp_path / "r.toml").write_text(
        f"[recipe]\nvolume = '{BLOCK}'\n\n[segment]\nlabels = true\n\n[[materials]]\nlabel = 1\nname = 'fat'\n\n"
        "[[materials]]\nlabel = 2\nname = 'muscle'\n\n[boundary]\n[[boundary.fixed_regions]]\naxis = 'z'\n"
        "side = 'min'\ndepth_mm = 1.0\n")
    traj = straight_incision([6.0, 9.2, 10.0], [14.0, 9.2, 10.0], [0, 0, -1.0], depth=3.0, approach=2.0,
                             press_time=0.05, cut_time=0.1, rate=100.0)
    write_trajectory(tmp_path / "c.csv", traj)
    monkeypatch.setattr(demo_module, "demo_inputs", lambda: (tmp_path / "r.toml", tmp_path / "c.csv"))
    monkeypatch.setattr(warmup, "start_background", lambda: None)
    # what is asserted is the folder's handling, not the tissue's rest: no hold after the cut
    monkeypatch.setattr(simulate_module, "SimulateOptions", functools.partial(simulate_module.SimulateOptions,
                                                                              hold_s=0.0))
    out = tmp_path / "X"
    code, output = run(["demo", "-o", out, "--no-png"])
    assert code == 0, output
    stale = out / "frames" / "9999.vtu"
    stale.write_text("an earlier, longer run\n")
    code, output = run(["demo", "-o", out, "--no-png"])
    assert code == 0, output
    assert "(inputs unchanged, build reused)" in output
    assert not stale.exists()
    (out / "mine.txt").write_text("x\n")
    line = error_line(["demo", "-o", out, "--no-png"])
    assert line.startswith(f"cutkit: error: {out}: the output folder is not empty (") and "--overwrite" in line
    code, output = run(["demo", "-o", out, "--no-png", "--overwrite"])
    assert code == 0 and (out / "mine.txt").exists()
