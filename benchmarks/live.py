"""Benchmark of the live-session periphery: the window's drawing rate and the reference device's rate.

    .venv/bin/python benchmarks/live.py --json [--triangles 80000] [--frames 120] [--seconds 5]
    .venv/bin/python benchmarks/live.py --json --session cutkit-demo/knee.h5 [--strokes two|one|second] [--drawing auto|full|fast]

Every frame of the off-screen window is drawn as on screen (``--drawing``, default ``auto``:
``cutkit.live.window.DRAWINGS``); ``window`` in the results says how it drew (``full``/``fast``).

* window: an off-screen ``WindowView`` draws a textured sphere of about
  ``--triangles`` boundary triangles with a cut surface, moving every frame
  (positions, normals and colours uploaded each frame, as in a session);
  reports frames per second (the issue asks >= 30) and the time of one
  ``show``.
* play: ``cutkit haptics play --loop`` (its own process, as a device is)
  streams the shipped incision into a spawned ``cutkit haptics serve``
  while a ``HapticsPoseSource`` in this process takes the forwarded poses
  and answers with SIM_UPDATEs for ``--seconds``; reports the device's
  achieved rate, its p50/p99 period and the poses forwarded per second.
* session (``--session MODEL``): the device streams the incisions of
  ``--strokes`` (:func:`strokes`; default ``two``: the shipped incision,
  the blade lifted out, at once a parallel one 15 mm lower, then a pause)
  through the service into a live session (:func:`cutkit.simulate.live.run_live`)
  on MODEL, drawn by an off-screen window (default camera) and sent as
  OpenIGTLink POLYDATA at ``--igtl-rate`` to a client in its own process (as
  a Slicer peer is) that stamps every message's arrival: the haptic loop's rate and p99 period
  (server ticks), frames per second, relaxation passes per second, the
  latency from a pose arriving to the drawn frame showing its cut, the
  longest gaps between frames and between OpenIGTLink messages (over the
  session, and across every stroke's end: from half a second before it to
  two seconds after it or after its rebase), the rebases' wall time, and the tets each
  stroke cut; with ``two`` the second stroke is then run alone in a fresh
  session (``second_alone_cut_tets``).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def window_rate(triangles: int, frames: int, drawing: str = "auto") -> dict:
    import pyvista as pv

    from cutkit.live import LiveFrame
    from cutkit.live.window import WindowView

    pv.OFF_SCREEN = True
    level = max(1, int(round(np.log(triangles / 20.0) / np.log(4.0))))
    s = pv.Icosphere(radius=40.0, nsub=level)
    pts = np.array(s.points, np.float64)
    faces = s.faces.reshape(-1, 4)[:, 1:].astype(np.int64)
    cut = faces[pts[faces].mean(axis=1)[:, 2] > 36.0]  # a cap stands in for the cut surface
    rgb = np.clip(127 + pts * 3, 0, 255).astype(np.uint8)
    frame = LiveFrame(points=pts, boundary_faces=faces, cut_faces=cut, rgb=rgb, tip=np.array([0.0, 0.0, 45.0]),
                      a=np.array([0.0, 0.0, -1.0]), n=np.array([1.0, 0.0, 0.0]), force=np.array([0.5, 0.0, 0.2]),
                      rates={"haptic_hz": 1000.0, "relax_passes_per_s": 200.0})
    view = WindowView(off_screen=True, window_size=(1024, 768), drawing=drawing)
    view.show(frame)  # builds the window
    times = []
    for i in range(frames):
        frame.points = pts * (1.0 + 0.01 * np.sin(0.1 * i))
        t0 = time.perf_counter()
        view.show(frame)
        times.append(time.perf_counter() - t0)
    view.close()
    t = np.array(times)
    return {"triangles": int(len(faces)), "nodes": int(len(pts)), "frames": frames, "drawn_as": view.drawn_as,
            "fps": float(1.0 / t.mean()), "show_ms_p50": float(np.percentile(t, 50) * 1e3),
            "show_ms_p99": float(np.percentile(t, 99) * 1e3)}


def play_rate(seconds: float, priority: str) -> dict:
    import signal
    import subprocess
    import sys

    from cutkit.haptics.client import spawned_server
    from cutkit.live import HapticsPoseSource

    incision = ROOT / "sample_volumes" / "incision.csv"
    with spawned_server("--priority", priority) as (host, port, _):
        source = HapticsPoseSource(host, port)
        cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "play", str(incision), "--host", host,
               "--port", str(port), "--loop", "--json", "--priority", priority]
        play = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        polled, first = 0, None
        t_end = time.monotonic() + seconds + 30.0
        while time.monotonic() < t_end:
            if source.poll() is not None:
                polled += 1
                if first is None:
                    first = time.monotonic()
            source.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), contact=False)
            if first is not None and time.monotonic() - first > seconds:
                break
            time.sleep(0.002)
        play.send_signal(signal.SIGINT)
        out, _ = play.communicate(timeout=30)
        forwarded = source.poses_received
        source.close()
    result = json.loads(out)
    return {"device_rate_hz": result["rate_hz"], "device_period_p50_ms": result["period_p50_ms"],
            "device_period_p99_ms": result["period_p99_ms"], "device_resyncs": result["resyncs"],
            "forwarded_per_s": forwarded / seconds, "session_polls_with_a_pose": polled}


def lifted(traj, out_mm: float = 13.0, lift_s: float = 0.1):
    """``traj`` with one more row: the blade drawn back ``out_mm`` along its axis in ``lift_s``
    (the stroke ends; also benchmarks/rebase.py's)."""
    from cutkit.cutting.trajectory import Trajectory

    tip = traj.tip[-1] - out_mm * traj.a[-1]
    return Trajectory(np.append(traj.t, traj.t[-1] + lift_s), np.vstack([traj.tip, tip]),
                      np.vstack([traj.a, traj.a[-1]]), np.vstack([traj.n, traj.n[-1]]),
                      blade_length=traj.blade_length, blade_breadth=traj.blade_breadth)


def _then(first, second, gap: float):
    """``second`` begun ``gap`` s after ``first`` ends."""
    from cutkit.cutting.trajectory import Trajectory

    t2 = second.t - second.t[0] + first.t[-1] + gap
    return Trajectory(np.concatenate([first.t, t2]), np.vstack([first.tip, second.tip]),
                      np.vstack([first.a, second.a]), np.vstack([first.n, second.n]))


def strokes(which: str = "two", gap_s: float = 0.05, pause_s: float = 1.0):
    """The incisions of a session: ``one`` (the shipped incision, sample_volumes/incision.csv, lifted
    out), ``second`` (the same 15 mm lower, at z = 60 mm) or ``two`` (one, then second ``gap_s`` after
    the lift); the blade then rests outside for ``pause_s``."""
    from cutkit.cutting.trajectory import Trajectory, straight_incision

    def incision(z):  # as sample_volumes/incision.csv says it was made
        return lifted(straight_incision(start=[25.0, 6.0, z], end=[55.0, 6.0, z], inward=[0, 1, 0], depth=8,
                                         approach=5, press_time=0.4, cut_time=1.5, rate=100))

    traj = {"one": lambda: incision(75.0), "second": lambda: incision(60.0),
            "two": lambda: _then(incision(75.0), incision(60.0), gap_s)}[which]()
    rest = Trajectory(np.array([0.0]), traj.tip[-1:], traj.a[-1:], traj.n[-1:])
    return _then(traj, rest, pause_s)


#: The OpenIGTLink peer of :class:`MessageClock`, run in its own process: it reads every message
#: (protocol v1/v2 header of 58 bytes, then the body), stamps its arrival with ``perf_counter``
#: (CLOCK_MONOTONIC on Linux, the same clock in every process) and, when SIGTERM comes or the
#: session closes the connection, prints the stamps as JSON [[seconds, type], ...].
_PEER = r"""
import json, signal, socket, struct, sys, time
stamps = []
def done(*_):
    print(json.dumps(stamps), flush=True)
    sys.exit(0)
signal.signal(signal.SIGTERM, done)
sock = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=None)
print("connected", flush=True)
def exactly(n):
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError
        buf += chunk
    return bytes(buf)
try:
    while True:
        head = exactly(58)
        exactly(struct.unpack(">Q", head[42:50])[0])
        stamps.append((time.perf_counter(), head[2:14].rstrip(b"\0").decode("ascii", "replace")))
except (OSError, ConnectionError):
    pass
done()
"""


class MessageClock:
    """An OpenIGTLink client in its own process, as a Slicer peer is (a reader thread in the
    session's process would wait for the interpreter lock while the session draws, and stamp
    late); :attr:`arrivals` (perf_counter s, message type) once :meth:`close` has run."""

    def __init__(self, port: int):
        import subprocess
        import sys

        self.proc = subprocess.Popen([sys.executable, "-c", _PEER, str(port)], stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True)
        if self.proc.stdout.readline().strip() != "connected":
            raise RuntimeError("the OpenIGTLink clock could not connect")
        self.arrivals: list[tuple[float, str]] = []

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        out, _ = self.proc.communicate(timeout=30)
        self.arrivals = [tuple(a) for a in json.loads(out or "[]")]


def _gaps_ms(times, lo=-np.inf, hi=np.inf):
    """Longest gap between consecutive times (s) that overlaps [lo, hi], ms."""
    t = np.asarray(sorted(times), np.float64)
    if t.size < 2:
        return None
    starts, ends = t[:-1], t[1:]
    over = (ends >= lo) & (starts <= hi)
    return float((ends - starts)[over].max() * 1e3) if over.any() else None


def _gaps_in(times, spans):
    """Longest gap (ms) between consecutive times (s) that overlaps one of ``spans`` [(lo, hi), ...]."""
    gaps = [g for g in (_gaps_ms(times, lo, hi) for lo, hi in spans) if g is not None]
    return max(gaps) if gaps else None


def _session_views(window: str | None, igtl_rate: float):
    views, closers, clock = [], [], None
    if window:
        import pyvista as pv

        from cutkit.live.window import WindowView

        pv.OFF_SCREEN = True
        views.append(WindowView(off_screen=True, window_size=(1024, 768), drawing=window))
    if igtl_rate > 0:
        from cutkit.live.igtl import IGTLEndpoint, IGTLPolyDataView

        endpoint = IGTLEndpoint(0)
        views.append(IGTLPolyDataView(endpoint=endpoint, max_rate_hz=igtl_rate))
        clock = MessageClock(endpoint.port)
        closers += [clock, endpoint]
    return views, closers, clock


def run_session(model, trajectory_path: str, priority: str, window: str | None, igtl_rate: float,
                solver: str | None = None) -> dict:
    """`cutkit haptics play` streams ``trajectory_path`` through the service into a live session on ``model``
    (element ``solver``), drawn by an off-screen window drawing as ``window`` says (None: no
    window); ``step_walls`` is, for each tissue stepped, (perf_counter, tissue time) at
    the end of each of its relaxation steps."""
    import subprocess
    import sys
    import tempfile

    from cutkit.haptics.client import spawned_server
    from cutkit.live import HapticsPoseSource
    from cutkit.simulate import SimulateOptions
    from cutkit.relax.elastic_tissue import ElasticTissue
    from cutkit.simulate.live import run_live

    views, closers, clock = _session_views(window, igtl_rate)
    out = Path(tempfile.mkdtemp(prefix="cutkit-live-bench-"))
    frames = []  # (perf_counter, session time) of each frame
    with spawned_server("--priority", priority) as (host, port, _):
        source = HapticsPoseSource(host, port)
        plays = []

        def start_device():
            cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "play", trajectory_path, "--host", host,
                   "--port", str(port), "--json", "--priority", priority]
            plays.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))

        step_walls = {}  # id of each tissue -> (perf_counter, tissue time) at the end of each of its steps
        count = ElasticTissue._count

        def counted(self, info, true_residual, stop=None):  # the wall time each step ends (the benchmark's own record)
            count(self, info, true_residual, stop)
            step_walls.setdefault(id(self), []).append((time.perf_counter(), self.time))

        ElasticTissue._count = counted
        from cutkit.simulate.live_loop import LiveLoop

        idle_views, still = LiveLoop._idle_views, []

        def left_out(self):  # a frame clock tick with nothing moved: the picture is current
            idle_views(self)
            still.append(self.now())

        LiveLoop._idle_views = left_out
        record, zero = LiveLoop._record, []

        def recorded(self):  # the loop's own origin: perf_counter at session time 0 (the wall clock's scale)
            zero.append(self.t0)
            return record(self)

        LiveLoop._record = recorded
        try:
            s = run_live(model, source, views, out, SimulateOptions(solver=solver), max_seconds=300,
                         until_idle_s=2.0, on_start=start_device,
                         on_frame=lambda f: frames.append((time.perf_counter(), f.t)))
        finally:
            ElasticTissue._count = count
            LiveLoop._idle_views = idle_views
            LiveLoop._record = record
            source.close()
            for v in views + closers:
                v.close()
        device = json.loads(plays[0].communicate(timeout=60)[0]) if plays else {}
    return {"summary": s, "frames": frames, "still": still, "perf_at_zero": zero[-1] if zero else None, "messages": [] if clock is None else clock.arrivals,
            "device": device, "recording": str(out), "step_walls": list(step_walls.values()),
            "drawn_as": next((v.drawn_as for v in views if hasattr(v, "drawn_as")), None)}


