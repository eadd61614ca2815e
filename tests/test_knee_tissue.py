"""The demo knee through the demo incision with the default element model (as `cutkit demo` runs it)."""

import json

import numpy as np
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


def read_tets(path):
    """(points (n, 3), tets (m, 4)) of a written frame, read by VTK's own XML reader (ParaView's; a
    tenth of meshio's time on the knee's frames)."""
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    assert grid.GetNumberOfCells() and grid.IsHomogeneous() and grid.GetCellType(0) == vtk.VTK_TETRA, path
    tets = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 4)
    return vtk_to_numpy(grid.GetPoints().GetData()).astype(float), tets.astype(np.int64)


def inverted_per_frame(out):
    frames = sorted((out / "frames").glob("*.vtu"))
    assert len(frames) >= 20
    counts = []
    for f in frames:
        points, tets = read_tets(f)
        counts.append(int((signed_volumes(points, tets) <= 0).sum()))
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


def test_fracture_scalpel_on_the_knee_pays_J_c_times_depth_and_converges(demo_knee, tmp_path):
    """``simulate --scalpel fracture`` on the demo knee: every relaxation step converged under the
    blade's force, no tet inverted, a force row every 1 ms haptic tick, and the steady force while
    the crack advances J_c of the skin it entered times the depth of cut (docs/scalpel-model.md)."""
    import csv

    import numpy as np

    from cutkit.io.model_h5 import read_model

    _, incision = demo_inputs()
    out = tmp_path / "fracture"
    assert main(["simulate", str(demo_knee[1]), "--trajectory", str(incision), "-o", str(out), "--fps", "1",
                 "--scalpel", "fracture"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["options"]["scalpel"] == "fracture"
    assert s["relax_steps"]["not_converged"] == 0 and s["inverted_tets_deformed"] == 0
    assert s["cut_tets"] > 300 and s["edges_left_uncut"] == 0
    with open(out / "forces.csv") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["t"]) for r in rows])
    np.testing.assert_allclose(np.diff(t), 1e-3, atol=1e-9)  # the haptic rate, every tick written
    assert t[-1] == pytest.approx(s["simulated_s"], abs=1e-9)
    states = [r["state"] for r in rows]
    force = np.array([[float(r[c]) for c in ("F_ext_x", "F_ext_y", "F_ext_z")] for r in rows])
    tip_y = np.array([float(r["tip_y"]) for r in rows])  # the incision goes in along +y
    depth = tip_y.max() - tip_y[states.index("static")]  # from where the blade met the skin
    cutting = np.flatnonzero(np.array(states) == "cutting")
    steady = slice(cutting[len(cutting) // 2], cutting[-1])
    materials = read_model(demo_knee[1]).materials
    J_c = float(materials["J_c"][materials.name.index("skin")])
    mean = float(np.linalg.norm(force[steady], axis=1).mean())
    assert mean == pytest.approx(J_c * 1e-3 * depth, rel=0.15)
