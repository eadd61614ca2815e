"""Small-strain study: ANP with part of the deviatoric energy moved to the nodes, against refined P2.

Usage: python benchmarks/anp_deviatoric_blend.py [--sizes 1,2] [--nus 0.3,0.45,0.49] [--alphas 0,0.5,0.6,0.7] [--ref 3]
       [--quarter-everywhere]

The linear (small-strain) limit of the ANP tetrahedron (:mod:`cutkit.relax.anp`) with the
element's deviatoric energy blended with a node-based smoothed one, the alpha-FEM / selective
smoothed-FEM idea (Liu, Nguyen-Thoi & Lam 2008, "A novel alpha finite element method (alpha-FEM)";
Nguyen-Thoi, Liu et al. 2009, "Selective smoothed finite element method"):

    W = (1 - alpha) sum_e V_e mu |dev eps_e|^2 + sum_a V_a [alpha mu |dev eps_a|^2 + K_a / 2 (tr eps_a)^2]

with eps_a = sum_{e ni a} (V_e / 4) eps_e / V_a the node's smoothed strain; the volumetric term
is exactly ANP's (J_a - 1 = tr eps_a to first order), on the nodes not held, with each tet's
volume shared among its free corners (:func:`cutkit.relax.anp.pressure_shares`).  alpha = 0 is ANP; alpha = 1 is the
selective node-based smoothed FEM, which is over-soft (NS-FEM's spurious low-energy modes).
The nodal term has the same two-ring stencil as ANP's volumetric one.

Solved directly (sparse Cholesky-free LU) on the meshes and problems of
``benchmarks/element_locking.py``; prints one JSON object: per nu, problem, mesh, size and
alpha the ratio to the P2 reference.  The alpha = 0 column reproduces element_locking.py's
ANP column (to the nonlinear solve's small-strain error), which checks this assembly.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parent))

from element_locking import BLOCK, CANTILEVER, E, STRAIN, TRACTION, face_loads, mesh  # noqa: E402
from _fem_reference import p2_block_reaction, p2_cantilever  # noqa: E402

from cutkit.relax.anp import pressure_shares  # noqa: E402

#: [True]: held nodes carry no volume constraint (the runtime's rule); ``--quarter-everywhere``
#: sets [False]: every node does, with the quarter split of Bonet & Burton 1998.
HOLD_CONSTRAINS = [True]
#: vec(I) and the deviatoric projector on 3x3 tensors flattened row-major.
VEC_I = np.eye(3).ravel()
DEV = np.eye(9) - np.outer(VEC_I, VEC_I) / 3.0


def strain_operators(p, t):
    """Per tet the volume (m,) and the operator (m, 9, 12) from corner displacements (3 j + r) to eps."""
    X = p[t]
    Dm = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)
    vol = np.abs(np.linalg.det(Dm)) / 6.0
    inv = np.linalg.inv(Dm)  # rows: grad N_1..3
    b = np.concatenate([-inv.sum(axis=1, keepdims=True), inv], axis=1)  # (m, 4, 3)
    S = np.zeros((t.shape[0], 9, 12))
    for j in range(4):
        for r in range(3):
            for c in range(3):  # eps_rc = (du_r/dx_c + du_c/dx_r) / 2, du_r/dx_c = sum_j u_jr b_jc
                S[:, 3 * r + c, 3 * j + r] += 0.5 * b[:, j, c]
                S[:, 3 * r + c, 3 * j + c] += 0.5 * b[:, j, r]
    return vol, S


def stiffness(p, t, nu, alpha, held):
    """The blended element's small-strain stiffness (3n, 3n) CSR, N/mm, for E and nu; ``held`` (n,)
    bool: the nodes held in all directions, which carry no volume constraint (``pressure_shares``)."""
    n, m = p.shape[0], t.shape[0]
    mu, K = E / (2.0 * (1.0 + nu)), E / (3.0 * (1.0 - 2.0 * nu))
    vol, S = strain_operators(p, t)
    dofs = (3 * t[:, :, None] + np.arange(3)).reshape(m, 12)
    rows = np.repeat(9 * np.arange(m)[:, None] + np.arange(9), 12, axis=1).reshape(m, 9, 12)
    Se = sp.csr_matrix((S.ravel(), (rows.ravel(), np.broadcast_to(dofs[:, None, :], S.shape).ravel())), shape=(9 * m, 3 * n))
    Ke = Se.T @ sp.kron(sp.diags(2.0 * mu * (1.0 - alpha) * vol), sp.csr_matrix(DEV)) @ Se
    # nodal smoothed strain: eps_a = sum_e (V_e / 4) eps_e / V_a
    Va = np.bincount(t.ravel(), np.repeat(vol / 4.0, 4), minlength=n)
    corner = t.ravel()
    A = sp.csr_matrix((np.repeat(vol / 4.0, 4) / Va[corner], (corner, np.repeat(np.arange(m), 4))), shape=(n, m))
    Sn = sp.kron(A, sp.identity(9)) @ Se
    Kn = Sn.T @ sp.kron(sp.diags(Va), sp.csr_matrix(alpha * 2.0 * mu * DEV)) @ Sn
    # the volumetric term on the free nodes: eps_a = sum_e w_ea V_e eps_e / V_a, V_a = sum_e w_ea V_e
    q = (pressure_shares(t, vol, held) * vol[:, None]).ravel()
    Vp = np.bincount(corner, q, minlength=n)
    Ap = sp.csr_matrix((q / np.where(Vp[corner] > 0, Vp[corner], 1.0), (corner, np.repeat(np.arange(m), 4))),
                       shape=(n, m))
    Sp = sp.kron(Ap, sp.identity(9)) @ Se
    Kv = Sp.T @ sp.kron(sp.diags(Vp), sp.csr_matrix(K * np.outer(VEC_I, VEC_I))) @ Sp
    return (Ke + Kn + Kv).tocsr()


def solve(Kmat, fixed_dofs, u_fixed, f):
    """u (3n,) with u[fixed_dofs] = u_fixed and K u = f on the free dofs."""
    u = np.zeros(Kmat.shape[0])
    u[fixed_dofs] = u_fixed
    free = np.setdiff1d(np.arange(Kmat.shape[0]), fixed_dofs)
    rhs = f[free] - Kmat[free][:, fixed_dofs] @ u_fixed
    u[free] = spla.spsolve(Kmat[free][:, free].tocsc(), rhs)
    return u


def cantilever(p, t, nu, alpha):
    Kmat = stiffness(p, t, nu, alpha, (p[:, 0] < 1e-9) & HOLD_CONSTRAINS[0])
    clamped = np.flatnonzero(p[:, 0] < 1e-9)
    fixed = (3 * clamped[:, None] + np.arange(3)).ravel()
    lz = face_loads(p, t, 0, CANTILEVER[0], TRACTION)
    f = np.zeros(3 * p.shape[0])
    f[2::3] = lz
    u = solve(Kmat, fixed, np.zeros(fixed.size), f)
    return float((u[2::3] * lz).sum() / lz.sum())


def block(p, t, nu, alpha):
    top = p[:, 2] > BLOCK[2] - 1e-9
    Kmat = stiffness(p, t, nu, alpha, ((p[:, 2] < 1e-9) | top) & HOLD_CONSTRAINS[0])
    held = np.flatnonzero((p[:, 2] < 1e-9) | top)
    fixed = (3 * held[:, None] + np.arange(3)).ravel()
    uf = np.zeros(fixed.size)
    uf[2::3] = np.where(top[held], -STRAIN * BLOCK[2], 0.0)
    u = solve(Kmat, fixed, uf, np.zeros(3 * p.shape[0]))
    r = -(Kmat @ u)
    return float(r[3 * np.flatnonzero(top) + 2].sum())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1,2")
    ap.add_argument("--nus", default="0.3,0.45,0.49")
    ap.add_argument("--alphas", default="0,0.5,0.6,0.7")
    ap.add_argument("--ref", type=int, default=3)
    ap.add_argument("--quarter-everywhere", action="store_true",
                    help="held nodes keep their volume constraint (plain Bonet & Burton nodal volumes)")
    a = ap.parse_args(argv)
    HOLD_CONSTRAINS[0] = not a.quarter_everywhere
    rs, alphas = a.ref, [float(v) for v in a.alphas.split(",")]
    out = {"reference": f"scikit-fem P2, structured, {rs}x base cells", "results": []}
    for nu in (float(v) for v in a.nus.split(",")):
        ref = {"cantilever": p2_cantilever(CANTILEVER, (10 * rs, 2 * rs, 2 * rs), E, nu, TRACTION),
               "block": p2_block_reaction(BLOCK, (4 * rs, 4 * rs, 2 * rs), E, nu, STRAIN)}
        for name, L, base, run in (("cantilever", CANTILEVER, (10, 2, 2), cantilever), ("block", BLOCK, (4, 4, 2), block)):
            for kind in ("kuhn", "delaunay"):
                for s in (int(v) for v in a.sizes.split(",")):
                    p, t = mesh(kind, L, tuple(s * np.asarray(base)))
                    row = {"nu": nu, "problem": name, "mesh": kind, "size": s, "nodes": int(p.shape[0])}
                    for al in alphas:
                        row[f"alpha_{al:g}"] = round(run(p, t, nu, al) / ref[name], 4)
                    out["results"].append(row)
                    print(json.dumps(row), file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
