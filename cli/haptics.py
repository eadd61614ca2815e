"""``cutkit haptics``: the 1 kHz haptic scalpel service, its benchmark client and a reference device."""

import click


@click.group(name="haptics")
def command():
    """The 1 kHz haptic scalpel service (serve), its benchmark client (bench) and a reference device (play)."""


@command.command(name="serve")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to bind (loopback by default).")
@click.option("--port", default=4711, show_default=True, type=click.IntRange(0, 65535),
              help="TCP port; 0 picks a free one (printed on start).")
@click.option("--model", "model_path", type=click.Path(dir_okay=False), default=None,
              help="Model file whose material sets the scalpel's default cut parameters.")
@click.option("--material", default="muscle", show_default=True,
              help="Material name (or label number) to take from --model.")
@click.option("--priority", type=click.Choice(["normal", "high", "realtime"]), default="high", show_default=True,
              help="Scheduling priority of the loop (high = nice -10, realtime = SCHED_FIFO); falls back if refused.")
@click.option("--scalpel", type=click.Choice(["paper", "fracture"]), default="paper", show_default=True,
              help="Force model: the paper's (section 6) or fracture (J_c from --model's material; the "
                   "simulation's material updates keep it; docs/scalpel-model.md).")
@click.option("-v", "--verbose", is_flag=True, help="Log every connection, not only rejected frames.")
def serve(host, port, model_path, material, priority, scalpel, verbose):
    """Serve the scalpel force model at 1 kHz until Ctrl-C or SIGTERM."""
    import logging

    from cutkit.haptics.priority import drop_priority, raise_priority
    from cutkit.haptics.server import HapticsServer, material_from_model
    from cutkit.scalpel import ScalpelParams

    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="cutkit haptics: %(levelname)s: %(message)s")
    params = ScalpelParams(model=scalpel)
    if model_path is not None:
        params = ScalpelParams.from_material(material_from_model(model_path, material), model=scalpel)
    server = HapticsServer(host, port, params)
    got = raise_priority(priority)
    h, p = server.address
    # one plain line, flushed: scripts and `bench --spawn` read the port from it
    click.echo(f"cutkit haptics: listening on {h}:{p}", nl=True)
    click.get_text_stream("stdout").flush()
    try:
        stats = server.serve(install_signals=True)
    finally:
        drop_priority()  # the report and the exit at normal priority
    click.echo(f"cutkit haptics: stopped after {stats['ticks']} ticks, {stats['resyncs']} resyncs, "
               f"{stats['connections']} connections, {stats['rejected']} rejected frames ({got} priority)")


@command.command(name="bench")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address of the running `cutkit haptics serve`.")
@click.option("--port", default=4711, show_default=True, type=click.IntRange(1, 65535),
              help="Port of the running `cutkit haptics serve` (ignored with --spawn).")
@click.option("--seconds", default=3.0, show_default=True, type=click.FloatRange(0.1, 3600),
              help="Length of the run, wall seconds.")
@click.option("--spawn", is_flag=True, help="Start a server subprocess on a free port for the run.")
@click.option("--priority", type=click.Choice(["normal", "high", "realtime"]), default="high", show_default=True,
              help="Scheduling priority of the device loop (and of a --spawn server).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def bench(host, port, seconds, spawn, priority, as_json):
    """Drive a 1 kHz device loop against a server and report rate, jitter and round trip."""
    import contextlib
    import json

    from cutkit.haptics.client import run_bench, spawned_server
    from cutkit.haptics.priority import drop_priority, raise_priority

    with contextlib.ExitStack() as stack:
        if spawn:
            host, port, _ = stack.enter_context(spawned_server("--priority", priority, host=host))
        got = raise_priority(priority)
        try:
            result = run_bench(host, port, seconds)
        finally:
            drop_priority()
    result.update(host=host, port=port, spawned=bool(spawn), client_priority=got)
    if as_json:
        click.echo(json.dumps(result))
        return
    from cutkit.cli._ui import console, table

    rows = [[k, f"{v:.4g}" if isinstance(v, float) else v] for k, v in result.items()]
    console.print(table("haptics bench", ["figure", "value"], rows))


@command.command(name="play")
@click.argument("trajectory", type=click.Path(dir_okay=False))
@click.option("--host", default="127.0.0.1", show_default=True, help="Address of the running `cutkit haptics serve`.")
@click.option("--port", default=4711, show_default=True, type=click.IntRange(1, 65535),
              help="Port of the running `cutkit haptics serve`.")
@click.option("--rate", default=1000.0, show_default=True, type=click.FloatRange(1.0, 10000.0),
              help="Poses per second.")
@click.option("--loop", is_flag=True, help="Start again after the last row, until Ctrl-C.")
@click.option("--priority", type=click.Choice(["normal", "high", "realtime"]), default="high", show_default=True,
              help="Scheduling priority of the device loop; falls back if refused.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def play(trajectory, host, port, rate, loop, priority, as_json):
    """Stream a trajectory's poses to a running server as a device, at --rate Hz (1 kHz)."""
    import json
    import signal
    import threading

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.haptics.play import play_trajectory
    from cutkit.haptics.priority import drop_priority, raise_priority

    traj = read_trajectory(trajectory)
    stop = threading.Event()
    old = signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        got = raise_priority(priority)
        result = play_trajectory(traj, host, port, rate_hz=rate, loop=loop, stop=stop)
    finally:
        drop_priority()  # the report and the exit at normal priority
        signal.signal(signal.SIGINT, old)
    result.update(trajectory=str(trajectory), host=host, port=port, priority=got)
    if as_json:
        click.echo(json.dumps(result))
        return
    from cutkit.cli._ui import console, table

    rows = [[k, f"{v:.4g}" if isinstance(v, float) else v] for k, v in result.items()]
    console.print(table("haptics play", ["figure", "value"], rows))
