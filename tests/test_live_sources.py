"""Pose sources of a live session: trajectory replay, mouse and keyboard, OpenIGTLink TRANSFORMs."""

import math
import socket
import struct
import time
from pathlib import Path

import numpy as np
import pytest

from cutkit.cutting.trajectory import read_trajectory
from cutkit.errors import InputError
from cutkit.live import MouseKeyboardPoseSource, Pose, PoseSource, TrajectoryPoseSource

ROOT = Path(__file__).resolve().parents[1]
INCISION = ROOT / "sample_volumes" / "incision.csv"


class FakeClock:
    def __init__(self, t=1000.0):
        self.t = t

    def __call__(self):
        return self.t


# ---------------------------------------------------------------------------- trajectory
def test_trajectory_source_follows_the_file_on_the_clock():
    traj = read_trajectory(INCISION)
    clock = FakeClock()
    src = TrajectoryPoseSource(traj, clock=clock)
    assert isinstance(src, PoseSource)
    first = src.poll()
    assert first.t == 1000.0 and np.array_equal(first.tip, traj.tip[0])
    assert src.poll() is None  # no time has passed: nothing new
    for dt in (0.123, 0.4, 1.0, 1.7):
        clock.t = 1000.0 + dt
        pose = src.poll()
        tip, a, n = traj.pose_at(traj.t[0] + dt)
        np.testing.assert_allclose(pose.tip, tip, atol=1e-9)  # the clock's float rounding only
        np.testing.assert_allclose(pose.a, a, atol=1e-12)
        np.testing.assert_allclose(pose.n, n, atol=1e-12)
        assert pose.t == clock.t and not src.finished
    clock.t = 1000.0 + traj.duration + 5.0
    last = src.poll()
    np.testing.assert_array_equal(last.tip, traj.tip[-1])
    assert src.finished and src.poll() is None


def test_trajectory_source_loops_and_scales_time():
    traj = read_trajectory(INCISION)
    clock = FakeClock(0.0)
    src = TrajectoryPoseSource(traj, clock=clock, loop=True, speed=2.0, start=0.0)
    clock.t = (traj.duration + 0.25) / 2.0
    pose = src.poll()
    np.testing.assert_allclose(pose.tip, traj.pose_at(traj.t[0] + 0.25)[0], atol=1e-9)
    assert not src.finished
    with pytest.raises(InputError, match="speed"):
        TrajectoryPoseSource(traj, speed=0.0)


# ---------------------------------------------------------------------------- mouse and keyboard
def _drain(src):
    out = []
    for _ in range(100):
        p = src.poll()
        if p is None:
            return out
        out.append(p)
    raise AssertionError("poll never ran dry")


def test_a_drag_becomes_a_stroke_in_and_out_of_the_surface():
    clock = FakeClock()
    src = MouseKeyboardPoseSource(depth=4.0, approach=5.0, clock=clock)
    up = np.array([0.0, 0.0, 1.0])  # outward surface normal
    press = src.on_press([10.0, 0.0, 0.0], up)
    np.testing.assert_allclose(press.tip, [10.0, 0.0, 5.0])  # starts outside
    np.testing.assert_allclose(press.a, [0.0, 0.0, -1.0])  # blade straight into the surface
    assert press.buttons == 1
    for x in (11.0, 12.0, 13.0):
        src.on_drag([x, 0.0, 0.0], up)
    drag = src.on_drag([14.0, 0.0, 0.0], up)
    np.testing.assert_allclose(drag.tip, [14.0, 0.0, -4.0])  # depth below the surface point
    np.testing.assert_allclose(drag.n, [1.0, 0.0, 0.0])  # the edge faces the drag
    release = src.on_release()
    np.testing.assert_allclose(release.tip, [14.0, 0.0, 5.0])  # pulled back out along the blade
    assert release.buttons == 0
    # poll never skips the way in and the way out; in between the newest pose wins
    got = _drain(src)
    assert [tuple(p.tip) for p in got] == [tuple(press.tip), tuple(drag.tip), tuple(release.tip)]


