"""Face adjacency and boundary faces for building the surface hierarchy."""

from __future__ import annotations

import numpy as np

from cutkit.collision import _kernels as K
from cutkit.mesh.topology import boundary_faces as topology_boundary_faces


def edge_adjacency(faces: np.ndarray) -> np.ndarray:
    """Pairs of positions in ``faces`` sharing an edge, (e, 2) int64 one direction.

    At an edge shared by more than two faces (non-manifold) the faces are
    linked in a chain, which keeps them in one component.
    """
    m = faces.shape[0]
    if m < 2:
        return np.empty((0, 2), dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    owner = np.tile(np.arange(m, dtype=np.int64), 3)
    key = e[:, 0] * (int(faces.max()) + 1) + e[:, 1]
    order = np.argsort(key, kind="stable")
    key = key[order]
    owner = owner[order]
    same = key[1:] == key[:-1]
    pairs = np.stack([owner[:-1][same], owner[1:][same]], axis=1)
    return pairs[pairs[:, 0] != pairs[:, 1]]


def csr_adjacency(pairs: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Symmetric, de-duplicated CSR adjacency from undirected pairs.

    Returns (offsets (n+1,), indices, unique undirected pairs (e, 2) with a<b).
    """
    off, idx = K.adjacency_csr(np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2), n)
    src = np.repeat(np.arange(n, dtype=np.int64), np.diff(off))
    keep = src < idx
    return off, idx, np.stack([src[keep], idx[keep]], axis=1)


def boundary_faces(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boundary faces, outward oriented, and the tet of each (:func:`cutkit.mesh.topology.boundary_faces`).

    Parameters
    ----------
    tets : (m, 4) int64
        Positively oriented tetrahedra.

    Returns
    -------
    faces : (b, 3) int64
    face_tet : (b,) int64
    """
    return topology_boundary_faces(tets)
