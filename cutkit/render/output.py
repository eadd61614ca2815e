"""Pictures and a movie of an output folder (``cutkit render``, ``simulate --png/--movie``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from cutkit.errors import InputError
from cutkit.io.atomic import atomic_output, write_text_atomic
from cutkit.render.folder import Folder, read_folder
from cutkit.render.scene import camera_for, render_frame

#: Movie endings and how they are written.
MOVIE_SUFFIXES = (".mp4", ".gif")


def _title(folder: Folder, t: float, final: bool = False) -> str:
    s = folder.summary
    t0 = folder.frames[0][0]
    parts = [f"t = {t - t0:.2f} s"]
    state = folder.state_at(t)
    if state == "cutting" and folder.at_rest(t):
        state = "blade at rest"
    if state:
        parts.append(state)
    if folder.force.size:
        parts.append(f"hand force {folder.force_at(t):.2f} N")
    if final and s:
        parts.append(f"{s.get('cut_tets', 0)} tets cut")
        opening = s.get("cut_opening_mm", {}).get("final_mean")
        if opening is not None:
            parts.append(f"mean opening {opening:.2f} mm")
    return "   ".join(parts)


def _frame_image(folder: Folder, index: int, camera, size, final=False):
    t, frame = folder.frames[index]
    return render_frame(frame, folder.surface_at(t), path_done=folder.path_until(t), path_all=folder.path_tip,
                        camera=camera, title=_title(folder, t, final), size=size, label_names=folder.label_names)


def _save_png(path: Path, img: np.ndarray) -> None:
    import imageio.v3 as iio

    with atomic_output(path) as tmp:
        iio.imwrite(tmp, img, extension=".png")


def key_frames(folder: Folder) -> list[int]:
    """Frames worth a picture: half-way along the trajectory, its end, the last frame."""
    times = np.array([t for t, _ in folder.frames])
    t0 = times[0]
    t_end = float(times[-1])
    if len(folder.path_tip) > 1:
        # the trajectory ends where the tip stops moving (the hold keeps its last pose)
        moved = np.flatnonzero(np.any(np.abs(folder.path_tip - folder.path_tip[-1]) > 1e-9, axis=1))
        if moved.size:
            t_end = float(folder.path_t[min(moved[-1] + 1, len(folder.path_t) - 1)])
    wanted = [t0 + 0.5 * (t_end - t0), t_end, float(times[-1])]
    idx = []
    for w in wanted:
        i = int(np.argmin(np.abs(times - w)))
        if i not in idx:
            idx.append(i)
    return idx


def write_movie(path, frames: list[np.ndarray], fps: float) -> None:
    """Write ``frames`` ((h, w, 3) uint8, all one size) as an MP4 (H.264, imageio-ffmpeg) or an animated GIF."""
    import imageio.v2 as iio2

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MOVIE_SUFFIXES:
        raise InputError(f"{path}: a movie ends in {' or '.join(MOVIE_SUFFIXES)}")
    if not frames:
        raise InputError(f"{path}: no frame to write")
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401  (the writer's backend)
        except ImportError:
            raise InputError(f"{path}: MP4 needs the imageio-ffmpeg package; write a .gif instead") from None
        with atomic_output(path) as tmp:
            # even sizes for H.264; one key frame a second
            h, w = frames[0].shape[:2]
            with iio2.get_writer(tmp, format="FFMPEG", fps=fps, codec="libx264", quality=7, macro_block_size=2,
                                 pixelformat="yuv420p", ffmpeg_log_level="error") as writer:
                for f in frames:
                    writer.append_data(np.ascontiguousarray(f[: h - h % 2, : w - w % 2]))
    else:
        import imageio.v3 as iio

        with atomic_output(path) as tmp:
            iio.imwrite(tmp, np.stack(frames), extension=".gif", duration=1000.0 / fps, loop=0)


def render_output(out_dir, pictures: bool = True, views=("cut",), movie: str | None = None,
                  size=(1200, 900), movie_size=(960, 720), movie_fps: float | None = None,
                  progress: Callable[[int, int], None] | None = None) -> dict:
    """Render an output folder of ``cutkit simulate``.

    Parameters
    ----------
    out_dir : path-like
    pictures : bool
        ``pictures/NNNN_<view>.png`` of the key frames (:func:`key_frames`) in
        each of ``views`` (:data:`~cutkit.render.scene.VIEWS`).
    movie : str, optional
        File name (relative to ``out_dir``, or absolute) of a movie of every
        frame in the first view: ``.mp4`` or ``.gif``.
    movie_fps : float, optional
        Frames per second of the movie; default: the run's frame rate, so it
        plays in real time.
    progress : callable(done, total), optional

    Returns
    -------
    dict
        ``pictures`` (paths relative to ``out_dir``) and ``movie`` (or None).
        ``summary.json``, when present, gets the same two entries.
    """
    folder = read_folder(out_dir)
    out_dir = Path(out_dir)
    cameras = {v: camera_for(folder, v) for v in views}
    keys = key_frames(folder) if pictures else []
    total = len(keys) * len(views) + (len(folder.frames) if movie else 0)
    done = 0
    written = []
    for view in views:
        for i in keys:
            img = _frame_image(folder, i, cameras[view], size, final=i == len(folder.frames) - 1)
            rel = f"pictures/{i:04d}_{view}.png"
            _save_png(out_dir / rel, img)
            written.append(rel)
            done += 1
            if progress:
                progress(done, total)
    movie_rel = None
    if movie:
        camera = cameras[views[0]]
        images = []
        for i in range(len(folder.frames)):
            images.append(_frame_image(folder, i, camera, movie_size, final=i == len(folder.frames) - 1))
            done += 1
            if progress:
                progress(done, total)
        fps = movie_fps or folder.summary.get("options", {}).get("fps") or 10.0
        movie_path = Path(movie) if Path(movie).is_absolute() else out_dir / movie
        write_movie(movie_path, images, float(fps))
        movie_rel = str(movie_path.relative_to(out_dir)) if movie_path.is_relative_to(out_dir) else str(movie_path)
    result = {"pictures": written, "movie": movie_rel}
    summary_path = out_dir / "summary.json"
    if summary_path.is_file() and (written or movie_rel):
        summary = dict(folder.summary)
        summary["pictures"] = written
        if movie_rel:
            summary["movie"] = movie_rel
        write_text_atomic(summary_path, json.dumps(summary, indent=2, default=float) + "\n")
    return result
