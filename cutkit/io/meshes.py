"""Import and export tetrahedral meshes of other tools through meshio.

``import_mesh`` reads any tet mesh meshio reads (gmsh .msh, .vtu, .vtk,
medit .mesh, TetGen .ele/.node, ...) into a :class:`~cutkit.model.TetModel`;
``export_mesh`` writes a model's mesh by file extension.  Points and cells
round-trip exactly through the binary formats.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cutkit.errors import InputError, MeshError
from cutkit.io.atomic import atomic_output
from cutkit.model.tetmodel import TetModel

__all__ = ["import_mesh", "export_mesh", "LABEL_KEYS"]

#: Cell-data arrays taken as tissue labels, in order of preference; otherwise any integer array.
LABEL_KEYS = ("gmsh:physical", "medit:ref", "tetgen:ref", "label", "labels")


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def import_mesh(path: str | os.PathLike) -> TetModel:
    """Read the tetrahedra of a mesh file into a model.

    Parameters
    ----------
    path : path-like
        Any tetrahedral mesh meshio can read (format from the extension).

    Returns
    -------
    TetModel
        ``points`` (n, 3) float64 exactly as stored; ``tets`` (m, 4) int64,
        negatively oriented tets fixed by swapping their last two nodes;
        ``labels`` (m,) int32 from cell data (:data:`LABEL_KEYS`, else the
        first integer cell array, else 1).  ``provenance["import"]`` records
        the source file, the label array used and ``flipped_tets``.
        Other cell types (surface triangles, lines, ...) are ignored.

    Raises
    ------
    InputError
        Missing or unreadable file.
    MeshError
        No tetrahedra, non-finite coordinates or bad node indices.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"mesh file not found: {path}")
    if path.is_dir():
        raise InputError(f"mesh path is a folder, not a file: {path}")
    mesh = _read(path)

    blocks = [i for i, c in enumerate(mesh.cells) if c.type in ("tetra", "tetra10")]
    if not blocks:
        kinds = sorted({c.type for c in mesh.cells}) or ["none"]
        raise MeshError(f"{path} contains no tetrahedra (cell types: {', '.join(kinds)})")
    # tetra10: the first four nodes are the corners
    tets = np.concatenate([np.asarray(mesh.cells[i].data)[:, :4] for i in blocks]).astype(np.int64)

    points = np.asarray(mesh.points)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{path}: points have shape {points.shape}, expected (n, 3)")
    if points.shape[1] == 2:
        raise MeshError(f"{path}: points are 2D, a tetrahedral mesh needs 3D points")
    points = np.ascontiguousarray(points, dtype=np.float64)  # float32 -> float64 is exact
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        raise MeshError(f"{path}: node {int(bad[0])} has a non-finite coordinate ({bad.size} such nodes)")
    if tets.min() < 0 or tets.max() >= len(points):
        raise MeshError(f"{path}: a tetrahedron references node {int(tets.max() if tets.max() >= len(points) else tets.min())}, "
                        f"outside [0, {len(points)})")

    labels, label_key = _labels(mesh, blocks, len(tets))

    from cutkit.mesh.quality import signed_volumes

    neg = signed_volumes(points, tets) < 0
    flipped = int(neg.sum())
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()

    model = TetModel.from_arrays(points, tets, labels)
    model.provenance["import"] = {"source": str(path), "label_array": label_key, "flipped_tets": flipped}
    return model


def _read(path: Path):
    """meshio.read, trying each format the extension may mean, with meshio's own
    printing and sys.exit on failure turned into one InputError."""
    import contextlib
    import io

    import meshio

    ext = path.suffix.lower()
    formats = meshio.extension_to_filetypes.get(ext)
    if not formats:
        raise InputError(f"cannot read mesh {path}: unknown mesh file extension '{ext}'")
    formats = sorted(formats, key=lambda f: f != "gmsh")  # .msh: gmsh before ANSYS
    reason = ""
    for fmt in formats:
        sink = io.StringIO()
        try:
            with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
                return meshio.read(path, file_format=fmt)
        except SystemExit:
            lines = [ln.strip() for ln in sink.getvalue().splitlines() if ln.strip()]
            reason = reason or (lines[0].removeprefix("Error: ") if lines else f"not a valid {fmt} file")
        except Exception as exc:  # meshio raises many types for corrupt files
            reason = reason or _one_line(exc)
    raise InputError(f"cannot read mesh {path}: {reason}")


def _labels(mesh, blocks, m):
    data = mesh.cell_data
    keys = [k for k in LABEL_KEYS if k in data]
    keys += sorted(k for k in data if k not in keys and all(np.issubdtype(np.asarray(data[k][i]).dtype, np.integer) for i in blocks))
    for key in keys:
        arrs = [np.asarray(data[key][i]) for i in blocks]
        if all(a.ndim == 1 or (a.ndim == 2 and a.shape[1] == 1) for a in arrs):
            lab = np.concatenate([a.reshape(-1) for a in arrs])
            if lab.shape == (m,) and np.all(np.isfinite(lab)) and np.all(lab == np.rint(lab)):
                return lab.astype(np.int32), key
    return np.ones(m, np.int32), None


def export_mesh(model: TetModel, path: str | os.PathLike) -> None:
    """Write a model's mesh to a file, format by extension (.vtu, .vtk, .msh, .xdmf, .mesh, ...).

    Parameters
    ----------
    model : TetModel
    path : path-like
        Output file; written atomically.  Labels go to cell data (``label``,
        and ``gmsh:physical``/``gmsh:geometrical`` or ``medit:ref`` where the
        format wants them); texture colours, when the model has a texture
        and texture coordinates, to point data ``rgb`` (n, 3) uint8.

    Raises
    ------
    InputError
        Unknown extension or a write failure.
    """
    import meshio

    path = Path(path)
    ext = path.suffix.lower()
    labels = np.asarray(model.labels, np.int32)
    cell_data = {"label": [labels]}
    if ext == ".msh":
        cell_data = {"gmsh:physical": [labels], "gmsh:geometrical": [labels]}
    elif ext in (".mesh", ".meshb"):
        cell_data = {"medit:ref": [labels]}
    point_data = {}
    if model.texture is not None and model.texcoords is not None:
        point_data["rgb"] = model.texture.sample_rgb(np.asarray(model.texcoords, np.float64))
    mesh = meshio.Mesh(np.asarray(model.points, np.float64), [("tetra", np.asarray(model.tets, np.int64))],
                       cell_data=cell_data, point_data=point_data)
    kwargs = {}
    if ext == ".xdmf":
        kwargs["data_format"] = "XML"  # inline data: no side file named after the temporary file
    formats = meshio.extension_to_filetypes.get(ext)
    if not formats:
        raise InputError(f"cannot export to {path}: unknown mesh file extension '{ext}'")
    # .msh is also ANSYS's extension; meshio's gmsh 4.1 writer drops per-cell
    # physical tags, so labels go out as gmsh 2.2 (binary, exact).
    fmt = "gmsh22" if "gmsh" in formats else formats[0]
    try:
        with atomic_output(path) as tmp:
            meshio.write(tmp, mesh, file_format=fmt, **kwargs)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"cannot write {path}: {_one_line(exc)}") from None
