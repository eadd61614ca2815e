"""``cutkit demo``: build the knee phantom and cut it along the shipped incision."""

import click

from cutkit.cli._ui import overwrite_option, solver_option


@click.command(name="demo")
@click.option("-o", "--output", "out_dir", default="cutkit-demo", show_default=True,
              type=click.Path(file_okay=False),
              help="Output folder (the model, the simulation, pictures). Running the demo again into its own "
                   "folder replaces the earlier run's outputs and reuses the built model; a folder holding "
                   "other files is refused without --overwrite.")
@click.option("--fps", default=10.0, show_default=True, type=float,
              help="Frames per simulated second, as in `cutkit simulate` (output only: the same simulation "
                   "at any rate).")
@overwrite_option
@click.option("--no-png", is_flag=True, help="Skip the pictures.")
@click.option("--movie", is_flag=True, help="Also a movie of the cut, OUT/cut.mp4.")
@click.option("--material-model", type=click.Choice(["neohookean", "springs"]), default=None,
              help="Tissue model [default: the recipe's, neohookean].")
@solver_option
def command(out_dir, fps, overwrite, no_png, movie, material_model, solver):
    """Build pipelines/knee.toml (reused when unchanged), cut sample_volumes/incision.csv, take pictures."""
    import time

    from cutkit.cli._ui import folder_guard
    from cutkit.cli.simulate import _check_flags
    from cutkit.io.atomic import clear_outputs
    from cutkit.demo import demo_inputs, demo_outputs
    from cutkit.cli._ui import note
    from cutkit.demo.warmup import kernels_compiled, start_background

    t0 = time.perf_counter()
    _check_flags(fps=fps)
    _, trajectory = demo_inputs()
    # the earlier run's outputs go (its built model stays, to be reused): nothing of two runs mixes
    clear_outputs(demo_outputs(out_dir, overwrite))
    if kernels_compiled() is False:
        note("compiling the numba kernels (first run only: several minutes on two cores; later runs load "
             "them from the cache)")
    # a second process compiles the decimation and simulation kernels while this one builds
    warm = start_background()
    try:
        with folder_guard(out_dir):
            _run(out_dir, fps, no_png, movie, trajectory, warm, t0, material_model, solver)
    finally:
        if warm is not None and warm.poll() is None:
            warm.terminate()
            warm.wait()


def _run(out_dir, fps, no_png, movie, trajectory, warm, t0, material_model=None, solver=None):
    import time

    from cutkit.build import STAGES
    from cutkit.cli._ui import console, progress, say, stage_reporter
    from cutkit.cli.simulate import render_with_progress, report, run_with_progress
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions
    from cutkit.demo import build_or_reuse

    with progress() as bar:
        task = bar.add_task("build-model", total=len(STAGES))
        model_path, reused, _ = build_or_reuse(out_dir, on_stage=stage_reporter(bar, task))
        bar.update(task, completed=len(STAGES), description="build-model: " + ("reused" if reused else "done"))
    if warm is not None and warm.poll() is None:
        from cutkit.simulate.warmup import warm_up_extras

        with progress() as bar:  # this process's share of the run's kernels, then those the second one compiles
            bar.add_task("compiling kernels (first run only)", total=None)
            warm_up_extras()
            warm.wait()
    model = read_model(model_path)
    say(f"model {model_path}: {model.tets.shape[0]} tets, {model.points.shape[0]} nodes"
        + (" (inputs unchanged, build reused)" if reused else ""))
    opt = SimulateOptions(fps=fps, png=False, material_model=material_model, solver=solver)
    summary = run_with_progress(model, read_trajectory(trajectory), out_dir, opt, model_path=str(model_path))
    render_with_progress(summary, out_dir, not no_png, movie)
    report(console, summary, out_dir)
    say(f"demo finished in {time.perf_counter() - t0:.0f} s")
