"""``cutkit export model.h5 OUT.ext``: a model's mesh to another tool's format."""

from __future__ import annotations

import click


@click.command("export", help="Export a model's mesh to .vtu, .vtk, .msh, .xdmf, .mesh, ... by extension.")
@click.argument("model", type=click.Path(dir_okay=False, path_type=str))
@click.argument("output", type=click.Path(dir_okay=False, path_type=str))
def command(model: str, output: str) -> None:
    from cutkit.io.atomic import check_writable
    from cutkit.cli._ui import console
    from cutkit.io.meshes import export_mesh
    from cutkit.io.model_h5 import read_model

    check_writable(output)
    m = read_model(model)
    export_mesh(m, output)
    console.print(f"wrote {m.n_tets} tets, {m.n_points} nodes -> {output}")
