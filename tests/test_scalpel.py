"""The scalpel force model (paper section 6): each regime, and kernel vs NumPy twin."""

import numpy as np
import pytest

from _twins_scalpel import twin_step
from cutkit.errors import InputError
from cutkit.scalpel import (
    CUTTING, FREE, N_OUT, O_CUT, O_D_A, O_D_N, O_FORCE, O_PERP, STATIC, WITHDRAWING,
    Control, ScalpelParams, ScalpelState, blade_breadth, enter, leave, step,
)

A = np.array([1.0, 0.0, 0.0])  # cutting direction
N = np.array([0.0, 1.0, 0.0])  # along the blade
B = np.array([0.0, 0.0, 1.0])  # blade plane normal
ZERO = np.zeros(3)


def _start(params=None, entry=(0.0, 0.0, 0.0)):
    params = params or ScalpelParams()
    s, c, out = ScalpelState(), Control(), np.zeros(N_OUT)
    enter(s, entry, B, entry)
    c.set(entry, A, N)
    return params, s, c, out


def _push(p, s, c, out, force_a, steps=1, f_sim=ZERO, perp=0.0):
    """Hold the tip ahead of the proxy so the in-plane spring pulls with force_a along a."""
    for _ in range(steps):
        c.tip[:] = s.proxy + (force_a / p.k_spring) * A + perp * B
        step(p.array(), s, c, f_sim, out)


def test_free_proxy_follows_tip_without_force():
    p, s, c, out = ScalpelParams(), ScalpelState(), Control(), np.zeros(N_OUT)
    c.set([3.0, -2.0, 1.0], A, N)
    step(p.array(), s, c, ZERO, out)
    assert s.code[0] == FREE
    np.testing.assert_array_equal(s.proxy, [3.0, -2.0, 1.0])
    np.testing.assert_array_equal(out[O_FORCE:O_FORCE + 3], 0.0)


def test_below_F_enter_the_proxy_does_not_move():
    p, s, c, out = _start()
    for f in np.linspace(0.05, 0.95 * p.F_enter, 20):
        _push(p, s, c, out, f)
        assert s.code[0] == STATIC
        np.testing.assert_array_equal(s.proxy, 0.0)
        # eq. (12): the static cut friction compensates F_par exactly ...
        np.testing.assert_allclose(out[O_CUT:O_CUT + 3], -f * A, atol=1e-12)
        # ... and the user feels the full spring
        np.testing.assert_allclose(out[O_FORCE:O_FORCE + 3], -f * A, atol=1e-12)


def test_static_threshold_grows_with_depth_and_perpendicular_load():
    # eqs. (13)-(14): inside tissue, opening and friction add to F_enter
    p = ScalpelParams(mu_static=1e-4, alpha_static=0.5)
    _, s, c, out = _start(p)
    s.proxy[:] = [0.0, -5.0, 0.0]  # d_a = 5 mm below the entry point
    expect = p.F_enter + p.mu_static * p.eta * p.c_edge * 5.0
    _push(p, s, c, out, 0.98 * expect)
    assert s.code[0] == STATIC
    _push(p, s, c, out, 1.02 * expect)
    assert s.code[0] == CUTTING
    # a perpendicular load raises it by alpha_static * |F_perp|
    _, s, c, out = _start(p)
    _push(p, s, c, out, p.F_enter * 1.05, perp=1.0)  # |F_perp| = k_plane * 1 mm
    assert s.code[0] == STATIC
    _push(p, s, c, out, p.F_enter + p.alpha_static * p.k_plane * 1.0 + 0.01, perp=1.0)
    assert s.code[0] == CUTTING


def test_switch_to_dynamic_at_F_enter_and_the_blade_advances():
    p, s, c, out = _start()
    _push(p, s, c, out, 1.05 * p.F_enter)
    assert s.code[0] == CUTTING
    x0 = s.proxy[0]
    assert x0 > 0.0
    _push(p, s, c, out, 1.05 * p.F_enter, steps=20)
    assert s.code[0] == CUTTING and s.proxy[0] > x0 and s.velocity[0] > 0
    # dynamic cut friction is smaller than the static: the cut goes on below F_enter
    _push(p, s, c, out, 0.7 * p.F_enter, steps=5)
    assert s.code[0] == CUTTING
    # the proxy stays on the blade plane
    assert s.proxy[2] == 0.0
    # letting go: the friction stops the blade and the static regime returns
    c.tip[:] = s.proxy
    for _ in range(200):
        step(p.array(), s, c, ZERO, out)
        c.tip[:] = s.proxy
    assert s.code[0] == STATIC
    np.testing.assert_array_equal(s.velocity, 0.0)


def test_dynamic_cut_force_grows_with_velocity():
    p = ScalpelParams()
    forces = []
    for v in (10.0, 50.0, 200.0):
        _, s, c, out = _start(p)
        s.proxy[:] = [5.0, -4.0, 0.0]  # the blade is 6.4 mm deep
        s.velocity[:] = v * A
        s.code[0] = CUTTING
        _push(p, s, c, out, 0.5)
        assert s.code[0] == CUTTING
        forces.append(-out[O_CUT])  # F_cut opposes the motion along a
    assert forces[0] > 0 and forces[0] < forces[1] < forces[2]
    # eq. (17): F_displace = c v is linear in v; integrated implicitly it
    # acts on the new velocity, so dF = c dv / (1 + dt c / m)
    d_a = np.hypot(5.0, 4.0)
    c_disp = p.rho_dynamic * p.eta * p.c_shape * d_a * p.blade_depth
    implicit = 1.0 + p.dt * 1000.0 / p.mass * c_disp
    assert (forces[2] - forces[1]) == pytest.approx(c_disp * 150.0 / implicit, rel=1e-9)


