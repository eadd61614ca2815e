"""Simple structured tetrahedral meshes for tests, benchmarks and examples."""

from __future__ import annotations

from itertools import permutations

import numpy as np

from cutkit.mesh.geometry import tet_volumes

# Kuhn (Freudenthal) split of the unit cube into six tetrahedra that share the
# main diagonal (0,0,0)-(1,1,1): one tet per axis permutation, walking from the
# first to the last corner one axis at a time.  Every cube uses the same
# diagonal direction, so neighbouring cubes agree on their shared faces.
_KUHN_CORNERS = []
for _perm in permutations(range(3)):
    _c = np.zeros(3, int)
    _path = [tuple(_c)]
    for _axis in _perm:
        _c = _c.copy()
        _c[_axis] = 1
        _path.append(tuple(_c))
    _KUHN_CORNERS.append(_path)
#: (6, 4, 3) int: the corners (offsets in {0,1}^3) of the six Kuhn tetrahedra of a cube.
KUHN_TETS = np.array(_KUHN_CORNERS, dtype=np.int64)


def box_mesh(shape=(4, 4, 4), spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)):
    """A box of ``shape`` cubes, each split into six positively oriented tetrahedra.

    Parameters
    ----------
    shape : (3,) int
        Number of cubes along x, y, z.
    spacing : (3,) float
        Cube edge lengths, mm.
    origin : (3,) float
        Position of the first corner, mm.

    Returns
    -------
    points : (n_points, 3) float64
        Grid nodes, indexed ``i * (ny+1) * (nz+1) + j * (nz+1) + k``.
    tets : (6 * nx * ny * nz, 4) int64
        Positively oriented tetrahedra.
    """
    nx, ny, nz = (int(s) for s in shape)
    spacing = np.asarray(spacing, np.float64)
    origin = np.asarray(origin, np.float64)
    gi, gj, gk = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    points = origin + np.stack([gi.ravel(), gj.ravel(), gk.ravel()], axis=1) * spacing

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    ci, cj, ck = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    ci, cj, ck = ci.ravel(), cj.ravel(), ck.ravel()
    tets = np.empty((6 * ci.size, 4), np.int64)
    for t, corners in enumerate(KUHN_TETS):
        for v, (a, b, c) in enumerate(corners):
            tets[t::6, v] = node(ci + a, cj + b, ck + c)
    # Odd permutations give negatively oriented tets: swap two nodes to fix.
    neg = tet_volumes(points, tets) < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    return points, tets


def voxel_mesh(mask, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), labels=None):
    """Tetrahedralise the voxels of a mask, six Kuhn tets per voxel (a staircase boundary).

    Voxel (i, j, k) becomes the cube with corners ``origin + (i..i+1, j..j+1, k..k+1) * spacing``.

    Parameters
    ----------
    mask : (nx, ny, nz) bool or integer
        Voxels to mesh (non-zero).
    spacing, origin : (3,) float
    labels : (nx, ny, nz) integer, optional
        Label of each voxel; defaults to ``mask`` itself when it is integer, else 1.

    Returns
    -------
    points : (n_points, 3) float64
        Only the nodes used by a tet.
    tets : (6 * n_voxels, 4) int64
        Positively oriented.
    tet_labels : (6 * n_voxels,) int32
    """
    mask = np.asarray(mask)
    if labels is None:
        labels = mask.astype(np.int32) if mask.dtype.kind in "iu" else np.ones(mask.shape, np.int32)
    points, tets = box_mesh(mask.shape, spacing, origin)
    keep = np.repeat(mask.ravel() != 0, 6)
    tets = tets[keep]
    tet_labels = np.repeat(np.asarray(labels).ravel(), 6)[keep].astype(np.int32)
    used, inverse = np.unique(tets, return_inverse=True)
    return points[used], inverse.reshape(tets.shape).astype(np.int64), tet_labels
