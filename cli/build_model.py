"""``cutkit build-model``: volume -> segmentation -> mesh -> materials -> texture -> model.h5."""

import click


@click.command(name="build-model")
@click.argument("volume", required=False, type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output model file (.h5).")
@click.option("--recipe", "recipe_path", type=click.Path(dir_okay=False), help="TOML recipe (pipelines/*.toml).")
@click.option("--threshold", help="LOW[:HIGH] intensity threshold (overrides the recipe).")
@click.option("--channel", help="Colour channel of an RGB volume to threshold (red, green, blue).")
@click.option("--otsu", is_flag=True, help="Threshold at Otsu's value (blue channel: keep the dark side).")
@click.option("--labels", "labels_path", type=click.Path(),
              help="Use this label map as the segmentation (smoothed and resampled only when asked). "
                   "A VOLUME that is itself a label map (integers, at most 32 values in 0..255) needs no flag.")
@click.option("--voxel-size", type=float, help="Resample to this isotropic voxel size, mm.")
@click.option("--smooth", type=float, help="Gaussian smoothing sigma, mm.")
@click.option("--spacing", help="SX,SY,SZ voxel spacing in mm for formats without one (.npy).")
@click.option("--ratio", type=float,
              help="Decimation ratio of tets kept (overrides the recipe). Without --ratio or a recipe's "
                   "[decimate] table there is no decimation: every isovolume tet is kept.")
@click.option("--no-decimate", is_flag=True, help="Skip the decimation stage (even where the recipe has one).")
@click.option("--keep-record", is_flag=True,
              help="Keep the decimation's progressive record (the finest mesh and its collapses, for "
                   "`cutkit decimate --level`); about ten times the model's own size, so off by default.")
@click.option("--clean", "clean", flag_value=True, default=None,
              help="Morphological opening and closing of a thresholded mask (off by default: it erases "
                   "structures thinner than three voxels).")
@click.option("--no-clean", "clean", flag_value=False,
              help="Skip all clean-up: opening/closing, largest component and hole filling.")
@click.option("--texture", "texture_path", type=click.Path(), help="Texture volume (defaults to the recipe's, if any).")
def command(volume, output, recipe_path, threshold, channel, otsu, labels_path, voxel_size, smooth, spacing, ratio,
            no_decimate, keep_record, clean, texture_path):
    """Build a cuttable model from VOLUME (or the recipe's volume).

    Without a recipe: no decimation (give --ratio), no materials named
    (each label gets the generic soft tissue), no boundary condition.
    A model above 1,000,000 tets is warned about with the memory and time
    `cutkit simulate` would take."""
    import numpy as np

    from cutkit.io.atomic import check_writable
    from cutkit.build import STAGES, run_build
    from cutkit.cli._ui import (check_model_output, console, note, parse_vec3, progress, say, stage_reporter,
                                table, warn, warn_missing_geometry)
    from cutkit.errors import InputError
    from cutkit.io.model_h5 import write_model
    from cutkit.recipe import load_recipe, validate_recipe
    from cutkit.segment import check_sizes, cleanup_warning

    check_sizes(smooth, voxel_size, names=("--smooth", "--voxel-size"))
    rules = [flag for flag, given in (("--threshold", threshold is not None), ("--otsu", otsu),
                                      ("--channel", channel is not None)) if given]
    if labels_path is not None and rules:
        raise InputError(f"--labels uses the label map as the segmentation; it cannot be combined with {rules[0]}")
    if threshold is not None and otsu:
        raise InputError("--threshold and --otsu are two thresholds; give one")
    check_model_output(output)
    check_writable(output)
    spacing = parse_vec3(spacing, "--spacing")

    recipe = load_recipe(recipe_path) if recipe_path else {"_path": None, "_sha256": None}
    seg = dict(recipe.get("segment", {}))
    if threshold is not None:
        seg["threshold"] = _parse_threshold(threshold)
        seg.pop("labels", None)
        seg.pop("otsu", None)
    if otsu:
        seg["otsu"] = True
        seg.pop("labels", None)
        seg.pop("threshold", None)
    if labels_path is not None:
        for key in ("threshold", "otsu", "channel", "labels"):
            seg.pop(key, None)
    if clean is not None:
        seg["clean"] = clean
        if not clean:
            seg["largest_component"] = seg["fill_holes"] = False
    if channel is not None:
        seg["channel"] = channel
    if voxel_size is not None:
        seg["voxel_size_mm"] = voxel_size
    if smooth is not None:
        seg["smooth_mm"] = smooth
    recipe["segment"] = seg
    if ratio is not None:
        recipe["decimate"] = {**recipe.get("decimate", {}), "ratio": ratio}
        recipe["decimate"].pop("target_tets", None)
    if no_decimate:
        recipe.pop("decimate", None)
    if texture_path is not None:
        recipe["texture"] = {**recipe.get("texture", {}), "volume": texture_path}
    validate_recipe({k: v for k, v in recipe.items() if not k.startswith("_")}, "command-line options")

    volume = volume or recipe.get("recipe", {}).get("volume")
    if volume is None:
        raise InputError("no input volume: give VOLUME or a recipe with [recipe] volume")
    from pathlib import Path

    if not Path(volume).exists():
        raise InputError(f"{volume}: no such file or folder")
    if labels_path is not None and not Path(labels_path).exists():
        raise InputError(f"{labels_path}: no such file or folder")
    warn_missing_geometry(volume, spacing)

    with progress() as bar:
        task = bar.add_task("build-model", total=len(STAGES))
        ctx = run_build(volume, recipe, on_stage=stage_reporter(bar, task), spacing=spacing, labels_path=labels_path,
                        keep_record=keep_record)
        bar.update(task, description="build-model: write")
        write_model(output, ctx.model)

    from cutkit.mesh.quality import min_dihedral_angles, signed_volumes

    m = ctx.model
    mind = min_dihedral_angles(m.points, m.tets)
    vols = signed_volumes(m.points, m.tets)
    seg_vols = ctx.report.get("segment", {}).get("labels")
    if seg_vols is None:
        sv = ctx.segmentation
        lab, cnt = np.unique(sv.data[sv.data > 0], return_counts=True)
        seg_vols = {int(a): float(c) * float(np.prod(sv.spacing)) for a, c in zip(lab, cnt)}
    mesh_total = float(vols.sum())
    seg_total = float(sum(seg_vols.values()))
    seg_report = ctx.report.get("segment", {})
    rows = [
        ["tets", m.n_tets],
        ["nodes", m.n_points],
        ["min dihedral [deg]", f"{mind.min():.2f}"],
        ["1st percentile dihedral [deg]", f"{np.percentile(mind, 1):.2f}"],
    ]
    if "cleanup_change_percent" in seg_report:
        before = seg_report["voxels_selected"] * seg_report["voxel_mm3"]
        rows.append(["clean-up change", f"{seg_report['cleanup_change_percent']:+.2f} % "
                                        f"({seg_total:.0f} vs {before:.0f} mm^3 segmented)"])
    rows.append(["mesh vs segmentation", f"{100 * (mesh_total - seg_total) / seg_total:+.2f} % "
                                         f"({mesh_total:.0f} vs {seg_total:.0f} mm^3)"])
    tex = ctx.report.get("texture", {})
    if "residual_after_mm" in tex:
        rows.append(["registration residual [mm]", f"{tex['residual_before_mm']:.3f} -> {tex['residual_after_mm']:.3f}"])
    for name, figures in ctx.report.items():
        rows.append([f"time: {name} [s]", f"{figures['seconds']:.2f}"])
    console.print(table(f"build-model -> {output}", ["", "value"], rows))
    dec = recipe.get("decimate")
    if dec:
        what = f"ratio {dec['ratio']:g}" if dec.get("ratio") is not None else f"target {dec.get('target_tets')} tets"
        say(f"decimation: {what}, {ctx.report['isovolume'].get('tets', '?')} -> {m.n_tets} tets")
    else:
        say("decimation: none (" + ("--no-decimate" if no_decimate else "no --ratio and no recipe [decimate] table")
            + f"): all {m.n_tets} isovolume tets kept")
    warning = cleanup_warning(seg_report)
    if warning:
        warn(warning)
    for w in ctx.report.get("assign", {}).get("warnings", []):
        warn(w)
    size = size_warning(m.n_tets, m.n_points)
    if size:
        warn(size)
    if not recipe.get("boundary"):
        note("no boundary condition: nothing holds this model when it is simulated; add a "
             "[boundary] table (fixed_labels, fixed_regions) to a recipe and run `cutkit assign "
             f"{output} --recipe R.toml -o OUT.h5` (docs/recipes.md)")


#: Above this many tets build-model warns with the memory and time of `cutkit simulate`.
SIZE_WARN_TETS = 1_000_000


def size_warning(n_tets: int, n_points: int) -> str | None:
    """The warning of a model too large to simulate comfortably, or None."""
    from cutkit.simulate.run import SIMULATE_S_PER_TET_SECOND, available_memory_bytes, simulate_memory_bytes

    if n_tets <= SIZE_WARN_TETS:
        return None
    need = simulate_memory_bytes(n_tets, n_points)
    avail = available_memory_bytes()
    fits = "" if avail is None else f" ({avail / 2**30:.1f} GiB available now)"
    per_s = n_tets * SIMULATE_S_PER_TET_SECOND
    ratio = max(0.01, round(200_000 / n_tets, 2))
    return (f"{n_tets:,} tets (above {SIZE_WARN_TETS:,}): `cutkit simulate` would need about "
            f"{need / 2**30:.1f} GiB{fits} and about {per_s:.0f} s of wall time per simulated second on one "
            f"core; --ratio {ratio:g} keeps about 200,000 tets")


def _parse_threshold(text: str):
    from cutkit.errors import InputError

    parts = text.split(":")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 2:
        raise InputError(f"--threshold must be LOW or LOW:HIGH (got {text!r})")
    return values
