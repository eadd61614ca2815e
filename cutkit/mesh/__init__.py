"""Tetrahedral mesh core: topology, element quality and mesh checks."""

from cutkit.mesh.quality import dihedral_angles, min_dihedral_angles, signed_volumes
from cutkit.mesh.topology import (
    TET_EDGES,
    TET_FACES,
    boundary_faces,
    node_to_tets,
    tet_neighbors,
    unique_edges,
    unique_faces,
)

__all__ = [
    "TET_FACES",
    "TET_EDGES",
    "unique_edges",
    "unique_faces",
    "tet_neighbors",
    "boundary_faces",
    "node_to_tets",
    "signed_volumes",
    "dihedral_angles",
    "min_dihedral_angles",
]
