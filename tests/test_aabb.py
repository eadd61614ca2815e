"""Surface AABB hierarchy (paper 4.1): build, refit, insertion, queries."""

import numpy as np
import pytest

from cutkit.collision import (
    HIT_COPLANAR,
    HIT_EDGE,
    HIT_FACE,
    HIT_VERTEX,
    SurfaceBVH,
)
from cutkit.collision import _kernels as K
from cutkit.collision.adjacency import csr_adjacency, edge_adjacency
from cutkit.errors import InputError, MeshError

from _twins_aabb import brute_segment_hits, expected_boxes, pair_level, refit_tolerance


def icosphere(level=2, radius=10.0):
    """Icosphere: (points, outward faces)."""
    t = (1 + 5**0.5) / 2
    pts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
           (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    pts = [np.array(p, float) / np.linalg.norm(p) for p in pts]
    for _ in range(level):
        mid = {}

        def m(i, j):
            key = (min(i, j), max(i, j))
            if key not in mid:
                p = pts[i] + pts[j]
                pts.append(p / np.linalg.norm(p))
                mid[key] = len(pts) - 1
            return mid[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return radius * np.array(pts), np.array(faces, dtype=np.int64)


def kuhn_box(n, size=1.0):
    """A cube of n^3 cells, each split into 6 positive tets."""
    g = np.arange(n + 1)
    ii, jj, kk = np.meshgrid(g, g, g, indexing="ij")
    pts = np.column_stack([ii.ravel(), jj.ravel(), kk.ravel()]).astype(float) * size / n
    idx = lambda i, j, k: (i * (n + 1) + j) * (n + 1) + k  # noqa: E731
    tets = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                c = [idx(i + (q >> 0 & 1), j + (q >> 1 & 1), k + (q >> 2 & 1)) for q in range(8)]
                for perm in ((1, 2, 4), (1, 4, 2), (2, 1, 4), (2, 4, 1), (4, 1, 2), (4, 2, 1)):
                    a, b = perm[0], perm[0] | perm[1]
                    t = [c[0], c[a], c[b], c[7]]
                    p = pts[t]
                    if np.linalg.det(p[1:] - p[0]) < 0:
                        t[1], t[2] = t[2], t[1]
                    tets.append(t)
    return pts, np.array(tets, dtype=np.int64)


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)


def random_segments(rng, count, scale):
    p0 = rng.uniform(-1.5 * scale, 1.5 * scale, (count, 3))
    p1 = rng.uniform(-1.5 * scale, 1.5 * scale, (count, 3))
    return p0, p1


def assert_same_hits(bvh, points, p0, p1):
    hits = bvh.query_segment(points, p0, p1)
    ref = brute_segment_hits(points, bvh.faces, bvh.face_alive, p0, p1)
    assert sorted(hits.face.tolist()) == sorted(ref)
    for f, kind, t, x in zip(hits.face, hits.kind, hits.t, hits.point):
        assert kind == ref[f][0]
        assert t == pytest.approx(ref[f][1], abs=1e-9)
        np.testing.assert_allclose(x, p0 + t * (np.asarray(p1) - p0), atol=1e-9)
    assert np.all(np.diff(hits.t) >= 0)
    return hits


# -- build ---------------------------------------------------------------------


def test_pair_level_matches_twin(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.01)
    nodes = np.arange(len(faces), dtype=np.int64)
    off, idx, _ = csr_adjacency(edge_adjacency(faces), len(faces))
    first, second = K.pair_level(bvh.box_min, bvh.box_max, nodes, off, idx)
    adjacency = [set(idx[off[i]:off[i + 1]].tolist()) for i in range(len(faces))]
    assert list(zip(first.tolist(), second.tolist())) == pair_level(bvh.box_min, bvh.box_max, nodes, adjacency)


def test_build_is_consistent_and_balanced(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.01)
    bvh.check(pts)
    f = len(faces)
    # a binary tree with f leaves and no single-child nodes
    assert bvh.n_nodes == 2 * f - 1
    bmin, bmax = expected_boxes(bvh)
    np.testing.assert_array_equal(bvh.box_min, bmin)
    np.testing.assert_array_equal(bvh.box_max, bmax)
    # leaf boxes are the corners' bounding box grown by s_tol (Fig. 5a)
    corners = pts[faces]
    np.testing.assert_allclose(bvh.box_min[bvh.face_leaf], corners.min(axis=1) - 0.01)
    np.testing.assert_allclose(bvh.box_max[bvh.face_leaf], corners.max(axis=1) + 0.01)
    depth = np.zeros(bvh.n_nodes, dtype=int)
    for node in range(bvh.n_nodes):
        p, d = bvh.parent[node], 0
        while p >= 0:
            p, d = bvh.parent[p], d + 1
        depth[node] = d
    assert depth.max() <= 2 * np.log2(f)


def test_first_level_pairs_share_an_edge(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces)
    inner = np.flatnonzero(bvh.child[:, 0] >= 0)
    both_leaves = inner[(bvh.leaf_face[bvh.child[inner, 0]] >= 0) & (bvh.leaf_face[bvh.child[inner, 1]] >= 0)]
    assert len(both_leaves) >= 0.4 * len(faces)
    for node in both_leaves:
        a, b = faces[bvh.leaf_face[bvh.child[node]]]
        assert len(set(a) & set(b)) == 2


def test_two_components_get_one_root():
    pts, faces = icosphere(1)
    pts2 = np.vstack([pts, pts + [50.0, 0, 0]])
    faces2 = np.vstack([faces, faces + len(pts)])
    bvh = SurfaceBVH.build(pts2, faces2)
    bvh.check(pts2)
    # the root's children separate the two spheres
    l, r = bvh.child[bvh.root]
    assert {bvh.box_max[l, 0] < 25, bvh.box_max[r, 0] < 25} == {True, False}


def test_from_tets_uses_boundary(tmp_path):
    pts, tets = kuhn_box(3)
    bvh = SurfaceBVH.from_tets(pts, tets, s_tol=0.0)
    assert bvh.n_faces == 6 * 2 * 3**2
    bvh.check(pts)
    # outward orientation: normals point away from the centre
    tri = pts[bvh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", normal, tri.mean(axis=1) - 0.5) > 0)


def test_bad_input_messages():
    pts, faces = icosphere(0)
    with pytest.raises(MeshError, match=r"^faces refer to nodes outside \[0, 12\): 0\.\.12$"):
        SurfaceBVH.build(pts, np.vstack([faces, [[0, 1, 12]]]))
    with pytest.raises(InputError, match=r"^points must have shape \(n, 3\), got \(12, 2\)$"):
        SurfaceBVH.build(pts[:, :2], faces)
    with pytest.raises(InputError, match=r"^s_tol must be finite and >= 0, got -1.0$"):
        SurfaceBVH.build(pts, faces, s_tol=-1.0)
    with pytest.raises(MeshError, match=r"^tets must be an integer array of shape \(m, 4\), got int64 \(20, 3\)$"):
        SurfaceBVH.from_tets(pts, faces)
    with pytest.raises(MeshError, match=r"^tets refer to nodes outside \[0, 12\): 0\.\.12$"):
        SurfaceBVH.from_tets(pts, [[0, 1, 2, 12]])


# -- queries -------------------------------------------------------------------


def test_queries_match_brute_force(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.05)
    rng = np.random.default_rng(1)
    n_hits = 0
    for p0, p1 in zip(*random_segments(rng, 60, 10.0)):
        n_hits += len(assert_same_hits(bvh, pts, p0, p1))
        brute = bvh.query_segment(pts, p0, p1, brute_force=True)
        hits = bvh.query_segment(pts, p0, p1)
        np.testing.assert_array_equal(brute.face, hits.face)
    assert n_hits > 20


def test_segment_through_the_centre_hits_twice(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces)
    hits = bvh.query_segment(pts, [-20, 0.1234, 0.0567], [20, 0.1234, 0.0567])
    assert len(hits) == 2
    # the icosphere is inscribed in the radius-10 sphere: hits inside it, near it
    r = np.linalg.norm(hits.point, axis=1)
    assert np.all(r <= 10 + 1e-9) and np.all(r > 9.5)
    assert hits.point[0, 0] < 0 < hits.point[1, 0]


def square(n_split=2):
    """Unit square in z=0: two triangles, or four around the centre."""
    if n_split == 2:
        pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
        return pts, np.array([[0, 1, 2], [0, 2, 3]])
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]], float)
    return pts, np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])


