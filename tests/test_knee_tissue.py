"""The demo knee through the demo incision with the default element model (as `cutkit demo` runs it)."""

import json

import meshio
import pytest

from cutkit.cli.main import main
from cutkit.mesh.quality import signed_volumes
from cutkit.demo import demo_inputs

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def knee_run(tmp_path_factory, demo_knee):
    d = tmp_path_factory.mktemp("knee")
    model_path = demo_knee[1]
    _, incision = demo_inputs()
    out = d / "out"
    assert main(["simulate", str(model_path), "--trajectory", str(incision), "-o", str(out), "--fps", "30"]) == 0
    return out


def test_knee_wound_opens_without_inverted_tets(knee_run):
    s = json.loads((knee_run / "summary.json").read_text())
    assert s["material_model"] == "neohookean"
    assert s["settle"]["converged"]
    assert s["cut_tets"] > 100
    assert s["cut_opening_mm"]["final_mean"] > 1.0  # the prestressed wound gapes (paper Fig. 12)
    assert s["max_F_ext_N"] > 0.1
    # the paper's springs left 928 of 172k tets inverted here
    assert s["inverted_tets_deformed"] == 0


def inverted_per_frame(out):
    frames = sorted((out / "frames").glob("*.vtu"))
    assert len(frames) >= 20
    counts = []
    for f in frames:
        m = meshio.read(f)
        counts.append(int((signed_volumes(m.points, m.cells_dict["tetra"]) <= 0).sum()))
    return counts


def test_knee_no_frame_has_an_inverted_tet(knee_run):
    """Sub-tets born folded at the crack front are opened where they are made (ElasticTissue._unfold)."""
    counts = inverted_per_frame(knee_run)
    assert counts == [0] * len(counts)


def test_knee_frame_rate_does_not_change_what_is_simulated(knee_run, demo_knee, tmp_path):
    """Output independence on the demo knee: --fps 1 against the fixture's --fps 30."""
    import numpy as np

    from cutkit.io.model_h5 import read_model

    _, incision = demo_inputs()
    out = tmp_path / "fps1"
    assert main(["simulate", str(demo_knee[1]), "--trajectory", str(incision), "-o", str(out), "--fps", "1"]) == 0
    s1 = json.loads((out / "summary.json").read_text())
    s30 = json.loads((knee_run / "summary.json").read_text())
    assert s1["frames"] < s30["frames"]
    assert s1["cut_tets"] == s30["cut_tets"] > 100
    m1, m30 = read_model(out / "model.h5"), read_model(knee_run / "model.h5")
    np.testing.assert_array_equal(m1.tets, m30.tets)
    d1 = m1.points + m1.point_data["displacement"]
    d30 = m30.points + m30.point_data["displacement"]
    assert np.abs(d1 - d30).max() <= 1e-9
