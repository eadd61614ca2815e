"""``cutkit assign``: materials, boundary conditions and prestress from a recipe."""

import click


@click.command(name="assign")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--recipe", "recipe_path", required=True, type=click.Path(dir_okay=False), help="TOML recipe (pipelines/*.toml).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output model file.")
def command(model, recipe_path, output):
    """Assign the recipe's materials, boundary conditions and prestress to MODEL."""
    from cutkit.cli._ui import check_model_output
    from cutkit.io.atomic import check_writable
    from cutkit.assign import assign
    from cutkit.cli._ui import console, say, table, warn
    from cutkit.io.model_h5 import read_model, write_model
    from cutkit.recipe import load_recipe

    check_model_output(output)
    check_writable(output)
    recipe = load_recipe(recipe_path)
    warnings: list[str] = []
    out = assign(read_model(model), recipe, warnings=warnings)
    write_model(output, out)
    for w in warnings:
        warn(w)
    rows = [[r["label"], r["name"], f"{r['E']:.3g}", f"{r['density']:.0f}", f"{r['F_enter']:.2f}"] for r in out.materials.rows()]
    console.print(table("materials", ["label", "name", "E [Pa]", "density [kg/m^3]", "F_enter [N]"], rows))
    say(
        f"fixed nodes {out.boundary.fixed_nodes.size}, prescribed nodes {out.boundary.prescribed_nodes.size}, "
        f"prestressed labels {list(map(int, out.prestress.label))} -> {output}"
    )
