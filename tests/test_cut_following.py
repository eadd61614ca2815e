"""A blade drawn back into an earlier stroke's wound follows its walls (cutkit/cutting/following.py).

Retracing an incision (or deepening it) after the blade left the tissue used
to slice thin pieces off the old wound's walls: the retraces made the last
cut-made tetrahedra below 5 degrees of the thousand paths.  Following keeps
them above it, parts the tissue where a deeper pass goes past the old wound,
and leaves a cut across the wound (an X) as it was.
"""

import numpy as np
import pytest

from _cut_paths import check_followed, jittered_block, lift, make_path, point_triangle_distances
from _twins_cut import components
from test_cut_thousand_paths import ALL_KINDS, MESHES, TREMORS, cut_path

from cutkit.cutting import CutMesh, cut_step, to_model
from cutkit.cutting.step import finish_stroke
from cutkit.mesh.check import check_mesh
from cutkit.mesh.quality import min_dihedral_angles, signed_volumes

#: Retraces of the thousand paths' generator drawn with other seeds (mesh, path index, seed) whose
#: worst cut-made tetrahedron was 3.3-4.94 degrees before the blade followed earlier wounds.
RETRACES = [("decimated", 327, 20261129), ("gmsh", 57, 20261129), ("decimated", 57, 20261129),
            ("decimated", 27, 20261129), ("kuhn", 237, 777), ("decimated", 252, 777)]


def _stroke(cm, poses, stroke):
    """Cut along ``poses``, the step's swept triangles appended to ``stroke``; every edge followed is
    checked to lie in the wound's band at its step (:func:`_cut_paths.check_followed`)."""
    for tip, a in poses:
        prev, x0, followed = cm.prev_pose, cm.points.copy(), set(cm.followed_edges)
        cut_step(cm, tip, a)
        if prev is not None:
            P1, Q1 = cm.prev_pose
            stroke += [(prev[0], prev[1], Q1), (prev[0], Q1, P1)]
            assert not check_followed(cm, x0, stroke[-2:], followed)


def _line(y, z, tilt, n=12, x0=-0.5, x1=5.5):
    a = np.array([0.0, tilt, -1.0]) / np.hypot(tilt, 1.0)
    return [(np.array([x, y, z]), a) for x in np.linspace(x0, x1, n)]


def _worst_made(cm):
    m = to_model(cm)
    made = m.tets[m.cell_data["new_tet"] == 1]
    return float(min_dihedral_angles(m.points, made).min())


def _sound(cm, v0):
    m = to_model(cm)
    assert check_mesh(m.points, m.tets, m.labels).passed
    from cutkit.cutting.crumbs import crumb_volume

    assert abs(float(signed_volumes(m.points, m.tets).sum()) + crumb_volume(cm) - v0) <= 1e-12 * v0


@pytest.mark.parametrize("name, i, seed", RETRACES)
def test_a_retrace_keeps_the_dihedral_bound(name, i, seed):
    """Each of these paths cut its retrace's wall into slivers below 5 degrees before; following
    lifts them all to the bound, and the path's checks (soundness, every crossed edge cut, counted
    or followed within the band) still hold."""
    p, t = MESHES[name]
    kind, tremor = ALL_KINDS[i % len(ALL_KINDS)], TREMORS[(i // len(ALL_KINDS)) % len(TREMORS)]
    assert kind == "retrace"
    poses = make_path(kind, np.random.default_rng(1000 * i + seed), p.max(axis=0), tremor)
    missed, worst = cut_path(p, t, poses, 2.5 if i % 2 else 10.0, (name, i))
    assert not missed
    assert worst >= 5.0, (name, i, worst)
    if (name, i) == ("decimated", 327):  # the first of them without following: its slivers come back
        assert cut_path(p, t, poses, 2.5, (name, i), follow_wounds=False)[1] < 4.0


@pytest.mark.parametrize("offset", [0.0, 0.04])
def test_drawing_the_blade_again_along_a_through_cut_cuts_nothing_new(offset):
    """A through cut, the blade lifted out, then drawn along the same line again (exactly, or 0.04 mm
    beside it and tilted 2 degrees): the second pass follows the wound (every edge it crosses lies in
    the wound's band), the block stays in two pieces, no crumb comes off the walls, and no new
    tetrahedron is made."""
    p, t = jittered_block((5, 3, 3), 0.2, 0)
    v0 = float(signed_volumes(p, t).sum())
    cm = CutMesh(p, t, blade_length=10.0)
    _stroke(cm, _line(1.37, -0.5, 0.1), [])
    lift(cm)
    tets_before, crumbs_before = cm.tet_alive.sum(), cm.crumb_count
    stroke = []
    _stroke(cm, _line(1.37 + offset, -0.5, 0.1 + 0.035 * (offset > 0)), stroke)
    finish_stroke(cm)
    _sound(cm, v0)
    assert cm.followed_checked  # edges crossed in the wound's band (others lie in the blade's plane)
    assert components(cm.tets) == 2
    assert cm.crumb_count == crumbs_before and cm.tet_alive.sum() == tets_before
    assert cm.edges_left_uncut() == 0


def test_deepening_a_cut_parts_the_tissue_below_the_old_wound():
    """A cut 1.2 mm deep into the 3 mm block, lifted out, then drawn again along it to below the block:
    every step of the deeper pass crosses the tissue under the wound, outside its band, so it cuts all
    it crosses (a step follows the wound only where all its crossings lie in the band), joins the
    wound and the block falls in two; the cut keeps the dihedral bound."""
    p, t = jittered_block((5, 3, 3), 0.2, 0)
    v0 = float(signed_volumes(p, t).sum())
    cm = CutMesh(p, t, blade_length=10.0)
    top = p[:, 2].max()
    _stroke(cm, _line(1.37, top - 1.2, 0.1), [])
    lift(cm)
    assert components(cm.tets) == 1
    _stroke(cm, _line(1.39, -0.5, 0.12), [])
    finish_stroke(cm)
    _sound(cm, v0)
    assert cm.edges_followed() == 0
    assert components(cm.tets) == 2
    assert _worst_made(cm) >= 5.0
    assert cm.edges_left_uncut() == 0


def test_a_cut_across_the_wound_is_not_followed():
    """An X: the second through cut crosses the first at right angles, passing through the wound's
    band where it meets it; the walls' mean plane there is across the blade, so nothing is followed and
    the block falls in four pieces."""
    p, t = jittered_block((5, 3, 3), 0.2, 0)
    cm = CutMesh(p, t, blade_length=10.0)
    a = np.array([0.0, 0.0, -1.0])
    _stroke(cm, [(np.array([x, 1.37, -0.5]), a) for x in np.linspace(-0.5, 5.5, 12)], [])
    lift(cm)
    _stroke(cm, [(np.array([2.37, y, -0.5]), a) for y in np.linspace(-0.5, 3.5, 8)], [])
    finish_stroke(cm)
    assert cm.edges_followed() == 0
    assert components(cm.tets) == 4


def test_the_distance_reference_is_a_distance():
    """The test's own point-triangle distance (used to check followed crossings) against closed forms:
    above the face, beside an edge, beyond a corner, and a degenerate triangle."""
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    for q, d in (([0.2, 0.2, 0.5], 0.5), ([0.5, -1.0, 0.0], 1.0), ([-3.0, -4.0, 0.0], 5.0),
                 ([1.0, 1.0, 0.0], np.sqrt(0.5))):
        assert point_triangle_distances(np.array(q), a, b, c)[0] == pytest.approx(d)
    assert point_triangle_distances(np.array([0.5, 1.0, 0.0]), a, b, b)[0] == pytest.approx(1.0)
