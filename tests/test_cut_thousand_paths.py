"""A thousand blade paths, every kind, tremor 0-1 mm, on three kinds of mesh: the cut stays sound.

Meshes (small, so the thousand run in CI): a Kuhn-split box (exact contacts
with vertices, edges and faces), gmsh's Delaunay mesh of a box and a
decimated isovolume ellipsoid (``tests/data/cut_path_meshes.npz``, made by
``tests/data/make_cut_path_meshes.py``).  Each path is cut as ``cutkit cut``
cuts (a stroke ends where the blade leaves the tissue); at the end of every
stroke and of the path:

* the written mesh passes ``cutkit check`` (orientation, manifold faces,
  edges and vertices, no hanging and no unused node);
* the live volume plus the crumbs removed is the model's (1e-12 relative);
* no piece below ``CRUMB_VOLUME_FRACTION`` of the model is left to the physics;
* every original edge the stroke's swept surface crossed strictly inside
  (the oracle of ``tests/_cut_paths.py``) is cut or counted by
  ``edges_left_uncut`` (named in the warning line).
"""

from pathlib import Path

import numpy as np
import pytest

from _cut_paths import KINDS, MORE_KINDS, crossed_edges, lift, make_path

from cutkit.cutting import CutMesh, cut_step, to_model
from cutkit.cutting.crumbs import CRUMB_VOLUME_FRACTION, crumb_volume, loose_pieces
from cutkit.cutting.rebase import blade_in_tissue, rebase_if_left
from cutkit.mesh.check import check_mesh
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import signed_volumes

#: Paths per mesh (three meshes: 1,008 paths).
PATHS_PER_MESH = 336
#: Each mesh's paths in this many tests (spread over the test workers).
CHUNKS = 4
ALL_KINDS = KINDS + MORE_KINDS
TREMORS = (0.0, 0.1, 0.3, 1.0)


def _meshes():
    data = np.load(Path(__file__).parent / "data" / "cut_path_meshes.npz")
    kuhn = box_mesh((4, 2, 2))
    return {"kuhn": kuhn, "gmsh": (data["gmsh_points"], data["gmsh_tets"]),
            "decimated": (data["decimated_points"], data["decimated_tets"])}


MESHES = _meshes()


def _sound(cm, v0, where):
    m = to_model(cm)
    rep = check_mesh(m.points, m.tets, m.labels)
    assert rep.passed, (where, [(r.name, r.detail) for r in rep.rows if not r.passed])
    v = float(signed_volumes(m.points, m.tets).sum()) + crumb_volume(cm)
    assert abs(v - v0) <= 1e-12 * v0, (where, v, v0)
    assert loose_pieces(cm)[-1] > CRUMB_VOLUME_FRACTION * cm.model_volume, where


def _unreported(cm, stroke):
    """This stroke's original edges crossed strictly inside, left uncut and not counted."""
    crossed = crossed_edges(cm.points[:cm.n_orig_points], cm.edges, stroke)
    counted = cm.refused_edges | set(cm.pending_edges)
    return {e for e in crossed if not np.isfinite(cm.edge_t[e]) and e not in counted}


def cut_path(p, t, poses, blade_length, where):
    """Cut ``poses``; check the mesh at every stroke's end; returns the unreported uncut edges."""
    v0 = float(signed_volumes(p, t).sum())
    cm = CutMesh(p, t, blade_length=blade_length)
    stroke, missed = [], []

    def end():
        missed.extend(_unreported(cm, stroke))
        _sound(cm, v0, where)
        stroke.clear()

    for pose in poses:
        if pose is None:
            end()
            lift(cm)
            continue
        prev = cm.prev_pose
        cut_step(cm, *pose)
        if prev is not None:
            P1, Q1 = cm.prev_pose
            stroke.extend([(prev[0], prev[1], Q1), (prev[0], Q1, P1)])
        if not blade_in_tissue(cm) and cm.prev_pose is not None:
            end()
            rebase_if_left(cm)
    end()
    return missed


@pytest.mark.parametrize("chunk", range(CHUNKS))
@pytest.mark.parametrize("name", sorted(MESHES))
def test_a_thousand_paths_stay_sound(name, chunk):
    p, t = MESHES[name]
    L = p.max(axis=0)
    for i in range(chunk, PATHS_PER_MESH, CHUNKS):
        kind, tremor = ALL_KINDS[i % len(ALL_KINDS)], TREMORS[(i // len(ALL_KINDS)) % len(TREMORS)]
        rng = np.random.default_rng(1000 * i + 7)
        poses = make_path(kind, rng, L, tremor)
        where = (name, i, kind, tremor)
        missed = cut_path(p, t, poses, 2.5 if i % 2 else 10.0, where)
        assert not missed, (where, sorted(missed)[:10])
