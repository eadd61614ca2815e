"""``cutkit cut``: cut a model kinematically along a blade trajectory."""

import click

from cutkit.cli._ui import overwrite_option


@click.command(name="cut")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--trajectory", required=True, type=click.Path(dir_okay=False), help="Blade trajectory CSV.")
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output folder (frames/NNNN.vtu, cut.pvd, model.h5).")
@overwrite_option
@click.option("--blade-length", default=None, type=float, help="Blade length, mm (default: the reader's).")
@click.option("--centre-nodes", is_flag=True, help="Split faces with the Fig. 2c centre node (more tets, 16-20 per cut tet).")
def command(model, trajectory, out_dir, overwrite, blade_length, centre_nodes):
    """Cut MODEL along the poses of a trajectory; write a .vtu series and the cut model."""
    import os

    import numpy as np

    from cutkit.cli._ui import (folder_guard, missed_message, note, print_crumbs_note, progress, say,
                                warn)
    from cutkit.io.atomic import check_output_folder, clear_outputs
    from cutkit.cutting import CutMesh, cut_step, cut_surface_faces, to_model
    from cutkit.cutting.contact import uncut_edges_line
    from cutkit.cutting.step import finish_stroke, rebase_if_left
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.errors import InputError
    from cutkit.io.model_h5 import read_model, write_model
    from cutkit.io.series import SeriesWriter
    from cutkit.mesh.quality import min_dihedral_angles

    if blade_length is not None and not (np.isfinite(blade_length) and blade_length > 0):
        raise InputError(f"--blade-length must be a positive number, got {blade_length}")
    earlier = check_output_folder(out_dir, "cut", overwrite, inputs=(model, trajectory))
    tet_model = read_model(model)
    kw = {} if blade_length is None else {"blade_length": blade_length}
    traj = read_trajectory(trajectory, **kw)
    cm = CutMesh.from_model(tet_model, blade_length=traj.blade_length, centre_nodes=centre_nodes)
    clear_outputs(earlier)

    def frame_data():
        on_cut = np.zeros(cm.n_points, np.uint8)
        on_cut[cut_surface_faces(cm).ravel()] = 1  # every stroke's
        m = to_model(cm, tet_model, point_data={"cut_surface_node": on_cut})  # no orphan node
        pd = {"new_node": m.point_data["new_node"], "cut_surface_node": m.point_data["cut_surface_node"]}
        if tet_model.texture is not None and m.texcoords is not None:
            pd["texture_rgb"] = np.asarray(tet_model.texture.sample_rgb(m.texcoords))
        return m, pd, {"new_tet": m.cell_data["new_tet"]}

    strokes = 0
    with folder_guard(out_dir):
        os.makedirs(out_dir, exist_ok=True)
        with SeriesWriter(out_dir, "cut") as series, progress() as bar:
            task = bar.add_task("cutting", total=len(traj.t))
            for i in range(len(traj.t)):
                cut_step(cm, traj.tip[i], traj.a[i])
                # the blade out of the tissue after a stroke that cut: the next stroke may cross it
                strokes += rebase_if_left(cm)
                if i == len(traj.t) - 1:
                    finish_stroke(cm)  # the trajectory ends with the blade inside: its slivers looked at
                m, pd, cd = frame_data()
                series.write(float(traj.t[i]), m.points, m.tets, point_data=pd, cell_data=cd)
                bar.update(task, advance=1)
        m, _, _ = frame_data()
        write_model(os.path.join(out_dir, "model.h5"), m)
    # the worst angle of the written mesh: cut nodes move after their tets are made
    is_new = m.cell_data["new_tet"] == 1
    new = m.tets[is_new]
    worst = float(min_dihedral_angles(m.points, new).min()) if len(new) else 180.0
    # model tets cut, over every stroke (the cut-made tets' model tets; one truth, the written mesh)
    n_cut = np.unique(cm.model_tet[cm.tet_origin[is_new]]).size
    strokes += bool(cm.subtets)  # the last stroke, if it cut and did not end outside
    if not len(new):
        warn(missed_message(tet_model.points, traj.tip))
        say(f"{len(traj.t)} poses, nothing cut -> {out_dir}/cut.pvd, {out_dir}/model.h5")
        return
    say(f"{len(traj.t)} poses, {strokes} stroke{'s' * (strokes != 1)}, {n_cut} tets cut into "
        f"{len(new)}, worst new dihedral {worst:.1f} deg -> {out_dir}/cut.pvd, {out_dir}/model.h5")
    print_crumbs_note(cm)
    if cm.started_inside:
        note("the blade lay inside the tissue at the first pose: the cut starts where it lay, with no entry "
             "through the surface")
    line = uncut_edges_line(cm)
    if line:
        warn(line)
