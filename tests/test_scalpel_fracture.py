"""The fracture scalpel model: steady force per depth = J_c, sawtooth, energy balance, kernel vs twin.

Reference: in the steady state the blade's work over one crack increment da
pays exactly for the new crack area, F * da = J_c * depth * da, so
F / depth = J_c (plus the blade's Coulomb friction alpha * |F_perp|,
checked separately).  The slab is cut kinematically: the device tip moves
at a constant low speed through a straight cut of fixed depth.
"""

import numpy as np
import pytest

from _twins_fracture import twin_fracture_step
from cutkit.errors import InputError
from cutkit.scalpel import (
    CUTTING,
    FREE,
    N_OUT,
    O_CRACK,
    O_CUT,
    O_FORCE,
    STATIC,
    WITHDRAWING,
    Control,
    ScalpelParams,
    ScalpelState,
    enter,
    step,
)

A = np.array([1.0, 0.0, 0.0])  # cutting direction
B = np.array([0.0, 0.0, 1.0])  # blade plane normal; n = b x a = +y is the depth direction


def cut_slab(J_c, E, depth=5.0, speed=3.0, seconds=12.0, off_plane=0.0, **kw):
    """Force along the cut (N), edge travel (mm) and crack length (mm) per 1 ms step."""
    p = ScalpelParams(model="fracture", J_c=J_c, eta=E, k_spring=kw.pop("k_spring", 5.0), **kw).array()
    s, c, out = ScalpelState(), Control(), np.zeros(N_OUT)
    enter(s, np.zeros(3), B, np.zeros(3))
    c.a[:], c.n[:] = A, np.array([0.0, 1.0, 0.0])
    n = int(seconds * 1000)
    force, crack, codes = np.zeros(n), np.zeros(n), np.zeros(n, int)
    for i in range(n):
        c.tip[:] = (speed * i * 1e-3, depth, off_plane)
        step(p, s, c, np.zeros(3), out)
        force[i] = -out[O_CUT:O_CUT + 3] @ A
        crack[i] = out[O_CRACK]
        codes[i] = s.code[0]
    return force, crack, codes


def steady_mean(force, crack):
    """Mean force over whole sawtooth periods after the first crack advance."""
    jumps = np.flatnonzero(np.diff(crack) > 0) + 1
    assert jumps.size >= 5, "the crack must advance several times"
    return float(force[jumps[0]:jumps[-1]].mean())


@pytest.mark.parametrize("J_c", [200.0, 2000.0])  # liver-like and muscle-like toughness, J/m^2
def test_steady_force_per_depth_is_J_c(J_c):
    depth = 5.0
    force, crack, _ = cut_slab(J_c, E=100e3, depth=depth)
    per_mm = steady_mean(force, crack) / depth  # N/mm
    assert per_mm == pytest.approx(J_c * 1e-3, rel=0.15)  # J/m^2 = 1e-3 N/mm


def test_force_rises_with_J_c_and_depth_not_with_E():
    f_soft = steady_mean(*cut_slab(1000.0, E=100e3)[:2])
    f_stiff = steady_mean(*cut_slab(1000.0, E=400e3)[:2])
    assert abs(f_stiff / f_soft - 1.0) < 0.15
    assert steady_mean(*cut_slab(2000.0, E=100e3)[:2]) > 1.5 * f_soft
    f_shallow = steady_mean(*cut_slab(1000.0, E=100e3, depth=2.0)[:2])
    assert f_shallow / f_soft == pytest.approx(2.0 / 5.0, rel=0.15)


def test_friction_adds_alpha_times_F_perp():
    # the tip 1 mm off the blade plane: the plane spring presses the blade's faces
    # with |F_perp| = k_plane * 1 mm, and Coulomb friction alpha * |F_perp| adds to J_c * depth
    alpha, k_plane = 0.3, 0.8
    force, crack, _ = cut_slab(500.0, E=100e3, off_plane=1.0, alpha_dynamic=alpha, k_plane=k_plane)
    assert steady_mean(force, crack) == pytest.approx(500e-3 * 5.0 + alpha * k_plane * 1.0, rel=0.05)


def test_sawtooth_loads_then_unloads_suddenly():
    force, crack, codes = cut_slab(200.0, E=30e3, speed=2.0, crack_step=0.5)
    jumps = np.flatnonzero(np.diff(crack) > 0) + 1
    # each crack advance drops the force at once; between advances it rises
    drops = force[jumps] - force[jumps - 1]
    assert np.all(drops < 0.0)
    rises = np.diff(force[jumps[0]:jumps[-1]])
    rises = np.delete(rises, jumps[1:-1] - jumps[0] - 1)
    assert np.all(rises >= -1e-12)
    assert set(codes[jumps]) == {CUTTING}
    assert STATIC in set(codes[jumps[0] + 1:jumps[1]])


