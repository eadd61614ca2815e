"""Generated incisions (cutkit.cutting.incision) and ``cutkit trajectory``."""

import json

import numpy as np
import pytest

from cutkit.cli.main import main
from cutkit.cutting.incision import Incision, closest_boundary_point, incision
from cutkit.cutting.trajectory import read_trajectory, straight_incision
from cutkit.errors import InputError


def _slab():
    from test_simulate import slab

    return slab()


def test_straight_matches_straight_incision():
    params = Incision(start=[6.0, 0.0, 8.3], end=[26.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                      press_time=0.3, speed=20.0 / 0.6, rate=100)
    got = incision(params)
    ref = straight_incision([6.0, 0.0, 8.3], [26.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                            press_time=0.3, cut_time=0.6, rate=100)
    assert len(got) == len(ref) == 91
    for name in ("t", "tip", "a", "n"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), atol=1e-12)


def test_arc_blade_angle_and_tremor():
    base = dict(start=[0.0, 0.0, 0.0], end=[20.0, 0.0, 0.0], inward=[0, 1, 0], depth=4.0, approach=0.0,
                press_time=0.2, speed=10.0)
    arc = incision(Incision(**base, arc_height=5.0))
    # the path through the middle is 5 mm off the chord, sideways (inward x along = -z), at depth 4
    mid = np.argmin(np.abs(arc.tip[:, 0] - 10.0) + 100 * (arc.t < 0.2))
    np.testing.assert_allclose(arc.tip[mid], [10.0, 4.0, -5.0], atol=0.05)
    np.testing.assert_allclose(arc.tip[-1], [20.0, 4.0, 0.0], atol=1e-9)
    # arc of chord 20, sagitta 5: radius 12.5, angle 4 atan(0.5); cut time = length / speed
    length = 12.5 * 4 * np.arctan(0.5)
    assert arc.t[-1] == pytest.approx(0.2 + length / 10.0, abs=0.006)
    assert np.allclose(np.einsum("ij,ij->i", arc.a, arc.n), 0, atol=1e-12)

    tilted = incision(Incision(**base, blade_angle=30.0))
    assert np.degrees(np.arccos(tilted.a[-1] @ [0, 1, 0])) == pytest.approx(30.0)
    assert tilted.a[-1, 0] > 0  # the tip leads
    assert tilted.tip[-1, 1] == pytest.approx(4.0)  # depth measured along the skin normal

    shaky = incision(Incision(**base, tremor_amplitude=0.2, tremor_frequency=10.0, seed=3))
    steady = incision(Incision(**base, rate=200.0))  # tremor raises the rate to 20 rows per period
    assert len(shaky) == len(steady)
    dev = shaky.tip - steady.tip
    assert np.abs(dev[:, 0]).max() < 1e-12  # across the path only
    assert 0.15 < np.abs(dev[:, 1:]).max() <= 0.2 + 1e-12
    again = incision(Incision(**base, tremor_amplitude=0.2, tremor_frequency=10.0, seed=3))
    np.testing.assert_array_equal(again.tip, shaky.tip)


def test_points_are_moved_onto_the_model_surface():
    m = _slab()  # 32 x 12 x 16 mm, the blade enters the y = 0 face
    q, inward = closest_boundary_point(m, [10.0, -3.0, 8.3])
    np.testing.assert_allclose(q, [10.0, 0.0, 8.3], atol=1e-12)
    np.testing.assert_allclose(inward, [0.0, 1.0, 0.0], atol=1e-12)
    traj = incision(Incision(start=[6.0, -2.0, 8.3], end=[26.0, 1.0, 8.3], depth=5.0, approach=3.0), model=m)
    np.testing.assert_allclose(traj.tip[0], [6.0, -3.0, 8.3], atol=1e-9)
    np.testing.assert_allclose(traj.tip[-1], [26.0, 5.0, 8.3], atol=1e-9)


def test_bad_parameters_name_the_key():
    with pytest.raises(InputError, match=r"^incision.depthh: unknown incision parameter"):
        Incision.from_dict({"start": [0, 0, 0], "end": [1, 0, 0], "depthh": 3})
    with pytest.raises(InputError, match=r"^incision.speed: must be > 0, got -1"):
        Incision.from_dict({"start": [0, 0, 0], "end": [1, 0, 0], "speed": -1})
    with pytest.raises(InputError, match="inward direction needed"):
        incision(Incision(start=[0, 0, 0], end=[1, 0, 0]))


def test_cli_writes_a_readable_trajectory(tmp_path, capsys):
    from cutkit.io.model_h5 import write_model

    write_model(tmp_path / "slab.h5", _slab())
    out = tmp_path / "cut.csv"
    code = main(["trajectory", "-o", str(out), "--model", str(tmp_path / "slab.h5"), "--start", "6,-2,8.3",
                 "--end", "26,0,8.3", "--depth", "5", "--speed", "25", "--tremor-amplitude", "0.1", "--seed", "7"])
    assert code == 0, capsys.readouterr().err
    traj = read_trajectory(out)
    params = Incision(start=[6, -2, 8.3], end=[26, 0, 8.3], depth=5.0, speed=25.0, tremor_amplitude=0.1, seed=7)
    ref = incision(params, _slab())
    np.testing.assert_array_equal(traj.tip, ref.tip)
    first = out.read_text().splitlines()[0]
    assert first.startswith("# cutkit trajectory: ")
    assert json.loads(first[len("# cutkit trajectory: "):])["seed"] == 7


def test_cli_bad_vector_is_one_line(tmp_path, capsys):
    code = main(["trajectory", "-o", str(tmp_path / "c.csv"), "--start", "1,2", "--end", "3,4,5", "--inward", "0,1,0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--start must be three comma-separated numbers" in err[0]
    assert not (tmp_path / "c.csv").exists()
