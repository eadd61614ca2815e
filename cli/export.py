"""``cutkit export model.h5 OUT.ext``: a model's mesh to another tool's format."""

from __future__ import annotations

import click


@click.command("export")
@click.argument("model", type=click.Path(dir_okay=False, path_type=str))
@click.argument("output", type=click.Path(dir_okay=False, path_type=str))
@click.option("--rest", is_flag=True,
              help="Write the rest configuration; by default a model with a displacement (the output of "
                   "simulate, cut or relax) is written deformed, its displacement kept as point data.")
def command(model: str, output: str, rest: bool) -> None:
    """Export MODEL's mesh with its point and cell data to OUTPUT (format by extension).

    .vtu, .vtk, .xdmf, .msh (gmsh 2.2), .hmf, .med, .dat (Tecplot) and .avs carry every array:
    displacement, fixed and prescribed nodes, texture coordinates and colours, labels, material
    rows and material properties.  .mesh and .vol carry the labels only; .inp, .bdf, .cgns,
    .f3grid, .mdpa, .post, .su2, .ele/.node, .ugrid and .h5m the mesh only.
    """
    from cutkit.io.atomic import check_writable
    from cutkit.cli._ui import say
    from cutkit.io.meshes import export_mesh
    from cutkit.io.model_h5 import read_model

    check_writable(output)
    m = read_model(model)
    done = export_mesh(m, output, rest=rest)
    data = "; ".join(f"{what}: {', '.join(done[key])}" for what, key in (("point data", "point_data"),
                                                                        ("cell data", "cell_data")) if done[key])
    say(f"wrote {m.n_tets} tets, {m.n_points} nodes ({done['configuration']} configuration"
        + (f"; {data}" if data else f"; the {done['format']} format carries no data arrays")
        + f") -> {output}")
