"""``cutkit demo``: build the knee phantom (or reuse the build) and cut it along the shipped incision."""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path

from cutkit.errors import InputError

#: Recipe and trajectory of the demo, relative to the installed ``cutkit.pipelines`` folder.
DEMO_RECIPE = "knee.toml"
DEMO_TRAJECTORY = "../sample_volumes/incision.csv"


def demo_inputs() -> tuple[Path, Path]:
    """Paths of the demo recipe and trajectory; a clear error where they are missing."""
    import cutkit.pipelines

    base = Path(cutkit.pipelines.__file__).resolve().parent
    recipe = base / DEMO_RECIPE
    trajectory = (base / DEMO_TRAJECTORY).resolve()
    if not recipe.is_file():
        raise InputError(f"{recipe}: the demo recipe is missing from this installation")
    if not trajectory.is_file():
        raise InputError(f"{trajectory}: the demo needs the sample_volumes/ folder of a source checkout "
                         "(install with `pip install -e .` from a clone)")
    return recipe, trajectory


def demo_outputs(out_dir, overwrite: bool = False) -> list[Path]:
    """What of ``out_dir`` a new demo run replaces: the earlier run's outputs, never its built model.

    The demo's folder is its own: one that holds only what the demo writes is
    reused as it is (the model is rebuilt only when its inputs changed).  A
    folder with anything else in it is refused unless ``overwrite``; other
    files are never removed.
    """
    from cutkit.io.atomic import DEMO_MODEL, FOLDER_OUTPUTS, check_output_folder

    folder = Path(out_dir)
    ours = set(FOLDER_OUTPUTS["demo"])
    own = folder.is_dir() and all(e.name in ours for e in folder.iterdir())
    earlier = check_output_folder(out_dir, "demo", overwrite or own)
    return [p for p in earlier if p.name not in DEMO_MODEL]


def build_key(recipe: dict) -> str:
    """sha256 over what decides the build: the recipe, its input volumes and the cutkit version."""
    import cutkit

    h = hashlib.sha256()
    h.update(cutkit.__version__.encode())
    h.update(recipe["_sha256"].encode())
    for table in ("recipe", "texture"):
        path = recipe.get(table, {}).get("volume")
        if path:
            p = Path(path)
            if not p.is_file():
                raise InputError(f"{p}: no such file or folder (a volume the demo recipe names)")
            h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def build_or_reuse(out_dir, on_stage: Callable[[str, str], None] | None = None) -> tuple[Path, bool, dict]:
    """``out_dir/knee.h5`` built with the demo recipe, or reused when its inputs are unchanged.

    Returns
    -------
    path : Path
    reused : bool
    report : dict
        The build's per-stage report (empty when reused).
    """
    from cutkit.build import run_build
    from cutkit.io.atomic import write_text_atomic
    from cutkit.io.model_h5 import read_model, write_model
    from cutkit.recipe import load_recipe

    recipe_path, _ = demo_inputs()
    recipe = load_recipe(recipe_path)
    key = build_key(recipe)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model_path = out_dir / "knee.h5"
    key_path = out_dir / "knee.h5.key"
    if model_path.is_file() and key_path.is_file() and key_path.read_text().strip() == key:
        try:
            read_model(model_path)
            return model_path, True, {}
        except InputError:
            pass  # damaged: build again
    ctx = run_build(recipe["recipe"]["volume"], recipe, on_stage=on_stage)
    write_model(model_path, ctx.model)
    write_text_atomic(key_path, key + "\n")
    return model_path, False, ctx.report
