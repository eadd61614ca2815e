"""Decimation kernels against their NumPy twins (tests/_twins_decimate.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _twins_decimate import (
    cheapest_neighbours_twin,
    dihedral_angles,
    legal_collapse_twin,
    moved_tets_volume6,
    point_triangle_distance,
    surface_faces_twin,
    voxel_ellipsoid,
)
from cutkit.decimate import _candidates as C
from cutkit.decimate import _kernels as K
from cutkit.decimate import _legality as L
from cutkit.decimate import _pool as P
from cutkit.decimate import _state as S
from cutkit.mesh.geometry import point_triangle_dist2, tet_max_cos, tet_volume6
from cutkit.decimate.decimate import _adjacency, decimation_state


def test_tet_max_cos_matches_dihedral_angles():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(400, 3))
    tets = rng.permutation(400).reshape(100, 4)
    got = np.array([tet_max_cos(*pts[t]) for t in tets])
    want = np.cos(np.radians(dihedral_angles(pts, tets).min(axis=1)))
    np.testing.assert_allclose(got, want, atol=1e-9)
    # orientation does not matter; a flat tet is the worst possible
    assert math.isclose(tet_max_cos(*pts[tets[0, [1, 0, 2, 3]]]), got[0], rel_tol=1e-12)
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    assert tet_max_cos(*flat) == pytest.approx(1.0)
    assert tet_volume6(*flat) == 0.0


def test_regular_and_kuhn_tet_angles():
    reg = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    assert math.degrees(math.acos(tet_max_cos(*reg))) == pytest.approx(math.degrees(math.acos(1 / 3)))
    kuhn = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]], float)
    assert math.degrees(math.acos(tet_max_cos(*kuhn))) == pytest.approx(45.0)


def test_point_triangle_distance_matches_twin():
    rng = np.random.default_rng(1)
    for _ in range(300):
        p, a, b, c = rng.normal(size=(4, 3))
        assert math.sqrt(point_triangle_dist2(p, a, b, c)) == pytest.approx(point_triangle_distance(p, a, b, c), abs=1e-9)
    # degenerate triangles: a segment and a point
    p = np.array([0.3, 1.0, 0.0])
    a, b = np.zeros(3), np.array([1.0, 0, 0])
    assert math.sqrt(point_triangle_dist2(p, a, b, b)) == pytest.approx(1.0)
    assert math.sqrt(point_triangle_dist2(p, a, a, a)) == pytest.approx(math.hypot(0.3, 1.0))


def test_heap_pops_in_key_order_and_purges_stale_entries():
    rng = np.random.default_rng(2)
    n = 50
    ver = np.zeros(n, np.int64)
    key = np.empty(60)
    u = np.empty(60, np.int64)
    stamp = np.empty(60, np.int64)
    counters = np.zeros(P.N_COUNTERS, np.int64)
    latest = {}
    for _ in range(400):  # far more pushes than room: stale entries must be purged
        x = int(rng.integers(n))
        ver[x] += 1
        k = float(rng.random())
        latest[x] = k
        P.heap_push(k, x, ver[x], key, u, stamp, ver, counters)
    popped = []
    while counters[P.C_HEAP_SIZE]:
        k, x, s = P.heap_pop(key, u, stamp, counters)
        if s == ver[x]:
            popped.append((k, x))
    assert popped == sorted((k, x) for x, k in latest.items())


def test_pool_lists_match_python_lists():
    rng = np.random.default_rng(3)
    n = 20
    tets = rng.integers(0, n, size=(30, 4))
    start, length, cap, pool, end = _adjacency(tets, n)
    pool = pool[: end + 40].copy()  # little room: forces moves and compaction
    counters = np.zeros(P.N_COUNTERS, np.int64)
    counters[P.C_POOL_END] = end
    ref = {x: [t for t in range(30) for k in range(4) if tets[t, k] == x] for x in range(n)}
    for step in range(500):
        x = int(rng.integers(n))
        total = sum(len(r) for r in ref.values())
        # Like the decimator: the entries never outgrow the pool's slack.
        if ref[x] and (rng.random() < 0.4 or total >= 4 * tets.shape[0]):
            t = ref[x][int(rng.integers(len(ref[x])))]
            P.pool_remove(x, t, start, length, pool)
            ref[x].remove(t)
        else:
            t = 100 + step
            P.pool_append(x, t, start, length, cap, pool, counters)
            ref[x].append(t)
        for y in range(n):
            assert sorted(pool[start[y] : start[y] + length[y]].tolist()) == sorted(ref[y])
        assert counters[P.C_POOL_END] <= pool.shape[0]


def _state(points, tets, labels):
    n = points.shape[0]
    start, length, cap, pool, _ = _adjacency(tets, n)
    vclass = K.classify_vertices(tets, labels, start, length, pool)
    return start, length, pool, vclass


def test_surface_faces_match_twin():
    points, tets, labels = voxel_ellipsoid(7, radii=(0.45, 0.4, 0.45), inner=0.6)
    start, length, pool, vclass = _state(points, tets, labels)
    for x in range(points.shape[0]):
        m = 3 * length[x]
        fa, fb, f0, f1 = (np.empty(m, np.int64) for _ in range(4))
        k = L.surface_faces(x, S.Stars(tets, start, length, pool), labels, (fa, fb, f0, f1))
        got = {(frozenset((x, int(fa[i]), int(fb[i]))), (int(f0[i]), int(f1[i]))) for i in range(k)}
        assert len(got) == k
        assert got == surface_faces_twin(tets, labels, x)
        assert vclass[x] == (k > 0)


def test_legality_of_single_collapses_matches_twin():
    # Rules 1-3c (shape, link conditions, sheets); distances and volume
    # budgets are switched off here and tested on whole decimations.
    points, tets, labels = voxel_ellipsoid(5, radii=(0.5, 0.45, 0.45), inner=0.5)
    rng = np.random.default_rng(4)
    points = points + rng.uniform(-0.15, 0.15, points.shape)  # break the grid's symmetry
    n = points.shape[0]
    # the state a decimation builds (so the kernel is the one compiled for it), no volume budget
    state, _ = decimation_state(points, np.ascontiguousarray(tets, np.int64), np.ascontiguousarray(labels, np.int32),
                                np.zeros(tets.shape[0]), np.zeros(n, np.uint8), 1.0)
    k = state.budget.vol_budget.shape[0]
    state = state._replace(budget=S.Budget(np.zeros(k), np.full(k, np.inf)))
    start, length, pool = state.stars.adj_start, state.stars.adj_len, state.stars.pool
    params = np.zeros(L.N_PARAMS)
    params[L.P_H] = 1.0
    params[L.P_COS_MIN] = math.cos(math.radians(10.0))
    params[L.P_TOL] = 1e9
    params[L.P_SURF_SAFETY] = 1.0
    params[L.P_NORMAL_COS] = -1.0
    counters = np.zeros(P.N_COUNTERS, np.int64)
    edges = set()
    for t in tets:
        for a in t:
            for b in t:
                if a != b:
                    edges.add((int(a), int(b)))
    edges = sorted(edges)
    new_maxcos = np.empty(int(length.max()))
    picks = [edges[i] for i in rng.choice(len(edges), 250, replace=False)]
    n_legal = 0
    for u, v in picks:
        got, _ = L.can_collapse(u, v, state, counters, params, new_maxcos)
        want = legal_collapse_twin(points, tets, labels, u, v, params[L.P_COS_MIN], 1e9, -1.0)
        assert got == want, (u, v)
        if got:  # the dihedral cosines handed to the collapse are those of the new tets
            star = pool[start[u] : start[u] + length[u]]
            keep = [i for i, t in enumerate(star) if v not in tets[t]]
            new = np.where(tets[star[keep]] == u, v, tets[star[keep]])
            np.testing.assert_allclose(new_maxcos[keep], np.cos(np.radians(dihedral_angles(points, new).min(axis=1))), atol=1e-9)
        n_legal += got
    assert 0 < n_legal < len(picks)


def test_cheapest_neighbours_match_twin():
    points, tets, labels = voxel_ellipsoid(6, radii=(0.45, 0.4, 0.45), inner=0.6)
    points = points + np.random.default_rng(5).uniform(-0.1, 0.1, points.shape)
    start, length, pool, vclass = _state(points, tets, labels)
    n = points.shape[0]
    params = np.zeros(L.N_PARAMS)
    params[L.P_H] = 1.0
    params[L.P_W_SURFACE] = 3.0
    params[L.P_W_TOUCH] = 0.5
    mark = np.zeros(n, np.int64)
    counters = np.zeros(P.N_COUNTERS, np.int64)
    for k in (1, 4, 50):
        cand = np.empty(k, np.int64)
        key2 = np.empty(k)
        for u in range(n):
            nc = C.cheapest_neighbours(u, points, S.Stars(tets, start, length, pool), vclass, mark, counters,
                                       params, (cand, key2))
            star = pool[start[u] : start[u] + length[u]]
            want, want_keys = cheapest_neighbours_twin(points, tets, vclass, star, u, 3.0, 0.5, k)
            assert cand[:nc].tolist() == want, u
            np.testing.assert_allclose(key2[:nc], want_keys, rtol=1e-12)
            if nc:  # the heap key of a vertex is the cost of its cheapest half-edge
                assert math.sqrt(key2[0]) == pytest.approx(K.best_cost(u, points, tets, start, length, pool, vclass, params), rel=1e-12)


def test_volume_precheck_matches_twin():
    points, tets, labels = voxel_ellipsoid(5, radii=(0.5, 0.45, 0.45), inner=0.5)
    rng = np.random.default_rng(6)
    points = points + rng.uniform(-0.2, 0.2, points.shape)
    start, length, pool, _ = _state(points, tets, labels)
    grad = np.empty((int(length.max()), 3))
    base = np.empty(int(length.max()), np.int64)
    eps = 1e-3
    n_pass = n_fail = 0
    for u in range(points.shape[0]):
        star = pool[start[u] : start[u] + length[u]]
        C.volume_gradients(u, points, tets, start, length, pool, grad, base)
        # the affine volume equals the volume of the tets with u moved to x
        x = rng.normal(size=3) + points[u]
        moved = np.vstack([points, x])
        want = moved_tets_volume6(moved, tets, star, u, points.shape[0])
        got = np.einsum("ij,ij->i", grad[: star.size], x - points[base[: star.size]])
        np.testing.assert_allclose(got, want, atol=1e-9)
        for v in set(tets[star].ravel().tolist()) - {u}:
            ok = C.volume_precheck(u, v, points, S.Stars(tets, start, length, pool), (grad, base), eps)
            assert ok == bool(np.all(moved_tets_volume6(points, tets, star, u, v) > eps)), (u, v)
            n_pass += ok
            n_fail += not ok
    assert n_pass and n_fail
