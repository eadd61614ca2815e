"""Slow, obviously correct NumPy twin of cutkit.scalpel._kernels.scalpel_step."""

import numpy as np

from cutkit.scalpel import _kernels as K


def _unit(v):
    return v / np.linalg.norm(v)


def _frame(a_in, n_in, b):
    a = a_in - np.dot(a_in, b) * b
    if np.linalg.norm(a) < K.AXIS_EPS:
        a = np.cross(n_in, b)
        if np.linalg.norm(a) < K.AXIS_EPS:
            a = np.array([0.0, b[2], -b[1]]) if abs(b[0]) < 0.9 else np.array([-b[2], 0.0, b[0]])
    a = _unit(a)
    return a, np.cross(b, a)


def _axis(f, v, d, p, abs_perp):
    dt, inv_m = p[K.P_DT], K.MM_PER_M / p[K.P_MASS]
    coulomb = p[K.P_MU_DYNAMIC] * p[K.P_ETA] * p[K.P_C_EDGE] * d + p[K.P_ALPHA_DYNAMIC] * abs_perp
    viscous = p[K.P_RHO_DYNAMIC] * p[K.P_ETA] * p[K.P_C_SHAPE] * d * p[K.P_BLADE_DEPTH]
    if v == 0.0:
        if abs(f) <= coulomb:
            return 0.0
        return dt * inv_m * (f - np.sign(f) * coulomb) / (1 + dt * inv_m * viscous)
    new = (v + dt * inv_m * (f - np.sign(v) * coulomb)) / (1 + dt * inv_m * viscous)
    return 0.0 if new * np.sign(v) < 0 else new


def twin_step(p, proxy, velocity, code, entry, normal, tip, a_in, n_in, f_sim):
    """Return (proxy, velocity, code, out) after one step; inputs untouched."""
    proxy, velocity = proxy.copy(), velocity.copy()
    out = np.zeros(K.N_OUT)
    if code == K.FREE:
        out[K.O_A:K.O_A + 3], out[K.O_N:K.O_N + 3] = a_in, n_in
        return tip.copy(), np.zeros(3), code, out
    b = normal
    a, n = _frame(a_in, n_in, b)
    dist = np.dot(tip - entry, b)
    off = tip - proxy
    spring = p[K.P_K_SPRING] * (off - np.dot(off, b) * b) + p[K.P_K_PLANE] * dist * b
    F_ext = spring + f_sim
    f_perp = np.dot(F_ext, b)
    fa, fn = np.dot(F_ext, a), np.dot(F_ext, n)
    d_a = np.linalg.norm(proxy - entry)
    d_n = min(p[K.P_BLADE_TAPER] * d_a, p[K.P_BLADE_BREADTH])
    if code == K.WITHDRAWING:
        code = K.STATIC if fa > K.WITHDRAW_FORCE else K.WITHDRAWING
    elif fa < -K.WITHDRAW_FORCE:
        code = K.WITHDRAWING
    cut = np.zeros(2)
    if code == K.WITHDRAWING:
        new = tip - dist * b
        velocity = (new - proxy) / p[K.P_DT]
        proxy = new
    else:
        if code == K.STATIC:
            f_par = np.hypot(fa, fn)
            opening = p[K.P_MU_STATIC] * p[K.P_ETA] * p[K.P_C_EDGE]
            fric = p[K.P_ALPHA_STATIC] * abs(f_perp)
            limit = p[K.P_F_ENTER]
            if f_par > 0:
                limit += (abs(fa) * (opening * d_a + fric) + abs(fn) * (opening * d_n + fric)) / f_par
            velocity = np.zeros(3)
            if f_par < limit:
                cut = np.array([-fa, -fn])
            else:
                code = K.CUTTING
        if code == K.CUTTING:
            va, vn = np.dot(velocity, a), np.dot(velocity, n)
            va2 = _axis(fa, va, d_a, p, abs(f_perp))
            vn2 = _axis(fn, vn, d_n, p, abs(f_perp))
            m_dt = p[K.P_MASS] / (K.MM_PER_M * p[K.P_DT])
            cut = np.array([m_dt * (va2 - va) - fa, m_dt * (vn2 - vn) - fn])
            velocity = va2 * a + vn2 * n
            proxy = proxy + p[K.P_DT] * velocity
            if va2 == 0 and vn2 == 0:
                code = K.STATIC
        proxy = proxy - np.dot(proxy - entry, b) * b
    rel = proxy - tip
    out[K.O_FORCE:K.O_FORCE + 3] = p[K.P_K_SPRING] * (rel - np.dot(rel, b) * b) - p[K.P_K_PLANE] * dist * b
    out[K.O_CUT:K.O_CUT + 3] = cut[0] * a + cut[1] * n
    out[K.O_PERP:K.O_PERP + 3] = f_perp * b
    out[K.O_D_A], out[K.O_D_N] = d_a, d_n
    out[K.O_A:K.O_A + 3], out[K.O_N:K.O_N + 3] = a, n
    return proxy, velocity, code, out
