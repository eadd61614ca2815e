"""A live session's rebase between strokes runs off the main loop (cutkit.simulate.live_rebase).

The rebase is made to wait on an event, so that the second stroke comes
entirely while it is pending however fast or loaded the machine is: the
main loop must go on drawing, hold the poses, and cut them once the rebase
is done, as much as the same stroke cuts alone.
"""

import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from cutkit.cutting.trajectory import Trajectory, straight_incision
from cutkit.live import TrajectoryPoseSource
from cutkit.simulate.live_loop import LiveLoop

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_simulate import slab  # noqa: E402

#: The strokes' trajectory seconds per wall second: slow, so the in-process ticks sample each stroke
#: finely on a loaded machine too.
SPEED = 0.5


def _stroke(z: float) -> Trajectory:
    """A 5 mm deep incision across the slab's fibres at height z, then the blade lifted out."""
    cut = straight_incision([6.0, 0.0, z], [24.0, 0.0, z], inward=[0, 1, 0], depth=5.0, approach=3.0,
                            press_time=0.3, cut_time=0.6, rate=100)
    out = cut.tip[-1] - 8.0 * cut.a[-1]
    return Trajectory(np.append(cut.t, cut.t[-1] + 0.1), np.vstack([cut.tip, out]), np.vstack([cut.a, cut.a[-1]]),
                      np.vstack([cut.n, cut.n[-1]]))


def _then(first: Trajectory, second: Trajectory, gap: float = 0.02) -> Trajectory:
    """``second`` begun ``gap`` s after ``first`` ends."""
    t2 = second.t - second.t[0] + first.t[-1] + gap
    return Trajectory(np.concatenate([first.t, t2]), np.vstack([first.tip, second.tip]),
                      np.vstack([first.a, second.a]), np.vstack([first.n, second.n]))


@pytest.fixture(scope="module")
def model():
    return slab()


def _session(model, traj, out, block_first_rebase: bool):
    """Run ``traj`` live; with ``block_first_rebase`` the first rebase waits until the source has handed
    out its last pose.  Returns the summary and what the blocked rebase saw."""
    source = TrajectoryPoseSource(traj, speed=SPEED)
    loop = LiveLoop(model, source, [], out, None)
    s = loop.session
    seen = {"frames_while_pending": 0, "tets_before": None, "held": 0}
    release = threading.Event()
    rebase = s.rebase

    def blocking_rebase():
        if seen["tets_before"] is None:
            seen["tets_before"] = s.tets_cut
            if block_first_rebase:
                release.wait(timeout=120)
        return rebase()

    s.rebase = blocking_rebase

    def on_frame(frame):
        if loop.rebaser.busy:
            seen["frames_while_pending"] += 1
            seen["held"] = max(seen["held"], len(loop.held))
            if source.finished:
                release.set()

    try:
        summary = loop.run(max_seconds=120, idle_end_s=0.3, on_frame=on_frame)
    finally:
        release.set()
    seen["out"] = out
    return summary, seen


@pytest.fixture(scope="module")
def two_strokes(model, tmp_path_factory):
    """Strokes 7.4 mm apart across the fibres: offline the second cuts what it cuts alone (135 tets each)."""
    traj = _then(_stroke(4.3), _stroke(11.7))
    return _session(model, traj, tmp_path_factory.mktemp("two"), block_first_rebase=True)


def test_frames_go_on_and_poses_are_held_while_a_rebase_is_pending(two_strokes):
    summary, seen = two_strokes
    # the whole second stroke came while the first stroke's rebase was pending (it waited for it)
    assert seen["tets_before"] > 0
    assert seen["frames_while_pending"] >= 10, seen
    assert seen["held"] >= 50, seen  # the poses of the second stroke, kept
    assert summary["live"]["rebases"] >= 1


def test_a_second_stroke_begun_during_the_rebase_cuts_like_the_stroke_alone(model, two_strokes, tmp_path):
    summary, seen = two_strokes
    second = summary["cut_tets"] - seen["tets_before"]
    alone, _ = _session(model, _stroke(11.7), tmp_path / "alone", block_first_rebase=False)
    assert alone["cut_tets"] > 20
    assert abs(second - alone["cut_tets"]) <= 0.1 * alone["cut_tets"], (second, alone["cut_tets"])


def test_the_recorded_two_stroke_session_replays_offline_to_the_same_cut(model, two_strokes, tmp_path):
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.simulate import SimulateOptions, simulate

    summary, seen = two_strokes
    traj = read_trajectory(seen["out"] / "trajectory.csv")
    replay = simulate(model, traj, tmp_path / "replay", SimulateOptions(frames=False, hold_s=0.3))
    assert abs(replay["cut_tets"] - summary["cut_tets"]) <= 0.1 * summary["cut_tets"], (replay["cut_tets"],
                                                                                        summary["cut_tets"])


def test_twins_are_the_rows_whose_nodes_have_the_same_representatives():
    """find_twins' grouping (cutkit.cutting.rebase._twins) against all pairs compared one by one."""
    from cutkit.cutting.rebase import _twins

    rng = np.random.default_rng(7)
    for w in (2, 3):
        for _ in range(10):
            n = int(rng.integers(4, 40))
            rep = rng.integers(0, max(2, n // 3), n)  # several nodes share a representative
            rows = rng.integers(0, n, (int(rng.integers(1, 120)), w))
            key = [tuple(sorted(rep[r].tolist())) for r in rows]
            expected = {}
            for i in range(len(rows)):
                others = [j for j in range(len(rows)) if j != i and key[j] == key[i]]
                if others:
                    expected[i] = others
            assert _twins(rows, rep) == expected
