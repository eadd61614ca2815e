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


def test_locate_matches_a_scan_of_every_tet(block):
    """The first-pose point location (kernel ``locate``) against its twin: every tet's barycentric
    coordinates in NumPy, the first tet holding the point."""
    from cutkit.cutting._kernels_step import WALK_EPS, locate

    p, t, _ = block
    rng = np.random.default_rng(7)
    corners = p[t]  # (m, 4, 3)
    T = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))  # columns: the edges from corner 0
    for q in np.concatenate([rng.uniform(-0.5, 4.5, (40, 3)), p[t[:5]].mean(axis=1)]):
        lam = np.linalg.solve(T, (q - corners[:, 0])[..., None])[..., 0]
        bary = np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)
        inside = np.flatnonzero(bary.min(axis=1) >= -WALK_EPS)
        assert locate(p, t, q) == (inside[0] if inside.size else -1)


def test_a_blade_put_inside_the_tissue_cuts_from_where_it_lies():
    """A blade whose whole edge lies inside the tissue at its first pose (put there, never drawn in
    through the surface) cuts as it moves; the cut mesh stays valid and the start is recorded."""
    from cutkit.cutting import to_model
    from cutkit.mesh.check import check_mesh
    from cutkit.model.tetmodel import TetModel

    p, t = box_mesh((10, 6, 6), spacing=(2.0, 2.0, 2.0))
    cm = CutMesh(p, t, blade_length=4.0)
    n_cut = 0
    for s in np.linspace(0.0, 1.0, 40):  # the edge from y = 4.5 to 8.5 of 0..12, then out through x = 20
        n_cut += cut_step(cm, [4.0 + 18.0 * s, 8.5, 6.3], [0.0, 1.0, 0.0]).cut_edges.size
    assert cm.started_inside
    assert n_cut > 40
    assert components(cm.tets) == 1  # a slit from where the blade lay out through the side
    cut = to_model(cm, TetModel.from_arrays(p, t))  # as `cutkit cut` writes it: no unused node
    assert check_mesh(cut.points, cut.tets).passed
    # a blade that starts outside is not put inside
    cm = CutMesh(p, t, blade_length=4.0)
    cut_step(cm, [4.0, -2.0, 6.3], [0.0, 1.0, 0.0])
    assert not cm.started_inside and cm.tip_tet == -1


def _inside_incision(tmp_path):
    """A slab model and a trajectory whose first pose has the whole blade inside it."""
    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.cutting.trajectory import Trajectory, write_trajectory
    from cutkit.io.model_h5 import write_model
    from cutkit.model.tetmodel import Materials, TetModel

    p, t = box_mesh((10, 6, 6), spacing=(2.0, 2.0, 2.0))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    write_model(tmp_path / "slab.h5", TetModel.from_arrays(p, t, materials=Materials.from_rows([row])))
    k = 40
    tip = np.stack([np.linspace(4.0, 22.0, k), np.full(k, 8.5), np.full(k, 6.3)], axis=1)
    traj = Trajectory(t=np.linspace(0.0, 0.39, k), tip=tip, a=np.tile([0.0, 1.0, 0.0], (k, 1)),
                      n=np.tile([1.0, 0.0, 0.0], (k, 1)))
    write_trajectory(tmp_path / "in.csv", traj)
    return tmp_path / "slab.h5", tmp_path / "in.csv"


