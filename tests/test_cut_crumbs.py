"""Crumbs: a piece cut loose below CRUMB_VOLUME_FRACTION of the model is removed, its volume reported."""

import numpy as np
import pytest

from _twins_cut import loose_small_pieces_twin

from cutkit.cutting import CutMesh, cut_step, to_model
from cutkit.cutting import _kernels_crumbs as KC
from cutkit.cutting.crumbs import CRUMB_VOLUME_FRACTION, crumb_volume, loose_pieces
from cutkit.mesh.check import check_mesh
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import signed_volumes


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def corner_cut(cm, level):
    """Sweep a blade through the whole plane x + y + z = level (cuts the corner at the origin off)."""
    n, a, d = _unit([1, 1, 1]), _unit([1, -1, 0]), _unit([1, 1, -2])
    c = level / 3.0 * np.ones(3)
    for s in np.linspace(-6.0, 6.0, 25):
        cut_step(cm, c + s * d + 6.0 * a, a)
    return n


def assert_sound(cm, v0):
    m = to_model(cm)
    rep = check_mesh(m.points, m.tets, m.labels)
    assert rep.passed, [(r.name, r.detail) for r in rep.rows if not r.passed]
    assert abs(float(signed_volumes(m.points, m.tets).sum()) + crumb_volume(cm) - v0) <= 1e-12 * v0
    assert np.unique(m.tets).size == len(m.points)  # no orphan node written


@pytest.mark.parametrize("level", [0.4, 0.6])
def test_a_corner_cut_off_below_the_crumb_volume_is_removed(level):
    p, t = box_mesh((6, 4, 4))
    v0 = float(signed_volumes(p, t).sum())
    cm = CutMesh(p, t, blade_length=12.0)
    corner_cut(cm, level)
    assert cm.crumb_count >= 1
    # the piece that left: the tets on the corner's side of the cut, by the independent volume sum
    assert 0 < crumb_volume(cm) <= CRUMB_VOLUME_FRACTION * v0
    assert_sound(cm, v0)
    vols = loose_pieces(cm)
    assert vols.size == 1 and vols[0] == pytest.approx(v0 - crumb_volume(cm), rel=1e-12)


def test_a_larger_piece_cut_loose_stays_and_is_reported():
    p, t = box_mesh((6, 4, 4))
    v0 = float(signed_volumes(p, t).sum())
    cm = CutMesh(p, t, blade_length=12.0)
    corner_cut(cm, 2.2)
    assert cm.crumb_count == 0 and crumb_volume(cm) == 0.0
    vols = loose_pieces(cm)
    assert vols.size == 2 and vols[1] > CRUMB_VOLUME_FRACTION * v0
    assert vols.sum() == pytest.approx(v0, rel=1e-12)
    assert_sound(cm, v0)


def test_a_crumb_cut_again_into_a_larger_loose_piece_goes_with_it():
    """A retrace with tremor on the Kuhn box (without fairing) cuts the corner around one vertex loose
    below the crumb limit several steps running, and then makes part of it again as a piece just above
    the limit: kept alone, that piece was the corner with the removed part missing (an edge in four
    boundary faces).  It goes with the crumb (CRUMB_REGROWN_FRACTION)."""
    from _cut_paths import make_path
    from test_cut_thousand_paths import MESHES, cut_path

    p, t = MESHES["kuhn"]
    poses = make_path("retrace", np.random.default_rng(1000 * 237 + 99991), p.max(axis=0), 1.0)
    missed, _ = cut_path(p, t, poses, 2.5, "kuhn retrace", fair_nodes=False, smooth_vertices=False)  # checks every stroke's end
    assert not missed


def test_crumb_kernel_matches_twin():
    p, t = box_mesh((6, 4, 4))
    cm = CutMesh(p, t, blade_length=12.0)
    cm.model_volume = 1e-9  # keep every piece while cutting, to have pieces to sort
    corner_cut(cm, 0.6)
    corner_cut(cm, 2.2)
    total = cm.n_tets_total
    alive = cm._alive[:total].copy()
    live = np.flatnonzero(alive)
    rng = np.random.default_rng(0)
    m0 = cm.sub_count.shape[0]
    blocks = KC.make_blocks(np.ascontiguousarray(cm._X[:cm.n_orig_points]), cm.orig_tets, cm.neighbors, 0.5)
    changed = (cm.sub_count > 0) | ~alive[:m0]  # blocks with such a tet are dirty, the others count whole
    dirty = np.zeros(blocks[1].shape[0], bool)
    dirty[blocks[0][changed]] = True
    assert 0 < dirty.sum() < dirty.size
    inc = KC.Incidence(cm.node_tet_off, cm.node_tet_idx, cm._def_nodes, cm.n_orig_points, cm.sub_start,
                       cm.sub_count, cm.neighbors, *blocks, dirty)
    mark, block_mark = np.zeros(total, np.int64), np.zeros(dirty.size, np.int64)
    for i, limit in enumerate((1e-3, 0.05, 1.0, 5.0, 50.0, 1e3)):  # 1e3: the whole block is one crumb
        seeds = rng.choice(live, 12)
        got, k = KC.loose_small_pieces(cm._X, cm._tets[:total], alive, inc, seeds, limit, mark, block_mark,
                                       4 * (i + 1))
        ref, k_ref = loose_small_pieces_twin(cm._X, cm._tets[:total], alive, seeds, limit)
        assert k == k_ref
        np.testing.assert_array_equal(np.sort(got), ref)