def test_segment_through_a_shared_edge_hits_both():
    pts, faces = square(2)
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.0)
    hits = assert_same_hits(bvh, pts, np.array([0.3, 0.3, 1.0]), np.array([0.3, 0.3, -1.0]))
    assert sorted(hits.face) == [0, 1]
    assert list(hits.kind) == [HIT_EDGE, HIT_EDGE]
    np.testing.assert_allclose(hits.t, 0.5)


def test_segment_through_a_vertex_hits_its_fan():
    pts, faces = square(4)
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.0)
    hits = assert_same_hits(bvh, pts, np.array([0.5, 0.5, -2.0]), np.array([0.5, 0.5, 2.0]))
    assert sorted(hits.face) == [0, 1, 2, 3]
    assert set(hits.kind) == {HIT_VERTEX}
    np.testing.assert_allclose(hits.point, [[0.5, 0.5, 0.0]] * 4)


def test_inside_and_miss_and_touching_end():
    pts, faces = square(2)
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.0)
    hits = assert_same_hits(bvh, pts, np.array([0.8, 0.2, 1.0]), np.array([0.8, 0.2, -3.0]))
    assert list(hits.face) == [0] and list(hits.kind) == [HIT_FACE]
    assert hits.t[0] == pytest.approx(0.25)
    # just outside the square: no hit
    assert len(assert_same_hits(bvh, pts, np.array([1.0 + 1e-6, 0.5, 1.0]), np.array([1.0 + 1e-6, 0.5, -1.0]))) == 0
    # ending exactly on the surface counts (t = 1)
    hits = assert_same_hits(bvh, pts, np.array([0.8, 0.2, 1.0]), np.array([0.8, 0.2, 0.0]))
    assert list(hits.face) == [0] and hits.t[0] == 1.0
    # stopping short of it does not
    assert len(assert_same_hits(bvh, pts, np.array([0.8, 0.2, 1.0]), np.array([0.8, 0.2, 1e-6]))) == 0