def test_withdrawal_gives_no_cut_force():
    p, s, c, out = _start()
    _push(p, s, c, out, 1.1 * p.F_enter, steps=10)
    assert s.code[0] == CUTTING
    for k in range(1, 6):
        c.tip[:] = s.proxy - 0.5 * k * A + 0.3 * N
        step(p.array(), s, c, ZERO, out)
        assert s.code[0] == WITHDRAWING
        np.testing.assert_array_equal(out[O_CUT:O_CUT + 3], 0.0)
        np.testing.assert_allclose(out[O_FORCE:O_FORCE + 3], 0.0, atol=1e-12)
        np.testing.assert_allclose(s.proxy, c.tip)  # in plane: the proxy sits on the tip
    # pushing forward again meets the static friction first
    _push(p, s, c, out, 0.5 * p.F_enter)
    assert s.code[0] == STATIC


def test_perpendicular_restoring_force_is_proportional_to_distance():
    p = ScalpelParams(k_plane=1.5)
    for code in (STATIC, CUTTING, WITHDRAWING):
        for h in (-2.0, 0.5, 3.0):
            _, s, c, out = _start(p)
            s.code[0] = code
            c.tip[:] = s.proxy + h * B
            step(p.array(), s, c, ZERO, out)
            f = out[O_FORCE:O_FORCE + 3]
            assert f[2] == pytest.approx(-p.k_plane * h)
            assert out[O_PERP + 2] == pytest.approx(p.k_plane * h)
            assert s.proxy[2] == 0.0


def test_blade_breadth_function():
    p = ScalpelParams(blade_taper=0.5, blade_breadth=6.0)
    np.testing.assert_allclose(blade_breadth([0.0, 4.0, 12.0, 40.0], p), [0.0, 2.0, 6.0, 6.0])
    _, s, c, out = _start(p)
    s.proxy[:] = [3.0, -4.0, 0.0]
    _push(p, s, c, out, 0.1)
    assert out[O_D_A] == pytest.approx(5.0) and out[O_D_N] == pytest.approx(2.5)


def test_leave_returns_to_free():
    p, s, c, out = _start()
    _push(p, s, c, out, 0.3)
    leave(s)
    _push(p, s, c, out, 0.3)
    assert s.code[0] == FREE and np.all(out[O_FORCE:O_FORCE + 3] == 0.0)


def test_bad_parameters_are_rejected():
    with pytest.raises(InputError, match="scalpel parameter mass must be > 0"):
        ScalpelParams(mass=0.0)
    with pytest.raises(InputError, match="F_enter"):
        ScalpelParams(F_enter=float("nan"))
    with pytest.raises(InputError, match="too stiff"):
        ScalpelParams(k_spring=50.0, mass=0.001)
    with pytest.raises(InputError, match="material lacks the cut parameters c_shape"):
        ScalpelParams.from_material({k: 1.0 for k in ("E", "F_enter", "mu_static", "mu_dynamic", "rho_dynamic",
                                                      "alpha_static", "alpha_dynamic", "c_edge")})
    s = ScalpelState()
    with pytest.raises(InputError, match="blade plane normal must not be zero"):
        enter(s, ZERO, ZERO, ZERO)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_numpy_twin_on_random_sequences(seed):
    rng = np.random.default_rng(seed)
    p = ScalpelParams(mu_static=rng.uniform(0, 1e-5), mu_dynamic=rng.uniform(0, 5e-6),
                      rho_dynamic=rng.uniform(0, 2e-7), F_enter=rng.uniform(0.1, 1.5))
    pa = p.array()
    s, c, out = ScalpelState(), Control(), np.zeros(N_OUT)
    entry = rng.normal(size=3)
    normal = rng.normal(size=3)
    enter(s, entry, normal, entry)
    tip = entry.copy()
    a0 = np.cross(normal, rng.normal(size=3))
    a0 /= np.linalg.norm(a0)
    n0 = np.cross(normal, a0) / np.linalg.norm(normal)
    seen = set()
    for i in range(600):
        if i == 300:
            s.code[0] = FREE
        if i == 310:
            enter(s, entry, normal, tip)
        # the device wanders about a fixed blade pose, mostly pushing forward
        a = a0 + 0.2 * rng.normal(size=3) if i % 97 else normal.copy()  # now and then a degenerate a
        n = n0 + 0.2 * rng.normal(size=3)
        tip = s.proxy + a0 * rng.uniform(-1.0, 3.0) + rng.normal(scale=0.5, size=3)
        f_sim = rng.normal(scale=0.2, size=3)
        c.set(tip, a, n)
        ref = twin_step(pa, s.proxy, s.velocity, int(s.code[0]), s.entry, s.normal, tip, a, n, f_sim)
        step(pa, s, c, f_sim, out)
        seen.add(int(s.code[0]))
        np.testing.assert_allclose(s.proxy, ref[0], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(s.velocity, ref[1], rtol=1e-9, atol=1e-7)
        assert s.code[0] == ref[2]
        np.testing.assert_allclose(out, ref[3], rtol=1e-9, atol=1e-9)
        s.proxy[:], s.velocity[:] = ref[0], ref[1]  # keep rounding from compounding
    assert seen >= {FREE, STATIC, CUTTING, WITHDRAWING}
