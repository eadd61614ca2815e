"""``cutkit simulate``: cut and relax a model along a blade trajectory."""

import click

from cutkit.cli._ui import overwrite_option, solver_option


@click.command(name="simulate")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--trajectory", required=True, type=click.Path(dir_okay=False), help="Blade trajectory CSV.")
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output folder (frames/, cut.pvd, cut_surface.pvd, forces.csv, summary.json, model.h5).")
@click.option("--fps", default=10.0, show_default=True, type=float,
              help="Frames per simulated second, as in `cutkit demo`. Output only: the simulation is the same "
                   "at any rate; each frame of a large model costs disk and time (30 for a smooth movie).")
@overwrite_option
@click.option("--png", is_flag=True,
              help="Pictures of the cut half-way, at the trajectory's end and at the end (pictures/NNNN_cut.png); "
                   "`cutkit render OUT/` makes others.")
@click.option("--movie", is_flag=True, help="A movie of every frame, OUT/cut.mp4 (imageio-ffmpeg).")
@click.option("--realtime", is_flag=True, help="Pace to the wall clock and report the rate of each task.")
@click.option("--haptics", metavar="HOST:PORT", help="Use a running `cutkit haptics serve` for the force model.")
@click.option("--hold", "hold_s", default=0.5, show_default=True, type=float,
              help="Simulated seconds after the trajectory's end (the cut opens).")
@click.option("--geometry-rate", "geometry_rate_hz", default=50.0, show_default=True, type=float,
              help="Cut and relaxation updates per simulated second.")
@click.option("--blade-length", default=None, type=float, help="Blade length, mm [default: 20, the trajectory reader's; a trajectory file stores no blade size].")
@click.option("--material-model", type=click.Choice(["neohookean", "springs"]), default=None,
              help="Tissue model: stable neo-Hookean elements with the Poisson ratio of the materials table, "
                   "or the paper's springs [default: what the model file names, neohookean for most].")
@solver_option
@click.option("--rest-rtol", type=float, default=None,
              help="The tolerance over the force scale the hybrid's resting steps bring a tissue the blade has "
                   "left to [default: 1e-4]; under the blade they end at 3e-4, the first one after the blade left "
                   "at 1e-3 (each at least this) (docs/relaxation.md, Resting steps).")
@click.option("--element", type=click.Choice(["nh", "anp"]), default="nh", show_default=True,
              help="The element model's tetrahedron: stable neo-Hookean linear tets (nh) or the average nodal "
                   "pressure tetrahedron (anp), which does not lock near incompressibility; anp is solved by "
                   "newton.")
@click.option("--deviatoric-smoothing", type=float, default=None,
              help="With --element anp: the share of the deviatoric energy smoothed over the nodes, in [0, 1) "
                   "[default: 0.7, the share that meets the 5 % bound against quadratic tets; 0: plain ANP].")
@click.option("--volume-stiffness", default=0.0, show_default=True, type=float,
              help="Springs only: each tet resists a change of volume with bulk = this x E (0: springs only, "
                   "as in the paper; 0.3 leaves a tenth of the inverted tets on the demo knee, at about four "
                   "times the relaxation time).")
@click.option("--scalpel", type=click.Choice(["paper", "fracture"]), default="paper", show_default=True,
              help="Scalpel force model: the paper's (section 6: F_enter, cut friction) or fracture (the crack "
                   "advances when the blade pays the tissue's J_c per crack area; docs/scalpel-model.md). "
                   "With --haptics the service's own --scalpel decides.")
def command(model, trajectory, out_dir, fps, overwrite, png, movie, realtime, haptics, hold_s, geometry_rate_hz,
            blade_length, material_model, volume_stiffness, solver, rest_rtol, scalpel, element,
            deviatoric_smoothing):
    """Cut MODEL along TRAJECTORY with the scalpel force model and relax it; write frames and logs."""
    from cutkit.cli._ui import console, folder_guard
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.atomic import check_output_folder, clear_outputs
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions
    from cutkit.simulate.run import preflight

    _check_flags(fps=fps, hold=hold_s, geometry_rate=geometry_rate_hz, blade_length=blade_length,
                 volume_stiffness=volume_stiffness)
    opt = SimulateOptions(fps=fps, png=False, realtime=realtime, haptics=haptics, hold_s=hold_s,
                          geometry_rate_hz=geometry_rate_hz, blade_length=blade_length,
                          volume_stiffness=volume_stiffness, material_model=material_model, solver=solver,
                          rest_rtol=rest_rtol, scalpel=scalpel, element=element, deviatoric_smoothing=deviatoric_smoothing)
    opt.check()
    earlier = check_output_folder(out_dir, "simulate", overwrite, inputs=(model, trajectory))
    tet_model = read_model(model)
    traj = read_trajectory(trajectory)
    preflight(tet_model, str(model))
    clear_outputs(earlier)
    with folder_guard(out_dir):
        summary = run_with_progress(tet_model, traj, out_dir, opt, model_path=str(model))
        render_with_progress(summary, out_dir, png, movie)
    report(console, summary, out_dir)
    return 0


