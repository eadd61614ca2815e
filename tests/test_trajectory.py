"""Trajectory files: reading, checking, writing, the straight incision."""

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from cutkit.cutting.trajectory import (
    COLUMNS,
    DEFAULT_BLADE_BREADTH,
    DEFAULT_BLADE_LENGTH,
    Trajectory,
    read_trajectory,
    straight_incision,
    write_trajectory,
)
from cutkit.errors import InputError, TrajectoryError

HEADER = "t,x,y,z,ax,ay,az,nx,ny,nz"
GOOD = ["0.0,1,2,3,0,0,-1,1,0,0", "0.01,1.5,2,3,0,0,-1,1,0,0", "0.02,2,2,3,0,0,-1,1,0,0"]


def write(tmp_path, *lines, name="cut.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def error(path, line, msg):
    return "^" + re.escape(f"{path}:{line}: {msg}") + "$"


def test_read_good_file_with_comments(tmp_path):
    path = write(tmp_path, "# recorded 2026-11-23", "", HEADER, GOOD[0], "# pause", *GOOD[1:])
    traj = read_trajectory(path)
    assert len(traj) == 3
    np.testing.assert_array_equal(traj.t, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(traj.tip[:, 0], [1, 1.5, 2])
    np.testing.assert_array_equal(traj.a, [[0, 0, -1]] * 3)
    np.testing.assert_array_equal(traj.n, [[1, 0, 0]] * 3)
    assert traj.tip.dtype == np.float64 and traj.tip.shape == (3, 3)
    assert (traj.blade_length, traj.blade_breadth) == (DEFAULT_BLADE_LENGTH, DEFAULT_BLADE_BREADTH)


def test_columns_in_any_order(tmp_path):
    path = write(tmp_path, "nx,ny,nz,ax,ay,az,x,y,z,t", "1,0,0,0,0,-1,1,2,3,0.5")
    traj = read_trajectory(path, blade_length=30.0, blade_breadth=4.0)
    np.testing.assert_array_equal(traj.t, [0.5])
    np.testing.assert_array_equal(traj.tip, [[1, 2, 3]])
    np.testing.assert_array_equal(traj.n, [[1, 0, 0]])
    assert traj.blade_length == 30.0 and traj.blade_breadth == 4.0


def test_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 3))
    a /= np.linalg.norm(a, axis=1)[:, None]
    n = np.cross(a, rng.normal(size=(5, 3)))
    n /= np.linalg.norm(n, axis=1)[:, None]
    traj = Trajectory(t=np.cumsum(rng.uniform(0.001, 0.01, 5)), tip=rng.normal(size=(5, 3)) * 40, a=a, n=n)
    path = tmp_path / "out" / "rt.csv"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # exact round trip: no renormalisation
        write_trajectory(path, traj, comment="two\nlines")
        back = read_trajectory(path)
    assert path.read_text().startswith("# two\n# lines\n" + ",".join(COLUMNS) + "\n")
    for name in ("t", "tip", "a", "n"):
        np.testing.assert_array_equal(getattr(back, name), getattr(traj, name))
    assert sorted(p.name for p in path.parent.iterdir()) == ["rt.csv"]


def test_write_refuses_inconsistent_trajectories(tmp_path):
    good = dict(t=np.array([0.0, 1.0]), tip=np.zeros((2, 3)), a=np.tile([0, 0, 1.0], (2, 1)),
                n=np.tile([1.0, 0, 0], (2, 1)))
    path = tmp_path / "w.csv"
    with pytest.raises(InputError, match=r"^trajectory a must have shape \(2, 3\) to match t, got \(1, 3\)$"):
        write_trajectory(path, Trajectory(**{**good, "a": good["a"][:1]}))
    with pytest.raises(InputError, match="^trajectory times must increase strictly$"):
        write_trajectory(path, Trajectory(**{**good, "t": np.array([1.0, 1.0])}))
    with pytest.raises(InputError, match="^trajectory contains NaN or infinite values$"):
        write_trajectory(path, Trajectory(**{**good, "tip": np.full((2, 3), np.nan)}))
    assert not path.exists()


