"""The 1 kHz haptic service: rate and latency, malformed frames, watchdog, newest state wins."""

import json
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from cutkit.errors import InputError, ProtocolError
from cutkit.haptics import WATCHDOG_RAMP_S, HapticsClient, material_from_model, spawned_server
from cutkit.haptics import protocol as P
from cutkit.scalpel import CUT_FIELDS, CUTTING, FREE, STATIC, WITHDRAWING, ScalpelParams

A, N, B = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
#: Longest wait for a frame or a reply (s): a bound for a loaded machine (the service ticks every
#: millisecond), never waited out when a test passes.
WAIT_S = 30.0


@pytest.fixture(scope="module")
def server():
    with spawned_server() as (host, port, proc):
        yield host, port, proc
        assert proc.poll() is None, "the server died during the tests"
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        # every rejected frame was logged, and counted in the shutdown line
        n_rejected = int(out.split(" rejected frames")[0].rsplit(" ", 1)[1])
        assert err.count("rejected frame") == n_rejected


def _raw(host, port, hello_role=None):
    s = socket.create_connection((host, port), timeout=WAIT_S)
    if hello_role is not None:
        s.sendall(P.frame(P.HELLO, P.HELLO_PAYLOAD.pack(hello_role)))
        _read_frame(s)  # WELCOME
    return s


def _read_frame(s):
    head = _recv_exact(s, P.HEADER_SIZE)
    ftype, length, seq, ts = P.check_header(head)
    return ftype, _recv_exact(s, length)


def _recv_exact(s, n):
    data = b""
    while len(data) < n:
        chunk = s.recv(n - len(data))
        if not chunk:
            raise EOFError(f"closed after {len(data)} of {n} bytes")
        data += chunk
    return data


def _expect_error_then_close(s, code):
    """Skip FORCE frames; the connection must end with ERROR(code) and a clean EOF."""
    while True:
        ftype, payload = _read_frame(s)
        if ftype == P.ERROR:
            assert P.ERROR_HEAD.unpack_from(payload)[0] == code, payload
            break
    s.settimeout(WAIT_S)
    assert s.recv(1) == b""  # orderly close, not a reset
    s.close()


def _bench():
    """One 3 s run of `cutkit haptics bench --spawn` (the device loop against a spawned service)."""
    cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "bench", "--spawn", "--seconds", "3", "--json",
           "--priority", "realtime"]  # the paper's server controls its priority; falls back to nice -10
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)  # two process starts and 3 s
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    print(r)
    return r


def test_loopback_loop_never_runs_ahead_of_the_tick():
    """What the loop's pacing guarantees whatever the machine does: it never runs ahead of 1 kHz and
    its frames come back.  The rate it keeps (>= 999 Hz, periods over 2 ms, round trip), alone and
    with a relaxation on every core beside it, is the machine's: ``benchmarks/haptics.py
    [--with-relaxation]`` measures it, since a machine that stalls would fail a test asserting it."""
    r = _bench()
    assert r["frames"] > 0, r
    assert r["rate_hz"] <= 1050.0, r
    assert r["rtt_p50_ms"] > 0.0, r


def test_device_gets_force_frames_every_tick(server):
    host, port, _ = server
    with HapticsClient(host, port, "device") as c:
        assert c.rate_hz == 1000
        frames = [c.read_force(WAIT_S) for _ in range(50)]
    ticks = np.array([f.tick for f in frames])
    assert np.all(np.diff(ticks) >= 1)
    assert all(f.type == P.FORCE for f in frames)


def _acted_on(client, after_tick=None, timeout=30.0):
    """The first frame that echoes the client's newest message (at or after server tick ``after_tick``):
    the service has acted on it.  No sleep: the frames themselves say when."""
    t_end = time.monotonic() + timeout
    while True:
        f = client.read_force(timeout)
        if f.echo_seq == client.seq and (after_tick is None or f.seq >= after_tick):
            return f
        assert time.monotonic() < t_end, f"the service never acted on message {client.seq}; last {f}"


def _until(client, done, timeout=30.0):
    """Frames until one satisfies ``done`` (a bound generous enough for a loaded machine, never a timing)."""
    t_end = time.monotonic() + timeout
    while True:
        f = client.read_force(timeout)
        if done(f):
            return f
        assert time.monotonic() < t_end, f"no such frame within {timeout} s; last {f}"


