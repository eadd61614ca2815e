"""Numba cutting kernels (collision, step traversal, cut nodes) against their NumPy twins."""

import numpy as np
import pytest

from _twins_cut import (
    clamp_bary_twin,
    edge_crosses_triangle,
    min_volume_twin,
    segment_hits_tet,
    segment_triangle,
    set_node_twin,
    sweep_twin,
    tet_bary_twin,
    walk_twin,
)
from cutkit.cutting import CutMesh
from cutkit.cutting import _kernels as K
from cutkit.cutting import _kernels_split as KP
from cutkit.cutting import _kernels_step as KS
from cutkit.mesh import geometry as G
from cutkit.mesh.geometry import clamp_bary
from cutkit.tissue import _store_kernels as SK
from cutkit.mesh.generate import box_mesh


def test_seg_tri_and_seg_tet_match_twins():
    rng = np.random.default_rng(1)
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tv = np.arange(4)
    hits = 0
    for _ in range(400):
        p0, p1, a, b, c = rng.uniform(-0.5, 1.2, (5, 3))
        r = G.segment_triangle_crossing(p0, p1, a, b, c)
        assert np.isclose(r, segment_triangle(p0, p1, a, b, c))
        hits += r >= 0
        assert G.segment_meets_tet(p0, p1, x, tv) == segment_hits_tet(p0, p1, x)
    assert hits > 10


def test_tet_sweep_matches_twin():
    rng = np.random.default_rng(2)
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tv = np.arange(4)
    oe, of = np.empty(6), np.empty(4)
    for it in range(200):
        swept = rng.uniform(-0.5, 1.5, (2, 3, 3))
        if it % 2:  # the swept surface through a vertex of the tet: only edges going up cross
            v = x[rng.integers(4)]
            swept[:, 0] = v - 0.5 * (swept[:, 1] - v) - 0.5 * (swept[:, 2] - v)
        blade = rng.uniform(-0.5, 1.5, (2, 3))
        K.tet_sweep(x, tv, swept, blade, oe, of)
        k = 0
        for i in range(4):
            for j in range(i + 1, 4):
                ref = -1.0
                for s in range(2):
                    r = edge_crosses_triangle(x[i], x[j], swept[s], G.EDGE_END_EPS, G.EDGE_BARY_EPS)
                    if r >= 0:
                        ref = r
                        break
                assert np.isclose(oe[k], ref)
                k += 1
        for f in range(4):
            idx = [(f + 1) % 4, (f + 2) % 4, (f + 3) % 4]
            assert np.isclose(of[f], segment_triangle(blade[0], blade[1], *x[idx]))


# ---------------------------------------------------------------- step kernels (_kernels_step)

def _jittered_box(seed):
    p, t = box_mesh((4, 3, 3))
    rng = np.random.default_rng(seed)
    return p + rng.uniform(-0.08, 0.08, p.shape), t


def test_tet_bary_and_walk_match_twins():
    p, t = _jittered_box(3)
    cm = CutMesh(p, t)
    rng = np.random.default_rng(4)
    out = np.empty(4)
    for _ in range(200):
        target = rng.uniform([-0.5, -0.5, -0.5], [4.5, 3.5, 3.5])
        o = int(rng.integers(len(t)))
        assert KS.tet_bary(cm._x, t[o], target, out)
        np.testing.assert_allclose(out, tet_bary_twin(cm._x, t[o], target), atol=1e-12)
        assert KS.walk(cm._x, t, cm.neighbors, o, target, 10000) == walk_twin(cm._x, t, cm.neighbors, o, target)
    flat = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0.0]])
    assert not KS.tet_bary(flat, np.arange(4), np.zeros(3), out) and (out == -1).all()