def rest_to_balance(relax: dict, steps_of_tissues: list, stroke_end: float | None, perf_at_zero: float) -> dict | None:
    """After the hand's last stroke ended (``stroke_end``, session seconds; ``perf_at_zero`` the
    perf_counter at session time 0), the wall seconds until a relaxation step begun after that
    moment (so made with the load the blade's leaving left) ends within ``within`` of the force
    scale (the first resting step's tolerance once the blade has left, ``rest_unloaded_first_rtol``), within 1e-3
    (``wall_s_within_1e-3``) and within the rest tolerance the resting steps after it go on to
    (``wall_s_within_rest_rtol``), and the residual then;
    ``wall_s_tissue_time``: until a step that also simulates the tissue past the stroke's end does
    (the relaxation runs behind the clock while the blade cuts; its steps are then made with the
    newest load, so they bring the picture to rest before its clock has caught up).  None without
    a stroke end.  ``steps_of_tissues`` holds, for each tissue stepped, (perf_counter, tissue time)
    at the end of each of its steps."""
    rel = relax.get("relative_residual") or []
    # the session's tissue: the one with as many steps (the session also steps a small warm-up tissue)
    steps = next((w for w in steps_of_tissues if len(w) == len(rel)), None)
    if steps is None or not rel or stroke_end is None:
        return None
    within = relax.get("rest_unloaded_first_rtol") or relax.get("rest_rtol") or 1e-3
    end_wall = perf_at_zero + stroke_end

    def first(bound, tissue_time=False):
        for k in range(1, len(steps)):
            begun_after = steps[k - 1][0] > end_wall and (not tissue_time or steps[k][1] > stroke_end)
            if begun_after and rel[k] is not None and rel[k] <= bound:  # None: a step a cut ended early
                return k
        return None

    def wall(k):
        return None if k is None else steps[k][0] - end_wall

    done = first(within)
    return {"within": within, "stroke_end_s": stroke_end, "wall_s": wall(done),
            "wall_s_within_1e-3": wall(first(1e-3)), "wall_s_tissue_time": wall(first(within, True)),
            "rest_rtol": relax.get("rest_rtol"),
            "wall_s_within_rest_rtol": wall(first(relax.get("rest_rtol") or within)),
            "residual_then": None if done is None else rel[done], "final_residual": rel[-1]}


