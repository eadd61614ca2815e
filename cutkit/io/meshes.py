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
        raise InputError(f"{path}: no such file")
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


#: Formats whose meshio writer stores point and cell data arrays (checked by reading them back).
DATA_FORMATS = ("vtu", "vtk", "xdmf", "hmf", "med", "gmsh22", "tecplot", "avsucd")
#: Formats that store one integer per tet (the tissue label) under their own name, and nothing else.
LABEL_ONLY = {"medit": "medit:ref", "netgen": "netgen:index"}
#: Formats meshio writes that cutkit refuses, with the reason.
REFUSED = {
    "exodus": "meshio's Exodus writer needs the netCDF4 package (pip install netCDF4)",
    "dolfin-xml": "meshio's DOLFIN XML writer writes unreadable numbers with this NumPy; use .xdmf for FEniCS",
}
#: Formats that take points and tetrahedra but neither point nor cell data.
GEOMETRY_ONLY = ("abaqus", "ansys", "cgns", "flac3d", "mdpa", "nastran", "permas", "su2", "tetgen", "ugrid", "h5m")


def export_arrays(model: TetModel, rest: bool = False) -> tuple[np.ndarray, dict, dict]:
    """The points, point data and cell data :func:`export_mesh` writes.

    Returns
    -------
    points : (n, 3) float64
        Deformed positions (rest + ``point_data["displacement"]``) or, with
        ``rest`` or without a displacement, the rest positions.
    point_data : dict
        The model's point data (``displacement`` in mm, ``new_node``, ...),
        ``fixed`` and ``prescribed`` (1 for nodes under that boundary
        condition), ``texcoords`` (n, 3) and ``rgb`` (n, 3, the texture's
        colour) where the model has a texture.
    cell_data : dict
        ``label``, the model's cell data (``new_tet``, ...), ``material`` (row of
        the materials table, -1 for none) and one float array per material
        column (``E`` in Pa, ``density`` in kg/m^3, ...; units in docs/model-format.md).
    """
    n = model.n_points
    points = np.asarray(model.points, np.float64)
    pd = {k: np.asarray(v) for k, v in model.point_data.items()}
    disp = pd.get("displacement")
    if not rest and disp is not None and disp.shape == (n, 3):
        points = points + disp
    for name, nodes in (("fixed", model.boundary.fixed_nodes), ("prescribed", model.boundary.prescribed_nodes)):
        flag = np.zeros(n, np.uint8)
        flag[np.asarray(nodes, np.int64)] = 1
        pd[name] = flag
    if model.texcoords is not None:
        pd["texcoords"] = np.asarray(model.texcoords, np.float64)
        if model.texture is not None:
            pd["rgb"] = np.asarray(model.texture.sample_rgb(pd["texcoords"]), np.uint8)
    cd = {"label": np.asarray(model.labels, np.int32)}
    cd.update({k: np.asarray(v) for k, v in model.cell_data.items() if k != "label"})
    mats = model.materials
    if mats.n_materials:
        row = np.asarray(mats.row_of(np.asarray(model.labels)), np.int64)
        cd["material"] = row.astype(np.int32)
        for column, values in mats.values.items():
            v = np.asarray(values, np.float64)
            cd[column] = np.where(row >= 0, v[np.clip(row, 0, None)], np.nan)
    return points, pd, cd


def _plain(arr: np.ndarray) -> np.ndarray:
    """Integers and booleans as int32, floats as float64: the types every data-carrying writer takes."""
    arr = np.asarray(arr)
    if arr.dtype == np.bool_ or np.issubdtype(arr.dtype, np.integer):
        return arr.astype(np.int32)
    return arr.astype(np.float64)