def _sweep_resumed(cm, edge_t, stamp, step, seeds, swept, blade, p0):
    """KS.sweep from buffers far too small: every overflow returns, is grown, and resumes."""
    seeds = list(dict.fromkeys(seeds.tolist()))
    bufs = [np.array(seeds + [0] * 4, np.int64), np.empty(1, np.int64), np.empty((10, 2), np.int64), np.empty((10, 3))]
    counts = np.array([len(seeds), 0, 0])
    mesh = KS.SweepMesh(cm.orig_tets, cm.neighbors, cm.tet_edges, cm.tet_faces, cm.edges, cm.faces, edge_t)
    while not KS.sweep(cm._x, mesh, stamp, step, KS.SweepBlade(swept, blade, p0), KS.SweepBuffers(*bufs, counts)):
        bufs = [np.concatenate([b, np.empty_like(b)]) for b in bufs]
    return bufs[1][:counts[1]], bufs[2][:counts[2]], bufs[3][:counts[2]]


def test_sweep_matches_twin():
    p, t = _jittered_box(5)
    cm = CutMesh(p, t)
    rng = np.random.default_rng(6)
    n_events = 0
    for it in range(60):
        edge_t = np.where(rng.random(cm.edges.shape[0]) < 0.2, 0.5, np.nan)
        tip0, tip1 = rng.uniform([0, 0, 0], [4, 3, 3], (2, 3))
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        q0, q1 = tip0 - 2.0 * a, tip1 - 2.0 * a
        swept = np.array([[tip0, q0, q1], [tip0, q1, tip1]])
        blade = np.array([q1, tip1])
        seeds = rng.integers(0, len(t), 3)
        seeds = np.concatenate([seeds, seeds[:1]])  # duplicates keep their first place
        s1 = np.zeros(len(t), np.int64)
        s2 = s1.copy()
        got = _sweep_resumed(cm, edge_t, s1, it + 1, seeds, swept, blade, tip0)
        ref = sweep_twin(cm._x, t, cm.neighbors, cm.tet_edges, cm.tet_faces, cm.edges, cm.faces, edge_t,
                         s2, it + 1, seeds, swept, blade, tip0)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], np.stack([ref[1], ref[2]], 1).reshape(-1, 2))
        np.testing.assert_allclose(got[2], ref[3], atol=1e-9)
        np.testing.assert_array_equal(s1, s2)
        n_events += len(got[1])
    assert n_events > 100


def test_clamp_set_node_min_volume_match_twins():
    rng = np.random.default_rng(7)
    for k, lo in ((3, 0.1), (4, 0.05), (3, 1e-3), (2, 0.0)):
        for _ in range(50):
            b = rng.uniform(-0.5, 1.0, k)
            np.testing.assert_allclose(clamp_bary(b, lo), clamp_bary_twin(b, lo), atol=1e-15)
        np.testing.assert_allclose(clamp_bary(-np.ones(k), lo), clamp_bary_twin(-np.ones(k), lo))
    x, X, uvw = rng.normal(size=(3, 10, 3))
    dn, dw = -np.ones((10, 4), np.int64), np.zeros((10, 4))
    for k in (2, 3, 4):
        nodes = rng.choice(6, k, replace=False).astype(np.int64)
        w = rng.random(k)
        for tex in (uvw, np.zeros((0, 3))):
            SK.set_node(x, X, tex, dn, dw, 8, nodes, w)
            rx, rX, ru = set_node_twin(x, X, tex if len(tex) else None, nodes, w)
            np.testing.assert_allclose(x[8], rx, atol=1e-14)
            np.testing.assert_allclose(X[8], rX, atol=1e-14)
            if len(tex):
                np.testing.assert_allclose(uvw[8], ru, atol=1e-14)
            assert list(dn[8, :k]) == list(nodes) and (dn[8, k:] == -1).all() and (dw[8, k:] == 0).all()
            # clamped and set in one call: the weights are the clamp's
            w_raw = rng.uniform(-0.3, 1.0, k)
            SK.set_node_clamped(x, X, tex, dn, dw, 9, nodes, w_raw, 0.05)
            rx, rX, ru = set_node_twin(x, X, tex if len(tex) else None, nodes, clamp_bary_twin(w_raw, 0.05))
            np.testing.assert_allclose(x[9], rx, atol=1e-14)
            np.testing.assert_allclose(dw[9, :k], clamp_bary_twin(w_raw, 0.05), atol=1e-15)
            # several nodes in one call: each as alone
            rows = rng.uniform(-0.3, 1.0, (2, k))
            SK.set_nodes_clamped(x, X, tex, dn, dw, np.array([6, 7], np.int64), np.array([nodes, nodes[::-1]]),
                                 rows, 0.05)
            for i, nd, wr in ((6, nodes, rows[0]), (7, nodes[::-1], rows[1])):
                rx, rX, ru = set_node_twin(x, X, tex if len(tex) else None, nd, clamp_bary_twin(wr, 0.05))
                np.testing.assert_allclose(x[i], rx, atol=1e-14)
                np.testing.assert_allclose(X[i], rX, atol=1e-14)
                assert list(dn[i, :k]) == list(nd)
    p, t = _jittered_box(8)
    t = t.copy()
    t[::3] = t[::3, [1, 0, 2, 3]]  # some inverted
    assert G.min_volume(p, t) == pytest.approx(min_volume_twin(p, t), abs=1e-14)
    assert G.min_volume(p, t[:0]) == np.inf


