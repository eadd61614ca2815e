"""Containers of a tetrahedral tissue model (struct of arrays).

Everything here is what does not change while a model is simulated
(rest geometry, materials, boundary conditions) plus the texture that
colours it.  Per-step simulation state lives in the runtime modules.

Units: lengths in mm, forces in N, stiffness E in Pa, density in kg/m^3.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Numeric columns of the materials table, in file order, with their units.
#: The cut parameters are those of the paper's section 6 (eqs. 12-18).
MATERIAL_FIELDS: dict[str, str] = {
    "E": "Pa",  # Young's modulus; also the stiffness eta of eqs. (13), (16), (17)
    "poisson_ratio": "1",  # of the element model (schema version 2); the springs have their own, see docs
    "density": "kg/m^3",
    "damping": "1/s",  # mass-proportional damping: D = damping * m in eq. (1)
    "F_enter": "N",  # static cut friction threshold, eq. (12)
    "mu_static": "N/(Pa*mm)",  # tissue opening coefficient, eq. (13)
    "mu_dynamic": "N/(Pa*mm)",  # eq. (16)
    "rho_dynamic": "N*s/(Pa*mm^3)",  # displacement (viscosity) coefficient, eq. (17)
    "alpha_static": "1",  # surface friction coefficient, eq. (14)
    "alpha_dynamic": "1",  # eq. (18)
    "c_edge": "1",  # sharpness of the blade's edge (small = sharp)
    "c_shape": "1",  # shape of the blade
    "J_c": "J/m^2",  # fracture toughness of the fracture scalpel model (schema version 3); J/m^2 = N/m
}

#: Fields a row may leave out, with the value it then gets: J_c (J/m^2), the "muscle" row of
#: cutkit.assign.defaults, within the 550-8,000 J/m^2 published for muscle (a table written before
#: the fracture model had none; the model file reader gives older files the same value).
MATERIAL_FIELD_DEFAULTS: dict[str, float] = {"J_c": 2000.0}


#: Constitutive models a model can name: the element model (stable
#: neo-Hookean tetrahedra, docs/relaxation.md) and the paper's springs.
MATERIAL_MODELS = ("neohookean", "springs")
#: What a model that names none is simulated with.
DEFAULT_MATERIAL_MODEL = "neohookean"


@dataclass
class Materials:
    """Materials table, one row per tissue label.

    Attributes
    ----------
    label : (k,) int32
        Tissue label of each row; unique.
    name : list of str
        Tissue name of each row (``"skin"``, ``"muscle"``, ...).
    values : dict of str to (k,) float64
        One column per entry of :data:`MATERIAL_FIELDS`.
    material_model : str
        One of :data:`MATERIAL_MODELS`: how the tissue is simulated unless a
        run says otherwise.
    """

    label: np.ndarray
    name: list[str]
    values: dict[str, np.ndarray]
    material_model: str = DEFAULT_MATERIAL_MODEL

    def __getitem__(self, column: str) -> np.ndarray:
        return self.values[column]

    @property
    def n_materials(self) -> int:
        return int(self.label.shape[0])

    def row_of(self, labels: np.ndarray) -> np.ndarray:
        """Row index of each label in ``labels``; -1 where the table has none.

        Parameters
        ----------
        labels : (m,) integer
        Returns
        -------
        rows : (m,) int64
        """
        labels = np.asarray(labels)
        order = np.argsort(self.label)
        sorted_labels = self.label[order]
        pos = np.searchsorted(sorted_labels, labels)
        pos = np.clip(pos, 0, max(len(sorted_labels) - 1, 0))
        found = (len(sorted_labels) > 0) & (sorted_labels[pos] == labels) if len(sorted_labels) else np.zeros(labels.shape, bool)
        rows = np.where(found, order[pos] if len(order) else 0, -1)
        return rows.astype(np.int64)

    @classmethod
    def empty(cls) -> "Materials":
        return cls(
            label=np.zeros(0, np.int32),
            name=[],
            values={k: np.zeros(0, np.float64) for k in MATERIAL_FIELDS},
        )

    @classmethod
    def from_rows(cls, rows: list[dict], material_model: str = DEFAULT_MATERIAL_MODEL) -> "Materials":
        """Build the table from dicts with ``label``, ``name`` and every material field.

        A field of :data:`MATERIAL_FIELD_DEFAULTS` left out of a row gets its default there.
        """
        label = np.array([int(r["label"]) for r in rows], np.int32)
        name = [str(r["name"]) for r in rows]
        values = {k: np.array([float(r[k] if k in r or k not in MATERIAL_FIELD_DEFAULTS else MATERIAL_FIELD_DEFAULTS[k])
                               for r in rows], np.float64) for k in MATERIAL_FIELDS}
        return cls(label=label, name=name, values=values, material_model=material_model)

    def rows(self) -> list[dict]:
        """The table as a list of dicts (label, name and every material field)."""
        out = []
        for i in range(self.n_materials):
            row = {"label": int(self.label[i]), "name": self.name[i]}
            row.update({k: float(v[i]) for k, v in self.values.items()})
            out.append(row)
        return out


@dataclass
class BoundaryConditions:
    """Displacement boundary conditions.

    Attributes
    ----------
    fixed_nodes : (f,) int64
        Nodes held at their rest position.
    prescribed_nodes : (p,) int64
        Nodes moved by a prescribed displacement.
    prescribed_displacement : (p, 3) float64
        Displacement of each prescribed node, mm.
    """

    fixed_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    prescribed_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    prescribed_displacement: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))

    def held_mask(self, n_points: int) -> np.ndarray:
        """(n_points,) bool: the nodes these conditions hold, fixed or prescribed."""
        mask = np.zeros(int(n_points), bool)
        mask[np.asarray(self.fixed_nodes, np.int64)] = True
        mask[np.asarray(self.prescribed_nodes, np.int64)] = True
        return mask


@dataclass
class Prestress:
    """Anisotropic prestress per tissue label (paper section 7.3).

    Attributes
    ----------
    label : (k,) int32
        Tissue labels that are prestressed.
    fibre_direction : (k, 3) float64
        Unit fibre direction of each label.
    prestrain : (k,) float64
        Fractional shortening of spring rest lengths along the fibre
        (0.05 = rest length 5% shorter along the fibre), so that a cut opens.
    """

    label: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    fibre_direction: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float64))
    prestrain: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))


@dataclass
class Texture:
    """A 3D texture volume and how world coordinates map into it.

    Attributes
    ----------
    volume : (nx, ny, nz, c) uint8
        Grey (c = 1) or RGB (c = 3) voxels, indexed ``[i, j, k]`` along x, y, z.
    spacing : (3,) float64
        Voxel size in mm.
    origin : (3,) float64
        World position (mm) of voxel (0, 0, 0).
    direction : (3, 3) float64
        Columns are the world directions of the i, j, k axes.
    """

    volume: np.ndarray
    spacing: np.ndarray
    origin: np.ndarray
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))

    def world_to_index(self, points: np.ndarray) -> np.ndarray:
        """Continuous voxel indices of world points.

        Parameters
        ----------
        points : (n, 3) float64, mm
        Returns
        -------
        ijk : (n, 3) float64
        """
        local = (np.asarray(points, np.float64) - self.origin) @ self.direction
        return local / self.spacing

    def index_to_texcoord(self, ijk: np.ndarray) -> np.ndarray:
        """Normalised texture coordinates in [0, 1] (voxel centres at (i + 0.5) / n)."""
        shape = np.array(self.volume.shape[:3], np.float64)
        return (np.asarray(ijk, np.float64) + 0.5) / shape

    def texcoord_to_index(self, uvw: np.ndarray) -> np.ndarray:
        shape = np.array(self.volume.shape[:3], np.float64)
        return np.asarray(uvw, np.float64) * shape - 0.5

    def sample_rgb(self, uvw: np.ndarray) -> np.ndarray:
        """Trilinearly sampled colour at texture coordinates.

        Parameters
        ----------
        uvw : (n, 3) float64
            Normalised texture coordinates.
        Returns
        -------
        rgb : (n, 3) uint8
            Grey textures are repeated into three channels.
        """
        vol = self.volume
        shape = np.array(vol.shape[:3])
        ijk = self.texcoord_to_index(uvw)
        ijk = np.clip(ijk, 0.0, shape - 1.0)
        i0 = np.minimum(np.floor(ijk).astype(np.int64), shape - 2).clip(0)
        f = ijk - i0
        i1 = np.minimum(i0 + 1, shape - 1)
        acc = np.zeros((ijk.shape[0], vol.shape[3]), np.float64)
        for dx in (0, 1):
            wx = f[:, 0] if dx else 1.0 - f[:, 0]
            ix = i1[:, 0] if dx else i0[:, 0]
            for dy in (0, 1):
                wy = f[:, 1] if dy else 1.0 - f[:, 1]
                iy = i1[:, 1] if dy else i0[:, 1]
                for dz in (0, 1):
                    wz = f[:, 2] if dz else 1.0 - f[:, 2]
                    iz = i1[:, 2] if dz else i0[:, 2]
                    acc += (wx * wy * wz)[:, None] * vol[ix, iy, iz, :]
        rgb = np.clip(np.rint(acc), 0, 255).astype(np.uint8)
        if rgb.shape[1] == 1:
            rgb = np.repeat(rgb, 3, axis=1)
        return rgb


@dataclass
class TetModel:
    """A tetrahedral tissue model.

    Attributes
    ----------
    points : (n, 3) float64
        Node positions, mm.
    tets : (m, 4) int64
        Node indices of each tetrahedron, positively oriented
        (``det[p1 - p0, p2 - p0, p3 - p0] > 0``).
    labels : (m,) int32
        Tissue label of each tetrahedron (a row of ``materials``).
    materials : Materials
    boundary : BoundaryConditions
    prestress : Prestress
    texture : Texture or None
    texcoords : (n, 3) float64 or None
        Normalised 3D-texture coordinates of each node.
    point_data : dict of str to (n, ...) arrays
        Further per-node arrays (written as VTKHDF point data).
    cell_data : dict of str to (m, ...) arrays
        Further per-tet arrays (written as VTKHDF cell data).
    provenance : dict
        JSON-serialisable: cutkit version, recipe, input hashes, stage parameters.
    extra : dict of str to dict of str to arrays
        Named groups written by later stages (e.g. the progressive-mesh record).
    """

    points: np.ndarray
    tets: np.ndarray
    labels: np.ndarray
    materials: Materials = field(default_factory=Materials.empty)
    boundary: BoundaryConditions = field(default_factory=BoundaryConditions)
    prestress: Prestress = field(default_factory=Prestress)
    texture: Texture | None = None
    texcoords: np.ndarray | None = None
    point_data: dict[str, np.ndarray] = field(default_factory=dict)
    cell_data: dict[str, np.ndarray] = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    extra: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    @classmethod
    def from_arrays(cls, points, tets, labels=None, **kwargs) -> "TetModel":
        """Build a model from plain arrays, normalising dtypes and contiguity."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        tets = np.ascontiguousarray(tets, dtype=np.int64)
        if labels is None:
            labels = np.ones(tets.shape[0], np.int32)
        labels = np.ascontiguousarray(labels, dtype=np.int32)
        return cls(points=points, tets=tets, labels=labels, **kwargs)
