"""A thousand blade paths, every kind, tremor 0-1 mm, on three kinds of mesh: the cut stays sound.

Meshes (small, so the thousand run in CI): a Kuhn-split box (exact contacts
with vertices, edges and faces), gmsh's Delaunay mesh of a box and a
decimated isovolume ellipsoid (``tests/data/cut_path_meshes.npz``, made by
``tests/data/make_cut_path_meshes.py``).  Each path is cut as ``cutkit cut``
cuts (a stroke ends where the blade leaves the tissue); at the end of every
stroke (where the blade left, after the rebase and the look at every
cut-made tet it opens, which the tissue gets before its next step) and of
the path:

* the written mesh passes ``cutkit check`` (orientation, manifold faces,
  edges and vertices, no hanging and no unused node);
* the live volume plus the crumbs removed is the model's (1e-12 relative);
* no piece below ``CRUMB_VOLUME_FRACTION`` of the model is left to the physics;
* every original edge the stroke's swept surface crossed strictly inside
  (the oracle of ``tests/_cut_paths.py``) is cut, counted by
  ``edges_left_uncut`` (named in the warning line), or followed along an
  earlier stroke's wound with its crossing in the wound's band.

The bound on the cut-made tetrahedra's smallest dihedral angle
(``MIN_CUT_DIHEDRAL_DEG``) is checked on every path: every one keeps it but
the two of :data:`BELOW_BOUND`, which may not get worse (the distribution:
``benchmarks/cut_fresh_draw.py --seed 7``).
"""

import functools
from pathlib import Path

import numpy as np
import pytest

from _cut_paths import KINDS, MORE_KINDS, check_followed, crossed_edges, lift, make_path

from cutkit.cutting import CutMesh, cut_step, to_model
from cutkit.cutting.crumbs import CRUMB_VOLUME_FRACTION, crumb_volume, loose_pieces
from cutkit.cutting.step import blade_in_tissue, finish_stroke, rebase_if_left
from cutkit.mesh.check import check_mesh
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import min_dihedral_angles, signed_volumes

#: Paths per mesh (three meshes: 1,008 paths).
PATHS_PER_MESH = 336
#: Each mesh's paths in this many tests (spread over the test workers).
CHUNKS = 4
ALL_KINDS = KINDS + MORE_KINDS
TREMORS = (0.0, 0.1, 0.3, 1.0)
#: Every cut-made tetrahedron's smallest dihedral angle should be at least this (issue 30).
MIN_CUT_DIHEDRAL_DEG = 5.0
#: The paths that do not keep the bound yet (issue 30), with the worst angle each may reach (degrees,
#: 0.05 under what it has): retraces on the decimated ellipsoid whose last pass steps out of the
#: wound's band (0.1 mm tremor, 27) or zigzags across the wound (1 mm, 237) and cuts thin pieces off
#: tets the earlier pass made, whose vertices lie on that pass's bent walls and may not move.
BELOW_BOUND = {("decimated", 27): 2.42, ("decimated", 237): 4.22}


def _meshes():
    data = np.load(Path(__file__).parent / "data" / "cut_path_meshes.npz")
    kuhn = box_mesh((4, 2, 2))
    return {"kuhn": kuhn, "gmsh": (data["gmsh_points"], data["gmsh_tets"]),
            "decimated": (data["decimated_points"], data["decimated_tets"])}


MESHES = _meshes()


def _sound(cm, v0, where):
    """Assert the written mesh sound (docstring above); returns its cut-made tets' worst dihedral angle (deg)."""
    m = to_model(cm)
    rep = check_mesh(m.points, m.tets, m.labels)
    assert rep.passed, (where, [(r.name, r.detail) for r in rep.rows if not r.passed])
    v = float(signed_volumes(m.points, m.tets).sum()) + crumb_volume(cm)
    assert abs(v - v0) <= 1e-12 * v0, (where, v, v0)
    assert loose_pieces(cm)[-1] > CRUMB_VOLUME_FRACTION * cm.model_volume, where
    made = m.tets[m.cell_data["new_tet"] == 1]
    return float(min_dihedral_angles(m.points, made).min()) if len(made) else 180.0


def _unreported(cm, stroke):
    """This stroke's original edges crossed strictly inside, left uncut and not counted (an edge followed
    along an earlier stroke's wound counts where the test found its crossing in the wound's band at
    its step: :func:`_cut_paths.check_followed`)."""
    crossed = crossed_edges(cm.points[:cm.n_orig_points], cm.edges, stroke)
    counted = cm.refused_edges | set(cm.pending_edges) | vars(cm).get("followed_checked", set())
    return {e for e in crossed if not np.isfinite(cm.edge_t[e]) and e not in counted}


