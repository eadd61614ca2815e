"""Benchmark of the live-session periphery: the window's drawing rate and the reference device's rate.

    .venv/bin/python benchmarks/live.py --json [--triangles 80000] [--frames 120] [--seconds 5]

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
* session (``--session MODEL``): the device streams the shipped incision
  through the service into a live session (:func:`cutkit.simulate.live.run_live`)
  on MODEL, drawn by an off-screen window: the haptic loop's rate and p99
  period (server ticks), frames per second, relaxation passes per second
  and the latency from a pose arriving to the drawn frame showing its cut.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def window_rate(triangles: int, frames: int) -> dict:
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
    view = WindowView(off_screen=True, window_size=(1024, 768))
    view.show(frame)  # builds the window
    times = []
    for i in range(frames):
        frame.points = pts * (1.0 + 0.01 * np.sin(0.1 * i))
        t0 = time.perf_counter()
        view.show(frame)
        times.append(time.perf_counter() - t0)
    view.close()
    t = np.array(times)
    return {"triangles": int(len(faces)), "nodes": int(len(pts)), "frames": frames,
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


def session_rate(model_path: str, priority: str, window: bool) -> dict:
    """`cutkit haptics play` streams the shipped incision through the service into a live session on ``model_path``."""
    import subprocess
    import sys

    from cutkit.haptics.client import spawned_server
    from cutkit.io.model_h5 import read_model
    from cutkit.live import HapticsPoseSource
    from cutkit.simulate.live import run_live

    incision = ROOT / "sample_volumes" / "incision.csv"
    model = read_model(model_path)
    views = []
    if window:
        import pyvista as pv

        from cutkit.live.window import WindowView

        pv.OFF_SCREEN = True
        views.append(WindowView(off_screen=True, window_size=(1024, 768)))
    out = Path(__import__("tempfile").mkdtemp(prefix="cutkit-live-bench-"))
    with spawned_server("--priority", priority) as (host, port, _):
        source = HapticsPoseSource(host, port)
        plays = []

        def start_device():
            cmd = [sys.executable, "-m", "cutkit.cli.main", "haptics", "play", str(incision), "--host", host,
                   "--port", str(port), "--json", "--priority", priority]
            plays.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))

        try:
            s = run_live(model, source, views, out, max_seconds=120, until_idle_s=2.0, on_start=start_device)
        finally:
            source.close()
            for v in views:
                v.close()
        device = json.loads(plays[0].communicate(timeout=60)[0]) if plays else {}
    live = s["live"]
    lat = live.get("latency_ms") or {}
    return {"model": str(model_path), "tets": s["tets_initial"], "cut_tets": s["cut_tets"],
            "opening_mean_mm": s["cut_opening_mm"]["final_mean"], "haptic_hz": live["haptic_hz"],
            "haptic_period_p99_ms": live.get("period_p99_ms"), "haptic_periods_over_2ms": live.get("periods_over_2ms"),
            "fps": live["fps"], "relax_passes_per_s": live["relax_passes_per_s"],
            "relax_steps_per_s": live["relax_steps_per_s"], "latency_p50_ms": lat.get("p50"),
            "latency_p95_ms": lat.get("p95"), "geometry_updates_skipped": live.get("geometry_updates_skipped"),
            "device_rate_hz": device.get("rate_hz"), "window": window,
            "recording": str(out)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=80000)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--priority", choices=["normal", "high", "realtime"], default="realtime")
    ap.add_argument("--session", metavar="MODEL", help="Also a live session on this model (the demo knee: "
                    "cutkit-demo/knee.h5) driven by `cutkit haptics play`, drawn off screen.")
    ap.add_argument("--no-window", action="store_true", help="The session without the window.")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    result = {"machine": platform.machine(), "python": platform.python_version(),
              "window": window_rate(args.triangles, args.frames), "play": play_rate(args.seconds, args.priority)}
    if args.session:
        result["session"] = session_rate(args.session, args.priority, not args.no_window)
    if args.json:
        print(json.dumps(result))
    else:
        for part in [p for p in ("window", "play", "session") if p in result]:
            for k, v in result[part].items():
                print(f"{part + '.' + k:32s} {v:.4g}" if isinstance(v, float) else f"{part + '.' + k:32s} {v}")


if __name__ == "__main__":
    main()
