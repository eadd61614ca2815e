"""numba kernels of the live views (they check nothing; callers do)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def vertex_normals(points, faces, out):
    """Area-weighted unit vertex normals into ``out``.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int64, indices into ``points``
    out : (n, 3) float32
        Overwritten; zero for points in no face.
    """
    n = points.shape[0]
    acc = np.zeros((n, 3))
    for f in range(faces.shape[0]):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        ux = points[j, 0] - points[i, 0]
        uy = points[j, 1] - points[i, 1]
        uz = points[j, 2] - points[i, 2]
        vx = points[k, 0] - points[i, 0]
        vy = points[k, 1] - points[i, 1]
        vz = points[k, 2] - points[i, 2]
        cx = uy * vz - uz * vy
        cy = uz * vx - ux * vz
        cz = ux * vy - uy * vx
        for v in (i, j, k):
            acc[v, 0] += cx
            acc[v, 1] += cy
            acc[v, 2] += cz
    for v in range(n):
        length = np.sqrt(acc[v, 0] ** 2 + acc[v, 1] ** 2 + acc[v, 2] ** 2)
        if length > 0.0:
            out[v, 0] = acc[v, 0] / length
            out[v, 1] = acc[v, 1] / length
            out[v, 2] = acc[v, 2] / length
        else:
            out[v, 0] = 0.0
            out[v, 1] = 0.0
            out[v, 2] = 0.0