def _step(dev, sim, tip, **sim_kw):
    """One simulation update, then one device pose; the device's frame for that pose, after that update."""
    sim.send_sim((0, 0, 0), B, **sim_kw)
    st = _acted_on(sim)
    dev.send_pose(tip, A, N)
    return _acted_on(dev, after_tick=st.seq)


def test_cut_through_the_service(server):
    host, port, _ = server
    p = ScalpelParams()
    with HapticsClient(host, port, "device") as dev, HapticsClient(host, port, "simulation") as sim:
        f = _step(dev, sim, (0, 0, 0), material=p.material())
        assert f.state == STATIC
        # below F_enter: the proxy holds
        f = _step(dev, sim, (0.5 * p.F_enter / p.k_spring, 0, 0))
        assert f.state == STATIC and f.proxy == (0.0, 0.0, 0.0) and f.echo_seq == dev.seq
        # past F_enter the blade cuts and advances
        seen = set()
        for i in range(100):
            f = _step(dev, sim, (2.0 * p.F_enter / p.k_spring + 0.01 * i, 0, 0))
            seen.add(f.state)
        assert CUTTING in seen and f.proxy[0] > 0.0
        # pulling back: withdrawing, no in-plane force
        _step(dev, sim, (-5.0, 0, 0))
        f = _until(dev, lambda fr: fr.state == WITHDRAWING)
        assert abs(f.force[0]) < 1e-12
        sim.send_sim((0, 0, 0), B, contact=False)
        _until(dev, lambda fr: fr.state == FREE)