def session_rate(model_path: str, priority: str, window: str | None, which: str = "two", igtl_rate: float = 30.0,
                 solver: str | None = None, keep: bool = False) -> dict:
    """A live session on ``model_path`` with the strokes ``which`` (:func:`strokes`): rates, gaps, tets cut.
    The session's recording and trajectory are temporary folders, removed unless ``keep``."""
    import shutil
    import tempfile

    from cutkit.cutting.trajectory import write_trajectory
    from cutkit.io.model_h5 import read_model

    model = read_model(model_path)
    path = Path(tempfile.mkdtemp(prefix="cutkit-live-strokes-")) / f"{which}.csv"
    write_trajectory(path, strokes(which))
    run = run_session(model, str(path), priority, window, igtl_rate, solver)
    if not keep:  # a knee's recording is about 12 MB a session
        shutil.rmtree(run["recording"], ignore_errors=True)
        shutil.rmtree(path.parent, ignore_errors=True)
        run["recording"] = None
    s, live = run["summary"], run["summary"]["live"]
    lat = live.get("latency_ms") or {}
    frames = np.array(run["frames"]) if run["frames"] else np.zeros((0, 2))
    t0 = run["perf_at_zero"]  # perf_counter at session time 0
    if t0 is None:  # from the frames: each stamped after its drawing, so later by that much
        t0 = float(np.median(frames[:, 0] - frames[:, 1])) if len(frames) else 0.0
    # the messages while the session's loop ran (before it, the client waits for the settle)
    span = (frames[0, 1], frames[-1, 1]) if len(frames) else (0.0, 0.0)
    messages = [t - t0 for t, _ in run["messages"] if span[0] <= t - t0 <= span[1]]
    windows = live.get("rebase_windows_s") or []
    # the picture is current at every frame drawn and at every frame clock tick left out because
    # nothing had moved (LiveLoop._scene_still): the gaps between frames are taken over both
    current = np.sort(np.concatenate([frames[:, 1], run["still"]]))
    # across every stroke's end: from half a second before it to two seconds after it, and after
    # each rebase (a stroke begun before the last one's rebase started goes on without one)
    spans = [(e - 0.5, e + 2.0) for e in live.get("stroke_ends_s") or []] + [(a - 0.5, b + 2.0) for a, b in windows]
    result = {"model": str(model_path), "strokes": which, "tets": s["tets_initial"], "cut_tets": s["cut_tets"],
              "tets_cut_at_rebases": live.get("tets_cut_at_rebases"), "rebase_s": [b - a for a, b in windows],
              "opening_mean_mm": s["cut_opening_mm"]["final_mean"], "haptic_hz": live["haptic_hz"],
              "haptic_period_p99_ms": live.get("period_p99_ms"),
              "haptic_periods_over_2ms": live.get("periods_over_2ms"), "fps": live["fps"],
              "fps_up_to_date": live.get("fps_up_to_date"), "frames_left_out_still": live.get("frames_left_out_still"),
              "frame_gap_max_ms": _gaps_ms(current), "frame_gap_max_ms_at_stroke_end": _gaps_in(current, spans),
              "frame_gap_max_ms_drawn": _gaps_ms(frames[:, 1]),
              "igtl_rate_hz": igtl_rate, "igtl_messages": len(messages),
              "igtl_gap_max_ms": _gaps_ms(messages),
              "igtl_gap_max_ms_at_stroke_end": _gaps_in(messages, spans),
              "stroke_ends_s": live.get("stroke_ends_s"), "strokes_joined": live.get("strokes_joined"),
              "relax_passes_per_s": live["relax_passes_per_s"], "relax_steps_per_s": live["relax_steps_per_s"],
              "latency_p50_ms": lat.get("p50"), "latency_p95_ms": lat.get("p95"),
              "latency_outside_rebase_ms": live.get("latency_outside_rebase_ms"),
              "geometry_updates_skipped": live.get("geometry_updates_skipped"),
              "device_rate_hz": run["device"].get("rate_hz"), "window": run["drawn_as"], "recording": run["recording"],
              "solver": s["relax_steps"].get("solver", solver), "relax_not_converged": s["relax_steps"]["not_converged"],
              "rest_to_balance": rest_to_balance(s["relax_steps"], run["step_walls"],
                                                 (live.get("stroke_ends_s") or [None])[-1], t0)}
    at = live.get("tets_cut_at_rebases") or []
    if which == "two" and at:
        result["second_stroke_cut_tets"] = s["cut_tets"] - at[0]
        alone = session_rate(model_path, priority, window, "second", igtl_rate, solver, keep)
        result["second_alone_cut_tets"] = alone["cut_tets"]
        result["second_vs_alone"] = result["second_stroke_cut_tets"] / max(alone["cut_tets"], 1)
        result["alone"] = alone
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=80000)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--priority", choices=["normal", "high", "realtime"], default="realtime")
    ap.add_argument("--session", metavar="MODEL", help="Also a live session on this model (the demo knee: "
                    "cutkit-demo/knee.h5) driven by `cutkit haptics play`, drawn off screen.")
    ap.add_argument("--no-window", action="store_true", help="The session without the window.")
    ap.add_argument("--drawing", choices=["auto", "full", "fast"], default="auto",
                    help="How the off-screen window draws (cutkit.live.window.DRAWINGS).")
    ap.add_argument("--strokes", choices=["two", "one", "second"], default="two",
                    help="The session's incisions (see strokes()); two also runs the second alone.")
    ap.add_argument("--igtl-rate", type=float, default=30.0,
                    help="OpenIGTLink surfaces per second to the stamping client (0: no OpenIGTLink view).")
    ap.add_argument("--skip-periphery", action="store_true", help="Only the session (no window or play benchmark).")
    ap.add_argument("--solver", choices=["vbd", "hybrid", "newton"], default=None,
                    help="The session's element solver (SimulateOptions.solver; default: the runtime's).")
    ap.add_argument("--rest-smoothing", type=int, default=None,
                    help="Sweeps between a resting step's Newton iterations (default: the runtime's "
                         "REST_SMOOTHING_SWEEPS; 0: none), for a before/after on the same machine.")
    ap.add_argument("--keep-recording", action="store_true",
                    help="Keep the session's recording (its folder is the result's recording; else removed).")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.rest_smoothing is not None:
        from cutkit.relax import elastic_tissue

        elastic_tissue.REST_SMOOTHING_SWEEPS = args.rest_smoothing
    result = {"machine": platform.machine(), "python": platform.python_version(),
              "load_1min": __import__("os").getloadavg()[0]}
    if not args.skip_periphery:
        result["window"] = window_rate(args.triangles, args.frames, args.drawing)
        result["play"] = play_rate(args.seconds, args.priority)
    if args.session:
        result["session"] = session_rate(args.session, args.priority, None if args.no_window else args.drawing, args.strokes,
                                         args.igtl_rate, args.solver, args.keep_recording)
    if args.json:
        print(json.dumps(result))
    else:
        for part in [p for p in ("window", "play", "session") if p in result]:
            for k, v in result[part].items():
                if isinstance(v, dict):
                    continue
                print(f"{part + '.' + k:32s} {v:.4g}" if isinstance(v, float) else f"{part + '.' + k:32s} {v}")


if __name__ == "__main__":
    main()
