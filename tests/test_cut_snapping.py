"""Snapping (``CutMesh(snap_vertices=True)``, cutkit/cutting/snapping.py): a vertex near the cut moves away.

Checked against references written here: the crossing parameter of an edge
with a plane from the signed distances of its ends, the volume and the
dihedral angles of the vertex's star before the move, the face plane of a
boundary vertex.
"""

import numpy as np
import pytest

from _tissues import with_cut_mesh
from _cut_paths import jittered_block

from cutkit.cutting import CutMesh, cut_step, to_model
from cutkit.cutting import snapping as SN
from cutkit.mesh.check import check_mesh
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import min_dihedral_angles, signed_volumes


def _plane_through(point, normal, size=20.0):
    """Two big triangles (2, 3, 3) spanning the plane through ``point`` with unit ``normal``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    c = np.asarray(point, float)
    q = [c + size * (a * u + b * w) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return np.array([[q[0], q[1], q[2]], [q[0], q[2], q[3]]])


def _near_crossing(cm, v, swept, normal):
    """An edge of ``v`` crossing the plane and its parameter (from ``edges[e, 0]``), closest to ``v``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    h = (cm._x - swept[0, 0]) @ n
    best = None
    for e, (a, b) in enumerate(cm.edges.tolist()):
        if v in (a, b) and (h[a] > 0) != (h[b] > 0):
            s = h[a] / (h[a] - h[b])
            near = s if a == v else 1 - s
            if best is None or near < best[2]:
                best = (e, s, near)
    return best


def _star_tets(t, v):
    return t[(t == v).any(axis=1)]


@pytest.mark.parametrize("seed", range(4))
def test_an_interior_vertex_moves_away_keeping_volume_and_shape(seed):
    p, t = jittered_block((4, 4, 4), 0.15, seed)
    cm = CutMesh(p, t, snap_vertices=True)
    rng = np.random.default_rng(seed)
    v = int(np.flatnonzero(np.all((p > 0.5) & (p < 3.5), axis=1))[rng.integers(8)])
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    swept = _plane_through(p[v] - 0.05 * normal, normal)  # the plane passes 0.05 mm from v
    e, s, near = _near_crossing(cm, v, swept, normal)
    assert near < SN.SNAP_NEAR
    v0 = signed_volumes(p, t).sum()
    star = _star_tets(t, v)
    before = min_dihedral_angles(p, star).min()
    cm.store.begin_step()
    s_new = SN.snap_away(cm, e, s, swept)
    assert cm.snap_counts.get("moved", 0) + cm.snap_counts.get("moved part way", 0) == 1
    x = cm.points
    # volume kept exactly, star positive and no worse than min(before, SNAP_KEEP_DEG)
    assert abs(signed_volumes(x, t).sum() - v0) <= 1e-12 * v0
    assert (signed_volumes(x, star) > 0).all()
    assert min_dihedral_angles(x, star).min() >= min(before, SN.SNAP_KEEP_DEG) - 1e-9
    # the move: away from the plane, bounded, reported with the rest position before it
    d = x[v] - p[v]
    shortest = np.linalg.norm(p[np.unique(star)] - p[v], axis=1)
    assert 0 < np.linalg.norm(d) <= SN.SNAP_MOVE_MAX * shortest[shortest > 0].min() + 1e-12
    assert d @ normal > 0  # v lies above the plane
    assert np.allclose(cm.rest_points[v], x[v])
    log = cm.store.step_log
    assert log.moved_nodes == [v] and np.array_equal(log.moved_from[v], p[v])
    # the crossing, from the plane distances of the edge's ends now
    a, b = cm.edges[e]
    ha, hb = ((x[[a, b]] - swept[0, 0]) @ normal).tolist()
    assert s_new == pytest.approx(ha / (ha - hb), abs=1e-12)
    assert min(s_new, 1 - s_new) > near


def test_a_vertex_on_a_flat_face_moves_within_the_face():
    p, t = box_mesh((4, 4, 4))
    cm = CutMesh(p, t, snap_vertices=True)
    v = int(np.flatnonzero(np.all(np.isclose(p, [2.0, 2.0, 4.0]), axis=1))[0])  # centre of the top face
    normal = np.array([1.0, 0.3, 0.0])
    normal /= np.linalg.norm(normal)
    swept = _plane_through(p[v] + 0.05 * normal, normal)
    e, s, near = _near_crossing(cm, v, swept, normal)
    v0 = signed_volumes(p, t).sum()
    cm.store.begin_step()
    SN.snap_away(cm, e, s, swept)
    x = cm.points
    assert v in cm.snapped_nodes
    assert x[v, 2] == pytest.approx(4.0, abs=1e-12) and x[v, 0] < p[v, 0]  # v lies below the plane
    assert abs(signed_volumes(x, t).sum() - v0) <= 1e-12 * v0


def test_a_corner_vertex_stays():
    p, t = box_mesh((2, 2, 2))
    cm = CutMesh(p, t, snap_vertices=True)
    v = int(np.flatnonzero(np.all(p == 0.0, axis=1))[0])
    normal = np.array([1.0, 1.0, 0.2]) / np.linalg.norm([1.0, 1.0, 0.2])
    swept = _plane_through(p[v] + 0.05 * normal, normal)
    e, s, near = _near_crossing(cm, v, swept, normal)
    assert SN.snap_away(cm, e, s, swept) == s
    assert cm.snap_counts == {"curved or cornered surface": 1}
    assert np.array_equal(cm.points, p)


