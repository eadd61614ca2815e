"""Write ``cut_path_meshes.npz``: the small gmsh and decimated isovolume meshes of the thousand-path test.

    python tests/data/make_cut_path_meshes.py

* ``gmsh_points``, ``gmsh_tets``: gmsh's Delaunay tetrahedralisation of the
  box [0, 4] x [0, 2] x [0, 2] at mesh size 0.8;
* ``decimated_points``, ``decimated_tets``: the isovolume of an ellipsoid
  (radii 4.2, 2.8, 2.8 voxels in a 10 x 7 x 7 field) decimated to 40 % of
  its tets, moved to start at the origin.
"""

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))


def main():
    from _fem_reference import delaunay_box

    from cutkit.decimate import decimate
    from cutkit.isovolume import isovolume
    from cutkit.volumes import Volume

    gp, gt = delaunay_box(np.array([4.0, 2.0, 2.0]), 0.8)
    g = np.mgrid[0:10, 0:7, 0:7].astype(float)
    c, r = np.array([4.5, 3.0, 3.0]), np.array([4.2, 2.8, 2.8])
    f = 1.0 - (((g - c[:, None, None, None]) / r[:, None, None, None]) ** 2).sum(0)
    d = decimate(isovolume(Volume(f), level=0.0), ratio=0.4)
    np.savez_compressed(os.path.join(HERE, "cut_path_meshes.npz"), gmsh_points=gp, gmsh_tets=gt.astype(np.int64),
                        decimated_points=d.points - d.points.min(axis=0), decimated_tets=d.tets.astype(np.int64))


if __name__ == "__main__":
    main()
