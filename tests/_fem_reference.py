"""Reference solutions for the element model: linear P1 FEM (scikit-fem) and test meshes."""

import numpy as np

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

    gmsh.initialize(interruptible=False)  # it resets SIGPIPE: conftest's _sigpipe_ignored sets it again per test
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


def _p2_basis(L, cells):
    """A structured tet mesh of the box [0, L] and its P2 vector basis (scikit-fem)."""
    import skfem

    axes = [np.linspace(0.0, L[c], int(cells[c]) + 1) for c in range(3)]
    mesh = skfem.MeshTet.init_tensor(*axes)
    return mesh, skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP2()))


def _p2_problem(L, cells, E, nu):
    """:func:`_p2_basis` and its linear stiffness (scikit-fem)."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh, basis = _p2_basis(L, cells)
    return mesh, basis, skfem.asm(linear_elasticity(*lame_parameters(E, nu)), basis)


def p2_composite_block_sag(L, cells, E, nu, traction, split, factor):
    """Quadratic-tet (P2) block of two materials bonded to z = 0, the part x > ``split`` ``factor``
    times stiffer (both Lame constants), under a uniform traction (0, 0, traction) on the soft part's
    top (z = L[2], x < split) (linear elasticity, scikit-fem): the load's work-conjugate deflection
    there, (1 / A) int u_z dA, mm."""
    import skfem
    from skfem.helpers import ddot, eye, sym_grad, trace
    from skfem.models.elasticity import lame_parameters

    lam, mu = lame_parameters(E, nu)
    mesh, basis = _p2_basis(L, cells)

    @skfem.BilinearForm
    def stiffness(u, v, w):
        scale = np.where(w.x[0] > split, factor, 1.0)  # quadrature points lie inside the elements
        eu = sym_grad(u)
        return scale * ddot(2.0 * mu * eu + lam * eye(trace(eu), 3), sym_grad(v))

    top = mesh.facets_satisfying(lambda x: np.isclose(x[2], L[2]) & (x[0] < split))
    held = basis.get_dofs(lambda x: np.isclose(x[2], 0.0)).all()
    return _traction_sag(basis, skfem.asm(stiffness, basis), top, traction, held, split * L[1])


def _cholesky(A, b):
    """x with A x = b for the symmetric positive definite sparse A (cholespy): the condensed P2
    systems are too large for a general sparse LU on a few cores."""
    import cholespy

    A = A.tocsr()
    solver = cholespy.CholeskySolverD(A.shape[0], A.indptr.astype(np.int32), A.indices.astype(np.int32),
                                      A.data, cholespy.MatrixType.CSR)
    x = np.zeros(A.shape[0])
    solver.solve(np.ascontiguousarray(b, np.float64), x)
    return x


def p2_cantilever(L, cells, E, nu, traction):
    """Quadratic-tet (P2) cantilever clamped at x = 0 under a uniform traction (0, 0, traction) on
    x = L[0] (linear elasticity, scikit-fem): the load's work-conjugate deflection,
    (1 / A) int_tip u_z dA, mm."""

    mesh, basis, K = _p2_problem(L, cells, E, nu)
    tip = mesh.facets_satisfying(lambda x: np.isclose(x[0], L[0]))
    held = basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    return _traction_sag(basis, K, tip, traction, held, L[1] * L[2])


def _traction_sag(basis, K, facets, traction, held, area):
    """Solve K u = f for a uniform traction (0, 0, traction) on ``facets``, the dofs ``held`` at 0
    (scikit-fem): the load's work-conjugate deflection (1 / area) int u_z dA, mm."""
    import skfem

    fb = skfem.FacetBasis(basis.mesh, basis.elem, facets=facets)

    @skfem.LinearForm
    def load(v, w):
        return traction * v[2]

    @skfem.Functional
    def uz(w):
        return w["u"][2]

    u = skfem.solve(*skfem.condense(K, skfem.asm(load, fb), D=held), solver=_cholesky)
    return float(uz.assemble(fb, u=fb.interpolate(u))) / area


def p2_block_reaction(L, cells, E, nu, strain):
    """Quadratic-tet (P2) block bonded to z = 0 and to a plate at z = L[2] pressed down by
    ``strain`` L[2] (linear elasticity, scikit-fem): the plate's force, N (positive: pushes back)."""
    import skfem

    mesh, basis, K = _p2_problem(L, cells, E, nu)
    bottom = basis.get_dofs(lambda x: np.isclose(x[2], 0.0)).all()
    top = basis.get_dofs(lambda x: np.isclose(x[2], L[2]))
    top_all, top_z = top.all(), top.all(["u^3"])
    u = np.zeros(basis.N)
    u[top_z] = -strain * L[2]
    u = skfem.solve(*skfem.condense(K, np.zeros(basis.N), x=u, D=np.concatenate([bottom, top_all])), solver=_cholesky)
    return float(-(K @ u)[top_z].sum())


def trust_region_minimum(em, x0, f, free, *, ki=0.0, kd=0.0, y=None, gtol=1e-11, maxiter=500):
    """The minimiser over the ``free`` (n, 3) bool dofs of an element model ``em`` of

        W(x) + sum ki/2 |x - y|^2 + sum kd/2 |x - x0|^2 - f . x

    (``ki``, ``kd`` scalars or (n, 1) float64; ``y`` default ``x0``; static equilibrium with both 0,
    one backward Euler step with ki = m/h^2, kd = c m/h), by scipy's trust-region Newton
    (trust-exact) from ``x0``: gradient from the model's forces, Hessian by central differences of
    it; a method independent of every cutkit solver.  Returns the positions (n, 3) float64.
    """
    from scipy.optimize import minimize

    from cutkit.relax.vbd import elastic_energy, elastic_forces

    y = x0 if y is None else y

    def full(z):
        x = x0.copy()
        x[free] = z
        return x

    def fun(z):
        x = full(z)
        return (elastic_energy(em, x) + 0.5 * float(np.sum(ki * (x - y) ** 2 + kd * (x - x0) ** 2))
                - float(np.sum(f * x)))

    def jac(z):
        x = full(z)
        return -(elastic_forces(em, x) + f - ki * (x - y) - kd * (x - x0))[free]

    def hess(z, e=1e-6):
        cols = []
        for k in range(z.size):
            zp, zm = z.copy(), z.copy()
            zp[k] += e
            zm[k] -= e
            cols.append((jac(zp) - jac(zm)) / (2 * e))
        H = np.array(cols).T
        return 0.5 * (H + H.T)

    res = minimize(fun, x0[free], jac=jac, hess=hess, method="trust-exact", options={"gtol": gtol, "maxiter": maxiter})
    return full(res.x)
