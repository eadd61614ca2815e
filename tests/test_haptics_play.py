"""`cutkit haptics play` (the reference device) and DEVICE_POSE forwarding to a simulation."""

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cutkit.cutting.trajectory import read_trajectory
from cutkit.haptics import HapticsClient, spawned_server
from cutkit.haptics import protocol as P
from cutkit.haptics.play import pose_frame_payload
from cutkit.live.sources import HapticsPoseSource

ROOT = Path(__file__).resolve().parents[1]
INCISION = ROOT / "sample_volumes" / "incision.csv"
A, N = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)


@pytest.fixture(scope="module")
def server():
    with spawned_server("--priority", "normal") as (host, port, proc):
        yield host, port
        assert proc.poll() is None, "the server died during the tests"


def _grid(traj, rate=1000.0):
    """The poses `play` sends: pose k at k / rate s, the last one exactly the last row."""
    k = int(np.floor(traj.duration * rate + 1e-9)) + 1
    times = traj.t[0] + np.arange(k) / rate
    times[-1] = traj.t[-1]
    return np.array([traj.pose_at(t)[0] for t in times])


def test_play_streams_the_incision_to_a_simulation_in_order(server):
    host, port = server
    traj = read_trajectory(INCISION)
    grid = _grid(traj)
    source = HapticsPoseSource(host, port)
    cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "play", str(INCISION), "--host", host,
           "--port", str(port), "--priority", "normal", "--json"]
    play = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    poses, states = [], []
    try:
        # until the player has ended and its last row came through (a generous bound, not a timing)
        t_end = time.monotonic() + traj.duration + 60.0
        while time.monotonic() < t_end:
            pose = source.poll()
            if pose is not None:
                poses.append(pose)
                # the session's side of the loop: a free blade, so the proxy is the device's tip
                source.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), contact=False)
            if source.state is not None and (not states or source.state.tick != states[-1].tick):
                states.append(source.state)
            # and a STATE for the updates sent (a loop that saw only the last pose has sent one update)
            if (play.poll() is not None and poses and np.linalg.norm(np.asarray(poses[-1].tip) - grid[-1]) < 1e-9
                    and states):
                break
            time.sleep(0.001)
        out, err = play.communicate(timeout=30)
    finally:
        if play.poll() is None:
            play.kill()
        source.close()
    assert play.returncode == 0, err
    stats = json.loads(out)
    assert stats["ended"] == "trajectory" and stats["loops"] == 1
    assert 0 < stats["poses_sent"] <= len(grid)
    assert stats["forces_received"] > 0 and np.isfinite(stats["period_p99_ms"])
    # how many poses the player sends and this loop sees is the machine's (the player skips the poses of
    # a stall; poll() gives the newest only): every pose seen was received, and sent
    assert 1 <= len(poses) <= source.poses_received <= stats["poses_sent"], (len(poses), source.poses_received)
    tips = np.array([p.tip for p in poses])
    d = np.linalg.norm(tips[:, None, :] - grid[None, :, :], axis=2)
    k = d.argmin(axis=1)
    assert d[np.arange(len(k)), k].max() < 1e-9, "a forwarded tip is not one of the poses played"
    assert np.all(np.diff(k) > 0), "poses arrived out of order"
    assert k[-1] == len(grid) - 1, "the last row never arrived"
    # the trajectory's convention survives the device frame's swap of a and n
    for p in poses:
        np.testing.assert_allclose(p.a, traj.a[0], atol=1e-12)
        np.testing.assert_allclose(p.n, traj.n[0], atol=1e-12)
    assert all(np.isfinite(p.t) for p in poses) and all(np.diff([p.t for p in poses]) >= 0)
    # STATE came back for the SIM_UPDATEs, its proxy on the played poses
    assert states, "no STATE in reply to SIM_UPDATE"
    proxies = np.array([s.proxy for s in states])
    dp = np.linalg.norm(proxies[:, None, :] - grid[None, :, :], axis=2).min(axis=1)
    assert dp.max() < 1e-9


def test_pose_frame_swaps_the_trajectory_convention():
    v = P.POSE_PAYLOAD.unpack(pose_frame_payload((1, 2, 3), (0, 1, 0), (1, 0, 0), 5))
    assert v[0:3] == (1.0, 2.0, 3.0)
    assert v[3:6] == (1.0, 0.0, 0.0)  # forward cutting direction = the trajectory's n
    assert v[6:9] == (0.0, 1.0, 0.0)  # along the blade = the trajectory's a
    assert v[9] == 5


def _frames_for(client, seconds):
    types = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        types += [f[0] for f in client.drain()]
        time.sleep(0.005)
    return types


def _until_pose(client, device_seq, timeout=60.0):
    """Frames (type, seq, ts, payload) until the DEVICE_POSE of ``device_seq`` (bounded, not timed)."""
    from cutkit.haptics.client import decode_device_pose

    frames = []
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        for f in client.drain():
            frames.append(f)
            if f[0] == P.DEVICE_POSE and decode_device_pose(f[2], f[3], 0).device_seq == device_seq:
                return frames
        time.sleep(0.005)
    raise AssertionError(f"the DEVICE_POSE of device frame {device_seq} never came")