def render_with_progress(summary: dict, out_dir, png: bool, movie: bool) -> None:
    """Pictures and movie of the folder just written (:func:`cutkit.render.render_output`)."""
    if not (png or movie):
        return
    from cutkit.cli._ui import progress
    from cutkit.render import render_output

    with progress() as bar:
        task = bar.add_task("rendering", total=None)
        done = render_output(out_dir, pictures=png, movie="cut.mp4" if movie else None,
                             progress=lambda k, n: bar.update(task, completed=k, total=n))
    summary["pictures"] = done["pictures"]
    if done["movie"]:
        summary["movie"] = done["movie"]
    # summary.json was written before the pictures: it says what the folder holds now
    from pathlib import Path

    from cutkit.simulate.record import write_json

    summary.setdefault("options", {})["png"] = bool(done["pictures"])
    write_json(Path(out_dir) / "summary.json", summary)


def _check_flags(**values) -> None:
    """Check the numbers of the command line first, so that errors name the flags."""
    import numpy as np

    from cutkit.errors import InputError
    from cutkit.scalpel import HAPTIC_DT

    for name, v in values.items():
        flag = "--" + name.replace("_", "-")
        if v is None:
            continue
        if name in ("hold", "volume_stiffness"):
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"{flag} must be a number >= 0, got {v:g}")
        elif not (np.isfinite(v) and v > 0):
            raise InputError(f"{flag} must be a positive number, got {v:g}")
    if values.get("geometry_rate", 0.0) > 1.0 / HAPTIC_DT:
        raise InputError(f"--geometry-rate must be at most the haptic rate {1.0 / HAPTIC_DT:.0f} Hz, "
                         f"got {values['geometry_rate']:g}")


def states_line(states: list[str]) -> str:
    """The scalpel states a run went through, short: each state once, in order, and the number of changes."""
    seen = list(dict.fromkeys(states))
    changes = max(len(states) - 1, 0)
    return f"states {', '.join(seen)} ({changes} change{'s' if changes != 1 else ''}; every tick in forces.csv)"


def run_with_progress(tet_model, traj, out_dir, opt, model_path=None):
    """:func:`cutkit.simulate.simulate` under a rich progress bar."""
    from cutkit.cli._ui import progress
    from cutkit.simulate import simulate

    with progress() as bar:
        task = bar.add_task("simulating", total=1.0)

        def on_progress(t, total):
            bar.update(task, completed=t / total if total > 0 else 1.0,
                       description=f"simulating {t:.2f}/{total:.2f} s")

        return simulate(tet_model, traj, out_dir, opt, progress=on_progress, model_path=model_path)


def report(console, summary, out_dir) -> None:
    """Print the closing lines: warnings, counts, rates, what to open."""
    from cutkit.cli._ui import say, warn

    for w in summary["warnings"]:
        warn(w)
    t = summary["time_per_task_s"]
    say(
        f"{summary['cut_tets']} tets cut into {summary['new_tets']} "
        f"({summary['new_tets_per_cut_tet']:.1f} per cut tet); {states_line(summary['states'])}; "
        f"cut opening {summary['cut_opening_mm']['final_mean']:.2f} mm mean")
    say(
        f"{summary['simulated_s']:.2f} s simulated in {summary['wall_s']:.1f} s "
        f"(simulated/wall {summary['simulated_per_wall']:.2f}; relaxation {t['relaxation']:.1f} s, "
        f"cutting {t['collision_and_cut']:.1f} s, output {t['output']:.1f} s)")
    from cutkit.simulate.run import relax_steps_line

    line = relax_steps_line(summary["relax_steps"]) if "relax_steps" in summary else None
    if line:
        say(line)
    if "rates_hz" in summary:
        r = summary["rates_hz"]
        say(f"rates: haptics {r['haptics']:.0f} Hz, geometry {r['geometry_updates']:.0f} Hz, "
                      f"relaxation list passes {r['relaxation_list_passes']:.0f}/s, frames {r['frames']:.1f}/s")
    say(f"ParaView: open {out_dir}/cut.pvd (tissue) and {out_dir}/cut_surface.pvd (cut surface); "
                  f"forces in {out_dir}/forces.csv, summary in {out_dir}/summary.json")
    for p in summary["pictures"]:
        say(f"picture: {out_dir}/{p}")
    if summary.get("movie"):
        say(f"movie: {out_dir}/{summary['movie']}")
