"""``cutkit segment``: segment a volume into a uint8 label map."""

import click


def _parse_threshold(text):
    """``LOW[:HIGH]`` (either side may be empty) -> (low, high)."""
    from cutkit.errors import InputError

    if text is None:
        return None
    low, sep, high = text.partition(":")
    try:
        lo = float(low) if low.strip() else None
        hi = float(high) if sep and high.strip() else None
    except ValueError:
        lo = hi = None
        low = "bad"
    if (lo is None and hi is None) or (lo is not None and hi is not None and lo > hi) or low == "bad":
        raise InputError(f"--threshold must be LOW, LOW:HIGH or :HIGH with LOW <= HIGH (got {text!r})")
    return lo, hi


@click.command(name="segment")
@click.argument("volume_path", metavar="VOLUME", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Output label map (.nrrd, .nii.gz, .mha, .npz).")
@click.option("--threshold", default=None, metavar="LOW[:HIGH]", help="Keep LOW <= value <= HIGH (':HIGH' for below).")
@click.option("--channel", default=None, help="Colour channel of RGB data: red, green, blue (or r, g, b, 0..2).")
@click.option("--otsu", is_flag=True, help="Threshold at Otsu's value (blue channel: keep the dark side).")
@click.option("--labels", "labels_path", default=None, type=click.Path(), help="Use this label map as is.")
@click.option("--smooth", type=float, default=None, metavar="SIGMA_MM", help="Gaussian smoothing sigma in mm.")
@click.option("--voxel-size", type=float, default=None, metavar="MM", help="Resample to cubic voxels of this size.")
@click.option("--clean", "clean", flag_value=True, default=None,
              help="Morphological opening and closing (off by default: it erases structures thinner than "
                   "three voxels).")
@click.option("--no-clean", "clean", flag_value=False,
              help="Skip all clean-up: opening/closing, largest component and hole filling.")
@click.option("--spacing", default=None, metavar="SX,SY,SZ", help="Voxel size in mm (for .npy and TIFF input).")
def command(volume_path, output, threshold, channel, otsu, labels_path, smooth, voxel_size, clean, spacing):
    """Segment VOLUME by threshold, Otsu, a colour channel or a given label map (paper section 7.1).

    An integer VOLUME with at most 32 values in 0..255 and no rule given is taken as a label map.
    """
    import numpy as np

    from cutkit.cli._ui import console, parse_vec3, say, table, warn, warn_missing_geometry
    from cutkit.errors import InputError
    from cutkit.io.atomic import check_writable
    from cutkit.segment import check_sizes, cleanup_warning, looks_like_labels, segment
    from cutkit.volumes import read_volume, write_volume

    rng = _parse_threshold(threshold)
    check_sizes(smooth, voxel_size, names=("--smooth", "--voxel-size"))
    rules = [flag for flag, given in (("--threshold", rng is not None), ("--otsu", otsu),
                                      ("--channel", channel is not None)) if given]
    if labels_path is not None and rules:
        raise InputError(f"--labels uses the label map as the segmentation; it cannot be combined with {rules[0]}")
    if rng is not None and otsu:
        raise InputError("--threshold and --otsu are two thresholds; give one")
    check_writable(output)
    spacing = parse_vec3(spacing, "--spacing")
    volume = read_volume(volume_path, spacing=spacing)
    warn_missing_geometry(volume_path, spacing)
    labels = read_volume(labels_path) if labels_path else None
    if rng is None and not otsu and labels is None and channel is None and looks_like_labels(volume):
        labels = volume
    cleanup: dict = {}
    with console.status("segmenting ..."):
        seg = segment(
            volume,
            threshold=rng,
            channel=channel,
            otsu=otsu,
            labels=labels,
            smooth_sigma_mm=smooth,
            voxel_size_mm=voxel_size,
            clean=bool(clean),
            largest_component=clean is not False,
            fill_holes=clean is not False,
            report=cleanup,
        )
        write_volume(output, seg)
    voxel_mm3 = float(np.prod(seg.spacing))
    values, counts = np.unique(seg.data, return_counts=True)
    rows = [[int(v), int(c), f"{c * voxel_mm3:.1f}"] for v, c in zip(values, counts) if v != 0]
    console.print(table("segmentation", ["label", "voxels", "volume [mm^3]"], rows))
    sp = ", ".join(f"{s:g}" for s in seg.spacing)
    say(f"{seg.shape[0]} x {seg.shape[1]} x {seg.shape[2]} voxels of {sp} mm -> {output}")
    if cleanup.get("voxels_selected"):
        say(f"clean-up: {cleanup['voxels_selected']} voxels segmented, {cleanup['voxels_kept']} kept "
            f"({cleanup['cleanup_change_percent']:+.2f} %)")
    warning = cleanup_warning(cleanup)
    if warning:
        warn(warning)
