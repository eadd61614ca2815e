"""The models of a sweep: from a model file, a build recipe or a generated slab; content hashes.

A run's content key starts from the hash of its model's content (geometry,
labels, materials, boundary conditions, prestress, texture), so the same
model reached through another path, or rebuilt identically, keeps its key.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from cutkit.errors import InputError

#: Parameters of a generated slab and their defaults: a 32 x 12 x 16 mm box of
#: 16 x 6 x 8 Kuhn-split cubes (4,608 tets) of one prestressed tissue, its two
#: z ends fixed; the blade enters its y = 0 face.
SLAB_DEFAULTS = {"shape": [16, 6, 8], "spacing": 2.0, "tissue": "muscle", "prestrain": 0.15,
                 "fibre_direction": [0.0, 0.0, 1.0]}


def slab_model(shape=(16, 6, 8), spacing=2.0, tissue="muscle", prestrain=0.15, fibre_direction=(0.0, 0.0, 1.0)):
    """A box of one prestressed tissue, fixed at both ends along z: the small model of tests and benchmarks.

    Parameters
    ----------
    shape : (3,) int
        Cubes along x, y, z (six tets each).
    spacing : float
        Cube edge, mm.
    tissue : str
        A name of :data:`cutkit.assign.defaults.DEFAULT_MATERIALS` (label 1).
    prestrain : float
        Shortening of the springs along ``fibre_direction`` (0: none).
    fibre_direction : (3,) float

    Returns
    -------
    TetModel
        ``6 * prod(shape)`` tets; nodes with z = 0 or z = max fixed.
    """
    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel

    shape = tuple(int(s) for s in shape)
    if len(shape) != 3 or min(shape) < 1:
        raise InputError(f"slab shape must be three whole numbers >= 1, got {list(shape)}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise InputError(f"slab spacing must be a positive number, got {spacing}")
    if tissue not in DEFAULT_MATERIALS:
        raise InputError(f"slab tissue must be one of {', '.join(sorted(DEFAULT_MATERIALS))}, got {tissue!r}")
    points, tets = box_mesh(shape, spacing=(spacing,) * 3)
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == shape[2] * spacing))
    row = dict(label=1, name=tissue, **DEFAULT_MATERIALS[tissue])
    fibre = np.asarray(fibre_direction, np.float64)
    return TetModel.from_arrays(
        points, tets, materials=Materials.from_rows([row]),
        boundary=BoundaryConditions(fixed_nodes=ends),
        prestress=Prestress(label=np.array([1], np.int32), fibre_direction=(fibre / np.linalg.norm(fibre))[None],
                            prestrain=np.array([float(prestrain)])))


def model_hash(model) -> str:
    """sha256 (hex) of a model's content; its provenance and extra groups are left out.

    Parameters
    ----------
    model : TetModel
    """
    h = hashlib.sha256()
    _feed(h, {f.name: getattr(model, f.name) for f in dataclasses.fields(model)
              if f.name not in ("provenance", "extra")})
    return h.hexdigest()


def _feed(h, obj) -> None:
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"nd{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(type(obj).__name__.encode())
        _feed(h, {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)})
    elif isinstance(obj, dict):
        h.update(b"{")
        for k in sorted(obj, key=str):
            h.update(repr(k).encode())
            _feed(h, obj[k])
        h.update(b"}")
    elif isinstance(obj, (list, tuple)):
        h.update(b"[")
        for v in obj:
            _feed(h, v)
        h.update(b"]")
    else:
        h.update(repr(obj).encode())


def load_model_source(source: dict, base: Path, where: str):
    """The model a spec's ``[[models]]`` entry names.

    Parameters
    ----------
    source : dict
        Exactly one of ``path`` (a model file), ``recipe`` (a build recipe,
        built here once) or ``slab`` (a table of :func:`slab_model`'s
        parameters).
    base : Path
        Folder that relative paths start from (the spec's).
    where : str
        Prefix of error messages.

    Returns
    -------
    TetModel
    """
    if "path" in source:
        from cutkit.io.model_h5 import read_model

        return read_model(_resolve(source["path"], base))
    if "recipe" in source:
        from cutkit.build import run_build
        from cutkit.recipe import load_recipe

        recipe = load_recipe(_resolve(source["recipe"], base))
        volume = recipe.get("recipe", {}).get("volume")
        if not volume:
            raise InputError(f"{where}.recipe: the recipe names no volume ([recipe] volume = ...)")
        return run_build(volume, recipe).model
    params = dict(SLAB_DEFAULTS)
    for key, value in source["slab"].items():
        if key not in SLAB_DEFAULTS:
            raise InputError(f"{where}.slab.{key}: unknown slab parameter (known: {', '.join(SLAB_DEFAULTS)})")
        params[key] = value
    return slab_model(**params)


def _resolve(path, base: Path) -> Path:
    p = Path(path)
    return p if p.is_absolute() else base / p