def test_keys_set_depth_and_bevel():
    src = MouseKeyboardPoseSource(depth=5.0, depth_step=1.0, angle_step=10.0, max_depth=6.0, clock=FakeClock())
    src.on_press([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    src.on_drag([0.0, 2.0, 0.0])
    assert src.on_key("Up") and src.on_key("Up")  # deeper, clamped at max_depth
    assert src.depth == 6.0
    pose = _drain(src)[-1]
    np.testing.assert_allclose(pose.tip, [0.0, 2.0, -6.0])
    assert src.on_key("Right")
    pose = _drain(src)[-1]
    # bevelled by 10 degrees about the edge (+y): still perpendicular to it
    assert math.degrees(math.acos(-pose.a[2])) == pytest.approx(10.0)
    assert abs(np.dot(pose.a, pose.n)) < 1e-12 and pose.a[1] == pytest.approx(0.0)
    np.testing.assert_allclose(pose.tip, np.array([0.0, 2.0, 0.0]) + 6.0 * pose.a)
    assert not src.on_key("q")
    src.on_key("0")
    assert src.depth == 5.0 and src.bevel == 0.0
    for _ in range(20):
        src.on_key("Down")
    assert src.depth == 0.0


# ---------------------------------------------------------------------------- OpenIGTLink
pyigtl = pytest.importorskip("pyigtl")


#: Longest wait for the endpoint (s): a bound for a loaded machine, never waited out when a test passes.
WAIT_S = 60.0


def _wait(cond, seconds=WAIT_S):  # a bound for a loaded machine, not a timing
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


def _tool_matrix_ras(tip, a, n):
    """A tool matrix in RAS whose -z column is the blade axis and x column the edge (LPS pose in)."""
    flip = np.array([-1.0, -1.0, 1.0])
    m = np.eye(4)
    m[:3, 0] = n * flip
    m[:3, 2] = -a * flip
    m[:3, 1] = np.cross(m[:3, 2], m[:3, 0])
    m[:3, 3] = tip * flip
    return m


@pytest.fixture
def igtl_source():
    from cutkit.live.igtl import IGTLPoseSource

    src = IGTLPoseSource(port=0)
    client = pyigtl.OpenIGTLinkClient("127.0.0.1", src.endpoint.port)
    try:
        assert _wait(lambda: src.endpoint.connected), "the client did not connect"
        yield src, client
    finally:
        client.stop()
        src.close()


def test_igtl_transforms_along_an_incision_become_poses(igtl_source):
    src, client = igtl_source
    traj = read_trajectory(INCISION)
    rows = range(0, len(traj), 10)
    got = []
    for i in rows:
        m = _tool_matrix_ras(traj.tip[i], traj.a[i], traj.n[i])
        client.send_message(pyigtl.TransformMessage(m, device_name="ScalpelToReference"), wait=True)
        client.send_message(pyigtl.TransformMessage(np.eye(4), device_name="SomethingElse"), wait=True)
        box = []
        assert _wait(lambda: box.append(src.poll()) or box[-1] is not None), f"row {i} never arrived"
        got.append(box[-1])
    assert all(isinstance(p, Pose) for p in got)
    for i, pose in zip(rows, got):
        # float32 on the wire: 1e-5 relative
        np.testing.assert_allclose(pose.tip, traj.tip[i], atol=1e-4)
        np.testing.assert_allclose(pose.a, traj.a[i], atol=1e-6)
        np.testing.assert_allclose(pose.n, traj.n[i], atol=1e-6)
    # the last "SomethingElse" may still be on the wire when its scalpel pose has been polled
    assert _wait(lambda: src.endpoint.received.get("SomethingElse", 0) == len(rows))
    assert src.poll() is None  # each TRANSFORM is returned once; other devices give no pose


def test_igtl_axis_options_and_lps():
    from cutkit.live.igtl import pose_from_matrix, tracker_to_model

    m = np.eye(4)
    m[:3, 3] = (1.0, 2.0, 3.0)
    tip, a, n = pose_from_matrix(m, axis="z", edge="y", to_model=tracker_to_model("LPS"))
    np.testing.assert_array_equal(tip, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(a, [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(n, [0.0, 1.0, 0.0])
    tip, a, n = pose_from_matrix(m)  # RAS -> LPS, blade along -z, edge x
    np.testing.assert_array_equal(tip, [-1.0, -2.0, 3.0])
    np.testing.assert_array_equal(a, [0.0, 0.0, -1.0])
    np.testing.assert_array_equal(n, [-1.0, 0.0, 0.0])
    shift = np.eye(4)
    shift[:3, 3] = (10.0, 0.0, 0.0)
    tip, _, _ = pose_from_matrix(m, to_model=tracker_to_model("RAS", registration=shift))
    np.testing.assert_array_equal(tip, [9.0, -2.0, 3.0])
    with pytest.raises(InputError, match="tool axis"):
        pose_from_matrix(m, axis="w")
    with pytest.raises(InputError, match="different axes"):
        pose_from_matrix(m, axis="-x", edge="x")


def test_igtl_malformed_messages_are_dropped_with_one_line(igtl_source, caplog):
    src, client = igtl_source
    client.stop()  # the raw socket below is then the only client
    assert _wait(lambda: not src.endpoint.connected)
    good = pyigtl.TransformMessage(np.eye(4), device_name="ScalpelToReference").pack()
    header = bytearray(good[:58])
    header[42:50] = struct.pack(">Q", 7)  # a TRANSFORM body of 7 bytes cannot be decoded
    header[50:58] = struct.pack(">Q", pyigtl.messages.CRC64(b"1234567"))  # its CRC is right
    s = socket.create_connection(("127.0.0.1", src.endpoint.port), timeout=WAIT_S)
    try:
        with caplog.at_level("WARNING", logger="cutkit.live"):
            s.sendall(bytes(header) + b"1234567" + good)
            assert _wait(lambda: src.poll() is not None), "the good message after the bad one was lost"
        assert src.endpoint.errors == 1
        lines = [r.getMessage() for r in caplog.records if "malformed" in r.getMessage()]
        assert len(lines) == 1 and "\n" not in lines[0] and "TRANSFORM" in lines[0]
        # a header that cannot start a message ends the connection, not the server
        s.sendall(b"\x00\x07" + bytes(56))
        s.settimeout(WAIT_S)
        while s.recv(1 << 16):  # STATUS messages, then the end of the stream
            pass
    finally:
        s.close()
    s = socket.create_connection(("127.0.0.1", src.endpoint.port), timeout=WAIT_S)
    s.sendall(good)
    assert _wait(lambda: src.poll() is not None), "the endpoint stopped serving"
    s.close()


def test_the_mirrored_force_model_keeps_the_service_alive_without_flooding_it(monkeypatch):
    """A SIM_UPDATE at most every KEEP_ALIVE_S (well inside the service's watchdog), however often the loop asks."""
    import cutkit.simulate.live_parts as live
    from cutkit.haptics.server import WATCHDOG_TIMEOUT_S

    class Source:
        sent = 0

        def update(self, *args, **kwargs):
            Source.sent += 1

    clock = [100.0]
    monkeypatch.setattr(live.time, "perf_counter", lambda: clock[0])
    model = live.MirroredForceModel(Source(), blade_breadth=0.3)
    for _ in range(50):  # one loop pass every 0.5 ms for 25 ms
        model.keep_alive()
        clock[0] += 0.0005
    assert Source.sent == math.ceil(0.025 / live.KEEP_ALIVE_S)
    assert live.KEEP_ALIVE_S <= WATCHDOG_TIMEOUT_S / 5
