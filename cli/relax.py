"""``cutkit relax``: settle a model under its prestress, boundary conditions and gravity."""

import click

from cutkit.cli._ui import overwrite_option


@click.command(name="relax")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--seconds", required=True, type=float, help="Simulated time, s.")
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output folder (frames/NNNN.vtu and relax.pvd).")
@overwrite_option
@click.option("--fps", default=30.0, show_default=True, type=float, help="Frames per simulated second.")
@click.option("--gravity", default="0,0,0", show_default=True,
              help="Gravity vector in m/s^2, e.g. 0,0,-9.81.")
@click.option("--dt", "dt0", default=None, type=float,
              help="Finest time step, s (default: the explicit stability limit of the model).")
@click.option("--lists", "n_lists", default=6, show_default=True, type=int,
              help="Number of node lists (steps dt, 2 dt, ..., 2^(lists-1) dt).")
def command(model, seconds, out_dir, overwrite, fps, gravity, dt0, n_lists):
    """Relax MODEL for SECONDS of simulated time and write a .vtu series."""
    import numpy as np

    from cutkit.cli._ui import folder_guard, parse_vec3, progress, say
    from cutkit.io.atomic import check_output_folder, clear_outputs
    from cutkit.errors import InputError
    from cutkit.io.model_h5 import read_model
    from cutkit.relax.run import settle
    from cutkit.simulate.run import preflight

    for flag, value in (("--seconds", seconds), ("--fps", fps), ("--dt", dt0)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise InputError(f"{flag} must be a positive number, got {value}")
    if not 1 <= n_lists <= 30:
        raise InputError(f"--lists must lie in 1..30, got {n_lists}")
    earlier = check_output_folder(out_dir, "relax", overwrite, inputs=(model,))
    g = np.asarray(parse_vec3(gravity, "--gravity"), np.float64) * 1000.0  # m/s^2 -> mm/s^2
    tet_model = read_model(model)
    preflight(tet_model, str(model), memory=False)  # mesh and materials, before the folder
    clear_outputs(earlier)
    with folder_guard(out_dir), progress() as bar:
        task = bar.add_task("relaxing", total=seconds)

        def report(t, total):
            bar.update(task, completed=t)

        summary = settle(tet_model, seconds, out_dir, fps=fps, gravity_mm_s2=g, dt0=dt0, n_lists=n_lists,
                         progress=report)
    say(
        f"{summary['frames']} frames, dt0 {summary['dt0']:.3g} s, {summary['node_updates']} node updates, "
        f"max displacement {summary['max_displacement']:.4g} mm -> {out_dir}/relax.pvd"
    )
