"""Build recipes: TOML files that make a model build reproducible.

A recipe has one table per stage (``segment``, ``isovolume``, ``decimate``,
``texture``), the tissue ``materials``, the ``boundary`` conditions and the
``prestress``.  :func:`load_recipe` checks every key and type and raises a
one-line :class:`~cutkit.errors.InputError` naming the file and the key.
Paths inside a recipe are relative to the recipe file.  See
``docs/recipes.md`` and ``pipelines/knee.toml``.
"""

from __future__ import annotations

import copy
import hashlib
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from cutkit.errors import InputError
from cutkit.model.tetmodel import MATERIAL_FIELDS, MATERIAL_MODELS

_NUM = (int, float)
_VEC3 = "vec3"

#: Allowed keys of each table and the type of each value.
SCHEMA: dict[str, dict[str, object]] = {
    "recipe": {"name": str, "description": str, "volume": str},
    "segment": {
        "labels": bool,
        "threshold": list,
        "channel": str,
        "otsu": bool,
        "smooth_mm": _NUM,
        "voxel_size_mm": _NUM,
        "clean": bool,
        "largest_component": bool,
        "fill_holes": bool,
        "spacing": _VEC3,
    },
    "isovolume": {"level": _NUM, "snap": _NUM},
    "decimate": {"ratio": _NUM, "target_tets": int, "surface_tolerance_mm": _NUM, "min_dihedral_deg": _NUM, "optimize": str},
    "texture": {"volume": str, "register": str, "max_voxels": int},
    "boundary": {"fixed_labels": list, "fixed_regions": list, "prescribed": list},
    "mechanics": {"material_model": str},
}
_MATERIAL_KEYS = {"label": int, "name": str, **{k: _NUM for k in MATERIAL_FIELDS}}
_REGION_KEYS = {"axis": str, "side": str, "depth_mm": _NUM, "box_min": _VEC3, "box_max": _VEC3}
_PRESCRIBED_KEYS = {**_REGION_KEYS, "displacement_mm": _VEC3}
_PRESTRESS_KEYS = {"label": int, "fibre_direction": _VEC3, "prestrain": _NUM}


