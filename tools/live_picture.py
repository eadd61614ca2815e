"""The picture of the default live view at mid-cut in docs/live.md, made again.

    .venv/bin/python tools/live_picture.py MODEL [--out docs/images/live.png] [--camera follow]

A live session (:func:`cutkit.simulate.live.run_live`) on MODEL (the demo
knee, ``cutkit demo -o DIR`` writes ``DIR/knee.h5``) replays the shipped
incision on the wall clock (at ``--speed``) into an off-screen
``WindowView`` with the window's default options; the frame drawn when the
blade has gone half the incision's length is saved.  Prints one JSON line:
the picture, the frame's time, tets cut, and the fraction of its pixels in
the cut surface's colour.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def mid_cut_distance(traj) -> tuple[np.ndarray, np.ndarray, float]:
    """Where the cut starts (the first pose at full depth), its direction and half its length, mm."""
    depth = (traj.tip - traj.tip[0]) @ traj.a[0]
    deep = np.flatnonzero(depth >= 0.95 * depth.max())
    start, end = traj.tip[deep[0]], traj.tip[deep[-1]]
    length = float(np.linalg.norm(end - start))
    return start, (end - start) / max(length, 1e-12), 0.5 * length


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model")
    ap.add_argument("--trajectory", default=str(ROOT / "sample_volumes" / "incision.csv"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "live.png"))
    ap.add_argument("--camera", default="follow")
    ap.add_argument("--speed", type=float, default=0.5, help="Trajectory seconds per wall second.")
    ap.add_argument("--size", type=int, nargs=2, default=(1024, 768))
    args = ap.parse_args()

    import pyvista as pv

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.live import TrajectoryPoseSource
    from cutkit.live.window import WindowView, cut_colour_fraction
    from cutkit.simulate.live import run_live

    pv.OFF_SCREEN = True
    traj = read_trajectory(args.trajectory)
    start, along, half = mid_cut_distance(traj)
    window = WindowView(off_screen=True, window_size=tuple(args.size), camera=args.camera)
    shot = {}

    def at_mid_cut(frame):
        if "path" in shot or frame.tip is None or frame.tets_cut == 0:
            return
        if float((frame.tip - start) @ along) >= half:
            image = window.screenshot(args.out)
            shot.update(path=args.out, t=frame.t, tets_cut=frame.tets_cut,
                        cut_pixels=cut_colour_fraction(image))

    try:
        run_live(read_model(args.model), TrajectoryPoseSource(traj, speed=args.speed), [window],
                 Path(tempfile.mkdtemp(prefix="cutkit-live-picture-")), max_seconds=120, idle_end_s=0.2,
                 on_frame=at_mid_cut)
    finally:
        window.close()
    print(json.dumps(shot))


if __name__ == "__main__":
    main()
