"""cutkit sweep: a sweep on the block phantom on a 2-worker local Dask cluster.

Failed runs are recorded with their error, a worker killed mid-sweep has
its run redone elsewhere, an interrupted sweep resumes without redoing a
finished run.
"""

import os
import sys
from pathlib import Path

import cloudpickle
import numpy as np
import pyarrow.parquet as pq
import pytest

from cutkit.cli.main import main
from cutkit.io.model_h5 import read_model
from cutkit.mesh.quality import signed_volumes
from cutkit.sweep import load_spec, local_cluster, run_sweep

SAMPLES = Path(__file__).resolve().parents[1] / "sample_volumes"

# the hooks below run on the workers, which cannot import this test module
cloudpickle.register_pickle_by_value(sys.modules[__name__])

BLOCK_RECIPE = """
[recipe]
name = "block"
volume = "{volume}"
[segment]
labels = true
voxel_size_mm = 2.0
[[materials]]
label = 1
name = "muscle"
[[materials]]
label = 2
name = "fat"
[[boundary.fixed_regions]]
axis = "x"
side = "min"
depth_mm = 2.5
[[boundary.fixed_regions]]
axis = "x"
side = "max"
depth_mm = 2.5
[[prestress]]
label = 1
fibre_direction = [1.0, 0.0, 0.0]
prestrain = 0.1
"""

# 8 product runs + 4 explicit ones; one explicit run has an impossible Young's modulus.
SPEC = """
[sweep]
name = "block study"
retries = 1

[options]
material_model = "springs"
hold_s = 0.1
settle_iterations = 20

[[models]]
name = "block"
recipe = "block.toml"

[[trajectories]]
name = "across"   # across the muscle's fibres on the top face, moved onto the surface
incision = {{ start = [0.0, 8.0, 30.0], end = [0.0, 16.0, 30.0], depth = 3.0, speed = 40.0, press_time = 0.15 }}

[product]
material.muscle.F_enter = {f_enter}
incision.depth = [2.0, 3.0]

[[runs]]
material.muscle.E = 20000.0
option.write_model = true
[[runs]]
material.muscle.E = 40000.0
[[runs]]
material.muscle.E = 60000.0
[[runs]]
material.muscle.E = -1000.0
"""


def write_spec(d: Path, f_enter=(0.3, 0.6, 0.9, 1.2), explicit=True) -> Path:
    (d / "block.toml").write_text(BLOCK_RECIPE.format(volume=SAMPLES / "block_labels.nrrd"))
    text = SPEC.format(f_enter=list(f_enter))
    if not explicit:
        text = text.split("[[runs]]")[0]
    (d / "sweep.toml").write_text(text)
    return d / "sweep.toml"


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client

    cluster = local_cluster(2)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


class ExitOnce:
    """Kill the worker process the first time the run with ``key`` starts (a marker file says it happened)."""

    def __init__(self, key, marker):
        self.key, self.marker = key, str(marker)

    def __call__(self, run):
        if run["key"] == self.key and not os.path.exists(self.marker):
            open(self.marker, "w").close()
            os._exit(1)


class Touch:
    """Leave a file named after each run that starts."""

    def __init__(self, folder):
        self.folder = str(folder)

    def __call__(self, run):
        open(os.path.join(self.folder, run["key"]), "w").close()


