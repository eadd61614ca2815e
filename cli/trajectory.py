"""``cutkit trajectory``: write the trajectory file of a straight or arc-shaped incision."""

import click


@click.command(name="trajectory")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Trajectory CSV to write.")
@click.option("--start", required=True, metavar="X,Y,Z", help="Skin point where the incision starts, mm.")
@click.option("--end", required=True, metavar="X,Y,Z", help="Skin point where it ends, mm.")
@click.option("--model", type=click.Path(dir_okay=False),
              help="Move START and END onto this model's surface and take the inward direction from it.")
@click.option("--inward", metavar="X,Y,Z", help="Direction into the tissue (default: from --model).")
@click.option("--arc-height", default=0.0, show_default=True, type=float,
              help="Sideways bulge of the path at its middle, mm (0: straight).")
@click.option("--depth", default=5.0, show_default=True, type=float, help="Tip depth below the skin, mm.")
@click.option("--approach", default=3.0, show_default=True, type=float,
              help="Start this far outside the skin along the blade, mm.")
@click.option("--blade-angle", default=0.0, show_default=True, type=float,
              help="Tilt of the blade from the skin normal in the cutting plane, degrees (+: tip leads).")
@click.option("--speed", default=20.0, show_default=True, type=float, help="Cutting speed along the path, mm/s.")
@click.option("--press-time", default=0.3, show_default=True, type=float, help="Time to press the blade in, s.")
@click.option("--rate", default=100.0, show_default=True, type=float, help="Rows per second.")
@click.option("--tremor-amplitude", default=0.0, show_default=True, type=float,
              help="Hand tremor across the path, mm (0: none).")
@click.option("--tremor-frequency", default=10.0, show_default=True, type=float, help="Tremor frequency, Hz.")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the tremor.")
def command(output, start, end, model, inward, arc_height, depth, approach, blade_angle, speed, press_time, rate,
            tremor_amplitude, tremor_frequency, seed):
    """Write the trajectory of an incision from START to END (see docs/trajectory-format.md)."""
    import json

    from cutkit.cli._ui import parse_vec3, say
    from cutkit.cutting.incision import Incision, incision
    from cutkit.cutting.trajectory import write_trajectory

    params = Incision(start=parse_vec3(start, "--start"), end=parse_vec3(end, "--end"),
                      inward=parse_vec3(inward, "--inward"), arc_height=arc_height, depth=depth,
                      approach=approach, blade_angle=blade_angle, speed=speed, press_time=press_time, rate=rate,
                      tremor_amplitude=tremor_amplitude, tremor_frequency=tremor_frequency, seed=seed)
    params.check("incision")
    tet_model = None
    if model is not None:
        from cutkit.io.model_h5 import read_model

        tet_model = read_model(model)
    traj = incision(params, tet_model)
    comment = "cutkit trajectory: " + json.dumps(params.to_dict(), separators=(",", ":"))
    if model is not None:
        comment += f"\nonto the surface of {model}"
    write_trajectory(output, traj, comment=comment)
    length = float(sum(((traj.tip[1:] - traj.tip[:-1]) ** 2).sum(axis=1) ** 0.5))
    say(f"{output}: {len(traj)} rows over {traj.t[-1]:.2f} s, tip path {length:.1f} mm; "
        f"entry at {', '.join(f'{v:.2f}' for v in traj.tip[0] + params.approach * traj.a[0])} mm")
    return 0
