"""Static equilibrium of a spring model by a sparse Newton solve.

The reference the time integrators converge to: the minimum of the
potential energy  sum_s 1/2 k_s (|x_b - x_a| - l_s)^2 - sum_k (f_k + m_k g) . x_k
over the free nodes.  Meant for checks and small to medium models.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from cutkit.relax.integrate import control_arrays, spring_energy, spring_forces
from cutkit.relax.model import Control, SpringModel

#: Newton stops when the largest free-node force residual is below this, N.
RESIDUAL_TOLERANCE = 1e-10
MAX_NEWTON_ITERATIONS = 100


def _potential(model, x, f_ext, gravity):
    load = f_ext + model.masses[:, None] * gravity
    return spring_energy(model, x) - float(np.sum(load * x))


def _hessian(model: SpringModel, x: np.ndarray) -> sp.csr_matrix:
    """Spring stiffness matrix with the transverse term clipped at 0 (positive semi-definite)."""
    a, b = model.springs[:, 0], model.springs[:, 1]
    d = x[b] - x[a]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    u = d / length[:, None]
    k = model.stiffness
    t = np.maximum(1.0 - model.rest_length / length, 0.0)
    blocks = k[:, None, None] * (u[:, :, None] * u[:, None, :] * (1.0 - t)[:, None, None] + t[:, None, None] * np.eye(3))
    n3 = 3 * model.n_nodes
    ii = np.arange(3)
    rows, cols, vals = [], [], []
    for p, q, sign in ((a, a, 1.0), (b, b, 1.0), (a, b, -1.0), (b, a, -1.0)):
        rows.append((3 * p[:, None, None] + ii[None, :, None]) + 0 * ii[None, None, :])
        cols.append((3 * q[:, None, None] + ii[None, None, :]) + 0 * ii[None, :, None])
        vals.append(sign * blocks)
    rows = np.concatenate([r.ravel() for r in rows])
    cols = np.concatenate([c.ravel() for c in cols])
    vals = np.concatenate([v.ravel() for v in vals])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n3, n3))


def static_equilibrium(model: SpringModel, control: Control | None = None, x0: np.ndarray | None = None) -> np.ndarray:
    """Equilibrium positions under the control's forces and gravity.

    Parameters
    ----------
    model : SpringModel
    control : Control, optional
    x0 : (n, 3) float64, optional
        Start (default: rest positions plus prescribed displacements).

    Returns
    -------
    positions : (n, 3) float64, mm
        Fixed nodes sit at rest plus their prescribed displacement.
    """
    f_ext, g = control_arrays(model, control)
    x = (model.rest_positions + model.prescribed_displacement) if x0 is None else np.array(x0, np.float64)
    x[model.fixed] = (model.rest_positions + model.prescribed_displacement)[model.fixed]
    free = np.flatnonzero(~np.repeat(model.fixed, 3))
    load = f_ext + model.masses[:, None] * g
    for _ in range(MAX_NEWTON_ITERATIONS):
        r = (spring_forces(model, x) + load).ravel()  # minus the gradient
        if np.max(np.abs(r[free]), initial=0.0) < RESIDUAL_TOLERANCE:
            break
        H = _hessian(model, x)[free][:, free].tocsc()
        # a tiny shift keeps floating (unconstrained) directions solvable
        H = H + sp.identity(len(free), format="csc") * (1e-12 * H.diagonal().max())
        dx = np.zeros(x.size)
        dx[free] = spl.spsolve(H, r[free])
        e0 = _potential(model, x, f_ext, g)
        alpha = 1.0
        while alpha > 1e-6:
            xn = x + alpha * dx.reshape(-1, 3)
            if _potential(model, xn, f_ext, g) <= e0:
                break
            alpha *= 0.5
        x = xn
    return x
