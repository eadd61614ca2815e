"""The material of each tetrahedron, in solver units, from a model's tables: one place for both tissue models.

Units: lengths mm, time s, mass t (tonne), so forces are N and stresses MPa
(:data:`PA_TO_MPA`, :data:`KG_M3_TO_T_MM3`).  The paper's springs
(:mod:`cutkit.relax.model`) read E, density and damping; the element model
(:mod:`cutkit.relax.elastic`) reads the Lame parameters of E and the
Poisson ratio as well.  Both read the prestress (section 7.3) per tet.
"""

from __future__ import annotations

import numpy as np

from cutkit.errors import InputError

#: E [Pa] -> [N/mm^2].
PA_TO_MPA = 1e-6
#: density [kg/m^3] -> [t/mm^3].
KG_M3_TO_T_MM3 = 1e-12
#: |prestrain| at or above this would give springs nearly zero (or doubled) rest lengths.
MAX_PRESTRAIN = 0.9


def lame(E, nu):
    """Lame parameters (mu, lam) of Young's modulus E and Poisson ratio nu (same units as E)."""
    E = np.asarray(E, np.float64)
    nu = np.asarray(nu, np.float64)
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def material_of_tets(model, labels, poisson_ratio=None) -> dict:
    """Per-tet material in solver units: ``mu``, ``lam`` (MPa), ``density`` (t/mm^3), ``damping`` (1/s), ``E`` (MPa).

    Raises
    ------
    InputError
        A label has no row in the materials table, or a Poisson ratio lies outside [0, 0.5).
    """
    rows = model.materials.row_of(labels)
    if np.any(rows < 0):
        bad = int(np.asarray(labels)[np.argmax(rows < 0)])
        raise InputError(f"tet label {bad} has no row in the materials table")
    nu = model.materials["poisson_ratio"][rows] if poisson_ratio is None else np.full(rows.shape, poisson_ratio)
    if np.any(~np.isfinite(nu) | (nu < 0.0) | (nu >= 0.5)):
        raise InputError(f"Poisson ratio must lie in [0, 0.5), got {float(nu[np.argmax((nu < 0) | (nu >= 0.5))])}")
    E = model.materials["E"][rows] * PA_TO_MPA
    mu, lam = lame(E, nu)
    return {"E": E, "mu": mu, "lam": lam, "density": model.materials["density"][rows] * KG_M3_TO_T_MM3,
            "damping": model.materials["damping"][rows]}


def prestress_of_tets(model, labels):
    """Prestrain (m,) and unit fibre direction (m, 3) of each tet from the model's prestress table."""
    labels = np.asarray(labels)
    prestrain = np.zeros(labels.shape[0])
    fibre = np.zeros((labels.shape[0], 3))
    ps = model.prestress
    for lab, f, eps in zip(ps.label, np.asarray(ps.fibre_direction, np.float64).reshape(-1, 3),
                           np.asarray(ps.prestrain, np.float64)):
        if not abs(eps) < MAX_PRESTRAIN:
            raise InputError(f"prestrain of label {int(lab)} must lie in (-{MAX_PRESTRAIN}, {MAX_PRESTRAIN}), got {eps}")
        sel = labels == lab
        prestrain[sel] = eps
        fibre[sel] = f / np.linalg.norm(f)
    return prestrain, fibre
