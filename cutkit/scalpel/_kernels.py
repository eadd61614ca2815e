"""Numba kernel of the haptic scalpel model (paper section 6).

One call advances the proxy by one fixed time step ``dt`` (1 ms at the
haptic rate).  The kernel never checks its inputs: :mod:`cutkit.scalpel.model`
builds and validates the arrays.

Units: lengths in mm, forces in N, velocities in mm/s, masses in kg,
stiffness eta in Pa.  An acceleration F/m in N/kg = m/s^2 is multiplied by
``MM_PER_M`` to become mm/s^2.
"""

from __future__ import annotations

import math
from collections import namedtuple

from numba import njit

# -- state codes -----------------------------------------------------------
FREE = 0  # blade not in contact with tissue: the proxy follows the tip
STATIC = 1  # static cut friction holds the proxy (eqs. 12-14)
CUTTING = 2  # dynamic cut friction, the proxy moves (eqs. 15-18)
WITHDRAWING = 3  # F_par . a < 0: the blade is pulled back, no cut force (6.5)

STATE_NAMES = ("free", "static", "cutting", "withdrawing")

# -- layout of the params vector (ScalpelParams.array()) -----------------------
P_DT = 0  # time step, s
P_K_SPRING = 1  # tip-proxy coupling spring in the blade plane, N/mm
P_K_PLANE = 2  # restoring stiffness towards the blade plane, N/mm (6.5)
P_MASS = 3  # proxy (blade) mass, kg, for F_m of eq. (15)
P_ETA = 4  # material stiffness eta = E, Pa
P_F_ENTER = 5  # N
P_MU_STATIC = 6
P_MU_DYNAMIC = 7
P_RHO_DYNAMIC = 8
P_ALPHA_STATIC = 9
P_ALPHA_DYNAMIC = 10
P_C_EDGE = 11
P_C_SHAPE = 12
P_BLADE_DEPTH = 13  # d_d of eq. (17), mm
P_BLADE_TAPER = 14  # d_n = min(taper * d_a, breadth), dimensionless
P_BLADE_BREADTH = 15  # widest breadth of the blade, mm
P_MODEL = 16  # PAPER or FRACTURE: which force model step() runs
P_J_C = 17  # fracture toughness J_c, J/m^2 = N/m (fracture model)
P_CRACK_STEP = 18  # crack increment da of the fracture model, mm
P_EDGE_RADIUS = 19  # radius of the blade's sharp edge, mm: the size of the fracture model's contact zone
N_PARAMS = 20

# -- force models (params[P_MODEL]) -------------------------------------------
PAPER = 0  # the paper's section 6: F_enter and cut friction (eqs. 12-18)
FRACTURE = 1  # cutting as fracture: the crack advances when J_c * depth * da is paid
MODEL_NAMES = ("paper", "fracture")

# -- layout of the out vector ------------------------------------------------
O_FORCE = 0  # (3) force to render on the device, N
O_CUT = 3  # (3) cut friction F_cut acting on the blade, N (eqs. 10-12)
O_PERP = 6  # (3) F_perp of eq. (9), N
O_D_A = 9  # penetration depth d_a, mm
O_D_N = 10  # blade breadth d_n, mm
O_A = 11  # (3) blade direction a used this step (in the blade plane)
O_N = 14  # (3) in-plane direction n used this step
O_CRACK = 17  # fracture model: crack length from the entry point along a, mm (0 in the paper's)
N_OUT = 18

#: What of the scalpel changes every step, as the step kernels read it (``ScalpelState``): the
#: proxy P_s and its velocity (3,) float64 (mm, mm/s), the state ``code`` (1,) int64, the crack
#: length ``crack`` (1,) float64 (mm, the fracture model), the entry point P_e and the blade
#: plane's unit normal b (3,) float64.
BladeState = namedtuple("BladeState", ["proxy", "velocity", "code", "crack", "entry", "normal"])