def test_serial_dihedral_kernel_matches_the_mesh_core():
    """The one-thread kernel the cut scores its candidates with is the mesh core's dihedral angle."""
    from cutkit.mesh import _quality_kernels as Q
    from cutkit.mesh.quality import dihedral_angles

    p, t = _jittered_box(4)
    np.testing.assert_array_equal(Q.dihedral_angles_serial(p, t), dihedral_angles(p, t))


def test_segment_against_several_tets_matches_the_twin_in_either_orientation():
    """``seg_meets_any_tet`` (the blade against a step's active tets) is any() of the twin, whatever the corner order."""
    rng = np.random.default_rng(7)
    x = rng.uniform(0.0, 1.0, (12, 3))
    tets = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]])
    hits = 0
    for _ in range(300):
        p0, p1 = rng.uniform(-0.2, 1.2, (2, 3))
        want = False
        for tv in tets:
            pts = x[tv]
            if np.dot(np.cross(pts[1] - pts[0], pts[2] - pts[0]), pts[3] - pts[0]) < 0:
                pts = pts[[0, 2, 1, 3]]  # the twin needs positive orientation
            want |= segment_hits_tet(p0, p1, pts)
        assert G.segment_meets_any_tet(p0, p1, x, tets) == want
        assert G.segment_meets_any_tet(p0, p1, x, tets[:, [1, 0, 2, 3]]) == want
        hits += want
    assert 20 < hits < 280
    assert not G.segment_meets_any_tet(np.zeros(3), np.ones(3), x, np.zeros((0, 4), np.int64))


def test_best_cone_apex_matches_twin():
    """The T-cone choice: over random tets and cut triangles, the kernel's apex and angle are the
    twin's, the spare row is the only row written, and a single blend gives the clamped centroid."""
    from _twins_cut import best_cone_apex_twin

    rng = np.random.default_rng(5)
    for trial in range(40):
        x = rng.uniform(-1.0, 1.0, (12, 3))
        x[:4] = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]] + rng.normal(0, 0.1, (4, 3))
        corners = np.arange(4)
        tris = np.array([rng.choice(11, 3, replace=False) for _ in range(int(rng.integers(2, 9)))])
        tb = rng.dirichlet(np.ones(4))
        blends = np.array([0.0, 0.35, 0.7])
        before = x.copy()
        b, angle = KS.best_cone_apex(x, corners, tb, blends, tris, 0.15, 11)
        b_t, angle_t = best_cone_apex_twin(before, corners, tb, blends, tris, 0.15)
        np.testing.assert_allclose(b, b_t, atol=1e-12)
        assert angle == pytest.approx(angle_t, abs=1e-9)
        np.testing.assert_array_equal(x[:11], before[:11])
    one, _ = KS.best_cone_apex(x, corners, tb, np.zeros(1), tris, 0.15, 11)
    np.testing.assert_allclose(one, clamp_bary_twin(tb, 0.15), atol=1e-15)


