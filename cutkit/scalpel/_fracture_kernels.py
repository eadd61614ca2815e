"""Numba kernel of the fracture scalpel model (docs/scalpel-model.md, "Fracture model").

Cutting as fracture (Atkins 2009, *The Science and Engineering of Cutting*;
Mahvash & Okamura 2008, IEEE TBME): the blade edge presses on a contact
(rupture) zone ahead of the crack front, which stores elastic energy; the
crack front advances in increments ``da`` once the energy that one increment
releases pays for the new crack area, ``J_c * depth * da``.  The kernel checks
nothing; :mod:`cutkit.scalpel.model` builds and validates its arrays.

Units as in :mod:`cutkit.scalpel._kernels`: mm, N, s; E in Pa, J_c in J/m^2.
"""

from __future__ import annotations

import math

from numba import njit

from cutkit.scalpel._kernels import (
    blade_frame,
    free_blade,
    CUTTING,
    N_PER_MM2_PER_PA,
    N_PER_MM_PER_J_PER_M2,
    O_A,
    O_CRACK,
    O_CUT,
    O_D_A,
    O_D_N,
    O_FORCE,
    O_N,
    O_PERP,
    P_ALPHA_DYNAMIC,
    P_BLADE_BREADTH,
    P_C_SHAPE,
    P_CRACK_STEP,
    P_BLADE_DEPTH,
    P_DT,
    P_EDGE_RADIUS,
    P_ETA,
    P_J_C,
    P_K_PLANE,
    P_K_SPRING,
    STATIC,
    WITHDRAWING,
)

#: The edge counts as moving back when it moves back by more than this, mm.
BACK_EPS = 1e-9


@njit(cache=True)
def contact_stiffness(depth, params):
    """Stiffness k_c of the contact zone ahead of the edge, N/mm (docs/scalpel-model.md, eq. F0).

    The edge indents the tissue over its face, blade thickness w by the depth
    d; the strain concentrates in a zone of the edge's radius r, so
    k_c = c_shape * E * w * d / r.
    """
    return (params[P_C_SHAPE] * params[P_ETA] * N_PER_MM2_PER_PA * params[P_BLADE_DEPTH] * depth
            / params[P_EDGE_RADIUS])


@njit(cache=True)
def crack_advance(t_a, crack, depth, params):
    """New crack length for the edge driven to ``t_a`` (mm along a from the entry).

    The device spring k_s and the contact zone k_c (:func:`contact_stiffness`) act
    in series, k = k_s k_c / (k_s + k_c), so the stored energy is
    U = k (t_a - c)^2 / 2.  One increment da releases
    k da (t_a - c - da/2) at fixed t_a; it is taken while that is at least
    J_c * depth * da (eq. F2 of docs/scalpel-model.md).
    """
    k_s = params[P_K_SPRING]
    k_c = contact_stiffness(depth, params)
    if k_c <= 0.0:
        return crack  # no depth of cut: no contact zone, nothing to break
    k = k_s * k_c / (k_s + k_c)
    da = params[P_CRACK_STEP]
    need = params[P_J_C] * N_PER_MM_PER_J_PER_M2 * depth / k + 0.5 * da
    excess = t_a - crack - need
    if excess < 0.0:
        return crack
    return crack + (math.floor(excess / da) + 1.0) * da


@njit(cache=True)
def fracture_step(params, blade, control, f_sim, out):
    """Advance the fracture scalpel by one time step.

    Parameters
    ----------
    params : (N_PARAMS,) float64
    blade : _kernels.BladeState
        In/out: the blade edge P_s (mm, in the blade plane), its velocity
        (mm/s), the code (FREE, STATIC (loading), CUTTING (the crack
        advanced) or WITHDRAWING) and the crack length c from the entry point
        along a (mm); the entry point P_e and unit blade plane normal b.
    control : tuple of three (3,) float64
        Device tip, a and n (``Control``).
    f_sim : (3,) float64
        External force from the tissue simulation, N.
    out : (N_OUT,) float64, out
    """
    proxy, velocity, code, crack = blade.proxy, blade.velocity, blade.code, blade.crack
    entry, normal = blade.entry, blade.normal
    tip, a_in, n_in = control
    if free_blade(code, proxy, velocity, tip, a_in, n_in, out):
        return
    a0, a1, a2, n0, n1, n2 = blade_frame(normal, a_in, n_in)
    r0, r1, r2 = tip[0] - entry[0], tip[1] - entry[1], tip[2] - entry[2]
    dist = r0 * normal[0] + r1 * normal[1] + r2 * normal[2]
    t_a = r0 * a0 + r1 * a1 + r2 * a2
    t_n = r0 * n0 + r1 * n1 + r2 * n2
    depth = min(max(t_n, 0.0), params[P_BLADE_BREADTH])  # depth of cut, mm
    s_old = (proxy[0] - entry[0]) * a0 + (proxy[1] - entry[1]) * a1 + (proxy[2] - entry[2]) * a2
    c = crack_advance(t_a, crack[0], depth, params)
    # the edge where device spring and contact zone balance (eq. F1)
    k_s = params[P_K_SPRING]
    k_c = contact_stiffness(depth, params)
    s = t_a
    if t_a > c and k_c > 0.0:
        s = (k_s * t_a + k_c * c) / (k_s + k_c)
    f_contact = k_c * (s - c) if s > c else 0.0
    f_perp = params[P_K_PLANE] * dist + f_sim[0] * normal[0] + f_sim[1] * normal[1] + f_sim[2] * normal[2]
    # blade friction (eq. F3): Coulomb on the blade faces, while the edge moves forward in tissue
    f_fric = params[P_ALPHA_DYNAMIC] * abs(f_perp) if (s > s_old and depth > 0.0) else 0.0
    if c > crack[0] and depth > 0.0:
        code[0] = CUTTING
    elif s < s_old - BACK_EPS:
        code[0] = WITHDRAWING
    else:
        code[0] = STATIC
    crack[0] = c
    dt = params[P_DT]
    for i in range(3):
        ai = a0 if i == 0 else (a1 if i == 1 else a2)
        ni = n0 if i == 0 else (n1 if i == 1 else n2)
        bi = normal[i]
        p_new = entry[i] + s * ai + t_n * ni  # the edge follows the tip along n and onto the plane
        velocity[i] = (p_new - proxy[i]) / dt
        proxy[i] = p_new
        out[O_FORCE + i] = -(f_contact + f_fric) * ai - params[P_K_PLANE] * dist * bi
        out[O_CUT + i] = -(f_contact + f_fric) * ai
        out[O_PERP + i] = f_perp * bi
        out[O_A + i] = ai
        out[O_N + i] = ni
    out[O_D_A] = s
    out[O_D_N] = depth
    out[O_CRACK] = c
