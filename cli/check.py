"""``cutkit check model.h5``: validity of a model's mesh; exit 1 naming failed checks."""

from __future__ import annotations

import click


@click.command("check", help="Check a model's mesh: indices, orientation, manifold boundary, hanging nodes, quality.")
@click.argument("model", type=click.Path(dir_okay=False, path_type=str))
@click.option("--min-dihedral", type=float, default=0.0, show_default=True,
              help="Fail when the worst dihedral angle (degrees) is below this.")
def command(model: str, min_dihedral: float) -> None:
    from cutkit.cli._ui import console, table
    from cutkit.io.model_h5 import read_model
    from cutkit.mesh.check import check_mesh

    m = read_model(model)
    rep = check_mesh(m.points, m.tets, m.labels, min_dihedral=min_dihedral)
    rows = [[r.name, "ok" if r.passed else "FAIL", r.detail] for r in rep.rows]  # table cells are plain text
    console.print(table(f"check {model}", ["check", "result", "detail"], rows))
    if not rep.passed:
        console.print(f"[red]failed:[/] {', '.join(rep.failed)}")
        raise SystemExit(1)
    console.print(f"[green]all {len(rep.rows)} checks passed[/]")
