"""Volumetric locking of the element choices: P1 (``nh``) and ANP (``anp``) against a refined P2 reference.

Usage: python benchmarks/element_locking.py [--sizes 1,2] [--nus 0.3,0.45,0.49] [--ref 3] [--smoothing 0.7]

Two problems, E = 1 MPa, on Kuhn-split and gmsh Delaunay meshes at ``s`` times the base
resolution (cantilever 10 x 2 x 2 mm, 10s x 2s x 2s cells; block 4 x 4 x 2 mm, 4s x 4s x 2s cells):

  cantilever  clamped at x = 0, a uniform traction of 10 Pa along -z on x = 10: the load's
              work-conjugate tip deflection (consistent nodal loads)
  block       bonded to z = 0 and to a plate at z = 2 pressed down by 1 %: the plate's force

Each is solved by cutkit (projected Newton, converged) with each element, and by scikit-fem
with quadratic tets (P2, linear elasticity) on a structured mesh of ``--ref`` times the base
cells.  Prints one JSON object: per nu, problem, mesh and size the nodes and the ratio of
cutkit's result to the P2 reference (1 = no locking).  ``--smoothing alpha`` adds a column for
ANP with that share of the deviatoric energy on the nodes (``deviatoric_smoothing``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _fem_reference import delaunay_box, kuhn_box, p2_block_reaction, p2_cantilever  # noqa: E402

from cutkit.model.tetmodel import Materials, TetModel  # noqa: E402
from cutkit.relax.anp import anp_forces  # noqa: E402
from cutkit.relax.elastic import build_element_model  # noqa: E402
from cutkit.relax.equilibrium import static_solve  # noqa: E402
from cutkit.relax.vbd import elastic_forces  # noqa: E402

E_PA = 1.0e6
E = E_PA * 1e-6
CANTILEVER = np.array([10.0, 2.0, 2.0])
BLOCK = np.array([4.0, 4.0, 2.0])
TRACTION = -1e-5  # MPa: 10 Pa, tip deflection about 0.01 mm
STRAIN = 0.01
#: Relative residual the solves stop at: far below what the ratios resolve, above the rounding
#: floor that the nu 0.49 cantilever reaches near 1e-8.
TIGHT = dict(rtol=1e-7, atol=1e-16, max_iterations=200)


def solid(nu):
    return Materials.from_rows([dict(label=1, name="solid", E=E_PA, poisson_ratio=nu, density=1000.0, damping=0.0,
                                     F_enter=1.0, mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8,
                                     alpha_static=0.1, alpha_dynamic=0.1, c_edge=1.0, c_shape=1.0)])


def mesh(kind, L, cells):
    if kind == "kuhn":
        return kuhn_box(L, cells)
    return delaunay_box(L, float(np.min(L / np.asarray(cells))))


def face_loads(p, t, axis, value, traction):
    """Consistent nodal loads (n,) of a uniform traction on the boundary faces with x_axis = value."""
    loads = np.zeros(p.shape[0])
    for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]):
        tri = t[:, f]
        tri = tri[np.all(np.abs(p[tri][..., axis] - value) < 1e-9, axis=1)]
        area = 0.5 * np.linalg.norm(np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1)
        np.add.at(loads, tri.ravel(), np.repeat(area * traction / 3.0, 3))
    return loads


def element_model(p, t, nu, element):
    """``element`` "nh", "anp" or "anp:alpha" (ANP with deviatoric smoothing alpha)."""
    name, _, alpha = element.partition(":")
    return build_element_model(TetModel.from_arrays(p, t, materials=solid(nu)), element=name,
                               deviatoric_smoothing=float(alpha or 0.0))


def cantilever(p, t, nu, element):
    """Work-conjugate tip deflection, mm."""
    em = element_model(p, t, nu, element)
    em.fixed[p[:, 0] < 1e-9] = True
    loads = np.zeros(p.shape)
    loads[:, 2] = face_loads(p, t, 0, CANTILEVER[0], TRACTION)
    x = p.copy()
    info = static_solve(em, x, f_ext=loads, **TIGHT)
    if not info.converged:
        raise RuntimeError(f"cantilever did not converge: {info}")
    return float(((x - p)[:, 2] * loads[:, 2]).sum() / loads[:, 2].sum())


def block(p, t, nu, element):
    """The plate's force, N."""
    em = element_model(p, t, nu, element)
    top = p[:, 2] > BLOCK[2] - 1e-9
    em.fixed[(p[:, 2] < 1e-9) | top] = True
    x = p.copy()
    x[top, 2] -= STRAIN * BLOCK[2]
    info = static_solve(em, x, **TIGHT)
    if not info.converged:
        raise RuntimeError(f"block did not converge: {info}")
    forces = anp_forces if element.startswith("anp") else elastic_forces
    return float(forces(em, x)[top, 2].sum())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1,2")
    ap.add_argument("--nus", default="0.3,0.45,0.49")
    ap.add_argument("--ref", type=int, default=3, help="P2 reference at this many times the base cells")
    ap.add_argument("--smoothing", type=float, default=None, help="add ANP with this deviatoric smoothing")
    ap.add_argument("--elements", default="nh,anp")
    a = ap.parse_args(argv)
    elements = a.elements.split(",") + ([f"anp:{a.smoothing:g}"] if a.smoothing else [])
    sizes = [int(s) for s in a.sizes.split(",")]
    rs = a.ref
    out = {"reference": f"scikit-fem P2, structured, {rs}x base cells", "results": []}
    for nu in (float(v) for v in a.nus.split(",")):
        t0 = time.perf_counter()
        ref = {"cantilever": p2_cantilever(CANTILEVER, (10 * rs, 2 * rs, 2 * rs), E, nu, TRACTION),
               "block": p2_block_reaction(BLOCK, (4 * rs, 4 * rs, 2 * rs), E, nu, STRAIN)}
        for name, L, base, run in (("cantilever", CANTILEVER, (10, 2, 2), cantilever), ("block", BLOCK, (4, 4, 2), block)):
            for kind in ("kuhn", "delaunay"):
                for s in sizes:
                    p, t = mesh(kind, L, tuple(s * np.asarray(base)))
                    row = {"nu": nu, "problem": name, "mesh": kind, "size": s, "nodes": int(p.shape[0]),
                           "p2_reference": ref[name]}
                    for element in elements:
                        row[f"{element}_over_p2"] = round(run(p, t, nu, element) / ref[name], 4)
                    out["results"].append(row)
                    print(json.dumps(row), file=sys.stderr, flush=True)
        out.setdefault("seconds", {})[str(nu)] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
