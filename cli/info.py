"""``cutkit info FILE``: describe a model file or a volume."""

from __future__ import annotations

from pathlib import Path

import click

#: At most this many distinct values are listed as labels of a volume.
MAX_VOLUME_LABELS = 64


@click.command("info", help="Describe a volume or a model file.")
@click.argument("path", type=click.Path(path_type=str))
def command(path: str) -> None:
    from cutkit.errors import InputError

    p = Path(path)
    if not p.exists():
        raise InputError(f"{path}: no such file or folder")
    if p.is_file() and p.suffix.lower() in (".h5", ".hdf5"):
        from cutkit.io.model_h5 import read_schema_version

        # an .h5 file is only ever a model: a damaged one is reported as such
        _model_info(path, read_schema_version(p))
        return
    _volume_info(path)


def _model_info(path: str, version: int) -> None:
    import numpy as np

    from cutkit.cli._ui import console, esc, say, table
    from cutkit.io.model_h5 import read_model
    from cutkit.mesh.quality import signed_volumes

    m = read_model(path)
    vol = signed_volumes(m.points, m.tets)
    lo, hi = (m.points.min(axis=0), m.points.max(axis=0)) if m.n_points else (np.zeros(3), np.zeros(3))
    console.print(f"[bold]model[/] {esc(path)}  (schema version {version})")
    say(f"  {m.n_points} nodes, {m.n_tets} tets, total volume {vol.sum():.6g} mm^3")
    say(f"  bounding box [{', '.join(f'{v:.6g}' for v in lo)}] .. [{', '.join(f'{v:.6g}' for v in hi)}] mm")
    labels, inv = np.unique(m.labels, return_inverse=True)
    counts = np.bincount(inv, minlength=labels.size)
    volumes = np.bincount(inv, weights=vol, minlength=labels.size)
    names = {int(l): n for l, n in zip(m.materials.label, m.materials.name)}
    rows = [[int(l), names.get(int(l), "-"), int(c), f"{v:.6g}"] for l, c, v in zip(labels, counts, volumes)]
    console.print(table("labels", ["label", "material", "tets", "volume [mm^3]"], rows))
    if m.materials.n_materials:
        from cutkit.model.tetmodel import MATERIAL_FIELDS

        cols = list(m.materials.values)
        mrows = [[int(l), n] + [f"{m.materials.values[c][i]:.4g}" for c in cols]
                 for i, (l, n) in enumerate(zip(m.materials.label, m.materials.name))]
        heads = [f"{c} [{MATERIAL_FIELDS[c]}]" if MATERIAL_FIELDS.get(c, "1") != "1" else c for c in cols]
        console.print(table("materials (units in brackets; the others are ratios)", ["label", "name"] + heads, mrows))
    else:
        say("  no materials assigned")
    extras = []
    if m.texture is not None:
        extras.append(f"texture {tuple(m.texture.volume.shape)}")
    if m.texcoords is not None:
        extras.append("texture coordinates")
    if m.boundary.fixed_nodes.size:
        extras.append(f"{m.boundary.fixed_nodes.size} fixed nodes")
    if m.boundary.prescribed_nodes.size:
        extras.append(f"{m.boundary.prescribed_nodes.size} prescribed nodes")
    if m.prestress.label.size:
        extras.append(f"prestress on {m.prestress.label.size} labels")
    if m.point_data:
        extras.append("point data: " + ", ".join(m.point_data))
    if m.cell_data:
        extras.append("cell data: " + ", ".join(m.cell_data))
    if extras:
        say("  " + "; ".join(extras))


def _volume_info(path: str) -> None:
    import numpy as np

    from cutkit.cli._ui import console, esc, say
    from cutkit.errors import InputError

    try:
        from cutkit.volumes import read_volume
    except ImportError:
        raise InputError(f"{path} is not a cutkit model file (volume reading is not available)") from None
    from cutkit.cli._ui import table
    from cutkit.volumes.describe import describe_volume

    v = read_volume(path)
    data = v.data
    d = describe_volume(v)
    console.print(f"[bold]volume[/] {esc(path)}")
    say(f"  dims {tuple(int(s) for s in data.shape[:3])}"
        + (f" x {data.shape[3]} channels" if data.ndim == 4 else "") + f", dtype {data.dtype}")
    say(f"  spacing {', '.join(f'{s:g}' for s in v.spacing)} mm, origin "
        f"{', '.join(f'{s:g}' for s in v.origin)} mm, extent {' x '.join(f'{s:g}' for s in d['extent_mm'])} mm")
    say(f"  orientation {orientation_code(v.direction)}: voxel axes i, j, k point to "
        f"{', '.join(AXIS_WORDS[c] for c in orientation_code(v.direction))}; world frame LPS "
        "(x left, y posterior, z superior, as DICOM and ITK; nibabel's RAS affine has x and y negated)")
    if not np.allclose(v.direction, np.eye(3)):
        say(f"  direction {np.asarray(v.direction).round(6).tolist()}")
    if np.issubdtype(data.dtype, np.floating):
        say(f"  NaN voxels: {d['n_nan']}")
    if data.size and np.issubdtype(data.dtype, np.integer):
        vals, counts = np.unique(data, return_counts=True)
        if vals.size <= MAX_VOLUME_LABELS:
            rows = [[int(a), int(c), f"{c * d['voxel_mm3']:.6g}"] for a, c in zip(vals, counts)]
            console.print(table("values", ["value", "voxels", "volume [mm^3]"], rows))
        else:
            say(f"  {vals.size} distinct values in [{vals.min()}, {vals.max()}] (intensity image)")
    elif data.size:
        lo, hi = d["value_range"]
        say(f"  values in [{lo:.6g}, {hi:.6g}]" if lo is not None else "  no finite value")


#: Letter of the world direction each voxel axis points to (LPS world frame).
AXIS_WORDS = {"L": "left", "R": "right", "P": "posterior", "A": "anterior", "S": "superior", "I": "inferior"}


def orientation_code(direction) -> str:
    """Three letters: the world direction (LPS frame) each voxel axis i, j, k points to most, e.g. ``LPS``."""
    import numpy as np

    d = np.asarray(direction, float)
    letters = (("L", "R"), ("P", "A"), ("S", "I"))
    code = ""
    for col in d.T:
        axis = int(np.argmax(np.abs(col)))
        code += letters[axis][0 if col[axis] > 0 else 1]
    return code