def test_cut_cli_notes_a_blade_put_inside(tmp_path, capsys):
    from cutkit.cli.main import main

    model, traj = _inside_incision(tmp_path)
    assert main(["cut", str(model), "--trajectory", str(traj), "-o", str(tmp_path / "out"), "--blade-length", "4"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "the blade lay inside the tissue at the first pose: the cut starts where it lay" in out
    assert "nothing cut" not in out


def test_simulate_refuses_a_blade_put_inside(tmp_path, capsys):
    """The scalpel model needs an entry through the surface: one line, exit 2, no output folder."""
    from cutkit.cli.main import main

    model, traj = _inside_incision(tmp_path)
    out = tmp_path / "sim"
    assert main(["simulate", str(model), "--trajectory", str(traj), "-o", str(out), "--blade-length", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("cutkit: error: the blade lies inside the tissue at the trajectory's first pose (tip at 4, 8.5, 6.3 mm): "
                   "start the trajectory outside the tissue, so that the blade enters through its surface")
    assert not out.exists()


@pytest.mark.parametrize("face", ["y0", "y3", "z0", "z3"])
@pytest.mark.parametrize("upwards", [False, True])
def test_a_blade_lying_on_the_skin_cuts_nothing(face, upwards):
    """A blade in a boundary face's plane, sliding over the face, never enters: no edge is cut,
    whichever way it moves (the swept quad's normal then points into the tissue or out of it)."""
    p, t = box_mesh((5, 3, 3))
    axis, level = {"y": 1, "z": 2}[face[0]], float(face[1])
    other = 3 - axis  # the blade slides along the other of y, z
    cm = CutMesh(p, t, blade_length=10.0)
    for s in np.linspace(-0.5, 3.5, 9)[::1 if upwards else -1]:
        tip = np.zeros(3)
        tip[0], tip[axis], tip[other] = 4.0, level, s
        cut_step(cm, tip, np.array([1.0, 0.0, 0.0]))
    assert not cm.subtets and cm.n_points == len(p)


def test_a_blade_through_the_tissue_in_an_inner_face_plane_still_cuts():
    """The same slide one cell in, in the plane of inner faces: a through cut (one wall)."""
    p, t = box_mesh((5, 3, 3))
    cm = CutMesh(p, t, blade_length=10.0)
    for s in np.linspace(-0.5, 3.5, 9):
        cut_step(cm, np.array([6.0, 1.0, s]), np.array([1.0, 0.0, 0.0]))
    assert components(cm.tets) == 2


@pytest.mark.parametrize("a", [(0.0, 0.0, -1.0), (0.3, 0.0, -1.0), (0.0, 0.3, -1.0), (-0.5, 0.2, -1.0)])
@pytest.mark.parametrize("y", [1.0, 1.37])
def test_a_tip_sliding_along_the_skin_cuts_nothing(a, y):
    """The tip dragged over the top face, the blade above it: the swept quad meets the surface only
    along its border (the tip's path), never goes in, and cuts nothing; 0.3 mm deeper it cuts."""
    p, t = box_mesh((5, 3, 3))
    a = np.asarray(a) / np.linalg.norm(a)
    for depth, cuts in ((0.0, False), (0.3, True)):
        cm = CutMesh(p, t, blade_length=10.0)
        for x in np.linspace(-0.5, 5.5, 25):
            cut_step(cm, [x, y, 3.0 - depth], a)
        assert bool(cm.subtets) == cuts and (cm.n_points > len(p)) == cuts


def test_the_uncut_edges_line_counts_and_names_them():
    """The warning line: the count, one midpoint per edge up to NAMED_UNCUT_EDGES (rest, mm), singular
    for one edge; nothing when every crossed edge was cut."""
    from types import SimpleNamespace

    from cutkit.cutting import contact

    def line(k):
        places = np.arange(3.0 * k).reshape(k, 3)
        return contact.uncut_edges_line(SimpleNamespace(uncut_edge_places=lambda: places))

    assert line(0) == ""
    assert line(1) == ("1 edge the blade met could not be cut (deferred where its stroke ended, or a copy along "
                       "an earlier cut cut elsewhere) and stays joined; midpoint at (0.00, 1.00, 2.00) mm; "
                       "see docs/cutting.md")
    many = line(contact.NAMED_UNCUT_EDGES + 2)
    assert many.startswith(f"{contact.NAMED_UNCUT_EDGES + 2} edges the blade met") and "and stay joined" in many
    assert many.count("(") == 1 + contact.NAMED_UNCUT_EDGES and " and 2 more mm;" in many


def _random_poses(rng, n):
    """Blade moves around and through the block (4 x 4 x 4): entries of every kind, exits, misses,
    still blades, moves along the blade's own axis (a flat swept quad)."""
    for k in range(n):
        p0 = rng.uniform(-2.0, 6.0, 3)
        a0 = rng.normal(size=3)
        a0 /= np.linalg.norm(a0)
        kind = k % 4
        if kind == 0:  # a still blade
            p1, a1 = p0.copy(), a0
        elif kind == 1:  # along its own axis
            p1, a1 = p0 + rng.uniform(-3.0, 3.0) * a0, a0
        else:  # a free move and turn
            p1 = p0 + rng.normal(scale=1.5 if kind == 2 else 0.3, size=3)
            a1 = a0 + rng.normal(scale=0.3, size=3)
            a1 /= np.linalg.norm(a1)
        length = rng.uniform(0.5, 6.0)
        yield p0, p0 - length * a0, p1, p1 - length * a1


def test_blade_entry_kernel_matches_its_twin(block):
    """The one-call entry kernel against the same tests made of the public queries, on 600 random
    moves (still, along the axis, free) around, into and through a jittered block."""
    from _twins_aabb import blade_entry_twin

    p, _, bvh = block
    kinds = {"tip_path": 0, "blade": 0, "swept": 0, None: 0}
    for p0, q0, p1, q1 in _random_poses(np.random.default_rng(11), 600):
        got = blade_entry(bvh, p, p0, q0, p1, q1)
        ref = blade_entry_twin(bvh, p, p0, q0, p1, q1)
        if ref is None:
            assert got is None
            kinds[None] += 1
            continue
        assert got is not None and (got.kind, got.face) == ref[:2]
        np.testing.assert_array_equal(got.point, ref[2])
        kinds[got.kind] += 1
    assert min(kinds.values()) >= 20, kinds  # every kind of answer is met, misses too


def test_blade_entry_refuses_points_the_hierarchy_was_not_built_for(block):
    from cutkit.errors import InputError

    p, _, bvh = block
    with pytest.raises(InputError, match="rows, expected"):
        blade_entry(bvh, p[:-1], p[0], p[1], p[2], p[3])