def test_best_face_apex_matches_twin():
    """The face-node cone of a partly cut tet: over random tets whose faces are fanned from a node
    on each, and over random triangles (inverted and flat cones among them), the kernel picks the
    twin's face with the twin's angle; every pick tiles the tet (cone volumes sum to its volume)."""
    from _twins_cut import best_face_apex_twin, volumes

    from cutkit.mesh.topology import TET_FACES

    rng = np.random.default_rng(17)
    picked = 0
    for trial in range(60):
        x = np.zeros((8, 3))
        x[:4] = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]] + rng.normal(0, 0.15, (4, 3))
        tris, tri_face = [], []
        for lf in range(4):  # each face fanned from a node on it (outward, as face_triangles gives)
            a, b, c = TET_FACES[lf]
            x[4 + lf] = rng.dirichlet(np.ones(3) * 2) @ x[[a, b, c]]
            for p, q in ((a, b), (b, c), (c, a)):
                tris.append((p, q, 4 + lf))
                tri_face.append(lf)
        tris, tri_face = np.array(tris, np.int64), np.array(tri_face, np.int64)
        if trial % 3 == 2:  # random triangles: most cones fail the volume test
            tris = np.array([rng.choice(8, 3, replace=False) for _ in range(12)], np.int64)
        face_nodes = np.where(rng.random(4) < 0.6, 4 + np.arange(4), -1).astype(np.int64)
        vol_min = 1e-3 * abs(volumes(x, np.array([[0, 1, 2, 3]]))[0]) * rng.choice([0.0, 1.0, 50.0])
        lf, angle = KP.best_face_apex(x, tris, tri_face, face_nodes, vol_min)
        lf_t, angle_t = best_face_apex_twin(x, tris, tri_face, face_nodes, vol_min)
        assert lf == lf_t
        assert angle == pytest.approx(angle_t, abs=1e-9)
        if lf >= 0 and trial % 3 != 2:
            picked += 1
            sel = tris[tri_face != lf]
            cone = np.column_stack([sel[:, 0], sel[:, 2], sel[:, 1], np.full(len(sel), face_nodes[lf])])
            v = volumes(x, cone)
            assert v.min() > 0 and v.sum() == pytest.approx(volumes(x, np.array([[0, 1, 2, 3]]))[0], rel=1e-12)
    assert picked >= 10


def test_best_compact_split_matches_twin():
    """The compact split choice: over random candidate cones (some inverted, some flat) the
    kernel picks the twin's candidates with the twin's angle; a rotation with a side whose
    candidates all fail the volume test is never picked; none passing gives (-1, -1, 0)."""
    from _twins_cut import best_compact_split_twin

    rng = np.random.default_rng(11)
    for trial in range(60):
        x = rng.uniform(-1.0, 1.0, (10, 3))
        n_rot = int(rng.integers(1, 4))
        candidates = []
        for r in range(n_rot):
            for side in (0, 1):
                for _ in range(int(rng.integers(0, 3))):
                    tets = [tuple(rng.choice(10, 4, replace=False)) for _ in range(int(rng.integers(1, 5)))]
                    candidates.append((r, side, tets))
        if not candidates:
            continue
        flat = np.array([t for _, _, c in candidates for t in c], np.int64)
        starts = np.concatenate([[0], np.cumsum([len(c) for _, _, c in candidates])]).astype(np.int64)
        rot = np.array([r for r, _, _ in candidates], np.int64)
        side = np.array([s for _, s, _ in candidates], np.int64)
        vol_min = float(rng.choice([-1.0, 0.0, 0.01]))
        got = KP.best_compact_split(x, flat, starts, rot, side, n_rot, vol_min)
        want = best_compact_split_twin(x, candidates, vol_min, n_rot)
        assert got[:2] == want[:2]
        assert got[2] == pytest.approx(want[2], abs=1e-9)
        if got[0] >= 0:
            assert candidates[got[0]][0] == candidates[got[1]][0]
            assert (candidates[got[0]][1], candidates[got[1]][1]) == (0, 1)
    # one rotation, side 1 only inverted tets: no split
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    flat = np.array([[0, 1, 2, 3], [0, 2, 1, 3]], np.int64)
    got = KP.best_compact_split(x, flat, np.array([0, 1, 2]), np.zeros(2, np.int64), np.array([0, 1]), 1, 0.0)
    assert got == (-1, -1, 0.0)