#: Below this length a projected blade axis is treated as degenerate.
AXIS_EPS = 1e-9
#: |F_par . a| below this (N) is no direction: a blade pressed straight along
#: itself (a stab, F_par . a = 0 up to rounding) neither cuts forward nor withdraws.
WITHDRAW_FORCE = 1e-3
#: mm per m: converts F/m (m/s^2) into mm/s^2.
MM_PER_M = 1000.0
#: N/mm^2 per Pa: a modulus in Pa times this is a stiffness per mm of depth, N/mm^2.
N_PER_MM2_PER_PA = 1e-6
#: (N/mm) per (J/m^2): J_c in J/m^2 = N/m times this is a force per mm of cut depth.
N_PER_MM_PER_J_PER_M2 = 1e-3


@njit(cache=True)
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True)
def _dynamic_axis(f_x, v_x, d_x, p, abs_perp):
    """New velocity along one blade axis under dynamic cut friction (eqs. 15-18).

    F_open and F_friction are Coulomb-like: they oppose the motion (or the
    applied force at rest) and can stop the blade but never reverse it.
    F_displace is viscous, c_x * v_x, and is integrated implicitly so that a
    stiff material cannot make the step unstable.
    """
    dt = p[P_DT]
    inv_m = MM_PER_M / p[P_MASS]
    coulomb = p[P_MU_DYNAMIC] * p[P_ETA] * p[P_C_EDGE] * d_x + p[P_ALPHA_DYNAMIC] * abs_perp  # (16) + (18)
    viscous = p[P_RHO_DYNAMIC] * p[P_ETA] * p[P_C_SHAPE] * d_x * p[P_BLADE_DEPTH]  # (17) / v_x
    s = _sign(v_x)
    if s == 0.0:
        if abs(f_x) <= coulomb:
            return 0.0
        s = _sign(f_x)
        return dt * inv_m * (f_x - s * coulomb) / (1.0 + dt * inv_m * viscous)
    v_new = (v_x + dt * inv_m * (f_x - s * coulomb)) / (1.0 + dt * inv_m * viscous)
    if v_new * s < 0.0:
        return 0.0
    return v_new


@njit(cache=True)
def free_blade(code, proxy, velocity, tip, a_in, n_in, out):
    """Clear ``out``; a free blade (no contact) puts the proxy on the tip at rest and reports
    the device's own frame.  True when the blade is free (the step is then done)."""
    for i in range(N_OUT):
        out[i] = 0.0
    if code[0] != FREE:
        return False
    for i in range(3):
        proxy[i] = tip[i]
        velocity[i] = 0.0
        out[O_A + i] = a_in[i]
        out[O_N + i] = n_in[i]
    return True


@njit(cache=True)
def blade_frame(normal, a_in, n_in):
    """Unit (a, n) in the blade plane of unit normal ``normal`` (section 6.1), as 6 floats.

    ``a`` is the device's ``a_in`` projected into the plane (or a fallback
    in the plane where it is degenerate), ``n = b x a``.
    """
    b0, b1, b2 = normal[0], normal[1], normal[2]
    ab = a_in[0] * b0 + a_in[1] * b1 + a_in[2] * b2
    a0, a1, a2 = a_in[0] - ab * b0, a_in[1] - ab * b1, a_in[2] - ab * b2
    la = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if la < AXIS_EPS:
        a0 = n_in[1] * b2 - n_in[2] * b1
        a1 = n_in[2] * b0 - n_in[0] * b2
        a2 = n_in[0] * b1 - n_in[1] * b0
        la = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if la < AXIS_EPS:
            if abs(b0) < 0.9:
                a0, a1, a2 = 0.0, b2, -b1
            else:
                a0, a1, a2 = -b2, 0.0, b0
            la = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0 /= la
    a1 /= la
    a2 /= la
    return a0, a1, a2, b1 * a2 - b2 * a1, b2 * a0 - b0 * a2, b0 * a1 - b1 * a0


