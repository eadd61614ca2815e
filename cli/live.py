"""``cutkit live``: cut a model by hand (haptic device, mouse, 3D Slicer) and see it in real time."""

import click


@click.command(name="live")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Recording folder: trajectory.csv, forces.csv, summary.json, model.h5.")
@click.option("--haptics", metavar="HOST:PORT", help="Poses from a device through a running `cutkit haptics serve`.")
@click.option("--trajectory", type=click.Path(dir_okay=False), help="Poses from a trajectory file, on the wall clock.")
@click.option("--speed", default=1.0, show_default=True, type=click.FloatRange(min=1e-3),
              help="Trajectory seconds per wall second (--trajectory).")
@click.option("--igtl", "igtl_port", type=click.IntRange(1, 65535), default=None,
              help="Poses from OpenIGTLink TRANSFORMs on this port (3D Slicer: 18944); the tissue goes back as POLYDATA.")
@click.option("--igtl-device", default="ScalpelToReference", show_default=True,
              help="Device name of the tool's TRANSFORM (--igtl).")
@click.option("--no-window", is_flag=True, help="No window (needs no display); without a pose option the mouse needs one.")
@click.option("--fps", default=30.0, show_default=True, type=click.FloatRange(min=1.0), help="Frames per second to the views.")
@click.option("--seconds", type=click.FloatRange(min=0.0), default=None, help="End after this many seconds.")
@click.option("--until-idle", type=click.FloatRange(min=0.0), default=None,
              help="End once the tissue has relaxed this many seconds of its own time past the last pose.")
@click.option("--geometry-rate", "geometry_rate_hz", default=50.0, show_default=True, type=float,
              help="Cut updates per second.")
@click.option("--blade-length", default=None, type=float, help="Blade length, mm [default: 20].")
@click.option("--material-model", type=click.Choice(["neohookean", "springs"]), default=None,
              help="Tissue model [default: what the model file names].")
@click.option("--solver", type=click.Choice(["newton", "vbd"]), default=None,
              help="How the element model's relaxation steps are solved: projected Newton or vertex block "
                   "descent [default: vbd].")
def command(model, out_dir, haptics, trajectory, speed, igtl_port, igtl_device, no_window, fps, seconds, until_idle,
            geometry_rate_hz, blade_length, material_model, solver):
    """Cut MODEL live; Ctrl-C (or closing the window) ends the session, its recording stays valid."""
    from cutkit.cli._ui import console
    from cutkit.errors import InputError
    from cutkit.io.atomic import check_writable
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions
    from cutkit.simulate.live import run_live

    if sum(x is not None for x in (haptics, trajectory, igtl_port)) > 1:
        raise InputError("give at most one of --haptics, --trajectory, --igtl")
    if no_window and haptics is None and trajectory is None and igtl_port is None:
        raise InputError("--no-window needs a pose source: --haptics, --trajectory or --igtl (the mouse needs the window)")
    opt = SimulateOptions(geometry_rate_hz=geometry_rate_hz, blade_length=blade_length,
                          material_model=material_model, frames=False, solver=solver)
    opt.check()
    check_writable(out_dir, folder=True)
    tet_model = read_model(model)
    source, views, closers = _open(haptics, trajectory, speed, igtl_port, igtl_device, no_window)
    try:
        summary = run_live(tet_model, source, views, out_dir, opt, max_seconds=seconds, fps=fps,
                           until_idle_s=until_idle, model_path=str(model), on_start=_started)
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


def _open(haptics, trajectory, speed, igtl_port, igtl_device, no_window):
    """The pose source, the views and what else to close."""
    views, closers = [], []
    mouse = None
    if haptics is not None:
        from cutkit.live import HapticsPoseSource
        from cutkit.simulate.blade import parse_host_port

        source = HapticsPoseSource(*parse_host_port(haptics))
    elif trajectory is not None:
        from cutkit.live import TrajectoryPoseSource

        source = TrajectoryPoseSource(trajectory, speed=speed)
    elif igtl_port is not None:
        from cutkit.live.igtl import IGTLEndpoint, IGTLPolyDataView, IGTLPoseSource

        endpoint = IGTLEndpoint(igtl_port)
        closers.append(endpoint)
        source = IGTLPoseSource(endpoint=endpoint, device_name=igtl_device)
        views.append(IGTLPolyDataView(endpoint=endpoint, max_rate_hz=15.0))
    else:
        from cutkit.live import MouseKeyboardPoseSource

        source = mouse = MouseKeyboardPoseSource()
    if not no_window:
        from cutkit.live.window import WindowView

        views.insert(0, WindowView(pose_source=mouse))
    return source, views, closers


def _report(console, summary, out_dir) -> None:
    from cutkit.cli._ui import print_uncut_note

    live = summary["live"]
    for w in summary["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {w}")
    lat = live.get("latency_ms") or {}
    console.print(f"{summary['cut_tets']} tets cut; cut opening {summary['cut_opening_mm']['final_mean']:.2f} mm mean; "
                  f"{live['wall_s']:.1f} s, haptics {live['haptic_hz']:.0f} Hz, {live['fps']:.0f} fps, "
                  f"relaxation {live['relax_passes_per_s']:.0f} passes/s"
                  + (f", pose-to-picture latency p50 {lat['p50']:.0f} ms p95 {lat['p95']:.0f} ms" if lat else ""))
    print_uncut_note(summary["edges_left_uncut"])
    console.print(f"recorded: {out_dir}/trajectory.csv (replay: cutkit simulate MODEL --trajectory "
                  f"{out_dir}/trajectory.csv -o OUT/), forces.csv, summary.json, model.h5")