def test_cut_nodes_centroid_matches_twin():
    """T's default place (the mean of a tet's cut nodes) in every tet a blade left cut, partly or
    completely, against the twin; the weights sum to 1; each tet's mask of cut edges."""
    from _twins_cut import cut_nodes_centroid_twin

    from cutkit.cutting import cut_step
    from cutkit.cutting import subdivision as S

    p, t = _jittered_box(8)
    cm = CutMesh(p, t)
    a = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    for x in np.linspace(-0.5, 2.7, 9):  # the blade stops inside: crack-front tets stay partly cut
        cut_step(cm, np.array([x, 1.4, 1.2]), a)
    seen = set()
    for o in range(len(t)):
        assert cm.tet_mask(o) == sum(1 << k for k in range(6) if np.isfinite(cm.edge_t[cm.tet_edges[o, k]]))
        mask = S.REDUCE_TABLE[cm.tet_mask(o)]
        if mask == 0:
            continue
        b = KS.cut_nodes_centroid(cm.cut_tables(), o, mask)
        np.testing.assert_allclose(b, cut_nodes_centroid_twin(cm, o, mask), rtol=0, atol=1e-15)
        assert b.sum() == pytest.approx(1.0, abs=1e-12)
        seen.add(S.CLASSIFY_TABLE[mask][0])
    assert seen == {"partial", "corner", "quad"}