@njit(cache=True)
def scalpel_step(params, blade, control, f_sim, out):
    """Advance the scalpel proxy by one time step.

    Parameters
    ----------
    params : (N_PARAMS,) float64
    blade : BladeState
        In/out: the proxy (kept in the blade plane), its velocity and the
        code (FREE, STATIC, CUTTING or WITHDRAWING); the entry point is a
        point of the blade plane.
    control : tuple of three (3,) float64
        The device tip (mm), blade direction a (the way the sharp edge
        faces) and in-plane direction n along the blade, a and n need not be
        exactly unit.
    f_sim : (3,) float64
        External force from the tissue simulation, N.
    out : (N_OUT,) float64, out
    """
    proxy, velocity, code, entry, normal = blade.proxy, blade.velocity, blade.code, blade.entry, blade.normal
    tip, a_in, n_in = control
    if free_blade(code, proxy, velocity, tip, a_in, n_in, out):
        return
    # a: the device's a projected into the blade plane, n = b x a (6.1)
    frame = blade_frame(normal, a_in, n_in)
    a0, a1, a2, n0, n1, n2 = frame
    dist, e0, e1, e2 = _external_force(params, proxy, entry, normal, tip, f_sim)
    # eq. (9): F_ext = F_par_a + F_par_n + F_perp
    f_perp = e0 * normal[0] + e1 * normal[1] + e2 * normal[2]
    fa = e0 * a0 + e1 * a1 + e2 * a2
    fn = e0 * n0 + e1 * n1 + e2 * n2
    abs_perp = abs(f_perp)

    # d_a = |P_s - P_e|; d_n grows with d_a up to the blade's breadth
    q0, q1, q2 = proxy[0] - entry[0], proxy[1] - entry[1], proxy[2] - entry[2]
    d_a = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
    d_n = min(params[P_BLADE_TAPER] * d_a, params[P_BLADE_BREADTH])

    c = code[0]
    # forward-only cutting (6.5): the sign of F_par . a tells cutting from withdrawing
    if c == WITHDRAWING:
        if fa > WITHDRAW_FORCE:
            c = STATIC
    elif fa < -WITHDRAW_FORCE:
        c = WITHDRAWING

    dt = params[P_DT]
    cut_a = 0.0
    cut_n = 0.0
    if c == WITHDRAWING:
        _withdraw(proxy, velocity, tip, normal, dist, dt)
    else:
        if c == STATIC:
            c, cut_a, cut_n = _static_friction(params, fa, fn, abs_perp, d_a, d_n, velocity)
        if c == CUTTING:
            c, cut_a, cut_n = _dynamic_cut(params, fa, fn, abs_perp, d_a, d_n, frame, velocity, proxy)
        # keep the proxy on the blade plane (6.5)
        pd = (proxy[0] - entry[0]) * normal[0] + (proxy[1] - entry[1]) * normal[1] + (proxy[2] - entry[2]) * normal[2]
        proxy[0] -= pd * normal[0]
        proxy[1] -= pd * normal[1]
        proxy[2] -= pd * normal[2]
    code[0] = c
    _device_feedback(params, proxy, normal, tip, frame, dist, (cut_a, cut_n, f_perp, d_a, d_n), out)


@njit(cache=True)
def _external_force(params, proxy, entry, normal, tip, f_sim):
    """F_ext from the coupling springs (6.5): the in-plane spring from the proxy to the tip plus the
    plane restoring spring, proportional to the tip's signed distance ``dist`` from the blade
    plane, plus the tissue's force ``f_sim``.  Returns (dist, F_ext as three floats)."""
    b0, b1, b2 = normal[0], normal[1], normal[2]
    dist = (tip[0] - entry[0]) * b0 + (tip[1] - entry[1]) * b1 + (tip[2] - entry[2]) * b2
    o0, o1, o2 = tip[0] - proxy[0], tip[1] - proxy[1], tip[2] - proxy[2]
    ob = o0 * b0 + o1 * b1 + o2 * b2
    k = params[P_K_SPRING]
    kp = params[P_K_PLANE]
    s0 = k * (o0 - ob * b0) + kp * dist * b0
    s1 = k * (o1 - ob * b1) + kp * dist * b1
    s2 = k * (o2 - ob * b2) + kp * dist * b2
    return dist, s0 + f_sim[0], s1 + f_sim[1], s2 + f_sim[2]