def test_cut_cli_reports_the_crumb_it_removed_and_writes_no_trace_of_it(tmp_path):
    import re

    from click.testing import CliRunner

    from cutkit.cli.cut import command
    from cutkit.cutting.trajectory import Trajectory, write_trajectory
    from cutkit.io.model_h5 import read_model, write_model
    from cutkit.model.tetmodel import TetModel

    p, t = box_mesh((6, 4, 4))
    v0 = float(signed_volumes(p, t).sum())
    write_model(tmp_path / "m.h5", TetModel(points=p, tets=t, labels=np.ones(len(t), np.int32)))
    a, d = _unit([1, -1, 0]), _unit([1, 1, -2])
    tips = np.array([0.2 * np.ones(3) + s * d + 6.0 * a for s in np.linspace(-6.0, 6.0, 25)])
    axes = np.repeat(a[None], len(tips), 0)
    normals = np.repeat(_unit(np.cross(a, d))[None], len(tips), 0)
    write_trajectory(tmp_path / "f.csv", Trajectory(t=np.arange(len(tips)) * 0.01, tip=tips, a=axes, n=normals,
                                                     blade_length=12.0))
    r = CliRunner().invoke(command, [str(tmp_path / "m.h5"), "--trajectory", str(tmp_path / "f.csv"),
                                     "-o", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    found = re.search(r"1 crumb cut loose .* removed: ([0-9.e-]+) mm\^3", r.output.replace("\n", " "))
    assert found, r.output
    m = read_model(tmp_path / "out" / "model.h5")
    # the written model: one piece, its volume the model's less the crumb's, every node used
    assert float(signed_volumes(m.points, m.tets).sum()) + float(found.group(1)) == pytest.approx(v0, rel=1e-3)
    assert np.unique(m.tets).size == len(m.points)
    assert "cut loose besides the largest" not in r.output


def _clean_blocks_are_whole(cm, where):
    """Every block the crumb search counts whole (not dirty) has all its tets live and uncut, and its
    volume as made is theirs at their rest places now."""
    of, volume = cm.crumb_blocks[0], cm.crumb_blocks[1]
    m0 = cm.sub_count.shape[0]
    changed = (cm.sub_count > 0) | ~cm._alive[:m0]
    clean = ~cm.crumb_block_dirty
    assert not changed[clean[of]].any(), where
    now = np.bincount(of, weights=signed_volumes(cm._X, cm.orig_tets), minlength=volume.size)
    np.testing.assert_allclose(now[clean], volume[clean], rtol=1e-12, atol=0, err_msg=str(where))
    return int(clean.sum())


@pytest.mark.parametrize("name,i,crumbs", [("kuhn", 42, 1), ("decimated", 168, 2), ("decimated", 35, 1),
                                           ("gmsh", 104, 0), ("decimated", 73, 0)])
def test_a_clean_block_is_whole_and_keeps_its_volume(name, i, crumbs):
    """After every step of cut paths that subdivide, remove crumbs, move cut nodes (fairing) and
    vertices (smoothing) and rebase between strokes, the blocks the crumb search counts whole are
    whole: the search's shortcut (cutkit/cutting/_kernels_crumbs.py) is exact only so."""
    from _cut_paths import lift
    from test_cut_thousand_paths import MESHES, _path

    from cutkit.cutting.step import blade_in_tissue, finish_stroke, rebase_if_left

    p, t = MESHES[name]
    poses, blade_length, where = _path(name, i)
    cm = CutMesh(p, t, blade_length=blade_length)
    counted = []
    for k, pose in enumerate(poses):
        if pose is None:
            finish_stroke(cm)
            lift(cm)
        else:
            cut_step(cm, *pose)
            if not blade_in_tissue(cm) and cm.prev_pose is not None:
                rebase_if_left(cm)
        counted.append(_clean_blocks_are_whole(cm, (where, k)))
    finish_stroke(cm)
    _clean_blocks_are_whole(cm, (where, "end"))
    assert min(counted) > 0 and cm.crumb_blocks[1].size > 1 and cm.crumb_count == crumbs


def test_a_crumb_of_uncut_tets_leaves_their_blocks_dirty():
    """A corner cut off the box whose piece holds whole uncut cubes, below the crumb limit (the model's
    volume set large): the crumb's uncut tets go, and their blocks are no longer counted whole."""
    p, t = box_mesh((6, 4, 4))
    cm = CutMesh(p, t, blade_length=12.0)
    cm.model_volume = 8000.0  # the limit, 8 mm^3, above the corner piece's 7.1 mm^3
    corner_cut(cm, 3.5)
    m0 = cm.sub_count.shape[0]
    assert cm.crumb_count == 1 and (~cm._alive[:m0] & (cm.sub_count == 0)).sum() >= 6  # uncut tets removed
    _clean_blocks_are_whole(cm, "corner")
