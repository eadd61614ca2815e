"""``cutkit decimate``: progressive decimation of a model, or extraction of a recorded level."""

import click


@click.command(name="decimate")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output model file.")
@click.option("--target-tets", type=int, default=None, help="Stop at this many tets.")
@click.option("--ratio", type=float, default=None, help="Fraction of the tets to keep, in (0, 1] (0.1 = ten times fewer).")
@click.option("--surface-tolerance", "tolerance", type=float, default=None,
              help="How far boundary and tissue interfaces may move, mm [default: one voxel, the median shortest tet edge].")
@click.option("--min-dihedral", type=float, default=10.0, show_default=True,
              help="Smallest dihedral angle a collapse may create, degrees.")
@click.option("--level", type=int, default=None,
              help="Instead of decimating, extract level K (K collapses) of the model's progressive record.")
@click.option("--optimize", "optimizer", type=click.Choice(["netgen"]), default=None,
              help="Then try gmsh's Netgen optimiser; kept only if it raises the minimum dihedral angle "
                   "with the boundary, the interfaces and the node data unchanged (docs/decimation.md).")
@click.option("--no-record", is_flag=True,
              help="Leave the progressive record out of the output (a model of about a tenth of the size; "
                   "no --level later).")
def command(model, output, target_tets, ratio, tolerance, min_dihedral, level, optimizer, no_record):
    """Decimate MODEL by half-edge collapses (paper section 7.1), interior edges first.

    The collapses are recorded in the output (extra/progressive, compressed), so any
    coarser or finer level can be extracted later with --level (--no-record leaves it out).
    """
    import math
    import time

    from cutkit.cli._ui import check_model_output
    from cutkit.io.atomic import check_writable
    from cutkit.cli._ui import console, progress, say, table, warn
    from cutkit.decimate import decimate, extract_level, n_levels, quality_summary
    from cutkit.errors import InputError
    from cutkit.io.model_h5 import read_model, write_model

    if level is not None and (target_tets is not None or ratio is not None):
        raise InputError("--level extracts a recorded level; it cannot be combined with --target-tets or --ratio")
    if level is None and (target_tets is None) == (ratio is None):
        raise InputError("give exactly one of --target-tets or --ratio (or --level K)")
    # the numbers first, with the flags' names, before any progress display
    if target_tets is not None and target_tets < 1:
        raise InputError(f"--target-tets must be a whole number >= 1, got {target_tets}")
    if ratio is not None and not (0.0 < ratio <= 1.0):
        raise InputError(f"--ratio must be the fraction of tets to keep, in (0, 1], got {ratio:g}")
    if not (0.0 <= min_dihedral < 70.0):
        raise InputError(f"--min-dihedral must lie in [0, 70) degrees, got {min_dihedral:g}")
    if tolerance is not None and not (math.isfinite(tolerance) and tolerance >= 0.0):
        raise InputError(f"--surface-tolerance must be a number of mm >= 0, got {tolerance:g}")
    check_model_output(output)
    check_writable(output)
    src = read_model(model)
    before = quality_summary(src.points, src.tets, min_dihedral)
    t0 = time.perf_counter()
    if level is not None:
        out = extract_level(src, level)
        what = f"level {level} of {n_levels(src)}"
    else:
        with progress() as bar:
            task = bar.add_task("decimating", total=None)

            def report(done, total):
                bar.update(task, completed=done, total=max(total, 1))

            out = decimate(src, target_tets=target_tets, ratio=ratio, surface_tolerance_mm=tolerance,
                           min_dihedral_deg=min_dihedral, progress=report)
        prov = out.provenance["decimate"]
        what = f"{prov['collapses']} collapses (level {prov['level']})"
    seconds = time.perf_counter() - t0
    opt = None
    if optimizer is not None:
        from cutkit.decimate.optimize import optimize

        out, opt = optimize(out, optimizer)
    after = quality_summary(out.points, out.tets, min_dihedral)
    if no_record:
        from cutkit.decimate import RECORD

        out.extra.pop(RECORD, None)
    write_model(output, out)
    rows = [
        ["tets", src.n_tets, out.n_tets],
        ["nodes", src.n_points, out.n_points],
        ["min dihedral (deg)", f"{before['min_dihedral_deg']:.2f}", f"{after['min_dihedral_deg']:.2f}"],
        [f"tets below {min_dihedral:g} deg", f"{100 * before['fraction_below']:.2f}%", f"{100 * after['fraction_below']:.2f}%"],
    ]
    console.print(table(f"{what} in {seconds:.2f} s -> {output}", ["", "input", "output"], rows))
    if opt is not None:
        verdict = "accepted" if opt["accepted"] else "rejected"
        say(f"{optimizer} optimiser ({opt['seconds']:.2f} s): min dihedral {opt['min_dihedral_before_deg']:.2f} -> "
            f"{opt['min_dihedral_after_deg']:.2f} deg, {opt['tets_before']} -> {opt['tets_after']} tets: "
            f"{verdict} ({opt['reason']})")
    if level is None and out.n_tets > out.provenance["decimate"]["target_tets"]:
        warn(f"no legal collapse left at {out.n_tets} tets (target {out.provenance['decimate']['target_tets']})")
