"""``cutkit demo``: build the knee phantom and cut it along the shipped incision."""

import click


@click.command(name="demo")
@click.option("-o", "--output", "out_dir", default="cutkit-demo", show_default=True,
              type=click.Path(file_okay=False), help="Output folder (the model, the simulation, pictures).")
@click.option("--fps", default=10.0, show_default=True, type=float, help="Frames per simulated second.")
@click.option("--no-png", is_flag=True, help="Skip the pictures.")
@click.option("--movie", is_flag=True, help="Also a movie of the cut, OUT/cut.mp4.")
@click.option("--material-model", type=click.Choice(["neohookean", "springs"]), default=None,
              help="Tissue model [default: the recipe's, neohookean].")
@click.option("--solver", type=click.Choice(["newton", "vbd"]), default=None,
              help="How the element model's relaxation steps are solved: projected Newton or vertex block "
                   "descent [default: vbd].")
def command(out_dir, fps, no_png, movie, material_model, solver):
    """Build pipelines/knee.toml (reused when unchanged), cut sample_volumes/incision.csv, take pictures."""
    import time

    from cutkit.io.atomic import check_writable
    from cutkit.simulate.demo import demo_inputs
    from cutkit.simulate.warmup import start_background

    t0 = time.perf_counter()
    _, trajectory = demo_inputs()
    check_writable(out_dir, folder=True)
    # a second process compiles the decimation and simulation kernels while this one builds
    warm = start_background()
    try:
        _run(out_dir, fps, no_png, movie, trajectory, warm, t0, material_model, solver)
    finally:
        if warm is not None and warm.poll() is None:
            warm.terminate()
            warm.wait()


def _run(out_dir, fps, no_png, movie, trajectory, warm, t0, material_model=None, solver=None):
    import time

    from cutkit.build import STAGES
    from cutkit.cli._ui import console, progress, stage_reporter
    from cutkit.cli.simulate import render_with_progress, report, run_with_progress
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions
    from cutkit.simulate.demo import build_or_reuse

    with progress() as bar:
        task = bar.add_task("build-model", total=len(STAGES))
        model_path, reused, _ = build_or_reuse(out_dir, on_stage=stage_reporter(bar, task))
        bar.update(task, completed=len(STAGES), description="build-model: " + ("reused" if reused else "done"))
    if warm is not None:
        warm.wait()
    model = read_model(model_path)
    console.print(f"model {model_path}: {model.tets.shape[0]} tets, {model.points.shape[0]} nodes"
                  + (" (inputs unchanged, build reused)" if reused else ""))
    opt = SimulateOptions(fps=fps, png=False, material_model=material_model, solver=solver)
    summary = run_with_progress(model, read_trajectory(trajectory), out_dir, opt, model_path=str(model_path))
    render_with_progress(summary, out_dir, not no_png, movie)
    report(console, summary, out_dir)
    console.print(f"demo finished in {time.perf_counter() - t0:.0f} s")
