"""Fairing (cutkit.cutting.fairing): cut nodes around slivers re-placed within their own simplex.

On paths of the thousand-path generator whose cut made slivers, against the
same cut without fairing: the worst cut-made dihedral angle rises, the mesh
stays sound and volume-exact, every cut node stays in its simplex within the
snap limits and within FAIR_MOVE_MAX of where the cut put it, coincident
copies stay coincident, and every move is a moved node of its step.
"""

import numpy as np
import pytest

from test_cut_thousand_paths import MESHES, _path

from cutkit.cutting import CutMesh, cut_step, to_model
from cutkit.cutting import cutmesh as CM
from cutkit.cutting import fairing as FA
from cutkit.cutting.step import blade_in_tissue, rebase_if_left
from cutkit.mesh.check import check_mesh
from cutkit.mesh.quality import min_dihedral_angles, signed_volumes

#: (mesh, path index): single strokes whose cut made a tet below 5 degrees without fairing.
SLIVER_PATHS = [("gmsh", 105), ("kuhn", 40), ("decimated", 195)]


def _cut(name, i, fair, monkeypatch):
    """Cut path ``i`` of mesh ``name``; returns the CutMesh at the end of its first stroke that cut, the clamped
    crossing of every edge it cut and the step results."""
    p, t = MESHES[name]
    poses, blade_length, _ = _path(name, i)
    crossing = {}
    cut_edge = CM.CutMesh._cut_edge

    def recording(self, e, s):
        crossing[int(e)] = min(max(float(s), CM.EDGE_SNAP), 1.0 - CM.EDGE_SNAP)
        return cut_edge(self, e, s)

    monkeypatch.setattr(CM.CutMesh, "_cut_edge", recording)
    cm = CutMesh(p, t, blade_length=blade_length, fair_nodes=fair, smooth_vertices=False)
    results = []
    for pose in poses:
        if pose is None:
            break
        results.append(cut_step(cm, *pose))
        if cm.subtets and not blade_in_tissue(cm):  # the first stroke that cut has ended
            break
    return cm, crossing, results


def _worst_made(cm):
    m = to_model(cm)
    made = m.tets[m.cell_data["new_tet"] == 1]
    return float(min_dihedral_angles(m.points, made).min()), m


@pytest.mark.parametrize("name,i", SLIVER_PATHS)
def test_fairing_lifts_the_slivers_and_keeps_the_cut_sound(name, i, monkeypatch):
    plain, _, _ = _cut(name, i, False, monkeypatch)
    cm, crossing, results = _cut(name, i, True, monkeypatch)
    before, _ = _worst_made(plain)
    after, m = _worst_made(cm)
    assert before < 5.0 < after, (before, after)
    rep = check_mesh(m.points, m.tets, m.labels)
    assert rep.passed, [(r.name, r.detail) for r in rep.rows if not r.passed]
    p, t = MESHES[name]
    v0 = float(signed_volumes(p, t).sum())
    assert abs(float(signed_volumes(m.points, m.tets).sum()) - v0) <= 1e-12 * v0
    # every cut edge's node: both copies at its parameter, within the snap limits and FAIR_MOVE_MAX
    for e, s in crossing.items():
        t_now = float(cm.edge_t[e])
        assert CM.EDGE_SNAP - 1e-12 <= t_now <= 1.0 - CM.EDGE_SNAP + 1e-12
        assert abs(t_now - s) <= FA.FAIR_MOVE_MAX + 1e-12
        a, b = cm.edges[e]
        for c in cm.edge_node[e][cm.edge_node[e] >= 0]:
            np.testing.assert_allclose(cm._x[c], (1 - t_now) * cm._x[a] + t_now * cm._x[b], atol=1e-12)
    # every cut node: weights >= its simplex's snap limit, summing to one
    k = (cm._def_nodes[cm.n_orig_points:cm.n_points] >= 0).sum(axis=1)
    w = cm._def_w[cm.n_orig_points:cm.n_points]
    for size in (2, 3, 4):
        rows = w[k == size, :size]
        assert (rows >= FA._LO[size] - 1e-12).all()
        np.testing.assert_allclose(rows.sum(axis=1), 1.0, atol=1e-12)
    # the moves are the steps' moved nodes: some step reports a moved node it did not make
    assert any(r.moved_nodes.size for r in results)


def test_fairing_is_on_by_default_and_kept_over_a_rebase():
    p, t = MESHES["kuhn"]
    cm = CutMesh(p, t)
    assert cm.fair_nodes
    off = CutMesh(p, t, fair_nodes=False)
    poses, blade_length, _ = _path("kuhn", 40)
    for pose in poses:
        if pose is None:
            break
        cut_step(off, *pose)
    rebase_if_left(off) or off.rebase()
    assert off.fair_nodes is False and off.fair_pending == {}


def test_a_t_node_moves_only_within_its_cut_plane():
    """A T node's moves (fairing._plane_moves) keep its weights summing to one and its place in the plane
    through it with the given normal; each move's largest weight change is one step."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        xc = rng.normal(size=(4, 3))
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        d = FA._plane_moves(xc, normal)
        assert d.shape == (8, 4)
        np.testing.assert_allclose(d.sum(axis=1), 0.0, atol=1e-12)
        np.testing.assert_allclose((d @ xc) @ normal, 0.0, atol=1e-12)
        np.testing.assert_allclose(np.abs(d).max(axis=1), 1.0)
        assert np.linalg.matrix_rank(d) == 2


@pytest.mark.parametrize("centre", [False, True])
def test_a_straight_cut_stays_in_the_blade_plane(centre):
    """Through a bar, a straight vertical blade at y = 1.37: every node of the cut surface lies in that
    plane up to the snap of its split faces' centre nodes (fairing moves none off it)."""
    from cutkit.cutting import cut_surface_faces

    from test_cut import bar

    p, t = bar()
    devs = []
    for fair in (False, True):
        cm = CutMesh(p, t, blade_length=10.0, centre_nodes=centre, fair_nodes=fair)
        for x in np.linspace(-0.5, 6.5, 30):
            cut_step(cm, [x, 1.37, -0.5], [0, 0, -1.0])
        devs.append(np.abs(cm.points[np.unique(cut_surface_faces(cm))][:, 1] - 1.37).max())
    assert devs[1] <= devs[0] + 1e-12


@pytest.mark.parametrize("name,i", [("gmsh", 42), ("decimated", 209)])
def test_a_second_round_lifts_what_the_first_left(name, i, monkeypatch):
    """Where the first round's moves leave a sub-tet below FAIR_AGAIN_BELOW_DEG around them, the nodes of
    the poor sub-tets at the moved nodes are looked at once more: on these first strokes one round
    leaves the worst cut-made angle below 5 degrees and two lift it above; the cut stays sound."""
    cm, _, _ = _cut(name, i, True, monkeypatch)
    worst, m = _worst_made(cm)
    monkeypatch.setattr(FA, "FAIR_AGAIN_BELOW_DEG", 0.0)
    one_round, _, _ = _cut(name, i, True, monkeypatch)
    assert _worst_made(one_round)[0] < 5.0 <= worst
    assert check_mesh(m.points, m.tets, m.labels).passed