def _feed_until(dev, sim, done, tip, timeout=30.0):
    """Keep the simulation and the device sending until a FORCE frame satisfies ``done``."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        sim.send_sim((0, 0, 0), B)
        dev.send_pose(tip, A, N)
        time.sleep(0.005)
        f = dev.latest()
        if done(f):
            return f
    raise AssertionError(f"no such frame within {timeout} s; last {f}")


def test_watchdog_ramps_force_to_zero_when_the_simulation_stops(server):
    host, port, _ = server
    with HapticsClient(host, port, "device") as dev, HapticsClient(host, port, "simulation") as sim:
        dev.send_pose((0, 0, 0), A, N)
        time.sleep(0.01)
        # the blade rests in the tissue, pressed 2 mm off the blade plane; the
        # gain ramps up while the simulation keeps sending
        f = _feed_until(dev, sim, lambda fr: fr.gain == 1.0, tip=(0, 0, 2.0))
        assert f.force[2] < -1.0  # the plane spring pushes back
        full = f.force[2]
        # the simulation goes quiet: the gain ramps down, one step per tick at most
        frames = [dev.read_force(WAIT_S)]
        t_end = time.monotonic() + WAIT_S
        while frames[-1].gain > 0.0 and time.monotonic() < t_end:
            frames.append(dev.read_force(WAIT_S))
        gains = np.array([fr.gain for fr in frames])
        ticks = np.array([fr.tick for fr in frames])
        assert gains[-1] == 0.0 and frames[-1].force == (0.0, 0.0, 0.0)
        step = 1.0 / (WATCHDOG_RAMP_S * 1000)
        assert np.all(np.diff(gains) <= 1e-12)  # never back up without updates
        assert np.all(-np.diff(gains) <= step * np.diff(ticks) + 1e-9)  # a ramp, not a jump
        k = int(np.argmax((gains > 0) & (gains < 1)))
        assert frames[k].force[2] == pytest.approx(full * gains[k], rel=1e-9)
        # updates return: the force ramps back up
        _feed_until(dev, sim, lambda fr: fr.gain == 1.0, tip=(0, 0, 2.0))
        sim.send_sim((0, 0, 0), B, contact=False)


def test_newest_pose_wins(server):
    host, port, _ = server
    with HapticsClient(host, port, "device") as dev:
        dev.read_force(WAIT_S)
        burst = b""
        for i in range(1, 21):
            payload = P.POSE_PAYLOAD.pack(float(i), 0.0, 0.0, *A, *N, 0)
            burst += P.frame(P.POSE, payload, seq=1000 + i, ts=i)
        dev.send_raw(burst)
        echoes, f = [], None
        t_end = time.monotonic() + 30.0
        while time.monotonic() < t_end:
            f = dev.read_force(WAIT_S)
            echoes.append(f.echo_seq)
            if f.echo_seq == 1020:
                break
        assert f.echo_seq == 1020 and f.echo_ns == 20
        assert f.proxy == (20.0, 0.0, 0.0)  # free blade: the proxy is the newest tip
        burst_echoes = [e for e in echoes if e > 1000]
        assert burst_echoes == sorted(burst_echoes)  # never an older pose after a newer
        assert len(set(burst_echoes)) <= 3  # 20 poses in one send collapse into a tick or two


def test_newest_simulation_update_wins(server):
    host, port, _ = server
    with HapticsClient(host, port, "device") as dev, HapticsClient(host, port, "simulation") as sim:
        dev.send_pose((1.0, 2.0, 0.0), A, N)
        time.sleep(0.01)
        burst = b""
        for i in range(1, 11):
            payload = P.SIM_PAYLOAD.pack(0.0, 0.0, 0.1 * i, *B, 0.0, 0.0, 0.0, *([0.0] * 9), 1)
            burst += P.frame(P.SIM_UPDATE, payload, seq=500 + i)
        sim.send_raw(burst)
        states = []
        while not states or states[-1].echo_seq != 510:
            states.append(sim.read_force(WAIT_S))
        assert len(states) <= 3  # one STATE per tick, not one per update
        assert states[-1].proxy == pytest.approx((1.0, 2.0, 1.0))  # on the newest plane z = 1.0
        sim.send_sim((0, 0, 0), B, contact=False)


MALFORMED = [
    ("bad magic", lambda: b"XXXX" + P.frame(P.POSE, bytes(P.POSE_PAYLOAD.size))[4:], P.E_BAD_MAGIC),
    ("bad version", lambda: P.HEADER.pack(P.MAGIC, 9, P.POSE, P.POSE_PAYLOAD.size, 1, 0) + bytes(80), P.E_BAD_VERSION),
    ("bad type", lambda: P.HEADER.pack(P.MAGIC, 1, 77, 0, 1, 0), P.E_BAD_TYPE),
    ("bad length", lambda: P.HEADER.pack(P.MAGIC, 1, P.POSE, 12, 1, 0) + bytes(12), P.E_BAD_LENGTH),
    ("oversized", lambda: P.HEADER.pack(P.MAGIC, 1, P.POSE, 0xFFFFFFFF, 1, 0), P.E_OVERSIZED),
    ("non-finite", lambda: P.frame(P.POSE, P.POSE_PAYLOAD.pack(float("nan"), *([0.0] * 8), 0)), P.E_BAD_VALUE),
    ("wrong role", lambda: P.frame(P.SIM_UPDATE, bytes(P.SIM_PAYLOAD.size)), P.E_UNEXPECTED),
    ("second hello", lambda: P.frame(P.HELLO, P.HELLO_PAYLOAD.pack(P.ROLE_DEVICE)), P.E_UNEXPECTED),
]


class _GoodDevice(threading.Thread):
    """A well-behaved device that keeps sending poses and counting force frames."""

    def __init__(self, host, port):
        super().__init__(daemon=True)
        self.client = HapticsClient(host, port, "device")
        self.ticks = []
        self.error = None
        self.stop = threading.Event()

    def run(self):
        try:
            while not self.stop.is_set():
                self.client.send_pose((0.0, 0.0, 0.0), A, N)
                self.ticks.append(self.client.read_force(WAIT_S).tick)
        except Exception as err:  # reported by the test
            self.error = err

    def progress(self, ticks, timeout=60.0):
        """Wait until ``ticks`` more force frames came (bounded generously, never timed); how many came."""
        n = len(self.ticks)
        t_end = time.monotonic() + timeout
        while len(self.ticks) - n < ticks and time.monotonic() < t_end and self.is_alive():
            time.sleep(0.01)
        return len(self.ticks) - n


def test_malformed_frames_and_abusive_clients_never_stop_the_service(server):
    host, port, _ = server
    good = _GoodDevice(host, port)
    good.start()
    try:
        assert good.progress(100) >= 100, good.error  # served before the abuse, and after it below
        for name, make, code in MALFORMED:
            s = _raw(host, port, P.ROLE_DEVICE)
            s.sendall(make())
            _expect_error_then_close(s, code)
        # a frame other than HELLO first
        s = _raw(host, port)
        s.sendall(P.frame(P.POSE, bytes(P.POSE_PAYLOAD.size)))
        _expect_error_then_close(s, P.E_UNEXPECTED)
        # truncated: half a frame, then the client hangs up
        s = _raw(host, port, P.ROLE_DEVICE)
        s.sendall(P.frame(P.POSE, bytes(P.POSE_PAYLOAD.size))[:50])
        s.shutdown(socket.SHUT_WR)
        _expect_error_then_close(s, P.E_TRUNCATED)
        # random bytes, with and without a HELLO first
        rng = np.random.default_rng(7)
        for i in range(20):
            s = _raw(host, port, P.ROLE_SIMULATION if i % 2 else None)
            s.sendall(rng.integers(0, 256, int(rng.integers(1, 3000)), dtype=np.uint8).tobytes())
            s.close()
        # a frame trickled in byte by byte is still served
        s = _raw(host, port)
        for byte in P.frame(P.HELLO, P.HELLO_PAYLOAD.pack(P.ROLE_DEVICE)):
            s.sendall(bytes([byte]))
            time.sleep(0.002)
        assert _read_frame(s)[0] == P.WELCOME
        s.close()
        # clients that connect and never read, or vanish mid-stream
        idle = [_raw(host, port, P.ROLE_DEVICE) for _ in range(5)]
        for s in idle[:2]:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            s.close()  # reset
        assert good.progress(100) >= 100, good.error
        for s in idle[2:]:
            s.close()
    finally:
        good.stop.set()
        good.join(WAIT_S)
    assert good.error is None
    ticks = np.array(good.ticks)
    # how many frames the device read during the abuse is the machine's: 100 before it, 100 after it
    assert ticks.size >= 200 and np.all(np.diff(ticks) >= 1)


def test_a_frame_left_incomplete_is_dropped_after_the_timeout(server):
    from cutkit.haptics.server import PARTIAL_FRAME_TIMEOUT_S

    host, port, _ = server
    s = _raw(host, port, P.ROLE_SIMULATION)
    t0 = time.monotonic()  # before the send: a stall after it would shorten the time measured here
    s.sendall(P.frame(P.SIM_UPDATE, bytes(P.SIM_PAYLOAD.size))[:30])  # slow loris: never finished
    s.settimeout(PARTIAL_FRAME_TIMEOUT_S + 60.0)  # a bound for a loaded machine, not a timing
    _expect_error_then_close(s, P.E_TIMEOUT)
    assert PARTIAL_FRAME_TIMEOUT_S <= time.monotonic() - t0  # never dropped before its timeout


def test_server_shuts_down_cleanly_on_sigint():
    with spawned_server() as (host, port, proc):
        c = HapticsClient(host, port, "device")
        c.read_force(WAIT_S)
        proc.send_signal(signal.SIGINT)
        with pytest.raises(ProtocolError, match="BYE|closed"):
            for _ in range(5000):
                c.read_force(WAIT_S)
        c.sock.close()
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        assert "Traceback" not in err and "stopped after" in out


def test_material_from_model(tmp_path):
    from cutkit.io.model_h5 import write_model
    from cutkit.mesh.generate import box_mesh
    from cutkit.model import MATERIAL_FIELDS, Materials, TetModel

    points, tets = box_mesh((2, 2, 2), spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0))
    rows = [dict(label=1, name="fat", **{k: 1.0 for k in MATERIAL_FIELDS}),
            dict(label=2, name="muscle", **{k: 0.5 + i for i, k in enumerate(MATERIAL_FIELDS)})]
    for row in rows:
        if "poisson_ratio" in row:  # must lie in [0, 0.5)
            row["poisson_ratio"] = 0.3
    path = tmp_path / "m.h5"
    write_model(path, TetModel.from_arrays(points, tets, np.full(len(tets), 2), materials=Materials.from_rows(rows)))
    row = material_from_model(path, "muscle")
    p = ScalpelParams.from_material(row)
    assert p.material() == tuple(row[k] for k in CUT_FIELDS)
    assert p.eta == row["E"] == 0.5
    assert material_from_model(path, "1")["name"] == "fat"  # a label number works too
    with pytest.raises(InputError, match=r"no material named 'skin' \(materials: fat, muscle\)"):
        material_from_model(path, "skin")
    res = subprocess.run([sys.executable, "-m", "cutkit.cli.main", "haptics", "serve", "--model",
                          str(tmp_path / "missing.h5")], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert res.stderr.strip() == f"cutkit: error: {tmp_path / 'missing.h5'}: no such file"


def test_huge_finite_values_do_not_poison_the_scalpel(server):
    host, port, proc = server
    with HapticsClient(host, port, "device") as dev, HapticsClient(host, port, "simulation") as sim:
        f = _step(dev, sim, (1e300, -1e300, 1e300), f_ext=(1e308, 1e308, 0), material=(1e300,) * 9)
        assert all(np.isfinite(f.force)) and all(np.isfinite(f.proxy))
        # out of contact, then a pose: the frame the service computed from them (20 ms of sleep before
        # reading the newest frame was a timing: a stalled service had not acted on them yet)
        f = _step(dev, sim, (1.0, 2.0, 3.0), contact=False)
        assert f.state == FREE and f.proxy == (1.0, 2.0, 3.0)
        # restore the default material for later tests
        sim.send_sim((0, 0, 0), B, material=ScalpelParams().material(), contact=False)
    assert proc.poll() is None


def test_port_in_use_is_a_one_line_error():
    with socket.create_server(("127.0.0.1", 0)) as busy:
        port = busy.getsockname()[1]
        res = subprocess.run([sys.executable, "-m", "cutkit.cli.main", "haptics", "serve", "--port", str(port)],
                             capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert res.stderr.strip() == f"cutkit: error: cannot listen on 127.0.0.1:{port}: Address already in use"


def test_fracture_cut_through_the_service():
    """``serve --scalpel fracture``: the device feels J_c x depth of cut while the crack advances (closed form of
    docs/scalpel-model.md, eq. F2: within one sawtooth k da of it), and nothing once it pulls back behind the crack."""
    p = ScalpelParams(model="fracture")  # the service's defaults: J_c and k_spring as here
    depth = 5.0  # the tip 5 mm along n = b x a below the entry point
    k_c = p.c_shape * p.eta * 1e-6 * p.blade_depth * depth / p.edge_radius
    k = 1.0 / (1.0 / p.k_spring + 1.0 / k_c)
    steady = p.J_c * 1e-3 * depth
    with spawned_server("--scalpel", "fracture") as (host, port, proc), \
            HapticsClient(host, port, "device") as dev, HapticsClient(host, port, "simulation") as sim:
        f = _step(dev, sim, (0, depth, 0), material=p.material())
        assert f.state == STATIC
        seen = set()
        far = steady / k + 1.0  # past the first crack advance
        for i in range(40):
            tip = (far + 0.05 * i, depth, 0)
            f = _step(dev, sim, tip)
            seen.add(f.state)
        assert CUTTING in seen
        # full gain once the simulation has been fresh for the watchdog's ramp
        f = _feed_until(dev, sim, lambda fr: fr.gain == 1.0, tip)
        assert abs(-f.force[0] - steady) <= k * p.crack_step + 1e-9
        assert f.force[0] < 0.0  # the tissue pushes the blade back
        _step(dev, sim, (0.0, depth, 0))
        f = _until(dev, lambda fr: fr.state in (WITHDRAWING, STATIC) and abs(fr.force[0]) < 1e-12)
        sim.send_sim((0, 0, 0), B, contact=False)
        _until(dev, lambda fr: fr.state == FREE)


def test_a_process_leaving_its_loop_drops_to_normal_priority():
    """After the 1 kHz loop a process's report and exit run at normal priority (a device process that
    exited at SCHED_FIFO took a core from the live session beside it for 100-120 ms): from realtime
    (or the high nice value it falls back to) drop_priority returns to SCHED_OTHER and nice >= 0."""
    import subprocess
    import sys

    code = ("import os; from cutkit.haptics.priority import raise_priority, drop_priority\n"
            "got = raise_priority('realtime')\n"
            "raised = os.sched_getscheduler(0) != os.SCHED_OTHER or os.nice(0) < 0\n"
            "drop_priority()\n"
            "print(got, raised, os.sched_getscheduler(0) == os.SCHED_OTHER, os.nice(0) >= 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout.split()
    got, raised, other, nice_ok = out
    assert other == "True" and nice_ok == "True"
    assert raised == ("True" if got in ("realtime", "high") else "False")
