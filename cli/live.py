"""``cutkit live``: cut a model by hand (haptic device, mouse, 3D Slicer) and see it in real time."""

import click

from cutkit.cli._ui import overwrite_option, solver_option


@click.command(name="live")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Recording folder: trajectory.csv, forces.csv, summary.json, model.h5.")
@overwrite_option
@click.option("--haptics", metavar="HOST:PORT", help="Poses from a device through a running `cutkit haptics serve`.")
@click.option("--trajectory", type=click.Path(dir_okay=False),
              help="Poses from a trajectory file, on the session's clock (--clock).")
@click.option("--speed", default=1.0, show_default=True, type=click.FloatRange(min=1e-3),
              help="Trajectory seconds per second of the session's clock (--trajectory).")
@click.option("--igtl", "igtl_port", type=click.IntRange(1, 65535), default=None,
              help="Poses from OpenIGTLink TRANSFORMs on this port (3D Slicer: 18944); the tissue goes back as POLYDATA.")
@click.option("--igtl-device", default="ScalpelToReference", show_default=True,
              help="Device name of the tool's TRANSFORM (--igtl).")
@click.option("--igtl-axis", default=None, help="Tool axis along the blade, handle to tip: x y z -x -y -z [default: -z].")
@click.option("--igtl-edge", default=None, help="Tool axis the sharp edge faces [default: x].")
@click.option("--igtl-frame", default=None, help="Frame of the tool's and Slicer's coordinates: RAS or LPS [default: RAS].")
@click.option("--igtl-registration", default=None, metavar="FILE",
              help="Model (LPS) <- tracker registration after the frame change: a 4x4 matrix, .npy or text.")
@click.option("--igtl-surface-rate", default=None, type=float, metavar="HZ",
              help="POLYDATA surfaces sent per second at most [default: 15].")
@click.option("--igtl-driver", default=None,
              help="Which client drives the blade when several send the tool: first (holds it until it "
                   "disconnects) or latest [default: first].")
@click.option("--camera", type=click.Choice(["follow", "model", "fixed"]), default="follow", show_default=True,
              help="The window's camera: follow the blade and the wound, the whole model, or fixed (moved "
                   "only with the mouse).")
@click.option("--drawing", type=click.Choice(["auto", "full", "fast"]), default="auto", show_default=True,
              help="How the window draws: full (anti-aliased, five lights), fast (one light at the camera, no "
                   "anti-aliasing), or auto: fast where OpenGL runs on the processor (e.g. Mesa's llvmpipe).")
@click.option("--no-window", is_flag=True, help="No window (needs no display); without a pose option the mouse needs one.")
@click.option("--fps", default=30.0, show_default=True, type=click.FloatRange(min=1.0), help="Frames per second to the views.")
@click.option("--seconds", type=click.FloatRange(min=0.0), default=None, help="End after this many seconds.")
@click.option("--clock", type=click.Choice(["wall", "stepped"]), default="wall", show_default=True,
              help="The session's clock: the wall, or stepped (--trajectory only): one haptic tick per loop pass, "
                   "each done whole, so the session cuts what `cutkit simulate` replaying its recording cuts.")
@click.option("--until-idle", type=click.FloatRange(min=0.0), default=None,
              help="End once the tissue has relaxed this many seconds of its own time past the last pose.")
@click.option("--geometry-rate", "geometry_rate_hz", default=50.0, show_default=True, type=float,
              help="Cut updates per second.")
@click.option("--blade-length", default=None, type=float, help="Blade length, mm [default: 20].")
@click.option("--material-model", type=click.Choice(["neohookean", "springs"]), default=None,
              help="Tissue model [default: what the model file names].")
@solver_option
def command(model, out_dir, overwrite, haptics, trajectory, speed, igtl_port, igtl_device, camera, drawing, no_window,
            fps, seconds, clock, until_idle, geometry_rate_hz, blade_length, material_model, solver, **igtl_opts):
    """Cut MODEL live; Ctrl-C (or closing the window) ends the session, its recording stays valid."""
    from cutkit.cli._ui import console
    from cutkit.errors import InputError
    from cutkit.cli._ui import folder_guard
    from cutkit.io.atomic import check_output_folder, clear_outputs
    from cutkit.simulate.run import preflight
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions
    from cutkit.simulate.live import run_live

    if sum(x is not None for x in (haptics, trajectory, igtl_port)) > 1:
        raise InputError("give at most one of --haptics, --trajectory, --igtl")
    if no_window and haptics is None and trajectory is None and igtl_port is None:
        raise InputError("--no-window needs a pose source: --haptics, --trajectory or --igtl (the mouse needs the window)")
    if clock == "stepped" and trajectory is None:
        raise InputError("--clock stepped needs --trajectory: a device, 3D Slicer and the mouse move on the wall clock")
    igtl = _igtl_options(igtl_port, **igtl_opts)
    opt = SimulateOptions(geometry_rate_hz=geometry_rate_hz, blade_length=blade_length,
                          material_model=material_model, frames=False, solver=solver)
    opt.check()
    earlier = check_output_folder(out_dir, "live", overwrite, inputs=(model, trajectory))
    tet_model = read_model(model)
    preflight(tet_model, str(model))
    clear_outputs(earlier)
    session_clock = None
    if clock == "stepped":
        from cutkit.simulate.clock import SteppedClock

        session_clock = SteppedClock()
    source, views, closers = _open(haptics, trajectory, speed, igtl_port, igtl_device, no_window, igtl,
                                   (camera, drawing), session_clock)
    try:
        with folder_guard(out_dir):
            summary = run_live(tet_model, source, views, out_dir, opt, max_seconds=seconds, fps=fps,
                               until_idle_s=until_idle, model_path=str(model), on_start=_started,
                               clock=session_clock)
    finally:
        source.close()
        for v in views:
            v.close()
        for c in closers:
            c.close()
    _report(console, summary, out_dir)
    return 0


