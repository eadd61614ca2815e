"""Connectivity of a tetrahedral mesh: edges, faces, neighbours, boundary, node -> tets.

Conventions (see docs/mesh-core.md)
-----------------------------------
A tet ``(v0, v1, v2, v3)`` is positively oriented when
``det[p1 - p0, p2 - p0, p3 - p0] > 0``.  Local face ``i`` is the face
opposite local vertex ``i``; its vertex order in :data:`TET_FACES` gives,
by the right-hand rule, a normal pointing OUT of a positively oriented tet.
Local edges are numbered as in :data:`TET_EDGES`.

Unique edges and faces are found by bucketing the sorted vertex tuples by
their smallest vertex (a counting sort) and sorting each small bucket.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cutkit.errors import MeshError
from cutkit.mesh import _topology_kernels as _k
from cutkit.mesh.geometry import TET_EDGES, TET_FACES

__all__ = [
    "TET_FACES",
    "TET_EDGES",
    "unique_edges",
    "unique_faces",
    "tet_neighbors",
    "boundary_faces",
    "face_topology",
    "FaceTopology",
    "node_to_tets",
    "edge_to_tets",
]


def _check_tets(tets, n_points=None) -> np.ndarray:
    """Normalise ``tets`` to a C-contiguous (m, 4) int64 array; raise MeshError on bad input."""
    arr = np.asarray(tets)
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise MeshError(f"tets must have shape (m, 4), got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise MeshError(f"tets must be integer node indices, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.int64)
    if arr.size:
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0:
            raise MeshError(f"tets contain a negative node index ({lo})")
        if n_points is not None and hi >= n_points:
            raise MeshError(f"tets reference node {hi} but there are only {n_points} points")
    return arr


def _unique_rows(rows: np.ndarray, n: int):
    """Unique rows (lexicographic) and inverse of a (k, w) int64 array of ascending rows."""
    if rows.shape[0] == 0:
        return np.zeros((0, rows.shape[1]), np.int64), np.zeros(0, np.int64)
    return _k.unique_rows(rows, np.int64(max(n, int(rows[:, -1].max()) + 1)))


def unique_edges(tets):
    """Unique edges of a tet mesh.

    Parameters
    ----------
    tets : (m, 4) int
        Node indices of each tet.

    Returns
    -------
    edges : (e, 2) int64
        Each edge once, ``edges[:, 0] < edges[:, 1]``, lexicographically sorted.
    tet_edges : (m, 6) int64
        ``tet_edges[t, k]`` is the edge id of local edge ``TET_EDGES[k]`` of tet t.
    """
    tets = _check_tets(tets)
    pairs = _k.sorted_tuples(tets, np.ascontiguousarray(TET_EDGES))
    edges, inverse = _unique_rows(pairs, 0)
    return edges, inverse.reshape(-1, 6)


def _faces(tets: np.ndarray):
    triples = _k.sorted_tuples(tets, np.ascontiguousarray(TET_FACES))
    faces, inverse = _unique_rows(triples, 0)
    face_tets, count = _k.face_tets_from_inverse(inverse, faces.shape[0])
    return faces, inverse.reshape(-1, 4), face_tets, count


def unique_faces(tets):
    """Unique triangular faces of a tet mesh.

    Parameters
    ----------
    tets : (m, 4) int
        Node indices of each tet.

    Returns
    -------
    faces : (f, 3) int64
        Each face once, vertex ids ascending, lexicographically sorted.
    tet_faces : (m, 4) int64
        ``tet_faces[t, i]`` is the id of local face i (opposite vertex i) of tet t.
    face_tets : (f, 2) int64
        The tets on the two sides of each face; ``-1`` where there is none
        (boundary face: ``face_tets[f, 1] == -1``).  A non-manifold face
        shared by more than two tets lists only its first two (see
        :func:`cutkit.mesh.check.check_mesh`).
    """
    tets = _check_tets(tets)
    faces, tet_faces, face_tets, _ = _faces(tets)
    return faces, tet_faces, face_tets


def tet_neighbors(tets):
    """Neighbour of each tet across each of its faces.

    Parameters
    ----------
    tets : (m, 4) int

    Returns
    -------
    neighbors : (m, 4) int64
        ``neighbors[t, i]`` is the tet across face i (opposite vertex i), -1 on the boundary.
    """
    tets = _check_tets(tets)
    _, tet_faces, face_tets, _ = _faces(tets)
    return _k.neighbors_from_faces(tet_faces, face_tets)


class FaceTopology(NamedTuple):
    """Every face relation of a tet mesh, from one pass over its faces (:func:`face_topology`)."""

    faces: np.ndarray  #: (f, 3) int64, as :func:`unique_faces`
    tet_faces: np.ndarray  #: (m, 4) int64, as :func:`unique_faces`
    face_tets: np.ndarray  #: (f, 2) int64, as :func:`unique_faces`
    neighbors: np.ndarray  #: (m, 4) int64, as :func:`tet_neighbors`
    boundary_faces: np.ndarray  #: (b, 3) int64, as :func:`boundary_faces`
    boundary_face_tet: np.ndarray  #: (b,) int64, as :func:`boundary_faces`


def face_topology(tets) -> FaceTopology:
    """:func:`unique_faces`, :func:`tet_neighbors` and :func:`boundary_faces` at the cost of one.

    Parameters
    ----------
    tets : (m, 4) int
        Positively oriented tets.

    Returns
    -------
    FaceTopology
        The same arrays, equal to the last bit, as the three functions give.
    """
    tets = _check_tets(tets)
    faces, tet_faces, face_tets, count = _faces(tets)
    neighbors = _k.neighbors_from_faces(tet_faces, face_tets)
    bfaces, face_tet = _boundary(tets, tet_faces, count)
    return FaceTopology(faces, tet_faces, face_tets, neighbors, bfaces, face_tet)


def _boundary(tets, tet_faces, count):
    """Boundary faces (used by one tet), in their tets' order, oriented by :data:`TET_FACES`."""
    local = np.flatnonzero(count[tet_faces.ravel()] == 1)
    face_tet = local // 4
    faces = tets[face_tet[:, None], TET_FACES[local % 4]]
    return np.ascontiguousarray(faces), face_tet


