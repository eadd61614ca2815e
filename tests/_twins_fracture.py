"""Slow, obviously correct NumPy twin of cutkit.scalpel._fracture_kernels.fracture_step."""

import numpy as np

from _twins_scalpel import _frame
from cutkit.scalpel import _kernels as K


def twin_fracture_step(p, proxy, code, crack, entry, normal, tip, a_in, n_in, f_sim):
    """Return (proxy, code, crack, out) after one step; inputs untouched."""
    out = np.zeros(K.N_OUT)
    if code == K.FREE:
        out[K.O_A:K.O_A + 3] = a_in
        out[K.O_N:K.O_N + 3] = n_in
        return tip.copy(), code, crack, out
    b = normal
    a, n = _frame(a_in, n_in, b)
    r = tip - entry
    t_a, t_n, dist = r @ a, r @ n, r @ b
    depth = float(np.clip(t_n, 0.0, p[K.P_BLADE_BREADTH]))
    k_s = p[K.P_K_SPRING]
    # Pa -> N/mm^2; the edge's face (thickness x depth) strained over the edge radius
    k_c = p[K.P_C_SHAPE] * p[K.P_ETA] * 1e-6 * p[K.P_BLADE_DEPTH] * depth / p[K.P_EDGE_RADIUS]
    j = p[K.P_J_C] * 1e-3  # J/m^2 -> N/mm
    da = p[K.P_CRACK_STEP]
    c = crack
    if k_c > 0.0:
        k = 1.0 / (1.0 / k_s + 1.0 / k_c)  # springs in series
        # one increment at a time while the energy it releases pays for its area
        while 0.5 * k * (t_a - c) ** 2 - 0.5 * k * (t_a - c - da) ** 2 >= j * depth * da:
            c += da
    s = t_a
    if t_a > c and k_c > 0.0:
        s = np.linalg.solve([[k_s + k_c]], [k_s * t_a + k_c * c])[0]  # k_s (t_a - s) = k_c (s - c)
    f_contact = k_c * max(s - c, 0.0)
    f_perp = p[K.P_K_PLANE] * dist + f_sim @ b
    s_old = (proxy - entry) @ a
    f_fric = p[K.P_ALPHA_DYNAMIC] * abs(f_perp) if (s > s_old and depth > 0.0) else 0.0
    if c > crack and depth > 0.0:
        code = K.CUTTING
    elif s < s_old - 1e-9:
        code = K.WITHDRAWING
    else:
        code = K.STATIC
    out[K.O_FORCE:K.O_FORCE + 3] = -(f_contact + f_fric) * a - p[K.P_K_PLANE] * dist * b
    out[K.O_CUT:K.O_CUT + 3] = -(f_contact + f_fric) * a
    out[K.O_PERP:K.O_PERP + 3] = f_perp * b
    out[K.O_A:K.O_A + 3] = a
    out[K.O_N:K.O_N + 3] = n
    out[K.O_D_A], out[K.O_D_N], out[K.O_CRACK] = s, depth, c
    return entry + s * a + t_n * n, code, c, out