def _cut(cm, tips, a):
    moved = {}
    for tip in tips:
        res = cut_step(cm, tip, a)
        for k, X0 in zip(res.moved_nodes.tolist(), res.moved_from):
            moved.setdefault(k, X0)
    return moved


def test_a_cut_near_vertices_with_snapping_stays_sound_and_reports_its_moves():
    p, t = jittered_block((5, 3, 3), 0.2, 3)
    v0 = signed_volumes(p, t).sum()
    cm = CutMesh(p, t, blade_length=10.0, snap_vertices=True)
    a = np.array([0.05, 0.02, -1.0])
    a /= np.linalg.norm(a)
    # along y = 1.03: the jittered vertices near y = 1 lie within a quarter edge of the blade
    moved = _cut(cm, [[x, 1.03, -1.0] for x in np.linspace(-0.5, 5.5, 40)], a)
    m = to_model(cm)
    assert check_mesh(m.points, m.tets, m.labels).passed
    assert abs(signed_volumes(m.points, m.tets).sum() - v0) <= 1e-12 * v0
    snapped = sorted(cm.snapped_nodes)
    assert snapped, cm.snap_counts
    for v in snapped:  # every moved vertex was reported, with its rest position before the cut
        assert v in moved and np.array_equal(moved[v], p[v])
        assert not np.array_equal(cm.points[v], p[v])


def test_snapping_is_off_by_default():
    p, t = jittered_block((5, 3, 3), 0.2, 3)
    cm = CutMesh(p, t, blade_length=10.0)
    _cut(cm, [[x, 1.03, -1.0] for x in np.linspace(-0.5, 5.5, 40)], [0.05, 0.02, -1.0])
    assert not cm.snapped_nodes and np.array_equal(cm.points[:len(p)], p)


def _old_map(X_old, x_old, tets, point):
    """The tissue before a step, piecewise affine over ``tets``: the current place of rest ``point``.
    A point outside them all (a vertex on a curved surface moved within the plane that keeps the
    volume) takes the map of the tet it is nearest, by its smallest barycentric weight, extended,
    if that weight is within the tissue's reach (``PLACE_REACH``)."""
    from cutkit.relax.elastic_tissue import PLACE_REACH

    best, place = -np.inf, None
    for tv in tets:
        T = (X_old[tv[1:]] - X_old[tv[0]]).T
        b = np.linalg.solve(T, point - X_old[tv[0]])
        worst = min(b.min(), 1.0 - b.sum())
        if worst > best:
            best, place = worst, x_old[tv[0]] + (x_old[tv[1:]] - x_old[tv[0]]).T @ b
    if best < -min(PLACE_REACH, 0.25):
        raise AssertionError(f"point outside the star (barycentric weight {best})")
    return place


def cut_and_check_moved_vertices(tis, poses, n0: int) -> int:
    """Cut ``poses`` on ``tis.cm`` and hand each step to ``tis``; every original vertex (id < ``n0``) a
    step moved must then sit where the tissue before the step (its live tets around the vertex, over
    their rest places before the step) puts its new rest place.  Returns the vertices checked."""
    checked = 0
    for pose in poses:
        X_old, x_old, live = tis.cm.rest_points.copy(), tis.positions.copy(), tis.cm.tets
        res = cut_step(tis.cm, *pose)
        tis.apply_cut(res)
        for v in [k for k in res.moved_nodes.tolist() if k < n0]:
            X_before = X_old.copy()
            old = res.moved_nodes < len(X_old)
            X_before[res.moved_nodes[old]] = res.moved_from[old]
            ref = _old_map(X_before, x_old, live[(live == v).any(axis=1)], tis.cm.rest_points[v])
            assert np.allclose(tis.positions[v], ref, atol=1e-9)
            checked += 1
    return checked


def test_the_element_tissue_places_a_snapped_vertex_through_the_old_shape():
    from _fem_reference import kuhn_box
    from cutkit.model.tetmodel import Materials, Prestress, TetModel
    from cutkit.relax.elastic_tissue import ElasticTissue

    row = dict(label=1, name="m", E=30e3, poisson_ratio=0.45, density=1090.0, damping=8.0, F_enter=0.8,
               mu_static=1e-6, mu_dynamic=1e-6, rho_dynamic=1e-8, alpha_static=0.1, alpha_dynamic=0.1,
               c_edge=1.0, c_shape=1.0)
    p, t = kuhn_box((6.0, 3.0, 3.0), (6, 3, 3))
    rng = np.random.default_rng(5)
    inner = np.all((p > 0) & (p < [6.0, 3.0, 3.0]), axis=1)
    p = p + np.where(inner[:, None], rng.uniform(-0.2, 0.2, p.shape), 0.0)
    ps = Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[0.0, 1.0, 0.0]]),
                   prestrain=np.array([0.1]))
    tis = with_cut_mesh(ElasticTissue(TetModel.from_arrays(p, t, materials=Materials.from_rows([row]), prestress=ps), step_s=0.02), 1.6)
    tis.em.fixed[p[:, 2] == 0] = True
    tis.cm.snap_vertices = True
    X = tis.cm.rest_points
    tis.state.positions[:] = X + 0.1 * np.sin(X[:, [1, 2, 0]])  # a smooth deformation: current != rest
    checked = cut_and_check_moved_vertices(tis, [([xb, 1.03, 3.5], [0.0, 0.0, 1.0])
                                                 for xb in np.linspace(-0.5, 6.5, 15)], len(p))
    assert checked and np.isfinite(tis.positions).all()
    assert np.abs(tis.positions - tis.cm.rest_points).max() > 0.05
