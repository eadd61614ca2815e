"""The blade carried from the deformed tissue into the rest configuration (cutkit.relax.rest_map).

The cut is made in the rest configuration, so the blade's rest pose must
follow the hand's smoothly: a rest pose that jumps makes the swept surface
fold and the cut leave edges uncut.
"""

import numpy as np
import pytest

from _twins_simulate import nodes_near_blade_twin, rest_displacement_twin
from cutkit.cutting import CutMesh, cut_step
from cutkit.mesh.generate import box_mesh
from cutkit.relax.rest_map import (REST_MAP_RADIUS_EDGES, BladeNeighbourhood, blade_weights, rest_displacement,
                                      rest_map_radius)

BLADE = 5.0  # blade length, mm


def _block(seed=0):
    """A jittered 10 x 6 x 6 block with a 4 mm incision (rest positions X)."""
    rng = np.random.default_rng(seed)
    p, t = box_mesh((10, 6, 6))
    inner = ((p > 0) & (p < [10, 6, 6])).all(axis=1)
    p = p + inner[:, None] * rng.uniform(-0.25, 0.25, p.shape)
    cm = CutMesh(p, t, blade_length=BLADE)
    a = np.array([0.1, 0.05, -1.0]) / np.linalg.norm([0.1, 0.05, -1.0])
    for x in np.linspace(1.0, 5.0, 9):
        cut_step(cm, [x, 3.3, 2.6], a)
    return cm, cm.points.copy(), a


def _displacement(cm, x, X, tip, axis, seeds=None):
    """The library's blade displacement: the flood fill from ``seeds`` (default: the active tets), the weights."""
    radius = rest_map_radius(X[:cm.n_orig_points], cm.orig_tets)
    nodes, d2 = BladeNeighbourhood(cm.store, radius).nodes(cm.store, x, cm.active_tets if seeds is None else seeds,
                                                     tip - BLADE * axis, tip)
    return rest_displacement(x, X, nodes, blade_weights(d2, radius))


def test_radius_is_the_median_edge_times_the_factor():
    from cutkit.mesh.topology import TET_EDGES

    p, t = box_mesh((2, 1, 1))  # Kuhn cubes: edges 1 (axis), sqrt 2 (face), sqrt 3 (body)
    lengths = np.linalg.norm(p[t[:, TET_EDGES[:, 0]]] - p[t[:, TET_EDGES[:, 1]]], axis=2)
    assert rest_map_radius(p, t) == pytest.approx(REST_MAP_RADIUS_EDGES * np.median(lengths))


@pytest.mark.parametrize("seed", range(4))
def test_flood_fill_finds_every_node_near_the_blade(seed):
    """Kernel against its twin over *every* original node: the flood fill from the step's active tets
    finds exactly the nodes within the radius of the blade (a wobbling incision going on, the tissue
    displaced at random)."""
    cm, X, a = _block(seed)
    rng = np.random.default_rng(100 + seed)
    x = X + rng.normal(0.0, 0.1, X.shape)
    radius = rest_map_radius(X[:cm.n_orig_points], cm.orig_tets)
    hood = BladeNeighbourhood(cm.store, radius)
    for xx in np.linspace(5.0, 9.0, 9):
        tip = np.array([xx, 3.3 + rng.uniform(-0.6, 0.6), 2.6 + rng.uniform(-0.6, 0.6)])
        axis = a + rng.normal(0, 0.2, 3)
        axis /= np.linalg.norm(axis)
        cut_step(cm, tip, axis)  # its active tets are the seeds, as in a session
        nodes, d2 = hood.nodes(cm.store, x, cm.active_tets, tip - BLADE * axis, tip)
        want = nodes_near_blade_twin(x, tip - BLADE * axis, tip, radius, range(cm.n_orig_points))
        assert len(want) > 10 and sorted(nodes.tolist()) == sorted(want)
        np.testing.assert_allclose(d2, [want[i] for i in nodes.tolist()], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_rest_displacement_matches_its_twin(seed):
    cm, X, a = _block(seed)
    rng = np.random.default_rng(200 + seed)
    x = X + rng.normal(0.0, 0.2, X.shape)
    radius = rest_map_radius(X[:cm.n_orig_points], cm.orig_tets)
    nodes, every_tet = np.arange(cm.n_orig_points), np.arange(cm.orig_tets.shape[0])
    for _ in range(5):
        tip = np.array([rng.uniform(3, 7), rng.uniform(2.5, 3.5), rng.uniform(1, 3)])
        np.testing.assert_allclose(_displacement(cm, x, X, tip, a, every_tet),
                                   rest_displacement_twin(x, X, nodes, tip, a, BLADE, radius), atol=1e-12)
    far = np.array([30.0, 3.0, 3.0])  # no node within the radius
    assert _displacement(cm, x, X, far, a, every_tet) is None


def test_a_translated_tissue_translates_the_blade_exactly():
    cm, X, a = _block(3)
    shift = np.array([0.7, -0.4, 0.25])
    np.testing.assert_allclose(_displacement(cm, X + shift, X, np.array([6.0, 3.3, 2.4]), a), shift, atol=1e-12)


def test_rest_pose_moves_continuously_with_the_blade():
    """A blade drawn in steps of a micrometre through a rough displacement field: its rest pose never jumps
    (each step moves it by at most a bounded multiple of the step), where a mean over a changing node
    set jumps by a fraction of a node's displacement whenever the set changes."""
    cm, X, a = _block(7)
    rng = np.random.default_rng(7)
    x = X + rng.normal(0.0, 0.3, X.shape)  # rough: every node its own displacement
    radius = rest_map_radius(X[:cm.n_orig_points], cm.orig_tets)
    hood = BladeNeighbourhood(cm.store, radius)
    every_tet = np.arange(cm.orig_tets.shape[0])  # seeds everywhere: the weights alone make it continuous
    step = 1e-3
    xs = np.arange(2.0, 4.0, step)
    u = []
    for xx in xs:
        tip = np.array([xx, 3.3, 2.6])
        near, d2 = hood.nodes(cm.store, x, every_tet, tip - BLADE * a, tip)
        u.append(rest_displacement(x, X, near, blade_weights(d2, radius)))
    u = np.array(u)
    jump = np.linalg.norm(np.diff(u, axis=0), axis=1).max()
    scale = np.abs(x - X).max()
    # the weights' slope is at most 1.72 / r, so |du/db| stays of order max|u| / r (0.05 of the bound
    # here); a hard cut-off weight (1 inside the radius) jumps by about max|u| / (nodes inside), 8 times
    # the bound in one step (measured with the twin), and a mean over a changing set as much (below)
    assert jump <= 2.0 * scale / radius * step
    inside = [np.flatnonzero(np.linalg.norm(x[:cm.n_orig_points] - [xx, 3.3, 2.6], axis=1) < radius) for xx in xs]
    plain = np.array([(x[i] - X[i]).mean(axis=0) for i in inside])
    assert np.linalg.norm(np.diff(plain, axis=0), axis=1).max() > 100 * jump