def load_recipe(path: str | Path) -> dict:
    """Read and validate a recipe.

    Returns
    -------
    recipe : dict
        The parsed tables, with ``recipe["_path"]`` (the file) and
        ``recipe["_sha256"]`` (its hash) added and relative paths made absolute.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    raw = path.read_bytes()
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise InputError(f"{path}: not a valid TOML recipe ({' '.join(str(err).split())})") from None
    validate_recipe(data, str(path))
    data = copy.deepcopy(data)
    base = path.resolve().parent
    for table, key in (("recipe", "volume"), ("texture", "volume")):
        if key in data.get(table, {}):
            data[table][key] = str((base / data[table][key]).resolve())
    data["_path"] = str(path.resolve())
    data["_sha256"] = hashlib.sha256(raw).hexdigest()
    return data


def validate_recipe(data: dict, where: str = "recipe") -> None:
    """Check keys and value types of a parsed recipe (see :data:`SCHEMA`)."""
    known = set(SCHEMA) | {"materials", "prestress"}
    for table in data:
        if table not in known:
            raise InputError(f"{where}: unknown table [{table}] (allowed: {', '.join(sorted(known))})")
    for table, keys in SCHEMA.items():
        if table in data:
            if not isinstance(data[table], dict):
                raise InputError(f"{where}: [{table}] must be a table")
            _check_keys(data[table], keys, f"{where}: [{table}]")
    seg = data.get("segment", {})
    if "threshold" in seg:
        t = seg["threshold"]
        if not (1 <= len(t) <= 2 and all(isinstance(v, _NUM) and not isinstance(v, bool) for v in t)):
            raise InputError(f"{where}: [segment] threshold must be [low] or [low, high]")
    reg = data.get("texture", {}).get("register")
    if reg is not None and reg not in ("none", "rigid", "affine"):
        raise InputError(f"{where}: [texture] register must be 'none', 'rigid' or 'affine', not {reg!r}")
    opt = data.get("decimate", {}).get("optimize")
    if opt is not None and opt != "netgen":
        raise InputError(f"{where}: [decimate] optimize must be 'netgen', not {opt!r}")
    bnd = data.get("boundary", {})
    for i, region in enumerate(bnd.get("fixed_regions", [])):
        _check_region(region, _REGION_KEYS, f"{where}: [[boundary.fixed_regions]] #{i + 1}")
    for i, region in enumerate(bnd.get("prescribed", [])):
        _check_region(region, _PRESCRIBED_KEYS, f"{where}: [[boundary.prescribed]] #{i + 1}")
        if "displacement_mm" not in region:
            raise InputError(f"{where}: [[boundary.prescribed]] #{i + 1} needs displacement_mm")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in bnd.get("fixed_labels", [])):
        raise InputError(f"{where}: [boundary] fixed_labels must be a list of integer labels")
    labels_seen = set()
    for i, mat in enumerate(_array_of_tables(data, "materials", where)):
        here = f"{where}: [[materials]] #{i + 1}"
        _check_keys(mat, _MATERIAL_KEYS, here)
        if "label" not in mat or "name" not in mat:
            raise InputError(f"{here} needs a label and a name")
        if mat["label"] in labels_seen:
            raise InputError(f"{here} repeats label {mat['label']}")
        labels_seen.add(mat["label"])
        for key in MATERIAL_FIELDS:
            # one wording for every field: E and density > 0, the others >= 0
            if key in ("E", "density") and key in mat and not mat[key] > 0:
                raise InputError(f"{here}: {key} must be a positive number, got {mat[key]:g}")
            if key in mat and not mat[key] >= 0:
                raise InputError(f"{here}: {key} must be a number >= 0, got {mat[key]:g}")
        if not 0.0 <= mat.get("poisson_ratio", 0.25) < 0.5:
            raise InputError(f"{here}: poisson_ratio must lie in [0, 0.5), got {mat['poisson_ratio']}")
    model_name = data.get("mechanics", {}).get("material_model")
    if model_name is not None and model_name not in MATERIAL_MODELS:
        raise InputError(f"{where}: [mechanics] material_model must be one of {', '.join(MATERIAL_MODELS)}, "
                         f"not {model_name!r}")
    for i, pre in enumerate(_array_of_tables(data, "prestress", where)):
        here = f"{where}: [[prestress]] #{i + 1}"
        _check_keys(pre, _PRESTRESS_KEYS, here)
        if set(pre) != set(_PRESTRESS_KEYS):
            raise InputError(f"{here} needs label, fibre_direction and prestrain")
        if not -0.5 < pre["prestrain"] < 0.5:
            raise InputError(f"{here}: prestrain {pre['prestrain']} is outside (-0.5, 0.5)")
        if sum(v * v for v in pre["fibre_direction"]) == 0:
            raise InputError(f"{here}: fibre_direction must not be zero")


def _array_of_tables(data: dict, name: str, where: str) -> list:
    value = data.get(name, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise InputError(f"{where}: {name} must be an array of tables ([[{name}]])")
    return value


def _check_region(region, keys, here) -> None:
    if not isinstance(region, dict):
        raise InputError(f"{here} must be a table")
    _check_keys(region, keys, here)
    has_end = "axis" in region
    has_box = "box_min" in region or "box_max" in region
    if has_end == has_box:
        raise InputError(f"{here} needs either axis/side/depth_mm or box_min/box_max")
    if has_end:
        if region["axis"] not in ("x", "y", "z") or region.get("side") not in ("min", "max"):
            raise InputError(f"{here}: axis must be x, y or z and side min or max")
        if region.get("depth_mm", 0) <= 0:
            raise InputError(f"{here}: depth_mm must be positive")
    elif not ("box_min" in region and "box_max" in region):
        raise InputError(f"{here} needs both box_min and box_max")


def _check_keys(table: dict, keys: dict, here: str) -> None:
    for key, value in table.items():
        if key not in keys:
            raise InputError(f"{here}: unknown key {key!r} (allowed: {', '.join(sorted(keys))})")
        want = keys[key]
        if want == _VEC3:
            ok = isinstance(value, list) and len(value) == 3 and all(
                isinstance(v, _NUM) and not isinstance(v, bool) for v in value
            )
            if not ok:
                raise InputError(f"{here}: {key} must be a list of three numbers")
        elif want is _NUM:
            if not isinstance(value, _NUM) or isinstance(value, bool):
                raise InputError(f"{here}: {key} must be a number, not {value!r}")
        elif want is int:
            if not isinstance(value, int) or isinstance(value, bool):
                raise InputError(f"{here}: {key} must be an integer, not {value!r}")
        elif not isinstance(value, want):
            raise InputError(f"{here}: {key} must be a {want.__name__}, not {value!r}")
