"""Small meshes for the check and CLI tests."""

import numpy as np

from cutkit.mesh.generate import box_mesh


def merge(points, tets):
    """Merge coincident nodes (exact coordinates)."""
    uniq, inv = np.unique(points, axis=0, return_inverse=True)
    return uniq, inv.ravel()[tets]


def hanging_mesh():
    """A unit cube of 6 tets beside a unit cube split 2x2x2 (48 tets): the nodes of the
    split side's x = 1 face that are not cube corners hang on the coarse cube."""
    p1, t1 = box_mesh((1, 1, 1))
    p2, t2 = box_mesh((2, 2, 2), spacing=(0.5, 0.5, 0.5), origin=(1.0, 0.0, 0.0))
    return merge(np.vstack([p1, p2]), np.vstack([t1, t2 + len(p1)]))


def conforming_mesh():
    p1, t1 = box_mesh((1, 1, 1))
    p2, t2 = box_mesh((1, 1, 1), origin=(1.0, 0.0, 0.0))
    return merge(np.vstack([p1, p2]), np.vstack([t1, t2 + len(p1)]))