def test_pose_at_interpolates_and_clamps(tmp_path):
    traj = read_trajectory(write(tmp_path, HEADER, "0,0,0,0,1,0,0,0,1,0", "1,10,0,0,0,1,0,-1,0,0"))
    tip, a, n = traj.pose_at(0.5)
    np.testing.assert_allclose(tip, [5, 0, 0])
    np.testing.assert_allclose(a, [2**-0.5, 2**-0.5, 0])
    np.testing.assert_allclose(n, [-(2**-0.5), 2**-0.5, 0])
    assert abs(np.dot(a, n)) < 1e-15
    np.testing.assert_array_equal(traj.pose_at(-3)[0], [0, 0, 0])
    np.testing.assert_array_equal(traj.pose_at(7)[0], [10, 0, 0])
    np.testing.assert_array_equal(traj.pose_at(1.0)[1], [0, 1, 0])


@pytest.mark.parametrize(
    "lines, line, msg",
    [
        (["t,x,y,z,ax,ay,az,nx,ny", "0,1,2,3,0,0,-1,1,0"], 1,
         "header must name the columns t,x,y,z,ax,ay,az,nx,ny,nz (missing nz)"),
        ([HEADER + ",speed", GOOD[0] + ",1"], 1,
         "header must name the columns t,x,y,z,ax,ay,az,nx,ny,nz (unknown speed)"),
        (["t,x,y,z,ax,ay,az,nx,ny,nz,t", GOOD[0] + ",0"], 1,
         "header must name the columns t,x,y,z,ax,ay,az,nx,ny,nz (repeated t)"),
        ([HEADER, GOOD[0], "0.01,1,2,3,0,0,-1,1,0"], 3, "expected 10 values, got 9"),
        ([HEADER, GOOD[0], "0.01,1,2,abc,0,0,-1,1,0,0"], 3, "not a number: 'abc'"),
        ([HEADER, "# c", GOOD[0], "0.01,1,nan,3,0,0,-1,1,0,0"], 4, "y is not finite (nan)"),
        ([HEADER, GOOD[0], "0.01,1,2,3,inf,0,-1,1,0,0"], 3, "ax is not finite (inf)"),
        ([HEADER, GOOD[1], GOOD[0]], 3, "t = 0 does not increase (previous row t = 0.01)"),
        ([HEADER, GOOD[0], "0.0,1,2,3,0,0,-1,1,0,0"], 3, "t = 0 does not increase (previous row t = 0)"),
        ([HEADER, "0,1,2,3,0,0,-1.1,1,0,0"], 2, "vector a has length 1.1, expected 1 within 0.001"),
        ([HEADER, "0,1,2,3,0,0,-1,0,0,0"], 2, "vector n has length 0, expected 1 within 0.001"),
        ([HEADER, "0,1,2,3,0,0,-1,0.9950371902,0,0.0995037190"], 2,
         "a and n are not perpendicular (a.n = -0.0995037, tolerance 0.001)"),
    ],
)
def test_bad_rows(tmp_path, lines, line, msg):
    path = write(tmp_path, *lines)
    with pytest.raises(TrajectoryError, match=error(path, line, msg)):
        read_trajectory(path)


def test_slightly_off_vectors_are_fixed_with_a_warning(tmp_path):
    path = write(tmp_path, HEADER, "0,1,2,3,0,0,-1.0004,1,0,0", "1,1,2,3,0,0,-1,1,0,0.0005",
                 "2,1,2,3,0,0,-1,0.999999875,0,0.0005")
    with pytest.warns(UserWarning) as record:
        traj = read_trajectory(path)
    messages = [str(w.message) for w in record]
    assert messages == [
        f"{path}:2: vector a has length 1.0004; normalised",
        f"{path}:3: vector n has length 1.00000012; normalised",
        f"{path}:3: a.n = -0.0005; n re-orthogonalised",
        f"{path}:4: a.n = -0.0005; n re-orthogonalised",
    ]
    np.testing.assert_allclose(np.linalg.norm(traj.a, axis=1), 1, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(traj.n, axis=1), 1, atol=1e-15)
    assert np.all(np.abs(np.einsum("ij,ij->i", traj.a, traj.n)) < 1e-15)
    # a wider tolerance accepts, a narrower one rejects
    with pytest.raises(TrajectoryError, match=error(path, 2, "vector a has length 1.0004, expected 1 within 0.0001")):
        read_trajectory(path, normalize_tolerance=1e-4)


