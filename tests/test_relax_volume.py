"""The volume term of the mass-spring model (cutkit.relax.volume)."""

import numpy as np
import pytest

from _twins_relax import kuhn_grid, volume_forces_twin
from cutkit.errors import InputError
from cutkit.relax import Control, build_spring_model, initial_state, step
from cutkit.relax._volume_kernels import NodeSums, VolumeTets, add_volume_forces
from cutkit.relax.volume import VolumeTerm
from test_relax import block


def _volumes(x, tets):
    p = x[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


def _jittered_grid(seed=4):
    pts, tets = kuhn_grid(3, 2, 2, 1.5)
    x = pts + np.random.default_rng(seed).normal(0.0, 0.15, pts.shape)
    return pts, tets, x


def test_kernel_matches_twin():
    pts, tets, x = _jittered_grid()
    rng = np.random.default_rng(5)
    V0 = _volumes(pts, tets) * rng.uniform(0.8, 1.2, len(tets))
    bulk = rng.uniform(0.5, 2.0, len(tets))
    vt = VolumeTerm.build(pts, tets, V0, bulk)
    f_in, k_in = rng.normal(size=x.shape), rng.uniform(size=len(x))
    f, k = np.full_like(x, np.nan), np.full(len(x), np.nan)
    nodes = np.arange(len(x))[::2]  # only these rows are written
    add_volume_forces(nodes, x, VolumeTets(vt.tets, vt.tet_offsets, vt.node_tets, V0, bulk), NodeSums(f_in, k_in),
                      NodeSums(f, k))
    tf, tk = volume_forces_twin(x, tets, V0, bulk)
    np.testing.assert_allclose(f[nodes], f_in[nodes] + tf[nodes], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(k[nodes], k_in[nodes] + tk[nodes], rtol=1e-12)
    assert np.isnan(f[1::2]).all() and np.isnan(k[1::2]).all()


def test_forces_are_minus_the_energy_gradient():
    pts, tets, x = _jittered_grid(seed=6)
    V0 = _volumes(pts, tets)
    bulk = np.full(len(tets), 1.7)
    vt = VolumeTerm.build(pts, tets, V0, bulk)

    def energy(y):
        return float(np.sum(bulk * (_volumes(y, tets) - V0) ** 2 / (2 * V0)))

    f = np.zeros_like(x)
    add_volume_forces(np.arange(len(x)), x, VolumeTets(vt.tets, vt.tet_offsets, vt.node_tets, V0, bulk),
                      NodeSums(np.zeros_like(x), np.zeros(len(x))), NodeSums(f, np.zeros(len(x))))
    h = 1e-6
    for node in (0, 7, 20):
        for c in range(3):
            up, down = x.copy(), x.copy()
            up[node, c] += h
            down[node, c] -= h
            assert f[node, c] == pytest.approx(-(energy(up) - energy(down)) / (2 * h), rel=1e-5, abs=1e-9)
    # no net force: the term is translation invariant
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)


def test_squeezed_block_keeps_more_volume_with_the_term():
    """A block pressed from above: springs alone lose more volume than springs plus the volume term."""
    lost = {}
    for vs in (0.0, 1.0):
        model = block(4, 4, 3, h=2.0, damping=20.0)
        sm = build_spring_model(model, volume_stiffness=vs)
        assert (sm.volume is None) == (vs == 0.0)
        st = initial_state(sm)
        top = np.flatnonzero(model.points[:, 2] == model.points[:, 2].max())
        f = np.zeros((sm.n_nodes, 3))
        f[top, 2] = -0.15 * 1e-2 * 64 / len(top)  # N: 15 % of E (1e4 Pa = 1e-2 N/mm^2) on the 8 x 8 mm top
        for _ in range(400):
            step(sm, st, Control(external_forces=f), 2e-3, gauss_seidel=True)
        assert np.all(np.isfinite(st.positions))
        v0 = _volumes(model.points, model.tets).sum()
        lost[vs] = 1.0 - _volumes(st.positions, model.tets).sum() / v0
    assert lost[0.0] > 0.02  # the springs alone give way
    assert lost[1.0] < 0.6 * lost[0.0]


def test_bad_volume_term_input():
    pts, tets = kuhn_grid(1, 1, 1)
    V0 = _volumes(pts, tets)
    with pytest.raises(InputError, match="rest volumes must be > 0"):
        VolumeTerm.build(pts, tets, -V0, np.ones(len(tets)))
    with pytest.raises(InputError, match="tets index nodes outside"):
        VolumeTerm.build(pts, tets + 100, V0, np.ones(len(tets)))
    with pytest.raises(InputError, match="volume_stiffness must be a finite number >= 0"):
        build_spring_model(block(1, 1, 1), volume_stiffness=-1.0)
