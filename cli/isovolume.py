"""``cutkit isovolume``: tetrahedralise a label map (or scalar field) with the marching isovolume."""

import click


@click.command(name="isovolume")
@click.argument("volume_path", metavar="LABELS_VOLUME", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output model file (.h5).")
@click.option("--level", type=float, default=0.5, show_default=True,
              help="Iso-level of a scalar field (a label map is always cut at 0.5, the edge midpoints).")
@click.option("--snap", type=float, default=None,
              help="Crossings closer than this fraction of an edge to a sample snap onto it [default: 0.15].")
@click.option("--label", "labels", type=int, multiple=True,
              help="Mesh only this tissue label (repeatable); a scalar field: the label its tets get.")
def command(volume_path, output, level, snap, labels):
    """Split every voxel cube of LABELS_VOLUME into six tetrahedra and clip them (paper section 7.1)."""
    import numpy as np

    from cutkit.cli._ui import check_model_output
    from cutkit.io.atomic import check_writable
    from cutkit.cli._ui import console, say, table
    from cutkit.io.model_h5 import write_model
    from cutkit.isovolume import SNAP_FRACTION, dihedral_summary, isovolume
    from cutkit.mesh.geometry import tet_volumes
    from cutkit.volumes import read_volume

    check_model_output(output)
    check_writable(output)
    volume = read_volume(volume_path)
    with console.status("marching isovolume ..."):
        model, stats = isovolume(
            volume,
            level=level,
            labels=list(labels) or None,
            snap=SNAP_FRACTION if snap is None else snap,
            return_stats=True,
        )
    write_model(output, model)

    tet_volume = tet_volumes(model.points, model.tets)
    voxel_mm3 = float(np.prod(volume.spacing))
    data = np.asarray(volume.data)
    rows = []
    for lab in np.unique(model.labels):
        mesh_mm3 = float(tet_volume[model.labels == lab].sum())
        if stats.mode == "labels":
            vox_mm3 = float(np.count_nonzero(data == lab)) * voxel_mm3
        else:
            vox_mm3 = float(np.count_nonzero(data >= level)) * voxel_mm3
        diff = 100.0 * (mesh_mm3 - vox_mm3) / vox_mm3 if vox_mm3 else float("nan")
        rows.append([int(lab), int(np.count_nonzero(model.labels == lab)), f"{mesh_mm3:.1f}", f"{vox_mm3:.1f}", f"{diff:+.2f}%"])
    console.print(table("volume per label", ["label", "tets", "mesh [mm^3]", "voxels [mm^3]", "difference"], rows))
    min_dih, p1_dih = dihedral_summary(model.points, model.tets)
    say(
        f"{model.n_tets} tets, {model.n_points} nodes ({stats.n_grid_nodes} samples, {stats.n_crossing_nodes} crossings, "
        f"{stats.n_centre_nodes} centres; {stats.n_snapped} samples snapped); "
        f"dihedral min {min_dih:.2f} deg, 1st percentile {p1_dih:.2f} deg -> {output}"
    )
