"""Benchmark of the live-session periphery: the window's drawing rate and the reference device's rate.

    .venv/bin/python benchmarks/live.py --json [--triangles 80000] [--frames 120] [--seconds 5]

* window: an off-screen ``WindowView`` draws a textured sphere of about
  ``--triangles`` boundary triangles with a cut surface, moving every frame
  (positions, normals and colours uploaded each frame, as in a session);
  reports frames per second (the issue asks >= 30) and the time of one
  ``show``.
* play: ``cutkit haptics play`` streams the shipped incision (``--loop``
  for ``--seconds``) into a spawned ``cutkit haptics serve`` while a
  ``HapticsPoseSource`` takes the forwarded poses; reports the device's
  achieved rate, its p99 period and the poses forwarded per second.
"""

from __future__ import annotations

import argparse
import json
import platform
import threading
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
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.haptics.client import spawned_server
    from cutkit.haptics.play import play_trajectory
    from cutkit.live import HapticsPoseSource

    traj = read_trajectory(ROOT / "sample_volumes" / "incision.csv")
    with spawned_server("--priority", priority) as (host, port, _):
        source = HapticsPoseSource(host, port)
        done = threading.Event()
        result = {}

        def run():
            result.update(play_trajectory(traj, host, port, loop=True, max_seconds=seconds))
            done.set()

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        polled = 0
        t_end = time.monotonic() + seconds + 30.0
        while not done.is_set() and time.monotonic() < t_end:
            polled += source.poll() is not None
            source.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), contact=False)
            time.sleep(0.002)
        thread.join(10)
        forwarded = source.poses_received
        source.close()
    return {"device_rate_hz": result.get("rate_hz"), "device_period_p99_ms": result.get("period_p99_ms"),
            "device_resyncs": result.get("resyncs"), "forwarded_per_s": forwarded / seconds,
            "session_polls_with_a_pose": polled}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=80000)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--priority", choices=["normal", "high", "realtime"], default="normal")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    result = {"machine": platform.machine(), "python": platform.python_version(),
              "window": window_rate(args.triangles, args.frames), "play": play_rate(args.seconds, args.priority)}
    if args.json:
        print(json.dumps(result))
    else:
        for part in ("window", "play"):
            for k, v in result[part].items():
                print(f"{part + '.' + k:32s} {v:.4g}" if isinstance(v, float) else f"{part + '.' + k:32s} {v}")


if __name__ == "__main__":
    main()