def test_blade_work_equals_fracture_work_plus_stored_energy():
    """Energy balance over the whole cut: the device's work = J_c * area + what the springs store."""
    J_c, E, depth = 300.0, 50e3, 4.0
    p = ScalpelParams(model="fracture", J_c=J_c, eta=E, k_spring=5.0)
    force, crack, _ = cut_slab(J_c, E, depth=depth, speed=3.0, seconds=8.0)
    travel = 3.0 * np.arange(force.size) * 1e-3
    work_in = np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(travel))  # N mm
    k_c = E * 1e-6 * p.blade_depth * depth / p.edge_radius
    k = 1.0 / (1.0 / p.k_spring + 1.0 / k_c)
    stored = force[-1] ** 2 / (2.0 * k)
    fracture = J_c * 1e-3 * depth * crack[-1]
    # what one increment releases beyond J_c * depth * da is lost (the sudden unload): at most k * da^2 / 2 each
    lost_max = (crack[-1] / p.crack_step) * 0.5 * k * p.crack_step ** 2 + force.max() * 3e-3
    # the trapezoid rule misses up to half the drop times one step's travel at each advance
    n_jumps = crack[-1] / p.crack_step
    assert fracture + stored <= work_in + n_jumps * k * p.crack_step * 3e-3
    assert work_in - (fracture + stored) <= lost_max


def test_withdrawing_costs_nothing_and_the_crack_stays():
    p = ScalpelParams(model="fracture", J_c=200.0, eta=100e3, k_spring=5.0).array()
    s, c, out = ScalpelState(), Control(), np.zeros(N_OUT)
    enter(s, np.zeros(3), B, np.zeros(3))
    for i in range(3000):
        c.set((3e-3 * i, 5.0, 0.0), A, (0.0, 1.0, 0.0))
        step(p, s, c, np.zeros(3), out)
    length = s.crack[0]
    assert length > 0.0
    last = np.inf
    for i in range(2000):
        t_a = 3e-3 * (2998 - i)  # from one step behind the last forward pose
        c.set((t_a, 5.0, 0.0), A, (0.0, 1.0, 0.0))
        step(p, s, c, np.zeros(3), out)
        load = -out[O_FORCE:O_FORCE + 3] @ A
        assert load <= last  # the contact zone unloads as the blade backs off
        last = load
        if t_a <= length:  # the edge behind the crack front: it slides in the cut, no force
            assert np.allclose(out[O_FORCE:O_FORCE + 3], 0.0)
    assert s.crack[0] == length
    assert s.code[0] in (WITHDRAWING, STATIC)


def test_bad_fracture_parameters_are_rejected():
    with pytest.raises(InputError, match="J_c = -1.0 must be finite and >= 0"):
        ScalpelParams(model="fracture", J_c=-1.0)
    with pytest.raises(InputError, match="scalpel model 'blunt' is not one of paper, fracture"):
        ScalpelParams(model="blunt")
    with pytest.raises(InputError, match="crack_step must be > 0"):
        ScalpelParams(model="fracture", crack_step=0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fracture_kernel_matches_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    p = ScalpelParams(model="fracture", J_c=rng.uniform(50, 3000), eta=rng.uniform(5e3, 2e5),
                      k_spring=rng.uniform(0.5, 20.0), crack_step=rng.uniform(0.05, 0.5),
                      alpha_dynamic=rng.uniform(0, 0.5), edge_radius=rng.uniform(0.005, 0.5))
    pa = p.array()
    s, c, out = ScalpelState(), Control(), np.zeros(N_OUT)
    entry, normal = rng.normal(size=3), rng.normal(size=3)
    enter(s, entry, normal, entry)
    a0 = np.cross(normal, rng.normal(size=3))
    a0 /= np.linalg.norm(a0)
    n0 = np.cross(normal, a0) / np.linalg.norm(normal)
    seen = set()
    t_a = 0.0
    for i in range(800):
        if i == 400:
            s.code[0] = FREE
        if i == 410:
            enter(s, entry, normal, entry)
        t_a += rng.uniform(-0.5, 1.5)
        tip = entry + t_a * a0 + rng.uniform(-1.0, 8.0) * n0 + rng.normal(scale=0.5, size=3)
        a = a0 + 0.2 * rng.normal(size=3) if i % 97 else normal.copy()  # now and then a degenerate a
        n = n0 + 0.2 * rng.normal(size=3)
        f_sim = rng.normal(scale=0.2, size=3)
        c.set(tip, a, n)
        ref = twin_fracture_step(pa, s.proxy.copy(), int(s.code[0]), float(s.crack[0]), s.entry, s.normal,
                                 tip, a, n, f_sim)
        step(pa, s, c, f_sim, out)
        seen.add(int(s.code[0]))
        np.testing.assert_allclose(s.proxy, ref[0], rtol=1e-9, atol=1e-9)
        assert s.code[0] == ref[1]
        assert s.crack[0] == pytest.approx(ref[2], abs=1e-9)
        np.testing.assert_allclose(out, ref[3], rtol=1e-9, atol=1e-9)
    assert seen >= {FREE, STATIC, CUTTING, WITHDRAWING}


def test_unknown_scalpel_model_is_refused_in_one_line(tmp_path):
    from click.testing import CliRunner

    from cutkit.cli.main import cli
    from cutkit.simulate import SimulateOptions

    with pytest.raises(InputError, match="^scalpel must be one of paper, fracture, not 'blunt'$"):
        SimulateOptions(scalpel="blunt").check()
    SimulateOptions(scalpel="fracture").check()
    (tmp_path / "t.csv").write_text("0,0,0,0,1,0,0,0,0,1\n")
    for args in (["simulate", str(tmp_path / "m.h5"), "--trajectory", str(tmp_path / "t.csv"), "-o",
                  str(tmp_path / "out"), "--scalpel", "blunt"], ["haptics", "serve", "--scalpel", "blunt"]):
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 2
        errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
        assert errors == ["Error: Invalid value for '--scalpel': 'blunt' is not one of 'paper', 'fracture'."]
    assert not (tmp_path / "out").exists()
