"""A live session's rebase between strokes (cutkit.simulate.live_rebase).

On the wall clock the rebase runs off the main loop.  It is made to wait on
an event, so that the second stroke comes entirely while it is pending
however fast or loaded the machine is: the main loop must go on drawing,
hold the poses, and cut them once the rebase is done.  There the strokes
wait for the session, not for a time: each stops in the middle of its cut
until the session has cut there, and the second begins once the session
has seen the first one end.  What a stroke cuts
is asserted on a stepped clock (cutkit.simulate.clock), where the loop waits
for the rebase and the session is a function of its poses: the second
stroke cuts what it cuts alone, and the replay of the recording cuts what
the session cut, to the tet.
"""

import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from cutkit.cutting.trajectory import Trajectory, straight_incision
from cutkit.live import TrajectoryPoseSource
from cutkit.simulate.clock import SteppedClock
from cutkit.simulate.live_loop import LiveLoop

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_simulate import slab  # noqa: E402

#: The strokes' trajectory seconds per wall second on the wall clock: slow, so the in-process ticks
#: sample each stroke finely on a loaded machine too.
SPEED = 0.5
#: Seconds a stepped session goes on after its last pose, and its replay's hold.
END_S = 0.3


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


def _pieces(stroke: Trajectory) -> list[Trajectory]:
    """``stroke`` cut in two at the middle of its cut (x = 15 mm, 5 mm deep): both pieces hold that row."""
    k = int(np.argmin(np.abs(stroke.tip[:, 0] - 15.0)))
    return [Trajectory(stroke.t[a:b], stroke.tip[a:b], stroke.a[a:b], stroke.n[a:b]) for a, b in ((0, k + 1), (k, None))]


class _InStepWithTheSession:
    """Trajectory pieces on the wall clock (at SPEED), each begun once the session has done what the gate
    before it waits for (``gates[i]()`` true); until then the blade stays at the last pose handed out.

    The loop sees a pose only in a pass that comes while it is the newest, and a loaded machine's pass
    can take seconds (a loaded run's first cut held the loop for 3.2 s; on a wall clock alone such runs
    saw the two strokes as one, or a second stroke that cut nothing): the blade waits in the tissue
    until the session cut there, and out of it until the session saw the stroke end.
    """

    def __init__(self, pieces: list[Trajectory]):
        self.sources = [TrajectoryPoseSource(p, speed=SPEED) for p in pieces]  # each clock starts at its first poll
        self.gates = [lambda: True] * (len(pieces) - 1)
        self.k = 0

    @property
    def finished(self) -> bool:
        return self.sources[-1].finished

    def poll(self):
        while self.sources[self.k].finished and self.k < len(self.gates):
            if not self.gates[self.k]():
                return None
            self.k += 1
        return self.sources[self.k].poll()

    def close(self) -> None:
        for source in self.sources:
            source.close()


def _session(model, traj, out, block_first_rebase: bool = False, stepped: bool = False,
             rest_once_finished: bool = False, second: Trajectory | None = None):
    """Run ``traj`` live; with ``block_first_rebase`` the first rebase waits until the source has handed
    out its last pose; ``stepped``: on a stepped clock; ``rest_once_finished``: the tissue counts as at
    rest only once the source has handed out its last pose; ``second`` (on the wall clock): a stroke
    after ``traj``, both in step with the session (:class:`_InStepWithTheSession`).  Returns the summary
    and what the session saw."""
    clock = SteppedClock() if stepped else None
    if stepped:
        source = TrajectoryPoseSource(traj, clock=clock)
    elif second is not None:
        source = _InStepWithTheSession(_pieces(traj) + _pieces(second))
    else:
        source = TrajectoryPoseSource(traj, speed=SPEED)
    loop = LiveLoop(model, source, [], out, None, clock=clock)
    s = loop.session
    if second is not None:
        # the first stroke cut; its end seen; the second stroke back in the tissue cut there (while a
        # rebase is pending it cannot: its poses are held, the middle one among them)
        source.gates = [lambda: s.tets_cut > 0, lambda: bool(loop.stroke_ends),
                        (lambda: True) if block_first_rebase
                        else (lambda: loop.strokes_joined > 0 and s.tets_cut > loop.tets_at_rebases[0])]
    if rest_once_finished:
        s.tis.at_rest = lambda: source.finished
    seen = {"frames_while_pending": 0, "tets_before": None, "held": 0, "most_held": 0}
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
        seen["most_held"] = max(seen["most_held"], len(loop.held))
        if loop.rebaser.busy:
            seen["frames_while_pending"] += 1
            seen["held"] = max(seen["held"], len(loop.held))
            if source.finished:
                release.set()

    try:
        summary = loop.run(max_seconds=120, idle_end_s=END_S, on_frame=on_frame)
    finally:
        release.set()
    seen["out"] = out
    return summary, seen