def test_degenerate_triangle_and_segment_never_hit():
    pts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 1, 3]])  # the first has zero area
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.0)
    hits = assert_same_hits(bvh, pts, np.array([0.5, 0.0, 1.0]), np.array([0.5, 0.0, -1.0]))
    assert list(hits.face) == [1] and list(hits.kind) == [HIT_EDGE]
    # a zero-length segment, even one lying on the triangle
    assert len(bvh.query_segment(pts, [0.2, 0.2, 0.0], [0.2, 0.2, 0.0])) == 0


def test_coplanar_segment():
    pts, faces = square(2)
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.0)
    # along y = 0.25 from outside: enters face 0 (below the diagonal) at x = 0,
    # face 1 at the diagonal x = 0.25
    hits = assert_same_hits(bvh, pts, np.array([-1.0, 0.25, 0.0]), np.array([2.0, 0.25, 0.0]))
    assert list(hits.face) == [1, 0] or list(hits.face) == [0, 1]
    assert set(hits.kind) == {HIT_COPLANAR}
    t = dict(zip(hits.face.tolist(), hits.t.tolist()))
    assert t[1] == pytest.approx(1 / 3) and t[0] == pytest.approx(1.25 / 3)
    # parallel but above the plane: nothing
    assert len(assert_same_hits(bvh, pts, np.array([-1.0, 0.25, 1e-3]), np.array([2.0, 0.25, 1e-3]))) == 0
    # coplanar but beside the square: nothing
    assert len(assert_same_hits(bvh, pts, np.array([-1.0, 1.5, 0.0]), np.array([2.0, 1.5, 0.0]))) == 0


