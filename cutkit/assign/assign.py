"""Assign materials, boundary conditions and prestress to a model from a recipe."""

from __future__ import annotations

import dataclasses

import numpy as np

from cutkit.assign.defaults import DEFAULT_MATERIALS, GENERIC_SOFT_TISSUE
from cutkit.errors import InputError
from cutkit.model.tetmodel import DEFAULT_MATERIAL_MODEL, MATERIAL_FIELDS, BoundaryConditions, Materials, Prestress, TetModel

_AXES = {"x": 0, "y": 1, "z": 2}


def assign(model: TetModel, recipe: dict, warnings: list | None = None) -> TetModel:
    """Return a copy of ``model`` with the recipe's materials, boundary conditions and prestress.

    Parameters
    ----------
    model : TetModel
    recipe : dict
        A validated recipe (:func:`cutkit.recipe.load_recipe`); uses its
        ``materials``, ``boundary`` and ``prestress`` entries.

    Every tissue label of the mesh gets a materials row: the recipe's row
    (defaults looked up by tissue name, then overridden field by field),
    or, for a label the recipe does not name, a generic soft tissue named
    ``tissue_<label>``.  Fixed nodes are the nodes of tets whose label is in
    ``boundary.fixed_labels`` (rigid bone) plus the nodes of each
    ``boundary.fixed_regions`` entry.

    ``warnings``, when given, receives one line per default the materials
    took: a tissue name cutkit has no defaults for, a label the recipe does
    not name.

    Raises
    ------
    InputError
        The recipe names a label (materials, boundary.fixed_labels,
        prestress) that no tet of the model has.
    """
    _check_labels(model, recipe)
    notes = [] if warnings is None else warnings
    materials = _materials(model, recipe.get("materials", []),
                           recipe.get("mechanics", {}).get("material_model", DEFAULT_MATERIAL_MODEL), notes)
    boundary = _boundary(model, recipe.get("boundary", {}))
    prestress = _prestress(model, recipe.get("prestress", []))
    provenance = dict(model.provenance)
    stages = dict(provenance.get("stages", {}))
    stages["assign"] = {
        "materials": materials.rows(),
        "boundary": recipe.get("boundary", {}),
        "prestress": recipe.get("prestress", []),
    }
    provenance["stages"] = stages
    return dataclasses.replace(model, materials=materials, boundary=boundary, prestress=prestress, provenance=provenance)


def _check_labels(model: TetModel, recipe: dict) -> None:
    """A recipe label no tet has is an error naming the labels the model has."""
    have = {int(v) for v in np.unique(model.labels)}
    named = [("materials", [r["label"] for r in recipe.get("materials", [])]),
             ("boundary.fixed_labels", recipe.get("boundary", {}).get("fixed_labels", [])),
             ("prestress", [r["label"] for r in recipe.get("prestress", [])])]
    bad = [f"{', '.join(str(v) for v in sorted(missing))} ({where})"
           for where, labels in named if (missing := {int(v) for v in labels} - have)]
    if bad:
        raise InputError(f"the recipe names label{'s' * (len(bad) > 1 or ',' in bad[0])} {'; '.join(bad)} that no "
                         f"tet of the model has; the model's labels: {', '.join(str(v) for v in sorted(have))}")


def _materials(model: TetModel, rows: list[dict], material_model: str, notes: list) -> Materials:
    by_label = {int(r["label"]): r for r in rows}
    out = []
    for label in np.unique(model.labels):
        label = int(label)
        spec = by_label.get(label, {"label": label, "name": f"tissue_{label}"})
        known = spec["name"] in DEFAULT_MATERIALS
        base = DEFAULT_MATERIALS.get(spec["name"], GENERIC_SOFT_TISSUE)
        row = {"label": label, "name": spec["name"]}
        row.update({k: float(spec.get(k, base[k])) for k in MATERIAL_FIELDS})
        taken = [k for k in MATERIAL_FIELDS if k not in spec]
        if not known and taken:
            what = (f"label {label} is not in the recipe's materials" if label not in by_label
                    else f"material {spec['name']!r} (label {label}) is not one of cutkit's tissues "
                         f"({', '.join(DEFAULT_MATERIALS)})")
            main = [k for k in ("E", "poisson_ratio", "density") if k in taken]
            notes.append(f"{what}: it takes the generic soft tissue's (muscle's) defaults for "
                         f"{'every field' if len(taken) == len(MATERIAL_FIELDS) else ', '.join(taken)}"
                         + (f" ({', '.join(f'{k} = {base[k]:g}' for k in main)})" if main else ""))
        out.append(row)
    if not out:
        return dataclasses.replace(Materials.empty(), material_model=material_model)
    return Materials.from_rows(out, material_model=material_model)


