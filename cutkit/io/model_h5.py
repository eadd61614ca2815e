"""The model file (``model.h5``): the one module that knows its HDF5 layout.

Everything else reads and writes models through :func:`read_model` and
:func:`write_model`.  The layout (schema version :data:`SCHEMA_VERSION`)::

    /VTKHDF                         VTKHDF UnstructuredGrid, so ParaView opens the file
        attrs Version=(1, 0), Type="UnstructuredGrid"
        NumberOfPoints (1,) int64, NumberOfCells (1,) int64, NumberOfConnectivityIds (1,) int64
        Points (n, 3) float64                 node positions, mm
        Types (m,) uint8                      all 10 (VTK_TETRA)
        Offsets (m + 1,) int64                0, 4, 8, ...
        Connectivity (4 m,) int64             tets, positively oriented
        CellData/label (m,) int32             tissue label per tet
        CellData/<name>                       further per-tet arrays
        PointData/texcoords (n, 3) float64    normalised 3D-texture coordinates (if textured)
        PointData/texture_rgb (n, 3) uint8    texture colour at each node (if textured)
        PointData/<name>                      further per-node arrays
    /cutkit
        attrs schema_version=int, cutkit_version=str, provenance=JSON str
        materials/label (k,) int32, materials/name (k,) str, materials/<field> (k,) float64
            attrs material_model="neohookean" | "springs"            (schema version 2)
        materials/J_c (k,) float64            fracture toughness, J/m^2  (schema version 3)
        boundary/fixed_nodes (f,) int64
        boundary/prescribed_nodes (p,) int64, boundary/prescribed_displacement (p, 3) float64
        prestress/label (q,) int32, prestress/fibre_direction (q, 3) float64, prestress/prestrain (q,) float64
        texture/volume (nx, ny, nz, c) uint8 (gzip), texture/spacing (3,), texture/origin (3,),
            texture/direction (3, 3)                                     (only if textured)
        extra/<group>/<name>                  arrays of later stages (e.g. the progressive record)

Every failure to read a file is a :class:`~cutkit.errors.ModelFormatError`
whose one-line message names the file and the dataset.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from cutkit import __version__
from cutkit.errors import InputError, ModelFormatError
from cutkit.io.atomic import atomic_output
from cutkit.model.tetmodel import (
    DEFAULT_MATERIAL_MODEL,
    MATERIAL_FIELD_DEFAULTS,
    MATERIAL_FIELDS,
    MATERIAL_MODELS,
    BoundaryConditions,
    Materials,
    Prestress,
    TetModel,
    Texture,
)

#: Version of the layout above; bump on any incompatible change.
#: Version 2 added materials/poisson_ratio and the materials' material_model;
#: version 3 added materials/J_c.
SCHEMA_VERSION = 3
#: Older versions this module still reads (upgraded on reading, see
#: :data:`V1_POISSON_RATIO` and :data:`V2_J_C`).
READABLE_VERSIONS = (1, 2, 3)
#: Poisson ratio given to every material of a version-1 file (which has none):
#: soft tissue is nearly incompressible (docs/model-format.md).  Reading
#: records it in the provenance under ``schema_upgrade``.
V1_POISSON_RATIO = 0.45
#: Fracture toughness J_c (J/m^2) given to every material of a version 1 or 2
#: file (which has none): the "muscle" row of cutkit.assign.defaults, within
#: the 550-8,000 J/m^2 published for muscle (docs/model-format.md).  Reading
#: records it in the provenance under ``schema_upgrade``.
V2_J_C = MATERIAL_FIELD_DEFAULTS["J_c"]

#: VTKHDF version written under /VTKHDF (1.0 is read by every ParaView since 5.10).
VTKHDF_VERSION = (1, 0)

VTK_TETRA = 10

#: Arrays under /cutkit/extra with at least this many elements are stored compressed.
COMPRESS_MIN_ELEMENTS = 4096

#: Point/cell data names that the layout itself defines.
RESERVED_POINT_DATA = ("texcoords", "texture_rgb")
RESERVED_CELL_DATA = ("label",)

__all__ = ["SCHEMA_VERSION", "read_model", "write_model", "read_schema_version"]


# --------------------------------------------------------------------------- writing


def write_model(path: str | os.PathLike, model: TetModel) -> None:
    """Write ``model`` to ``path`` (atomically: a temporary file, then a rename).

    Parameters
    ----------
    path : path-like
        Destination ``.h5`` file; replaced if it exists.
    model : TetModel
    """
    _check_model_shapes(model)
    with atomic_output(path, suffix=".h5.tmp") as tmp:
        with h5py.File(tmp, "w") as f:
            _write_vtkhdf(f, model)
            _write_cutkit(f, model)


def _write_vtkhdf(f: h5py.File, model: TetModel) -> None:
    n, m = model.n_points, model.n_tets
    g = f.create_group("VTKHDF")
    g.attrs["Version"] = np.array(VTKHDF_VERSION, dtype=np.int64)
    type_name = b"UnstructuredGrid"
    g.attrs.create("Type", type_name, dtype=h5py.string_dtype("ascii", len(type_name)))
    g.create_dataset("NumberOfPoints", data=np.array([n], np.int64))
    g.create_dataset("NumberOfCells", data=np.array([m], np.int64))
    g.create_dataset("NumberOfConnectivityIds", data=np.array([4 * m], np.int64))
    g.create_dataset("Points", data=np.ascontiguousarray(model.points, np.float64))
    g.create_dataset("Types", data=np.full(m, VTK_TETRA, np.uint8))
    g.create_dataset("Offsets", data=np.arange(0, 4 * m + 1, 4, dtype=np.int64))
    g.create_dataset("Connectivity", data=np.ascontiguousarray(model.tets, np.int64).reshape(-1))

    cd = g.create_group("CellData")
    cd.create_dataset("label", data=np.asarray(model.labels, np.int32))
    for name, arr in model.cell_data.items():
        cd.create_dataset(name, data=np.asarray(arr))

    pd = g.create_group("PointData")
    if model.texcoords is not None:
        pd.create_dataset("texcoords", data=np.asarray(model.texcoords, np.float64))
        if model.texture is not None:
            pd.create_dataset("texture_rgb", data=model.texture.sample_rgb(model.texcoords))
    for name, arr in model.point_data.items():
        pd.create_dataset(name, data=np.asarray(arr))
    g.create_group("FieldData")


def _write_cutkit(f: h5py.File, model: TetModel) -> None:
    g = f.create_group("cutkit")
    g.attrs["schema_version"] = np.int64(SCHEMA_VERSION)
    g.attrs["cutkit_version"] = __version__
    prov = dict(model.provenance)
    prov.setdefault("cutkit_version", __version__)
    g.attrs["provenance"] = json.dumps(prov, sort_keys=True, default=str)

    mat = g.create_group("materials")
    mat.create_dataset("label", data=np.asarray(model.materials.label, np.int32))
    mat.create_dataset("name", data=np.array(model.materials.name, dtype=object), dtype=h5py.string_dtype("utf-8"))
    for key in MATERIAL_FIELDS:
        mat.create_dataset(key, data=np.asarray(model.materials.values[key], np.float64))
    mat.attrs["material_model"] = model.materials.material_model

    bc = g.create_group("boundary")
    bc.create_dataset("fixed_nodes", data=np.asarray(model.boundary.fixed_nodes, np.int64))
    bc.create_dataset("prescribed_nodes", data=np.asarray(model.boundary.prescribed_nodes, np.int64))
    bc.create_dataset(
        "prescribed_displacement",
        data=np.asarray(model.boundary.prescribed_displacement, np.float64).reshape(-1, 3),
    )

    ps = g.create_group("prestress")
    ps.create_dataset("label", data=np.asarray(model.prestress.label, np.int32))
    ps.create_dataset("fibre_direction", data=np.asarray(model.prestress.fibre_direction, np.float64).reshape(-1, 3))
    ps.create_dataset("prestrain", data=np.asarray(model.prestress.prestrain, np.float64))

    if model.texture is not None:
        tx = g.create_group("texture")
        vol = np.asarray(model.texture.volume, np.uint8)
        if vol.ndim == 3:
            vol = vol[..., None]
        tx.create_dataset("volume", data=vol, compression="gzip", compression_opts=4, chunks=True)
        tx.create_dataset("spacing", data=np.asarray(model.texture.spacing, np.float64))
        tx.create_dataset("origin", data=np.asarray(model.texture.origin, np.float64))
        tx.create_dataset("direction", data=np.asarray(model.texture.direction, np.float64))

    ex = g.create_group("extra")
    for group_name, arrays in model.extra.items():
        sub = ex.create_group(group_name)
        for name, arr in arrays.items():
            arr = np.asarray(arr)
            if arr.size >= COMPRESS_MIN_ELEMENTS and arr.dtype.kind in "iuf":
                # the progressive record holds the finest mesh (millions of tets): byte shuffle +
                # gzip level 1, transparent to every HDF5 reader: a fifth of the size (docs/model-format.md)
                sub.create_dataset(name, data=arr, chunks=True, shuffle=True, compression="gzip", compression_opts=1)
            else:
                sub.create_dataset(name, data=arr)


def _check_model_shapes(model: TetModel) -> None:
    """Refuse to write a model whose arrays disagree (a bug upstream, said plainly)."""
    n, m = model.n_points, model.n_tets
    problems = []
    if model.points.ndim != 2 or model.points.shape[1] != 3:
        problems.append(f"points has shape {model.points.shape}, expected (n, 3)")
    if model.tets.ndim != 2 or model.tets.shape[1] != 4:
        problems.append(f"tets has shape {model.tets.shape}, expected (m, 4)")
    if model.labels.shape != (m,):
        problems.append(f"labels has shape {model.labels.shape}, expected ({m},)")
    if model.texcoords is not None and model.texcoords.shape != (n, 3):
        problems.append(f"texcoords has shape {model.texcoords.shape}, expected ({n}, 3)")
    for name, arr in model.point_data.items():
        if name in RESERVED_POINT_DATA or np.shape(arr)[:1] != (n,):
            problems.append(f"point_data[{name!r}] is reserved or not one row per node")
    for name, arr in model.cell_data.items():
        if name in RESERVED_CELL_DATA or np.shape(arr)[:1] != (m,):
            problems.append(f"cell_data[{name!r}] is reserved or not one row per tet")
    if problems:
        raise ModelFormatError("cannot write model: " + "; ".join(problems))


# --------------------------------------------------------------------------- reading


def read_schema_version(path: str | os.PathLike) -> int:
    """Schema version stored in a model file (raises ModelFormatError if it is not a model)."""
    path = Path(path)
    with _open(path) as f:
        return _schema_version(f, path)


def read_model(path: str | os.PathLike) -> TetModel:
    """Read and validate a model file.

    Checks the schema version, every dataset's presence, shape and dtype,
    node index ranges and finite coordinates.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    TetModel

    Raises
    ------
    InputError
        The file does not exist.
    ModelFormatError
        Anything wrong with its content; the message names the dataset.
    """
    path = Path(path)
    with _open(path) as f:
        version = _schema_version(f, path)
        if version not in READABLE_VERSIONS:
            raise ModelFormatError(
                f"{path}: schema version {version} is not supported (this cutkit reads versions "
                f"{', '.join(map(str, READABLE_VERSIONS))})"
            )
        r = _Reader(f, path, version)
        model = r.read()
    return model


def _open(path: Path) -> h5py.File:
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a model file")
    try:
        return h5py.File(path, "r")
    except OSError as err:
        reason = "truncated" if "truncated" in str(err).lower() else "not an HDF5 file or corrupt"
        raise ModelFormatError(f"{path}: cannot open model file ({reason})") from None


def _schema_version(f: h5py.File, path: Path) -> int:
    if "cutkit" not in f:
        raise ModelFormatError(f"{path}: not a cutkit model (no /cutkit group)")
    try:
        return int(f["cutkit"].attrs["schema_version"])
    except (KeyError, TypeError, ValueError):
        raise ModelFormatError(f"{path}: /cutkit has no valid schema_version attribute") from None


class _Reader:
    """Reads datasets with checks; every error names ``path`` and the dataset."""

    def __init__(self, f: h5py.File, path: Path, version: int = SCHEMA_VERSION):
        self.f = f
        self.path = path
        self.version = version

    def fail(self, name: str, what: str):
        raise ModelFormatError(f"{self.path}: {name} {what}")

    def get(self, name: str, kind: str, shape: tuple, optional: bool = False):
        """Read dataset ``name``; ``kind`` is a numpy kind ('f', 'i', 'u', 'iu', 'O');
        ``shape`` uses None for free axes."""
        if name not in self.f:
            if optional:
                return None
            self.fail(name, "is missing")
        obj = self.f[name]
        if not isinstance(obj, h5py.Dataset):
            self.fail(name, "is not a dataset")
        try:
            if kind == "O":
                data = np.array([s.decode() if isinstance(s, bytes) else str(s) for s in obj[()]], dtype=object)
            else:
                data = obj[()]
        except Exception as err:  # HDF5 raises many kinds on damaged data
            self.fail(name, f"cannot be read ({type(err).__name__}: {' '.join(str(err).split())})")
        data = np.asarray(data)
        if kind != "O" and data.dtype.kind not in kind:
            self.fail(name, f"has dtype {data.dtype}, expected {_kind_name(kind)}")
        if len(shape) != data.ndim or any(s is not None and s != d for s, d in zip(shape, data.shape)):
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
            self.fail(name, f"has shape {data.shape}, expected {want}")
        return data

    def read(self) -> TetModel:
        f, path = self.f, self.path
        if "VTKHDF" not in f:
            raise ModelFormatError(f"{path}: /VTKHDF group is missing")
        points = self.get("VTKHDF/Points", "f", (None, 3)).astype(np.float64)
        n = points.shape[0]
        n_pts_decl = self.get("VTKHDF/NumberOfPoints", "iu", (1,))
        if int(n_pts_decl[0]) != n:
            self.fail("VTKHDF/NumberOfPoints", f"says {int(n_pts_decl[0])} but /VTKHDF/Points has {n} rows")
        bad = ~np.isfinite(points)
        if bad.any():
            first = int(np.argwhere(bad.any(axis=1))[0, 0])
            self.fail("VTKHDF/Points", f"has {int(bad.any(axis=1).sum())} nodes with non-finite coordinates (first: node {first})")

        types = self.get("VTKHDF/Types", "u", (None,))
        m = types.shape[0]
        n_cells_decl = self.get("VTKHDF/NumberOfCells", "iu", (1,))
        if int(n_cells_decl[0]) != m:
            self.fail("VTKHDF/NumberOfCells", f"says {int(n_cells_decl[0])} but /VTKHDF/Types has {m} cells")
        if m and np.any(types != VTK_TETRA):
            first = int(np.argmax(types != VTK_TETRA))
            self.fail("VTKHDF/Types", f"has cell {first} of VTK type {int(types[first])}; only tetrahedra (10) are allowed")
        offsets = self.get("VTKHDF/Offsets", "iu", (m + 1,))
        if not np.array_equal(offsets, np.arange(0, 4 * m + 1, 4)):
            self.fail("VTKHDF/Offsets", "is not 0, 4, 8, ... (every cell must have 4 nodes)")
        conn = self.get("VTKHDF/Connectivity", "iu", (4 * m,)).astype(np.int64)
        if conn.size and (conn.min() < 0 or conn.max() >= n):
            badi = int(np.argmax((conn < 0) | (conn >= n)))
            self.fail(
                "VTKHDF/Connectivity",
                f"has node index {int(conn[badi])} (tet {badi // 4}) out of range [0, {n})",
            )
        tets = conn.reshape(m, 4)
        labels = self.get("VTKHDF/CellData/label", "iu", (m,)).astype(np.int32)

        materials = self._materials()
        if materials.n_materials and m:
            missing = np.setdiff1d(np.unique(labels), materials.label)
            if missing.size:
                self.fail("VTKHDF/CellData/label", f"has label {int(missing[0])} with no row in /cutkit/materials")

        boundary = BoundaryConditions(
            fixed_nodes=self._node_index("cutkit/boundary/fixed_nodes", n),
            prescribed_nodes=self._node_index("cutkit/boundary/prescribed_nodes", n),
        )
        p = boundary.prescribed_nodes.shape[0]
        disp = self.get("cutkit/boundary/prescribed_displacement", "f", (p, 3))
        self._finite("cutkit/boundary/prescribed_displacement", disp)
        boundary.prescribed_displacement = disp.astype(np.float64)

        q_label = self.get("cutkit/prestress/label", "iu", (None,)).astype(np.int32)
        q = q_label.shape[0]
        fibre = self.get("cutkit/prestress/fibre_direction", "f", (q, 3)).astype(np.float64)
        prestrain = self.get("cutkit/prestress/prestrain", "f", (q,)).astype(np.float64)
        self._finite("cutkit/prestress/fibre_direction", fibre)
        self._finite("cutkit/prestress/prestrain", prestrain)
        prestress = Prestress(label=q_label, fibre_direction=fibre, prestrain=prestrain)

        texture = None
        if "cutkit/texture" in f:
            vol = self.get("cutkit/texture/volume", "u", (None, None, None, None))
            if vol.shape[3] not in (1, 3) or min(vol.shape[:3]) < 2:
                self.fail("cutkit/texture/volume", f"has shape {vol.shape}; expected (nx>=2, ny>=2, nz>=2, 1 or 3)")
            spacing = self.get("cutkit/texture/spacing", "f", (3,))
            origin = self.get("cutkit/texture/origin", "f", (3,))
            direction = self.get("cutkit/texture/direction", "f", (3, 3))
            for nm, arr in (("spacing", spacing), ("origin", origin), ("direction", direction)):
                self._finite(f"cutkit/texture/{nm}", arr)
            if np.any(spacing <= 0):
                self.fail("cutkit/texture/spacing", "must be positive")
            texture = Texture(volume=vol.astype(np.uint8), spacing=spacing, origin=origin, direction=direction)

        texcoords = self.get("VTKHDF/PointData/texcoords", "f", (n, 3), optional=True)
        if texcoords is not None:
            self._finite("VTKHDF/PointData/texcoords", texcoords)
            texcoords = texcoords.astype(np.float64)

        point_data = self._data_group("VTKHDF/PointData", n, RESERVED_POINT_DATA)
        cell_data = self._data_group("VTKHDF/CellData", m, RESERVED_CELL_DATA)

        try:
            provenance = json.loads(f["cutkit"].attrs.get("provenance", "{}"))
        except (TypeError, ValueError):
            self.fail("cutkit provenance attribute", "is not valid JSON")
        if self.version < SCHEMA_VERSION:
            provenance["schema_upgrade"] = {"from_version": self.version, "to_version": SCHEMA_VERSION,
                                            "J_c": V2_J_C}
            if self.version == 1:
                provenance["schema_upgrade"].update(poisson_ratio=V1_POISSON_RATIO,
                                                    material_model=DEFAULT_MATERIAL_MODEL)

        extra = {}
        if "cutkit/extra" in f:
            for gname, grp in f["cutkit/extra"].items():
                if isinstance(grp, h5py.Group):
                    extra[gname] = {k: self.get(f"cutkit/extra/{gname}/{k}", "biuf", (None,) * grp[k].ndim) for k in grp}

        return TetModel(
            points=np.ascontiguousarray(points),
            tets=np.ascontiguousarray(tets),
            labels=labels,
            materials=materials,
            boundary=boundary,
            prestress=prestress,
            texture=texture,
            texcoords=texcoords,
            point_data=point_data,
            cell_data=cell_data,
            provenance=provenance,
            extra=extra,
        )

    def _materials(self) -> Materials:
        label = self.get("cutkit/materials/label", "iu", (None,)).astype(np.int32)
        k = label.shape[0]
        if np.unique(label).size != k:
            self.fail("cutkit/materials/label", "has repeated labels")
        names = self.get("cutkit/materials/name", "O", (k,))
        values = {}
        for key in MATERIAL_FIELDS:
            if self.version == 1 and key == "poisson_ratio":
                values[key] = np.full(k, V1_POISSON_RATIO)
                continue
            if self.version < 3 and key == "J_c":
                values[key] = np.full(k, V2_J_C)
                continue
            col = self.get(f"cutkit/materials/{key}", "f", (k,)).astype(np.float64)
            self._finite(f"cutkit/materials/{key}", col)
            values[key] = col
        nu = values["poisson_ratio"]
        if np.any((nu < 0.0) | (nu >= 0.5)):
            self.fail("cutkit/materials/poisson_ratio", f"has {float(nu[np.argmax((nu < 0) | (nu >= 0.5))])}, "
                      "outside [0, 0.5)")
        material_model = DEFAULT_MATERIAL_MODEL
        if self.version >= 2 and "cutkit/materials" in self.f:
            raw = self.f["cutkit/materials"].attrs.get("material_model", DEFAULT_MATERIAL_MODEL)
            material_model = raw.decode() if isinstance(raw, bytes) else str(raw)
            if material_model not in MATERIAL_MODELS:
                self.fail("cutkit/materials attribute material_model",
                          f"is {material_model!r}, not one of {', '.join(MATERIAL_MODELS)}")
        return Materials(label=label, name=[str(s) for s in names], values=values, material_model=material_model)

    def _node_index(self, name: str, n: int) -> np.ndarray:
        idx = self.get(name, "iu", (None,)).astype(np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            bad = int(idx[np.argmax((idx < 0) | (idx >= n))])
            self.fail(name, f"has node index {bad} out of range [0, {n})")
        return idx

    def _finite(self, name: str, arr: np.ndarray) -> None:
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            self.fail(name, "has non-finite values")

    def _data_group(self, group: str, rows: int, reserved: tuple) -> dict:
        out = {}
        if group not in self.f:
            return out
        for name, ds in self.f[group].items():
            if name in reserved or not isinstance(ds, h5py.Dataset):
                continue
            arr = self.get(f"{group}/{name}", "biuf", (rows,) + (None,) * (ds.ndim - 1))
            out[name] = arr
        return out


def _kind_name(kind: str) -> str:
    names = {"f": "floating point", "i": "signed integer", "u": "unsigned integer", "b": "boolean"}
    return " or ".join(names[k] for k in kind if k in names)
