"""The demo knee through the demo incision with the default element model (as `cutkit demo` runs it)."""

import json

import meshio
import pytest

from cutkit.cli.main import main
from cutkit.mesh.quality import signed_volumes
from cutkit.simulate.demo import build_or_reuse, demo_inputs

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def knee_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("knee")
    model_path, _, _ = build_or_reuse(d)
    _, incision = demo_inputs()
    out = d / "out"
    assert main(["simulate", str(model_path), "--trajectory", str(incision), "-o", str(out), "--fps", "10"]) == 0
    return out


def test_knee_wound_opens_without_inverted_tets(knee_run):
    s = json.loads((knee_run / "summary.json").read_text())
    assert s["material_model"] == "neohookean"
    assert s["settle"]["converged"]
    assert s["cut_tets"] > 100
    assert s["cut_opening_mm"]["final_mean"] > 1.0  # the prestressed wound gapes (paper Fig. 12)
    assert s["max_F_ext_N"] > 0.1
    # the paper's springs left 928 of 172k tets inverted here; the element model a handful at most
    assert s["inverted_tets_deformed"] <= 5


def inverted_per_frame(out):
    frames = sorted((out / "frames").glob("*.vtu"))
    assert len(frames) >= 20
    counts = []
    for f in frames:
        m = meshio.read(f)
        counts.append(int((signed_volumes(m.points, m.cells_dict["tetra"]) <= 0).sum()))
    return counts


def test_knee_frames_keep_inverted_tets_below_a_ten_thousandth(knee_run):
    assert max(inverted_per_frame(knee_run)) <= 20  # of 172k: measured 0-3 while the blade cuts


@pytest.mark.xfail(strict=True, reason="sub-tets made at the crack front are born folded for a few frames while the "
                   "blade cuts (0-3 of 172k tets measured); docs/relaxation.md, 'Limits'")
def test_knee_no_frame_has_an_inverted_tet(knee_run):
    assert inverted_per_frame(knee_run) == [0] * len(inverted_per_frame(knee_run))