@pytest.fixture(scope="module")
def two_strokes(model, tmp_path_factory):
    """Strokes 7.4 mm apart across the fibres: offline the second cuts what it cuts alone (135 tets each).
    The first stroke's rebase starts as soon as the session sees the stroke end (no wait for rest); the
    second stroke begins then."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("cutkit.simulate.live_loop.REBASE_WAIT_MAX_S", 0.0)
        return _session(model, _stroke(4.3), tmp_path_factory.mktemp("two"), block_first_rebase=True,
                        second=_stroke(11.7))


@pytest.fixture(scope="module")
def joined_strokes(model, tmp_path_factory):
    """The same strokes on the wall clock, the first one's rebase waiting however long the machine
    takes (no time limit; the tissue counts as at rest only once the source is finished): the second
    stroke, begun once the session has seen the first one end, comes before it starts."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("cutkit.simulate.live_loop.REBASE_WAIT_MAX_S", float("inf"))
        return _session(model, _stroke(4.3), tmp_path_factory.mktemp("joined"), rest_once_finished=True,
                        second=_stroke(11.7))


@pytest.fixture(scope="module")
def stepped_two_strokes(model, tmp_path_factory):
    """The same two strokes on a stepped clock: the loop waits for the rebase between them."""
    traj = _then(_stroke(4.3), _stroke(11.7))
    return _session(model, traj, tmp_path_factory.mktemp("stepped-two"), stepped=True)


def test_frames_go_on_and_poses_are_held_while_a_rebase_is_pending(two_strokes):
    """On the wall clock, with the rebase in its own thread: only what a stalled machine cannot change
    (how many frames and poses a pending rebase sees is the machine's speed)."""
    summary, seen = two_strokes
    # the whole second stroke came while the first stroke's rebase was pending (it waited for it)
    assert seen["tets_before"] > 0
    assert seen["frames_while_pending"] >= 1, seen  # the loop drew while the rebase was pending
    assert seen["held"] >= 1, seen  # the poses of the second stroke, kept (its last one at least)
    assert summary["live"]["rebases"] >= 1 and summary["live"]["tets_cut_at_rebases"][0] == seen["tets_before"]
    assert summary["cut_tets"] > seen["tets_before"]  # the held poses were cut once the rebase was done


def test_a_stepped_session_waits_for_its_rebase(stepped_two_strokes):
    """On a stepped clock the rebase is done before the next pose is taken: no pose is ever held, no
    frame is drawn while one is pending, and no clock time passes during one."""
    summary, seen = stepped_two_strokes
    assert summary["live"]["rebases"] == 2 and seen["tets_before"] > 0
    assert seen["most_held"] == 0 and seen["frames_while_pending"] == 0
    assert all(a == b for a, b in summary["live"]["rebase_windows_s"])
    assert summary["live"]["tets_cut_at_rebases"][0] == seen["tets_before"]


def test_a_second_stroke_begun_at_once_cuts_like_the_stroke_alone(model, stepped_two_strokes, tmp_path):
    """Begun 20 ms after the first stroke's end, the second cuts the tets it cuts alone (offline too:
    the strokes are 7.4 mm apart, the first's wound does not reach the second's path)."""
    summary, seen = stepped_two_strokes
    second = summary["cut_tets"] - seen["tets_before"]
    alone, _ = _session(model, _stroke(11.7), tmp_path / "alone", stepped=True)
    assert alone["cut_tets"] > 20
    assert second == alone["cut_tets"]


def test_the_recorded_two_stroke_session_replays_offline_to_the_same_cut(model, stepped_two_strokes, tmp_path):
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions, simulate

    summary, seen = stepped_two_strokes
    traj = read_trajectory(seen["out"] / "trajectory.csv")
    replay = simulate(model, traj, tmp_path / "replay", SimulateOptions(frames=False, hold_s=END_S))
    assert (replay["cut_tets"], replay["new_tets"]) == (summary["cut_tets"], summary["new_tets"])
    live, again = read_model(seen["out"] / "model.h5"), read_model(tmp_path / "replay" / "model.h5")
    np.testing.assert_array_equal(live.tets, again.tets)
    np.testing.assert_array_equal(live.points, again.points)


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


