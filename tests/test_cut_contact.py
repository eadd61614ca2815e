"""Contact of the whole blade with the surface: swept-quad queries, edge-first entries."""

import numpy as np
import pytest

from _twins_aabb import triangle_faces_twin
from _twins_cut import components
from cutkit.collision import SurfaceBVH, blade_entry, query_triangle, swept_faces
from cutkit.cutting import CutMesh, cut_step
from cutkit.mesh.generate import box_mesh


@pytest.fixture(scope="module")
def block():
    p, t = box_mesh((4, 4, 4))
    rng = np.random.default_rng(3)
    inner = np.all((p > 0) & (p < 4), axis=1)
    p = p + np.where(inner[:, None], rng.uniform(-0.2, 0.2, p.shape), 0.0)
    return p, t, SurfaceBVH.from_tets(p, t)


def test_triangle_query_matches_brute_force(block):
    p, _, bvh = block
    rng = np.random.default_rng(0)
    n_hit = 0
    for _ in range(60):
        tri = rng.uniform(-1, 5, (3, 3)) * rng.uniform(0.2, 1.0)
        got, pts = query_triangle(bvh, p, tri)
        ref = triangle_faces_twin(p, bvh.faces, bvh.face_alive, tri)
        assert sorted(got.tolist()) == sorted(ref.tolist())
        n_hit += len(got) > 0
    assert n_hit > 10


def test_guillotine_drop_is_an_entry(block):
    """A horizontal blade longer than the block falls through it in one step: no tip path, no pose touches."""
    p, _, bvh = block
    P0, Q0 = np.array([2.1, -1.0, 6.0]), np.array([2.1, 6.0, 6.0])
    P1, Q1 = np.array([2.1, -1.0, -2.0]), np.array([2.1, 6.0, -2.0])
    assert len(bvh.query_segment(p, P0, P1)) == 0 and len(bvh.query_segment(p, Q1, P1)) == 0
    faces, _ = swept_faces(bvh, p, P0, Q0, P1, Q1)
    assert faces.size > 8
    hit = blade_entry(bvh, p, P0, Q0, P1, Q1)
    assert hit is not None and hit.kind == "swept"
    assert hit.point[2] == pytest.approx(4.0)  # the top face: met first, normal against the motion


def test_entry_kinds(block):
    p, _, bvh = block
    a = np.array([0.0, 0.0, -1.0])
    # the tip's path through the top: the paper's entry
    hit = blade_entry(bvh, p, np.array([2.1, 2.2, 5.0]), np.array([2.1, 2.2, 8.0]),
                      np.array([2.1, 2.2, 3.0]), np.array([2.1, 2.2, 6.0]))
    assert hit.kind == "tip_path" and hit.point[2] == pytest.approx(4.0)
    # a resting blade the surface has moved past: the tip is inside, nothing moved
    tip = np.array([2.1, 2.2, 3.0])
    hit = blade_entry(bvh, p, tip, tip - 3 * a, tip, tip - 3 * a)
    assert hit.kind == "blade" and hit.point[2] == pytest.approx(4.0)
    # a blade leaving upwards is no entry
    assert blade_entry(bvh, p, np.array([2.1, 2.2, 3.0]), np.array([2.1, 2.2, 6.0]),
                       np.array([2.1, 2.2, 5.0]), np.array([2.1, 2.2, 8.0])) is None


def test_kinematic_guillotine_and_cleaver_cut():
    p, t = box_mesh((4, 4, 4))
    # guillotine: one step from above to below, the tip beside the block
    cm = CutMesh(p, t, blade_length=10.0)
    cut_step(cm, [2.37, -2.0, 7.0], [0, -1.0, 0])
    r = cut_step(cm, [2.37, -2.0, -3.0], [0, -1.0, 0])
    assert r.tip_tet == -1 and len(r.cut_edges) > 30
    assert components(cm.tets) == 2
    # cleaver: the edge comes down in small steps, tip outside, and stops half way
    cm = CutMesh(p, t, blade_length=10.0)
    for z in np.linspace(5.0, 2.0, 7):
        cut_step(cm, [2.37, -2.0, z], [0, -1.0, 0])
    assert np.isfinite(cm.edge_t).any() and components(cm.tets) == 1