def test_blade_and_tip_path_queries(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces)
    tip = np.array([0.0, 0.0, 8.0])
    a = np.array([0.0, 0.0, -1.0])  # pointing down into the sphere from above
    hits = bvh.query_blade(pts, tip, a, blade_length=20.0)
    # the edge runs from z = 28 to z = 8 and crosses the top of the sphere once
    assert len(hits) >= 1 and np.all(np.abs(hits.point[:, 2] - 10) < 0.2)
    path = bvh.query_tip_path(pts, [0.0, 0.0, 12.0], tip)
    assert set(path.face) == set(hits.face)
    assert np.all((path.t > 0.4) & (path.t < 1.0))


# -- deformation -----------------------------------------------------------------


def test_small_jitter_inside_tolerance_refits_nothing(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.05)
    rng = np.random.default_rng(2)
    moved = pts + rng.uniform(-0.049, 0.049, pts.shape)
    assert bvh.update(moved) == 0
    assert bvh.refit_counts == {"nodes_left_tolerance": 0, "leaf_refits": 0, "node_refits": 0}
    bvh.check(moved)
    # without tolerance boxes every node triggers
    bare = SurfaceBVH.build(pts, faces, s_tol=0.0)
    assert bare.update(moved) == len(pts)
    assert bare.refit_counts["leaf_refits"] == len(faces)
    bare.check(moved)


def test_local_move_refits_only_its_faces(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.05)
    old_min, old_max = bvh.box_min.copy(), bvh.box_max.copy()
    moved = pts.copy()
    moved[7] *= 1.05
    tol_expected = refit_tolerance(moved, bvh.tol_min, bvh.tol_max, bvh.s_tol)
    assert bvh.update(moved) == 1
    np.testing.assert_array_equal(tol_expected[0], np.arange(len(pts)) == 7)
    np.testing.assert_array_equal(bvh.tol_min, tol_expected[1])
    np.testing.assert_array_equal(bvh.tol_max, tol_expected[2])
    ring = np.flatnonzero((faces == 7).any(axis=1))
    counts = bvh.refit_counts
    assert counts["leaf_refits"] == len(ring)
    bmin, bmax = expected_boxes(bvh)
    np.testing.assert_array_equal(bvh.box_min, bmin)
    np.testing.assert_array_equal(bvh.box_max, bmax)
    bvh.check(moved)
    # only the ring's leaves and some of their ancestors changed
    changed = np.flatnonzero(np.any(old_min != bvh.box_min, axis=1) | np.any(old_max != bvh.box_max, axis=1))
    assert set(bvh.face_leaf[ring]) <= set(changed)
    assert len(changed) <= len(ring) * (1 + 2 * np.log2(len(faces)))
    assert counts["node_refits"] < 0.1 * bvh.n_nodes


def test_large_deformation_then_queries(sphere):
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.05)
    rng = np.random.default_rng(3)
    moved = pts * [1.3, 0.8, 1.0] + rng.normal(0, 0.2, pts.shape)
    bvh.update(moved)
    bvh.check(moved)
    bmin, bmax = expected_boxes(bvh)
    np.testing.assert_array_equal(bvh.box_min, bmin)
    for p0, p1 in zip(*random_segments(rng, 20, 10.0)):
        assert_same_hits(bvh, moved, p0, p1)


# -- cuts: new and dead faces ---------------------------------------------------