def test_only_simulations_that_ask_get_device_poses(server):
    host, port = server
    with HapticsClient(host, port, "device", forward_poses=True) as dev, \
            HapticsClient(host, port, "simulation") as plain, \
            HapticsClient(host, port, "simulation", forward_poses=True) as asking:
        assert not dev.forwards_poses and not plain.forwards_poses and asking.forwards_poses
        for i in range(20):
            dev.send_pose((float(i), 0.0, 0.0), A, N, buttons=3)
        got = _until_pose(asking, dev.seq)  # every frame until the last pose came through
        got_plain = _frames_for(plain, 0.1)  # nothing of it for a simulation that did not ask
    assert P.DEVICE_POSE not in got_plain
    poses = [f for f in got if f[0] == P.DEVICE_POSE and f[3] is not None]
    assert poses, "no DEVICE_POSE frame"
    from cutkit.haptics.client import decode_device_pose

    last = decode_device_pose(poses[-1][2], poses[-1][3], 0)
    assert last.tip == (19.0, 0.0, 0.0) and last.a == A and last.n == N and last.buttons == 3
    assert last.device_seq == dev.seq and last.device_id != 0


def test_a_client_may_not_send_device_pose(server):
    host, port = server
    s = socket.create_connection((host, port), timeout=30.0)  # a bound for a loaded machine, not a timing
    s.sendall(P.frame(P.HELLO, P.HELLO_FLAGS_PAYLOAD.pack(P.ROLE_SIMULATION, P.HELLO_FORWARD_POSES)))
    s.sendall(P.frame(P.DEVICE_POSE, bytes(P.DEVICE_POSE_PAYLOAD.size)))
    data = b""
    t_end = time.monotonic() + 30.0
    while time.monotonic() < t_end:
        chunk = s.recv(4096)
        if not chunk:
            break
        data += chunk
    s.close()
    codes = []
    while len(data) >= P.HEADER_SIZE:
        ftype, length, _, _ = P.check_header(data)
        if ftype == P.ERROR:
            codes.append(P.ERROR_HEAD.unpack_from(data, P.HEADER_SIZE)[0])
        data = data[P.HEADER_SIZE + length:]
    assert codes == [P.E_UNEXPECTED]


def test_play_user_errors_are_one_line(tmp_path):
    with socket.create_server(("127.0.0.1", 0)) as s:
        port = s.getsockname()[1]  # nothing listens there after the block
    res = subprocess.run([sys.executable, "-m", "cutkit.cli.main", "haptics", "play", str(INCISION),
                          "--port", str(port), "--priority", "normal"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert res.stderr.startswith(f"cutkit: error: cannot connect to the haptics server at 127.0.0.1:{port}")
    assert len(res.stderr.strip().splitlines()) == 1
    res = subprocess.run([sys.executable, "-m", "cutkit.cli.main", "haptics", "play", str(tmp_path / "no.csv")],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and res.stderr.strip() == f"cutkit: error: {tmp_path / 'no.csv'}: no such file"


def test_play_loops_until_ctrl_c(server):
    import signal

    host, port = server
    cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "play", str(INCISION), "--host", host,
           "--port", str(port), "--priority", "normal", "--loop", "--json"]
    with HapticsClient(host, port, "simulation", forward_poses=True) as sim:
        play = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            seen = 0
            t_end = time.monotonic() + 60.0
            while seen < 50 and time.monotonic() < t_end:  # the device is streaming
                seen += sum(f[0] == P.DEVICE_POSE for f in sim.drain())
                time.sleep(0.01)
            assert seen >= 50
            play.send_signal(signal.SIGINT)
            out, err = play.communicate(timeout=30)
        finally:
            if play.poll() is None:
                play.kill()
    assert play.returncode == 0, err
    stats = json.loads(out)
    assert stats["ended"] == "stopped" and stats["poses_sent"] >= 50


def _old_server(listener, done):
    """A version 1 server without pose forwarding: a plain WELCOME (flags byte 0), then BYE."""
    conn, _ = listener.accept()
    with conn:
        conn.settimeout(60.0)  # bounds for a loaded machine, not timings
        data = b""
        while len(data) < P.HEADER_SIZE + P.HELLO_PAYLOAD.size:
            data += conn.recv(64)
        conn.sendall(P.frame(P.WELCOME, P.WELCOME_PAYLOAD.pack(P.ROLE_SIMULATION, 1, 1000)))
        done.wait(60.0)


def test_a_server_without_forwarding_is_refused_in_one_line():
    import threading

    from cutkit.errors import ProtocolError

    with socket.create_server(("127.0.0.1", 0)) as listener:
        done = threading.Event()
        thread = threading.Thread(target=_old_server, args=(listener, done), daemon=True)
        thread.start()
        port = listener.getsockname()[1]
        with pytest.raises(ProtocolError, match="does not forward device poses") as info:
            HapticsPoseSource("127.0.0.1", port)
        done.set()
        thread.join(60.0)
    assert "\n" not in str(info.value)


def test_the_source_after_the_server_is_gone():
    from cutkit.errors import ProtocolError

    with spawned_server("--priority", "normal") as (host, port, proc):
        source = HapticsPoseSource(host, port)
        proc.terminate()
        proc.wait(10)
        t_end = time.monotonic() + 60.0
        while not source.finished and time.monotonic() < t_end:
            assert source.poll() is None
            time.sleep(0.01)
        assert source.finished  # the server said BYE
        with pytest.raises(ProtocolError, match="connection is gone"):
            for _ in range(50):  # the first send may still reach the socket buffer
                source.update((0, 0, 0), (0, 0, 1), contact=False)
                time.sleep(0.01)
        source.close()