def test_a_strokes_rebase_waits_for_rest_or_the_time_limit_and_a_blade_back_in_goes_on_without_it():
    """On the wall clock a stroke's rebase starts when the tissue is at rest (in a step after the stroke
    ended) or REBASE_WAIT_MAX_S after the stroke ended; not while one runs or none waits.  A blade
    back in the tissue before then goes on in the same cut state: the rebase waits no more (it comes
    when that stroke ends), and the joined stroke is counted."""
    from types import SimpleNamespace

    from cutkit.scalpel import CUTTING, FREE
    from cutkit.simulate.live_loop import REBASE_WAIT_MAX_S

    def loop(waiting_since, code=FREE, at_rest=False, busy=False, tissue_time=10.0):
        tis = SimpleNamespace(at_rest=lambda: at_rest, time=tissue_time)
        return SimpleNamespace(rebase_waiting_since=waiting_since, rebaser=SimpleNamespace(busy=busy),
                               strokes_joined=0,
                               session=SimpleNamespace(scalpel=SimpleNamespace(code=code), tis=tis))

    due = LiveLoop._rebase_due
    assert not due(loop(None, at_rest=True), 10.0)  # no stroke ended
    assert not due(loop(1.0), 1.0 + 0.5 * REBASE_WAIT_MAX_S)  # the wound still moving, the blade out
    assert due(loop(1.0, at_rest=True), 1.1)
    assert not due(loop(1.0, at_rest=True, tissue_time=0.9), 1.1)  # a rest from before the stroke ended
    back = loop(1.0, code=CUTTING, at_rest=True)
    assert not due(back, 1.0 + REBASE_WAIT_MAX_S)  # the blade back in: the stroke goes on, no rebase
    assert back.rebase_waiting_since is None and back.strokes_joined == 1
    assert not due(back, 10.0)
    assert due(loop(1.0), 1.0 + REBASE_WAIT_MAX_S)
    assert not due(loop(1.0, at_rest=True, busy=True), 5.0)  # one is running already


def test_a_frame_waits_while_device_poses_wait_for_their_ticks_but_not_past_its_age():
    """The frame clock's rule: a frame is drawn when due or when a cut waits to be shown, but not while
    poses the device sent wait for their ticks (a frame then costs the poses its drawing time, and on a
    software OpenGL the backlog grew through a whole stroke), unless the newest frame is
    MAX_FRAME_AGE_S old."""
    import collections
    from types import SimpleNamespace

    from cutkit.simulate.live_loop import MAX_FRAME_AGE_S

    def loop(waiting=0, pending_cut=(), meter=True):
        queue = collections.deque(range(waiting))
        return SimpleNamespace(meter=SimpleNamespace(queue=queue) if meter else None,
                               pending_cut=list(pending_cut), frame_s=[10.0],
                               _behind_device=lambda: meter and bool(queue))

    due = LiveLoop._frame_due
    assert not due(loop(), 10.01, 10.03)  # not yet due, no cut to show
    assert due(loop(), 10.03, 10.03)
    assert due(loop(pending_cut=[10.005]), 10.01, 10.03)  # a cut is shown at once
    assert not due(loop(waiting=3), 10.03, 10.03)  # due, but three poses wait: their ticks first
    assert not due(loop(waiting=3, pending_cut=[10.005]), 10.01, 10.03)
    assert due(loop(waiting=3), 10.0 + MAX_FRAME_AGE_S, 10.03)  # the newest frame too old: drawn anyway
    assert due(loop(meter=False), 10.03, 10.03)  # poses of this process: no queue to wait for
    assert LiveLoop._behind_device(SimpleNamespace(meter=SimpleNamespace(queue=collections.deque([1]))))
    assert not LiveLoop._behind_device(SimpleNamespace(meter=SimpleNamespace(queue=collections.deque())))
    assert not LiveLoop._behind_device(SimpleNamespace(meter=None))