@pytest.mark.parametrize("reindex", [False, True])
def test_add_and_remove_faces(sphere, reindex, monkeypatch):
    if reindex:  # new faces go into the node-to-faces index at once
        monkeypatch.setattr("cutkit.collision.bvh.REINDEX_MIN", 0)
        monkeypatch.setattr("cutkit.collision.bvh.REINDEX_FRACTION", 0.0)
    pts, faces = sphere
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.05)
    n_nodes = bvh.n_nodes
    old_leaf_boxes = bvh.box_min[bvh.face_leaf].copy()
    # a cut removes the faces around node 0 and opens a little pocket: a fan
    # of new faces to a new node inside the sphere
    ring = np.flatnonzero((faces == 0).any(axis=1))
    bvh.remove_faces(ring)
    inner = pts[0] * 0.8
    moved = np.vstack([pts, inner])
    new_faces = faces[ring].copy()
    new_faces[new_faces == 0] = len(pts)  # same rim, apex pushed in
    ids = bvh.add_faces(moved, new_faces)
    assert bvh._n_indexed == (bvh.n_faces if reindex else len(faces))
    np.testing.assert_array_equal(ids, np.arange(len(faces), len(faces) + len(ring)))
    # no rebuild: old leaves keep their ids and boxes, new nodes are appended
    assert bvh.n_nodes == n_nodes + 2 * len(ring)
    alive_old = np.setdiff1d(np.arange(len(faces)), ring)
    np.testing.assert_array_equal(bvh.box_min[bvh.face_leaf[alive_old]], old_leaf_boxes[alive_old])
    bvh.check(moved)
    bmin, bmax = expected_boxes(bvh)
    np.testing.assert_array_equal(bvh.box_max, bmax)
    # the dead faces are not hit any more, the pocket is
    hits = assert_same_hits(bvh, moved, pts[0] * 1.5, pts[0] * 0.5)
    assert not set(hits.face) & set(ring)
    assert set(hits.face) <= set(ids) and len(hits) >= 1
    # and the pocket follows deformation like the rest
    moved2 = moved.copy()
    moved2[-1] *= 0.9
    assert bvh.update(moved2) == 1
    assert bvh.refit_counts["leaf_refits"] == len(ring)
    bvh.check(moved2)
    with pytest.raises(InputError, match=r"^face ids must lie in \[0, 1285\), got 0\.\.9999$"):
        bvh.remove_faces([0, 9999])


def test_random_cuts_and_deformations_stay_consistent():
    pts, faces = icosphere(2)
    bvh = SurfaceBVH.build(pts, faces, s_tol=0.1)
    rng = np.random.default_rng(4)
    points = pts.copy()
    for step in range(6):
        # a "cut": kill the faces around a random live vertex, open a pocket
        alive = np.flatnonzero(bvh.face_alive)
        v = bvh.faces[rng.choice(alive)][0]
        ring = alive[(bvh.faces[alive] == v).any(axis=1)]
        bvh.remove_faces(ring)
        points = np.vstack([points, points[v] * 0.9])
        pocket = bvh.faces[ring].copy()
        pocket[pocket == v] = len(points) - 1
        bvh.add_faces(points, pocket)
        # deformation: mostly jitter below s_tol, a few big moves
        points = points + rng.uniform(-0.05, 0.05, points.shape)
        big = rng.choice(len(points), 5, replace=False)
        points[big] += rng.normal(0, 1.0, (5, 3))
        bvh.update(points)
        bvh.check(points)
        bmin, bmax = expected_boxes(bvh)
        np.testing.assert_array_equal(bvh.box_min, bmin)
        np.testing.assert_array_equal(bvh.box_max, bmax)
        for p0, p1 in zip(*random_segments(rng, 10, 10.0)):
            assert_same_hits(bvh, points, p0, p1)
    assert bvh.face_alive.sum() == len(faces)  # each pocket replaces its ring
