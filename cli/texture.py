"""``cutkit texture``: register a 3D texture volume and store texture coordinates."""

import click


@click.command(name="texture")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--volume", "volume_path", required=True, type=click.Path(), help="Texture volume (RGB or grey).")
@click.option("--segmentation", "seg_path", type=click.Path(), help="Label map the mesh was built from (registration target).")
@click.option("--register", "method", type=click.Choice(["none", "rigid", "affine"]), default=None,
              help="Align the texture to the mesh: rigid or affine ICP of the segmentation's surface onto the "
                   "mesh's boundary (needs --segmentation), or none (the texture's own coordinates) "
                   "[default: rigid with --segmentation, none without].")
@click.option("--max-voxels", type=int, default=None, help="Block-average larger texture volumes down to this size.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output model file.")
def command(model, volume_path, seg_path, method, max_voxels, output):
    """Give every node of MODEL coordinates into a 3D texture (paper section 7.2)."""
    from cutkit.cli._ui import check_model_output
    from cutkit.io.atomic import check_writable
    from cutkit.cli._ui import say, warn
    from cutkit.io.model_h5 import read_model, write_model
    from cutkit.texture import register_texture
    from cutkit.volumes import read_volume

    check_model_output(output)
    check_writable(output)
    if method is None:
        method = "rigid" if seg_path is not None else "none"
    if seg_path is None and method != "none":
        method_note = f"--register {method} needs --segmentation; registering with 'none'"
        warn(method_note)
        method = "none"
    kwargs = {"max_voxels": max_voxels} if max_voxels else {}
    seg = read_volume(seg_path) if seg_path else None
    out, rep = register_texture(read_model(model), read_volume(volume_path), segmentation=seg, method=method, **kwargs)
    write_model(output, out)
    if rep.method == "none":
        how = "not registered (texture used in place)"
    else:
        how = (f"registration {rep.method}: residual {rep.residual_before_mm:.3f} mm -> "
               f"{rep.residual_after_mm:.3f} mm in {rep.iterations} iterations")
    say(f"texture {rep.texture_shape} (downsampled x{rep.downsample_factor}); {how} -> {output}")
