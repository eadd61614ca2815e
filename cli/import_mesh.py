"""``cutkit import MESH -o model.h5``: a tet mesh of another tool into a model file."""

from __future__ import annotations

import click


@click.command("import", help="Import a tetrahedral mesh (gmsh, TetGen, VTK, medit, ...) into a model file.")
@click.argument("mesh", type=click.Path(dir_okay=False, path_type=str))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=str), help="Model file to write (.h5).")
def command(mesh: str, output: str) -> None:
    import numpy as np

    from cutkit.cli._ui import check_model_output
    from cutkit.io.atomic import check_writable
    from cutkit.cli._ui import note, say
    from cutkit.io.meshes import import_mesh
    from cutkit.io.model_h5 import write_model

    check_model_output(output)
    check_writable(output)
    model = import_mesh(mesh)
    write_model(output, model)
    info = model.provenance.get("import", {})
    labels, counts = np.unique(model.labels, return_counts=True)
    say(f"imported {model.n_tets} tets, {model.n_points} nodes, {labels.size} labels "
        f"({', '.join(f'{int(l)}: {int(c)}' for l, c in zip(labels, counts))}) -> {output}")
    if info.get("flipped_tets"):
        say(f"fixed orientation of {info['flipped_tets']} negatively oriented tets")
    say(f"run `cutkit check {output}` to validate the mesh")
    if model.materials.n_materials == 0:
        note(f"the model has no materials yet: give them with `cutkit assign {output} --recipe R.toml "
             "-o MODEL.h5` (docs/recipes.md), then `cutkit simulate`")