def test_subdivision_kernels_match_twins_along_cut_paths(monkeypatch):
    """Along cut paths (jittered block and Delaunay ball; straight, tremor, crossing), the face
    patterns of every cut tet and every compact split are the twins' (the rules as first written,
    with dicts and lists): the same triangles and owners in the same order, the same split tets
    and angle, the refusals too (a volume floor raised to 5 % on the ball); with and without
    centre nodes.  The fused kernel that tries every combination of free diagonals picks the
    first best of them."""
    from _cut_paths import delaunay_ball, jittered_block, make_path
    from _twins_cut import compact_split_twin, face_triangles_twin

    import cutkit.cutting.splits as SP
    from cutkit.cutting import cut_step
    from cutkit.cutting import subdivision as S

    kernel, fused = KP.compact_split, KP.compact_split_diagonals
    calls = {"made": 0, "refused": 0, "faces": 0, "several": 0}
    current = {}

    def as_list(cm, o, tris, corner, face):
        v = cm.orig_tets[o].tolist()
        return [(tuple(t), v[c], f) for t, c, f in zip(tris.tolist(), corner.tolist(), face.tolist())]

    def one(ct, x, o, tris, corner, face, group, vol_min):
        """The kernel's split of one combination of diagonals, checked against the twin's."""
        cm = current["cm"]
        got = kernel(ct, x, o, tris, corner, face, group, vol_min)
        got = (None if got[0].shape[0] == 0 else got[0], got[1])
        v = cm.orig_tets[o].tolist()
        want = compact_split_twin(cm, o, as_list(cm, o, tris, corner, face), {v[i]: int(group[i]) for i in range(4)},
                                  SP.COMPACT_VOL_MIN)
        assert (got[0] is None) == (want[0] is None)
        if got[0] is not None:
            assert [tuple(q) for q in got[0].tolist()] == [tuple(int(a) for a in q) for q in want[0]]
            assert got[1] == pytest.approx(want[1], abs=1e-9)
        calls["made" if got[0] is not None else "refused"] += 1
        return got

    def both(ct, x, o, mask, group, vol_min, free, centre_nodes):
        # every combination of free split-face diagonals the fused kernel tries, in its order; its pick
        # is the first best (ties within SCORE_TIE_DEG keep the earlier)
        best = (-1, None, 0.0)
        for bits in range(1 << free.shape[0]):
            for i in range(free.shape[0]):
                ct.face_diag[free[i, 0]] = free[i, 1 + (bits >> i & 1)]
            tris, corner, face = KP.face_triangles(ct, o, mask, centre_nodes)
            tets, angle = one(ct, x, o, tris, corner, face, group, vol_min)
            if tets is not None and (best[0] < 0 or angle > best[2] + KP.SCORE_TIE_DEG):
                best = (bits, tets, angle)
        calls["several"] += free.shape[0] > 0
        got = fused(ct, x, o, mask, group, vol_min, free, centre_nodes)
        assert got[0] == best[0]
        if best[0] >= 0:
            assert got[4].tolist() == best[1].tolist() and got[5] == best[2]
        return got

    monkeypatch.setattr(KP, "compact_split_diagonals", both)
    for (p, t), floor, centre in ((jittered_block(), SP.COMPACT_VOL_MIN, False), (delaunay_ball(), 0.05, False),
                                  (jittered_block(seed=3), SP.COMPACT_VOL_MIN, True)):
        monkeypatch.setattr(SP, "COMPACT_VOL_MIN", floor)
        L = p.max(axis=0)
        for seed, (kind, tremor) in enumerate([("straight", 0.0), ("tremor", 0.3), ("crossing", 1.0)]):
            cm = current["cm"] = CutMesh(p, t, centre_nodes=centre)
            for pose in make_path(kind, np.random.default_rng(seed), L, tremor):
                if pose is None:
                    cm.rebase()
                    continue
                cut_step(cm, *pose)
                for o in range(cm.orig_tets.shape[0]):
                    mask = S.REDUCE_TABLE[cm.tet_mask(o)]
                    if mask:
                        got = KP.face_triangles(cm.cut_tables(), o, mask, cm.centre_nodes)
                        assert as_list(cm, o, *got) == face_triangles_twin(cm, o, mask)
                        calls["faces"] += 1
    assert calls["made"] > 50 and calls["refused"] > 0 and calls["faces"] > 1000
    assert calls["several"] > 10  # splits with a free diagonal: several combinations tried