def boundary_faces(tets):
    """Faces used by exactly one tet, oriented outward.

    Parameters
    ----------
    tets : (m, 4) int
        Positively oriented tets.

    Returns
    -------
    faces : (b, 3) int64
        Boundary triangles in the order of :data:`TET_FACES` of their tet, so
        that the right-hand normal points out of the mesh.
    face_tet : (b,) int64
        The tet each boundary face belongs to.
    """
    tets = _check_tets(tets)
    _, tet_faces, _, count = _faces(tets)
    return _boundary(tets, tet_faces, count)


def node_to_tets(tets, n_points):
    """Node -> tet incidence in compressed sparse row form.

    Parameters
    ----------
    tets : (m, 4) int
    n_points : int

    Returns
    -------
    offsets : (n_points + 1,) int64
    indices : (4 m,) int64
        Tets of node v are ``indices[offsets[v]:offsets[v + 1]]``, ascending.
    """
    n_points = int(n_points)
    tets = _check_tets(tets, n_points)
    return _k.csr_counts(tets, n_points)


def edge_to_tets(tet_edges, n_edges):
    """Edge -> tet incidence in compressed sparse row form.

    Parameters
    ----------
    tet_edges : (m, 6) int64
        Edge ids of each tet (:func:`unique_edges`).
    n_edges : int

    Returns
    -------
    offsets : (n_edges + 1,) int64
    indices : (6 m,) int64
        Tets of edge e are ``indices[offsets[e]:offsets[e + 1]]``, ascending.
    """
    return _k.csr_counts(np.ascontiguousarray(tet_edges, np.int64), int(n_edges))
