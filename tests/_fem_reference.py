"""Reference solutions for the element model: linear P1 FEM (scikit-fem) and test meshes."""

import numpy as np

from cutkit.decimate.optimize import _ignore_sigpipe_again
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import signed_volumes


def kuhn_box(L, n):
    """Kuhn-split box [0, L] (3,) with n (3,) cells per axis, as the isovolume makes: points, tets."""
    L = np.asarray(L, float)
    n = np.asarray(n, int)
    return box_mesh(tuple(n), spacing=tuple(L / n))


def delaunay_box(L, h):
    """gmsh's Delaunay tetrahedralisation of the box [0, L] (3,) at mesh size h: points, tets."""
    import gmsh

    gmsh.initialize(interruptible=False)
    _ignore_sigpipe_again()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("box")
        gmsh.model.occ.addBox(0, 0, 0, *L)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, _, conn = gmsh.model.mesh.getElements(3)
    finally:
        gmsh.finalize()
    points = coords.reshape(-1, 3)
    index = np.zeros(int(tags.max()) + 1, np.int64)
    index[tags.astype(np.int64)] = np.arange(tags.size)
    tets = index[np.asarray(conn[0], np.int64).reshape(-1, 4)]
    used = np.unique(tets)
    remap = np.full(points.shape[0], -1, np.int64)
    remap[used] = np.arange(used.size)
    points, tets = points[used], remap[tets]
    neg = signed_volumes(points, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return np.ascontiguousarray(points), np.ascontiguousarray(tets)


def linear_fem(points, tets, E, nu, fixed, prescribed, loads):
    """Linear elasticity with P1 tetrahedra (scikit-fem): displacement (n, 3).

    Parameters
    ----------
    fixed : (n, 3) bool
        Held components.
    prescribed : (n, 3) float
        Their displacement.
    loads : (n, 3) float
        Nodal forces.
    """
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = skfem.MeshTet(points.T.copy(), tets.T.copy())
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    K = skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis)
    dofs = basis.nodal_dofs  # (3, n): dof of component c of node i
    f = np.zeros(basis.N)
    u = np.zeros(basis.N)
    for c in range(3):
        f[dofs[c]] = loads[:, c]
        u[dofs[c]] = prescribed[:, c]
    D = np.concatenate([dofs[c][fixed[:, c]] for c in range(3)])
    u = skfem.solve(*skfem.condense(K, f, x=u, D=D))
    return np.stack([u[dofs[c]] for c in range(3)], axis=1)