def test_file_level_errors(tmp_path):
    empty = write(tmp_path, "# only a comment", name="empty.csv")
    with pytest.raises(TrajectoryError, match="^" + re.escape(f"{empty}: no header line (expected {HEADER})") + "$"):
        read_trajectory(empty)
    header_only = write(tmp_path, HEADER, name="h.csv")
    with pytest.raises(TrajectoryError, match="^" + re.escape(f"{header_only}: no rows after the header") + "$"):
        read_trajectory(header_only)
    missing = tmp_path / "nope.csv"
    with pytest.raises(TrajectoryError, match="^" + re.escape(f"{missing}: no such file") + "$"):
        read_trajectory(missing)
    with pytest.raises(TrajectoryError, match="blade length and breadth must be positive, got 0 and 5"):
        read_trajectory(write(tmp_path, HEADER, GOOD[0]), blade_length=0)


def test_straight_incision_shape():
    traj = straight_incision([0, -40, -20], [0, -40, 20], inward=[0, 1, 0], depth=10, approach=5,
                             press_time=0.5, cut_time=2.0, rate=100)
    assert len(traj) == 251
    np.testing.assert_allclose(np.diff(traj.t), 0.01)
    np.testing.assert_allclose(traj.tip[0], [0, -45, -20])  # 5 mm outside the skin
    np.testing.assert_allclose(traj.pose_at(0.5)[0], [0, -30, -20])  # 10 mm deep
    np.testing.assert_allclose(traj.tip[-1], [0, -30, 20])  # 40 mm further along
    np.testing.assert_array_equal(traj.a, [[0, 1, 0]] * 251)
    np.testing.assert_array_equal(traj.n, [[0, 0, 1]] * 251)
    speed = np.linalg.norm(np.diff(traj.tip, axis=0), axis=1) / 0.01
    np.testing.assert_allclose(speed[60:], 20.0)  # 40 mm in 2 s
    with pytest.raises(ValueError, match="inward is parallel to the incision"):
        straight_incision([0, 0, 0], [0, 0, 1], inward=[0, 0, 1])


def test_shipped_incision_reads_cleanly():
    path = Path(__file__).resolve().parents[1] / "sample_volumes" / "incision.csv"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        traj = read_trajectory(path)
    assert len(traj) == 191 and traj.duration == pytest.approx(1.9)
    depth = np.dot(traj.tip - traj.tip[0], traj.a[0])
    assert depth.max() == pytest.approx(13.0)  # 5 mm approach + 8 mm deep
    along = np.linalg.norm(traj.tip[-1] - traj.pose_at(0.4)[0])
    assert along == pytest.approx(30.0)
    # across the leg (x), blade pointing into the front of the leg (+y)
    np.testing.assert_allclose(traj.n[0], [1, 0, 0])
    np.testing.assert_allclose(traj.a[0], [0, 1, 0])


@pytest.mark.parametrize("flip", ["a", "n", "both"])
def test_pose_at_keeps_unit_vectors_when_a_row_turns_half_a_turn(flip):
    """A blade axis or edge that reverses between two rows (a stroke drawn back) has no blend:
    every pose in between is the nearer row's, finite, unit and perpendicular (was NaN)."""
    from cutkit.cutting.trajectory import MIN_BLEND_LENGTH, Trajectory

    a0, n0 = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    a1 = -a0 if flip in ("a", "both") else a0
    n1 = -n0 if flip in ("n", "both") else n0
    traj = Trajectory(t=np.array([0.0, 0.01]), tip=np.array([[0.0, 0, 0], [1.0, 0, 0]]),
                      a=np.array([a0, a1]), n=np.array([n0, n1]))
    for w in np.linspace(0.0, 1.0, 101):
        tip, a, n = traj.pose_at(0.01 * w)
        assert np.all(np.isfinite(a)) and np.all(np.isfinite(n))
        assert abs(np.linalg.norm(a) - 1.0) < 1e-12 and abs(np.linalg.norm(n) - 1.0) < 1e-12
        assert abs(np.dot(a, n)) < 1e-12
        np.testing.assert_allclose(tip, [w, 0.0, 0.0], atol=1e-12)
    # away from the flip the blend is the usual one: exact at the rows
    np.testing.assert_array_equal(traj.pose_at(0.0)[1], a0)
    assert MIN_BLEND_LENGTH < 0.01