@njit(cache=True)
def _withdraw(proxy, velocity, tip, normal, dist, dt):
    """Withdrawing (6.5): the proxy follows the tip within the blade plane; no cut force."""
    p0 = tip[0] - dist * normal[0]
    p1 = tip[1] - dist * normal[1]
    p2 = tip[2] - dist * normal[2]
    velocity[0] = (p0 - proxy[0]) / dt
    velocity[1] = (p1 - proxy[1]) / dt
    velocity[2] = (p2 - proxy[2]) / dt
    proxy[0], proxy[1], proxy[2] = p0, p1, p2


@njit(cache=True)
def _static_friction(params, fa, fn, abs_perp, d_a, d_n, velocity):
    """The static phase (eqs. 12-14): the proxy holds still (velocity zeroed) unless the in-plane
    force reaches the break-away threshold, raised above F_enter by static opening and friction
    per axis.  Returns (code, cut force along a, along n): STATIC with F_cut = -F_par, or CUTTING
    with no cut force yet."""
    f_par = math.sqrt(fa * fa + fn * fn)
    open_ = params[P_MU_STATIC] * params[P_ETA] * params[P_C_EDGE]
    fric = params[P_ALPHA_STATIC] * abs_perp
    threshold = params[P_F_ENTER]
    if f_par > 0.0:
        threshold += (abs(fa) * (open_ * d_a + fric) + abs(fn) * (open_ * d_n + fric)) / f_par
    velocity[0] = 0.0
    velocity[1] = 0.0
    velocity[2] = 0.0
    if f_par < threshold:
        return STATIC, -fa, -fn
    return CUTTING, 0.0, 0.0


@njit(cache=True)
def _dynamic_cut(params, fa, fn, abs_perp, d_a, d_n, frame, velocity, proxy):
    """The cutting phase: each in-plane axis moves by :func:`_dynamic_axis`; the proxy advances.
    Returns (code, cut force along a, along n) with F_cut = m dv/dt - F_par (eq. 15); the code
    falls back to STATIC when both axes stop."""
    a0, a1, a2, n0, n1, n2 = frame
    dt = params[P_DT]
    va = velocity[0] * a0 + velocity[1] * a1 + velocity[2] * a2
    vn = velocity[0] * n0 + velocity[1] * n1 + velocity[2] * n2
    va_new = _dynamic_axis(fa, va, d_a, params, abs_perp)
    vn_new = _dynamic_axis(fn, vn, d_n, params, abs_perp)
    m_dt = params[P_MASS] / (MM_PER_M * dt)
    cut_a = m_dt * (va_new - va) - fa
    cut_n = m_dt * (vn_new - vn) - fn
    for i in range(3):
        ai = a0 if i == 0 else (a1 if i == 1 else a2)
        ni = n0 if i == 0 else (n1 if i == 1 else n2)
        velocity[i] = va_new * ai + vn_new * ni
        proxy[i] += dt * velocity[i]
    if va_new == 0.0 and vn_new == 0.0:
        return STATIC, cut_a, cut_n
    return CUTTING, cut_a, cut_n


@njit(cache=True)
def _device_feedback(params, proxy, normal, tip, frame, dist, forces, out):
    """Fill ``out``: the device feels the in-plane spring to the proxy and the plane spring; also
    the cut force, F_perp, the blade frame and (d_a, d_n).  ``forces`` is
    (cut_a, cut_n, f_perp, d_a, d_n)."""
    a0, a1, a2, n0, n1, n2 = frame
    cut_a, cut_n, f_perp, d_a, d_n = forces
    k = params[P_K_SPRING]
    kp = params[P_K_PLANE]
    b0, b1, b2 = normal[0], normal[1], normal[2]
    for i in range(3):
        bi = b0 if i == 0 else (b1 if i == 1 else b2)
        ai = a0 if i == 0 else (a1 if i == 1 else a2)
        ni = n0 if i == 0 else (n1 if i == 1 else n2)
        off = proxy[i] - tip[i]
        out[O_FORCE + i] = k * (off + dist * bi) - kp * dist * bi
        out[O_CUT + i] = cut_a * ai + cut_n * ni
        out[O_PERP + i] = f_perp * bi
        out[O_A + i] = ai
        out[O_N + i] = ni
    out[O_D_A] = d_a
    out[O_D_N] = d_n