def test_the_vectorised_oracle_is_the_scalar_one():
    """The thousand-path oracle's segment/triangle test, all edges at once, classifies every segment as the
    scalar twin does (in-plane segments and segments from a triangle corner included)."""
    from _twins_cut import segment_triangle, segment_triangle_many

    rng = np.random.default_rng(1)
    for _ in range(20):
        a, b, c = rng.normal(size=(3, 3))
        p0, p1 = rng.normal(size=(2, 200, 3))
        p1[:20] = p0[:20] + (b - a) * rng.normal(size=(20, 1))  # parallel to the triangle's plane
        p0[20:30] = a
        got = segment_triangle_many(p0, p1, a, b, c)
        want = np.array([segment_triangle(x, y, a, b, c) for x, y in zip(p0, p1)])
        assert np.array_equal(got < 0, want < 0)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_fair_place_matches_twin():
    """The fairing's compass search: over random edge, face and tet nodes coned to random triangles
    around them (none through the node's own simplex, which would be flat), the kernel's weights and
    angle are the twin's, the weights stay in the box (each >= lo, within move_max of w_cut, summing
    to 1) or are w0, the angle never falls, x is left as it was, dead tets are not looked at, and a
    node at or above the angle limit is not moved."""
    from _twins_cut import fair_place_twin

    from cutkit.cutting import _kernels_fair as KF
    from cutkit.cutting import fairing as FA

    rng = np.random.default_rng(11)
    steps = np.array([0.08, 0.04, 0.02, 0.01])
    moved = 0
    for trial in range(45):
        k = 2 + trial % 3
        x = rng.uniform(-1.0, 1.0, (12, 3))
        corners = np.arange(k, dtype=np.int64)
        w0 = 0.25 + 0.5 * rng.dirichlet(np.ones(k))
        w0 /= w0.sum()
        x[10] = x[11] = w0 @ x[corners]  # the node and its coincident copy
        tets = []
        for _ in range(int(rng.integers(3, 9))):
            t = [int(rng.choice([10, 11]))] + rng.choice(np.arange(k, 10), 3, replace=False).tolist()
            a, b, c, d = x[t]
            tets.append(t if np.dot(np.cross(b - a, c - a), d - a) > 0 else [t[0], t[2], t[1], t[3]])
        tets = np.array(tets, np.int64)
        copies = np.array([10, 11], np.int64)
        before = x.copy()
        w_cut = w0 if trial % 2 else 0.25 + 0.5 * rng.dirichlet(np.ones(k))  # a box around another point
        w_cut = w_cut / w_cut.sum()
        # the tets in one original's range, with a dead tet among them (not looked at)
        buf = np.vstack([tets, [[10, 0, 1, 2]]])
        mesh = KF.FairMesh(x, buf, np.r_[np.ones(len(tets), bool), False], np.zeros(1, np.int64),
                           np.array([len(buf)]))
        limits = np.array([0.15, 0.2, np.inf])
        moves = FA._MOVES[k] if trial % 4 != 3 else FA._plane_moves(x[corners], rng.normal(size=3)) if k == 4 \
            else FA._MOVES[k][::-1]
        w, angle, start_k = KF.fair_place(mesh, np.zeros(1, np.int64), copies, corners, w0, w_cut, limits, steps, moves)
        w_t, angle_t = fair_place_twin(before, tets, copies, corners, w0, w_cut, 0.15, 0.2, steps, moves)
        np.testing.assert_allclose(w, w_t, atol=1e-12)
        assert angle == pytest.approx(angle_t, abs=1e-9)
        np.testing.assert_array_equal(x, before)
        assert w.min() >= 0.15 - 1e-12 and w.sum() == pytest.approx(1.0)
        assert np.array_equal(w, w0) or np.abs(w - w_cut).max() <= 0.2 + 1e-12
        start = fair_place_twin(before, tets, copies, corners, w0, w_cut, 0.15, 0.2, np.zeros(0), moves)[1]
        assert start_k == pytest.approx(start, abs=1e-9) and angle >= start - 1e-9
        moved += angle > start + 1e-9
        # at or above the limit nothing is searched
        limits[2] = start_k
        w_s, angle_s, _ = KF.fair_place(mesh, np.zeros(1, np.int64), copies, corners, w0, w_cut, limits, steps, moves)
        assert np.array_equal(w_s, w0) and angle_s == start_k
    assert moved >= 15  # the search moves most nodes


def test_poor_tets_are_the_live_sub_tets_below_the_limit():
    """poor_tets against min_dihedral_angles over every live sub-tet of the originals asked for, on a cut
    that made slivers: the same tets, in the same order, with their originals."""
    from test_cut_thousand_paths import MESHES, _path

    from cutkit.cutting import CutMesh, cut_step
    from cutkit.cutting import _kernels_fair as KF
    from cutkit.mesh.quality import min_dihedral_angles

    p, t = MESHES["gmsh"]
    poses, blade_length, _ = _path("gmsh", 105)
    cm = CutMesh(p, t, blade_length=blade_length, fair_nodes=False)
    for pose in poses[:40]:
        if pose is not None:
            cut_step(cm, *pose)
    originals = np.array(sorted(cm.subtets), np.int64)
    mesh = KF.FairMesh(cm._x, cm._tets, cm._alive, cm.sub_start, cm.sub_count)
    for below in (5.0, 12.0, 30.0):
        tets, owner = KF.poor_tets(mesh, originals, below)
        want = [(int(s), int(o)) for o in originals.tolist() for s in cm.subtets[o]
                if cm._alive[s] and min_dihedral_angles(cm._x, cm._tets[[s]])[0] < below]
        assert list(zip(tets.tolist(), owner.tolist())) == want
    assert 0 < len(KF.poor_tets(mesh, originals, 12.0)[0]) < len(KF.poor_tets(mesh, originals, 30.0)[0])