def cut_path(p, t, poses, blade_length, where, **options):
    """Cut ``poses`` (``options``: of :class:`CutMesh`); check the mesh at every stroke's end; returns the
    unreported uncut edges and the worst cut-made dihedral angle (deg)."""
    v0 = float(signed_volumes(p, t).sum())
    cm = CutMesh(p, t, blade_length=blade_length, **options)
    stroke, missed, worst = [], [], [180.0]

    def end(leave=None):  # the stroke ends: what the blade held is looked at once more, then the checks
        finish_stroke(cm)
        missed.extend(_unreported(cm, stroke))
        if leave is not None:  # the blade left: the rebase and its look come before the tissue moves on
            leave(cm)
        worst.append(_sound(cm, v0, where))
        stroke.clear()

    for pose in poses:
        if pose is None:
            end(lift)
            continue
        prev, x0, followed = cm.prev_pose, cm.points.copy(), set(cm.followed_edges)
        cut_step(cm, *pose)
        if prev is not None:
            P1, Q1 = cm.prev_pose
            stroke.extend([(prev[0], prev[1], Q1), (prev[0], Q1, P1)])
            missed.extend(check_followed(cm, x0, stroke[-2:], followed))  # followed outside an earlier cut's band
        if not blade_in_tissue(cm) and cm.prev_pose is not None:
            end(rebase_if_left)
    end()
    return missed, min(worst)


def _path(name, i):
    """(poses, blade length, where) of path ``i`` on mesh ``name``."""
    p, _ = MESHES[name]
    kind, tremor = ALL_KINDS[i % len(ALL_KINDS)], TREMORS[(i // len(ALL_KINDS)) % len(TREMORS)]
    poses = make_path(kind, np.random.default_rng(1000 * i + 7), p.max(axis=0), tremor)
    return poses, 2.5 if i % 2 else 10.0, (name, i, kind, tremor)


@functools.lru_cache(maxsize=None)
def _cut(name, i):
    """:func:`cut_path` of path ``i`` on mesh ``name``: (unreported uncut edges (tuple), worst cut-made
    dihedral angle); each path is cut once in a process (the bound's test reads what the soundness
    tests cut before it on the same worker: a file runs whole on one)."""
    p, t = MESHES[name]
    missed, worst = cut_path(p, t, *_path(name, i))
    return tuple(sorted(missed)), worst


@pytest.mark.parametrize("chunk", range(CHUNKS))
@pytest.mark.parametrize("name", sorted(MESHES))
def test_a_thousand_paths_stay_sound(name, chunk):
    for i in range(chunk, PATHS_PER_MESH, CHUNKS):
        missed, _ = _cut(name, i)
        assert not missed, (_path(name, i)[2], missed[:10])


@pytest.mark.parametrize("name", sorted(MESHES))
def test_cut_made_tets_keep_the_dihedral_bound(name):
    worst = {i: _cut(name, i)[1] for i in range(PATHS_PER_MESH)}
    below = {i: w for i, w in worst.items() if w < BELOW_BOUND.get((name, i), MIN_CUT_DIHEDRAL_DEG)}
    assert not below, (name, below)


@pytest.mark.parametrize("i", [102, 267])
def test_a_poor_split_flips_a_diagonal_an_earlier_split_fixed(i, monkeypatch):
    """Decimated retraces whose second pass cut a corner off a tet the first pass made: the split
    faces' diagonals were fixed by the neighbours split first, and every split with those is a
    sliver.  With a fixed diagonal flipped (the neighbour re-split, the worse of the two lifted) no
    cut-made tet is below the bound; with every fixed diagonal kept, one is."""
    import cutkit.cutting.splits as splits

    p, t = MESHES["decimated"]
    # the retraces' second pass would follow the first's wound now (cutkit/cutting/following.py) and
    # not cut that corner: the split is looked at as the cut makes it without following
    assert cut_path(p, t, *_path("decimated", i), follow_wounds=False)[1] >= MIN_CUT_DIHEDRAL_DEG
    monkeypatch.setattr(splits, "FLIP_DIAGONALS", False)
    assert cut_path(p, t, *_path("decimated", i), follow_wounds=False)[1] < MIN_CUT_DIHEDRAL_DEG