def export_mesh(model: TetModel, path: str | os.PathLike, rest: bool = False) -> dict:
    """Write a model's mesh to a file, format by extension (.vtu, .vtk, .msh, .xdmf, .mesh, ...).

    Parameters
    ----------
    model : TetModel
    path : path-like
        Output file; written atomically.
    rest : bool
        Write the rest configuration instead of the deformed one (points +
        ``point_data["displacement"]``, the default where the model has one).

    Formats that carry data (:data:`DATA_FORMATS`: .vtu, .vtk, .xdmf, .msh,
    .hmf, .med, .dat, .avs) get every array of :func:`export_arrays`, with
    integers as int32; .msh also gets the labels as ``gmsh:physical``/
    ``gmsh:geometrical`` (.avs stores its first integer array, the labels,
    as ``avsucd:material``).  :data:`LABEL_ONLY` formats (.mesh, .vol) get
    the labels under their own name; the
    others (:data:`GEOMETRY_ONLY`) points and tetrahedra only.

    Returns
    -------
    dict
        ``format`` (meshio's name), ``configuration`` ("deformed" or "rest"),
        ``point_data`` and ``cell_data`` (names written).

    Raises
    ------
    InputError
        Unknown extension, a format that takes no tetrahedra, or a write failure.
    """
    import meshio

    path = Path(path)
    name = path.name.lower()
    ext = ".vol.gz" if name.endswith(".vol.gz") else path.suffix.lower()
    formats = meshio.extension_to_filetypes.get(ext)
    if not formats:
        raise InputError(f"cannot export to {path}: unknown mesh file extension '{ext}'")
    # .msh is also ANSYS's extension; meshio's gmsh 4.1 writer drops per-cell
    # physical tags, so labels go out as gmsh 2.2 (binary, exact).
    fmt = "gmsh22" if "gmsh" in formats else formats[0]
    if fmt in REFUSED:
        raise InputError(f"cannot export to {path}: {REFUSED[fmt]}")
    if fmt not in DATA_FORMATS and fmt not in LABEL_ONLY and fmt not in GEOMETRY_ONLY:
        raise InputError(f"cannot export to {path}: the {fmt} format takes no tetrahedra")
    points, pd, cd = export_arrays(model, rest=rest)
    has_disp = "displacement" in model.point_data
    labels = np.asarray(model.labels, np.int32)
    if fmt in DATA_FORMATS:
        point_data = {k: _plain(v) for k, v in pd.items()}
        cell_data = {k: [_plain(v)] for k, v in cd.items()}
        if fmt == "gmsh22":
            cell_data.update({"gmsh:physical": [labels], "gmsh:geometrical": [labels]})
    elif fmt in LABEL_ONLY:
        point_data, cell_data = {}, {LABEL_ONLY[fmt]: [labels]}
    else:
        point_data, cell_data = {}, {}
    mesh = meshio.Mesh(points, [("tetra", np.asarray(model.tets, np.int64))],
                       cell_data=cell_data, point_data=point_data)
    kwargs = {}
    if fmt == "xdmf":
        kwargs["data_format"] = "XML"  # inline data: no side file named after the temporary file
    elif fmt == "nastran":
        # meshio's 16-character fields overflow on 12 significant digits of a small negative
        # number: 10 digits (0.1 nm at 1 m) fit
        mesh.points = np.array([float(f"{v:.9e}") for v in points.ravel()]).reshape(points.shape)
    try:
        if fmt == "tetgen":
            _write_tetgen(path, mesh)
        else:
            with atomic_output(path) as tmp:
                meshio.write(tmp, mesh, file_format=fmt, **kwargs)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"cannot write {path}: {_one_line(exc)}") from None
    return {"format": fmt, "configuration": "deformed" if (has_disp and not rest) else "rest",
            "point_data": sorted(point_data), "cell_data": sorted(cell_data)}


def _write_tetgen(path: Path, mesh) -> None:
    """TetGen's .node and .ele pair (either name given), each renamed into place when complete."""
    import tempfile

    import meshio

    with tempfile.TemporaryDirectory(prefix=".cutkit-", dir=path.parent) as tmp:
        meshio.write(Path(tmp) / "mesh.ele", mesh, file_format="tetgen")
        for ext in (".node", ".ele"):
            os.replace(Path(tmp) / f"mesh{ext}", path.with_suffix(ext))
