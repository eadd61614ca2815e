"""The image volume container shared by readers, segmentation and meshing."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Volume:
    """A 3D image on a regular grid, in world coordinates (mm).

    Attributes
    ----------
    data : (nx, ny, nz) or (nx, ny, nz, c) array
        Voxel values indexed ``[i, j, k]`` along the grid axes.  Scalar
        volumes have three dimensions, RGB volumes a trailing axis of 3,
        label maps an integer dtype.
    spacing : (3,) float64
        Voxel size along i, j, k in mm.
    origin : (3,) float64
        World position (mm) of the centre of voxel (0, 0, 0).
    direction : (3, 3) float64
        Columns are the unit world directions of the i, j, k axes.
    """

    data: np.ndarray
    spacing: np.ndarray = field(default_factory=lambda: np.ones(3))
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self):
        self.spacing = np.asarray(self.spacing, np.float64).reshape(3)
        self.origin = np.asarray(self.origin, np.float64).reshape(3)
        self.direction = np.asarray(self.direction, np.float64).reshape(3, 3)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.data.shape[:3])

    @property
    def n_channels(self) -> int:
        return 1 if self.data.ndim == 3 else int(self.data.shape[3])

    @property
    def affine(self) -> np.ndarray:
        """(4, 4) float64 matrix taking homogeneous voxel indices to world mm."""
        a = np.eye(4)
        a[:3, :3] = self.direction * self.spacing[None, :]
        a[:3, 3] = self.origin
        return a

    def index_to_world(self, ijk: np.ndarray) -> np.ndarray:
        """World positions (mm) of continuous voxel indices, ``(n, 3) -> (n, 3)``."""
        ijk = np.asarray(ijk, np.float64)
        return self.origin + (ijk * self.spacing) @ self.direction.T

    def world_to_index(self, xyz: np.ndarray) -> np.ndarray:
        """Continuous voxel indices of world positions, ``(n, 3) -> (n, 3)``."""
        xyz = np.asarray(xyz, np.float64)
        return ((xyz - self.origin) @ self.direction) / self.spacing