@pytest.mark.slow
def test_sweep_records_failures_and_survives_a_killed_worker(tmp_path, client):
    spec = load_spec(write_spec(tmp_path))
    assert len(spec.runs) == 12
    block = spec.resolve()["models"]["block"]
    victim = spec.runs[9].key  # the explicit run with E = 40000
    marker = tmp_path / "killed"
    report = run_sweep(spec, tmp_path / "out", client=client, before_run=ExitOnce(victim, marker))
    assert marker.exists()  # a worker died mid-sweep
    assert (report.total, report.ran, report.failed, report.skipped) == (12, 12, 1, 0)
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    assert len(rows) == 12 and len({r["key"] for r in rows}) == 12
    failed = [r for r in rows if r["status"] != "ok"]
    assert len(failed) == 1
    assert failed[0]["material.muscle.E"] == -1000.0
    assert failed[0]["error"] == "material.muscle.E: must be > 0, got -1000.0"
    ok = [r for r in rows if r["status"] == "ok"]
    by_key = {r["key"]: r for r in ok}
    assert by_key[victim]["material.muscle.E"] == 40000.0
    for r in ok:
        assert r["error"] == ""
        assert r["cut_tets"] > 0 and r["peak_force_N"] > 0 and r["mean_cut_force_N"] > 0
        assert r["opening_mm"] > 0 and np.isfinite(r["volume_change"]) and r["wall_s"] > 0
        run_dir = tmp_path / "out" / "runs" / r["key"]
        assert (run_dir / "forces.csv").is_file() and (run_dir / "summary.json").is_file()
        assert not list(run_dir.glob("frames/*.vtu"))  # frames only when asked
    # the volume change is that of the cut model the run with write_model wrote
    (written,) = [r for r in ok if r["option.write_model"]]
    cut = read_model(tmp_path / "out" / "runs" / written["key"] / "model.h5")
    rest = signed_volumes(block.points, block.tets).sum()
    deformed = signed_volumes(cut.points + cut.point_data["displacement"], cut.tets).sum()
    assert written["volume_change"] == pytest.approx(deformed / rest - 1.0, rel=1e-9, abs=1e-12)
    # static friction holds the blade until F_enter: a larger F_enter, a larger peak force
    peaks = {}
    for r in ok:
        if r.get("material.muscle.F_enter") is not None and r["incision.depth"] == 3.0:
            peaks[r["material.muscle.F_enter"]] = r["peak_force_N"]
    assert sorted(peaks) == [0.3, 0.6, 0.9, 1.2]
    assert [peaks[f] for f in sorted(peaks)] == sorted(peaks.values())
    assert peaks[1.2] >= 1.2 * 0.9
    csv_lines = (tmp_path / "out" / "results.csv").read_text().splitlines()
    assert len(csv_lines) == 13 and csv_lines[0].startswith("key,model,trajectory,material.muscle.F_enter")


def test_interrupted_sweep_resumes_without_redoing_finished_runs(tmp_path, client):
    spec_path = write_spec(tmp_path, f_enter=(0.3, 0.6, 0.9), explicit=False)  # 6 runs
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()

    def stop_after_three(kind, info):
        if kind == "result" and info["done"] == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec_path, tmp_path / "out", client=client, on_event=stop_after_three, before_run=Touch(first))
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    assert len(rows) == 3  # a valid table of what finished
    done = {r["key"] for r in rows}

    report = run_sweep(spec_path, tmp_path / "out", client=client, resume=True, before_run=Touch(second))
    assert (report.total, report.skipped, report.ran) == (6, 3, 3)
    rerun = {p.name for p in second.iterdir()}
    assert len(rerun) == 3 and not rerun & done
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    assert len(rows) == 6 and all(r["status"] == "ok" for r in rows)

    # a third time there is nothing left to do
    report = run_sweep(spec_path, tmp_path / "out", client=client, resume=True)
    assert (report.skipped, report.ran) == (6, 0)


def test_cli_on_an_existing_cluster(tmp_path, client, capsys):
    spec_path = write_spec(tmp_path, f_enter=(0.5,), explicit=False)  # 2 runs
    out = tmp_path / "out"
    address = client.scheduler.address
    assert main(["sweep", str(spec_path), "-o", str(out), "--scheduler", address]) == 0
    text = capsys.readouterr().out
    assert "2 runs in" in text and "0 failed" in text
    assert len((out / "results.csv").read_text().splitlines()) == 3
    # results there already: refused without --resume, nothing to do with it
    assert main(["sweep", str(spec_path), "-o", str(out), "--scheduler", address]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"cutkit: error: {out}: the output folder is not empty (results.csv, results.parquet, runs); "
                   "give --resume to continue the earlier sweep there, --overwrite to replace the outputs of an "
                   "earlier `cutkit sweep` there, or another folder"]
    assert main(["sweep", str(spec_path), "-o", str(out), "--scheduler", address, "--resume"]) == 0
    assert "0 runs in" in capsys.readouterr().out


@pytest.mark.slow
def test_cli_on_an_embedded_local_cluster(tmp_path, capsys):
    spec_path = write_spec(tmp_path, f_enter=(0.5,), explicit=False)  # 2 runs
    out = tmp_path / "out"
    assert main(["sweep", str(spec_path), "-o", str(out), "--workers", "1", "--threads", "1"]) == 0
    text = capsys.readouterr().out
    assert "block study: 2 runs, 0 with results already, 2 to run on 1 worker\n" in text
    assert "2 runs in" in text and "0 failed" in text
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert sorted(r["incision.depth"] for r in rows) == [2.0, 3.0]