def _started() -> None:
    # one plain line, flushed: scripts start the device once they read it
    click.echo("cutkit live: running", nl=True)
    click.get_text_stream("stdout").flush()


def _igtl_options(igtl_port, igtl_axis, igtl_edge, igtl_frame, igtl_registration, igtl_surface_rate, igtl_driver):
    """The --igtl-* options checked (one-line errors), as keyword arguments of the OpenIGTLink classes."""
    import math

    import numpy as np

    from cutkit.errors import InputError

    given = {"--igtl-axis": igtl_axis, "--igtl-edge": igtl_edge, "--igtl-frame": igtl_frame,
             "--igtl-registration": igtl_registration, "--igtl-surface-rate": igtl_surface_rate,
             "--igtl-driver": igtl_driver}
    if igtl_port is None:
        extra = [k for k, v in given.items() if v is not None]
        if extra:
            raise InputError(f"{', '.join(extra)} only work with --igtl PORT")
        return {}
    from cutkit.live.igtl import AXES, FRAMES, load_registration, pose_from_matrix
    from cutkit.live.igtl_server import DRIVER_RULES

    axis, edge = igtl_axis or "-z", igtl_edge or "x"
    for name, value in (("--igtl-axis", axis), ("--igtl-edge", edge)):
        if value.strip().lower() not in AXES:
            raise InputError(f"{name} must be one of {' '.join(AXES)}, got {value!r}")
    pose_from_matrix(np.eye(4), axis, edge)  # the two must be different axes
    frame = (igtl_frame or "RAS").upper()
    if frame not in FRAMES:
        raise InputError(f"--igtl-frame must be RAS or LPS, got {igtl_frame!r}")
    rate = 15.0 if igtl_surface_rate is None else igtl_surface_rate
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(f"--igtl-surface-rate must be a positive number of Hz, got {igtl_surface_rate}")
    driver = (igtl_driver or "first").lower()
    if driver not in DRIVER_RULES:
        raise InputError(f"--igtl-driver must be first or latest, got {igtl_driver!r}")
    registration = None if igtl_registration is None else load_registration(igtl_registration)
    return dict(axis=axis, edge=edge, frame=frame, registration=registration, rate=rate, driver=driver)


def _show_igtl_log() -> None:
    """Clients connecting, who drives the blade, dropped messages: one stderr line each."""
    import logging

    log = logging.getLogger("cutkit.live")
    if not log.handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("cutkit live: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)


def _open(haptics, trajectory, speed, igtl_port, igtl_device, no_window, igtl, window=("follow", "auto"),
          clock=None):
    """The pose source, the views and what else to close; a trajectory on ``clock`` when one is given."""
    views, closers = [], []
    mouse = None
    if haptics is not None:
        from cutkit.live import HapticsPoseSource
        from cutkit.simulate.blade import parse_host_port

        source = HapticsPoseSource(*parse_host_port(haptics))
    elif trajectory is not None:
        from cutkit.live import TrajectoryPoseSource

        source = TrajectoryPoseSource(trajectory, speed=speed, **({} if clock is None else {"clock": clock}))
    elif igtl_port is not None:
        from cutkit.live.igtl import IGTLEndpoint, IGTLPolyDataView, IGTLPoseSource

        _show_igtl_log()
        endpoint = IGTLEndpoint(igtl_port, driver=igtl["driver"])
        closers.append(endpoint)
        frame = dict(frame=igtl["frame"], registration=igtl["registration"])
        source = IGTLPoseSource(endpoint=endpoint, device_name=igtl_device, axis=igtl["axis"], edge=igtl["edge"],
                                **frame)
        views.append(IGTLPolyDataView(endpoint=endpoint, max_rate_hz=igtl["rate"], **frame))
    else:
        from cutkit.live import MouseKeyboardPoseSource

        source = mouse = MouseKeyboardPoseSource()
    if not no_window:
        from cutkit.live.window import WindowView

        camera, drawing = window
        views.insert(0, WindowView(pose_source=mouse, camera=camera, drawing=drawing))
    return source, views, closers


def _report(console, summary, out_dir) -> None:
    from cutkit.cli._ui import say, warn

    live = summary["live"]
    for w in summary["warnings"]:
        warn(w)
    lat = live.get("latency_ms") or {}
    say(f"{summary['cut_tets']} tets cut; cut opening {summary['cut_opening_mm']['final_mean']:.2f} mm mean; "
        f"{live['wall_s']:.1f} s, haptics {live['haptic_hz']:.0f} Hz, {live['fps']:.0f} fps, "
        f"relaxation {live['relax_passes_per_s']:.0f} passes/s"
        + (f", pose-to-picture latency p50 {lat['p50']:.0f} ms p95 {lat['p95']:.0f} ms" if lat else ""))
    from cutkit.simulate.run import relax_steps_line

    line = relax_steps_line(summary["relax_steps"]) if "relax_steps" in summary else None
    if line:
        say(line)
    say(f"recorded: {out_dir}/trajectory.csv (replay: cutkit simulate MODEL --trajectory "
                  f"{out_dir}/trajectory.csv -o OUT/), forces.csv, summary.json, model.h5")