def test_a_frame_clock_tick_is_left_out_only_while_nothing_a_frame_shows_has_moved():
    """Left out (the picture is current): the nodes, the blade, the force and the cut as the newest
    frame showed them, that frame younger than IDLE_FRAME_S, and no rebase running; any of them
    changed, the frame is drawn."""
    from types import SimpleNamespace

    from cutkit.simulate.live_loop import IDLE_FRAME_S

    points = np.arange(12.0).reshape(4, 3)
    pose = (np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]))

    def loop(**change):
        positions = change.get("positions", points.copy())
        cm = SimpleNamespace(n_rebases=0, n_tets_total=change.get("tets", 7))
        newest = change.get("newest", tuple(v.copy() for v in pose))
        force = change.get("force", np.zeros(3))
        return SimpleNamespace(shown=(points.copy(), pose, np.zeros(3)), faces_version=(0, 7), still=change.get("still"),
                               frame_s=[10.0], newest=newest, _hand_force=lambda: force,
                               session=SimpleNamespace(cut_mesh=cm, tis=SimpleNamespace(positions=positions)))

    still = LiveLoop._scene_still
    assert still(loop(), 10.1)
    assert not still(loop(), 10.0 + IDLE_FRAME_S)  # the status lines are drawn again now and then
    moved = points.copy()
    moved[2, 1] += 1e-9
    assert not still(loop(positions=moved), 10.1)
    assert not still(loop(positions=np.vstack([points, points[:1]])), 10.1)  # a cut added a node
    assert not still(loop(tets=8), 10.1)
    assert not still(loop(newest=(np.array([0.0, 0.0, 1e-6]), pose[1], pose[2])), 10.1)
    assert not still(loop(newest=None), 10.1)
    assert not still(loop(force=np.array([0.0, 0.1, 0.0])), 10.1)
    assert not still(loop(still=object()), 10.1)  # a rebase's still picture: the blade moves on it
    assert not still(SimpleNamespace(shown=None, still=None, frame_s=[]), 10.1)  # nothing drawn yet


def test_a_stroke_begun_before_the_last_ones_rebase_goes_on_without_holding_a_pose(joined_strokes):
    """A blade back in the tissue while the first stroke's rebase still waits goes on in the same cut
    state: no pose is held, one rebase comes after the second stroke, both strokes cut, and the cut mesh
    is whole.  How many tets each stroke cuts is asserted on the stepped clock only: on the wall clock
    the tissue under the blade follows the relaxation, which follows the machine, and so does the
    moment a stroke's end is seen (a loaded run counted 169 tets at the first stroke's end and 44 after
    it, where the stepped clock cuts 135 each)."""
    from cutkit.cli.main import main

    summary, seen = joined_strokes
    live = summary["live"]
    assert live["strokes_joined"] == 1 and seen["most_held"] == 0
    assert live["rebases"] == 1 and len(live["tets_cut_at_rebases"]) == 2
    ends = live["stroke_ends_s"]
    assert len(ends) == 2 and ends[0] < ends[1] <= live["rebase_windows_s"][0][0]
    first, total = live["tets_cut_at_rebases"]
    assert seen["tets_before"] == total == summary["cut_tets"]
    assert 0 < first < total, (first, total)
    assert main(["check", str(seen["out"] / "model.h5")]) == 0


@pytest.mark.parametrize("live", [False, True])
def test_a_rebase_is_followed_by_a_look_at_every_cut_made_tet_before_the_tissue_moves(model, tmp_path, monkeypatch,
                                                                                       live):
    """The blade leaves after one stroke: offline (``Session.rebase_if_left``) and live (the rebase's
    own thread, here on a stepped clock), the next thing after the rebase is ``finish_stroke`` in the
    fresh cut state (the stroke's cut is an earlier one's, nothing is subdivided, a look at every
    cut-made tet is due), before any relaxation step: vertex smoothing may move the cut's nodes
    there (docs/cutting.md, "Vertex smoothing")."""
    import cutkit.cutting as C
    from cutkit.cutting.cutmesh import CutMesh
    from cutkit.relax.elastic_tissue import ElasticTissue
    from cutkit.simulate import SimulateOptions, simulate

    events, finish, rebase, advance = [], C.finish_stroke, CutMesh.rebase, ElasticTissue.advance

    def recorded_finish(cm, every_cut_tet=True):
        events.append(("finish", bool(cm.cut_faces_before), len(cm.subtets), bool(cm.whole_look_due)))
        return finish(cm, every_cut_tet)

    def recorded_rebase(cm):
        events.append(("rebase",))
        return rebase(cm)

    def recorded_advance(tis, *args, **kw):
        events.append(("relax",))
        return advance(tis, *args, **kw)

    monkeypatch.setattr(C, "finish_stroke", recorded_finish)
    monkeypatch.setattr(CutMesh, "rebase", recorded_rebase)
    monkeypatch.setattr(ElasticTissue, "advance", recorded_advance)
    if live:
        _session(model, _stroke(4.3), tmp_path, stepped=True)
    else:
        simulate(model, _stroke(4.3), tmp_path, SimulateOptions(fps=5, hold_s=0.1, frames=False))
    k = events.index(("rebase",))
    assert events[k + 1] == ("finish", True, 0, True), events[k - 2:k + 4]