def test_vertex_place_matches_twin():
    """vertex_place (the smoothing's search) against its twin on random stars: a vertex, a cut node
    halfway along one of its edges following it by half its move, tets around both, the vertex's
    uncut edges and swept triangles near them.  Same move and angles; the move within reach; every
    tet positive after it; no uncut edge that missed the triangles (or met one at the vertex only)
    crosses one inside after it; the input left as it was; and where a triangle blocks the
    unconstrained best move, a shorter or other one."""
    from _twins_cut import edge_crosses_triangle, vertex_place_twin

    from cutkit.cutting import _kernels_fair as KF
    from cutkit.cutting import smoothing as SM

    rng = np.random.default_rng(23)
    steps = np.array([0.1, 0.05, 0.02, 0.01])
    moved = blocked = 0
    for trial in range(40):
        x = rng.uniform(-1.0, 1.0, (9, 3))
        x[0] = 0.0
        x[8] = 0.5 * (x[0] + x[1])  # a cut node on edge (0, 1): half the vertex's move
        share = np.zeros(9)
        share[0], share[8] = 1.0, 0.5
        tets = []
        for _ in range(int(rng.integers(4, 9))):
            t = [int(rng.choice([0, 8]))] + rng.choice(np.arange(2, 8), 3, replace=False).tolist()
            a, b, c, d = x[t]
            tets.append(t if np.dot(np.cross(b - a, c - a), d - a) > 0 else [t[0], t[2], t[1], t[3]])
        tets = np.array(tets, np.int64)
        ends = x[2:6].copy()
        swept = rng.uniform(-1.0, 1.0, (trial % 3, 3, 3))
        free, _, _ = KF.vertex_place(KF.VertexStar(x, tets, share, 0, ends, np.zeros((0, 3, 3))), SM._SPACE, steps, 0.3)
        if (trial % 2 or trial % 5 == 4) and free.any():
            # a large triangle across the free move: halfway along it, or (every fifth) through the
            # vertex, whose edges to ends behind it then cross it at the vertex only (not cut) and
            # would cross it inside after the move
            u = free / np.linalg.norm(free)
            e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(u, e1)
            c = x[0] + (0.0 if trial % 5 == 4 else 0.5) * free
            swept = np.array([[c - 10 * e1 - 10 * e2, c + 20 * e1 - 10 * e2, c - 10 * e1 + 20 * e2]])
        before = x.copy()
        star = KF.VertexStar(x, tets, share, 0, ends, swept)
        dx, angle, start = KF.vertex_place(star, SM._SPACE, steps, 0.3)
        dx_t, angle_t, start_t = vertex_place_twin(before, tets, share, 0, ends, swept, SM._SPACE, steps, 0.3)
        np.testing.assert_allclose(dx, dx_t, atol=1e-12)
        assert angle == pytest.approx(angle_t, abs=1e-9) and start == pytest.approx(start_t, abs=1e-9)
        np.testing.assert_array_equal(x, before)
        assert np.linalg.norm(dx) <= 0.3 + 1e-12 and angle >= start
        y = x + share[:, None] * dx
        assert all(np.dot(np.cross(y[b] - y[a], y[c] - y[a]), y[d] - y[a]) > 0 for a, b, c, d in tets)
        for q in ends:  # crossed strictly inside the edge after only where it was before
            was = any(0.0 < edge_crosses_triangle(x[0], q, tri) < 1.0 for tri in swept)
            assert was or not any(0.0 < edge_crosses_triangle(y[0], q, tri) < 1.0 for tri in swept)
        moved += angle > start + 1e-9
        blocked += not np.allclose(free, dx)
    assert moved >= 20 and blocked >= 3  # the search moves most vertices; triangles block some moves