def region_nodes(points: np.ndarray, region: dict) -> np.ndarray:
    """Indices of the nodes inside a recipe region.

    Parameters
    ----------
    points : (n, 3) float64
    region : dict
        Either ``axis`` ('x'|'y'|'z'), ``side`` ('min'|'max') and ``depth_mm``:
        the slab of that thickness at that end of the model's extent (the
        two ends of the leg in the paper's Fig. 14); or ``box_min`` and
        ``box_max``: an axis-aligned box, mm.

    Returns
    -------
    nodes : (k,) int64
    """
    if "axis" in region:
        ax = _AXES[region["axis"]]
        coord = points[:, ax]
        depth = float(region["depth_mm"])
        mask = coord <= coord.min() + depth if region["side"] == "min" else coord >= coord.max() - depth
    else:
        lo = np.asarray(region["box_min"], np.float64)
        hi = np.asarray(region["box_max"], np.float64)
        mask = np.all((points >= lo) & (points <= hi), axis=1)
    return np.flatnonzero(mask).astype(np.int64)


def _boundary(model: TetModel, spec: dict) -> BoundaryConditions:
    fixed = [np.asarray(model.boundary.fixed_nodes, np.int64)]
    labels = spec.get("fixed_labels", [])
    if labels:
        in_label = np.isin(model.labels, labels)
        fixed.append(np.unique(model.tets[in_label]))
    for i, region in enumerate(spec.get("fixed_regions", [])):
        nodes = region_nodes(model.points, region)
        if nodes.size == 0:
            raise InputError(f"boundary.fixed_regions #{i + 1} selects no node of the model")
        fixed.append(nodes)
    fixed_nodes = np.unique(np.concatenate(fixed)).astype(np.int64)

    pres_nodes, pres_disp = [], []
    for i, region in enumerate(spec.get("prescribed", [])):
        nodes = region_nodes(model.points, region)
        if nodes.size == 0:
            raise InputError(f"boundary.prescribed #{i + 1} selects no node of the model")
        nodes = np.setdiff1d(nodes, fixed_nodes)
        pres_nodes.append(nodes)
        pres_disp.append(np.tile(np.asarray(region["displacement_mm"], np.float64), (nodes.size, 1)))
    if pres_nodes:
        nodes = np.concatenate(pres_nodes)
        disp = np.concatenate(pres_disp)
        nodes, first = np.unique(nodes, return_index=True)  # first region naming a node wins
        disp = disp[first]
    else:
        nodes = np.asarray(model.boundary.prescribed_nodes, np.int64)
        disp = np.asarray(model.boundary.prescribed_displacement, np.float64).reshape(-1, 3)
    return BoundaryConditions(fixed_nodes=fixed_nodes, prescribed_nodes=nodes.astype(np.int64), prescribed_displacement=disp)


def _prestress(model: TetModel, rows: list[dict]) -> Prestress:
    if not rows:
        return model.prestress
    label = np.array([int(r["label"]) for r in rows], np.int32)
    fibre = np.array([r["fibre_direction"] for r in rows], np.float64)
    fibre /= np.linalg.norm(fibre, axis=1, keepdims=True)
    prestrain = np.array([float(r["prestrain"]) for r in rows], np.float64)
    return Prestress(label=label, fibre_direction=fibre, prestrain=prestrain)
