"""Crumbs: pieces the cut sets loose that are too small to be simulated.

A blade drawn back over its own cut, tremor or several strokes can cut a
piece loose that is a sliver of a few tetrahedra.  The physics would carry
it as a free body with almost no mass.  :func:`remove_crumbs` runs at the
end of every cut step (:func:`cutkit.cutting.step.cut_step`): a piece made
loose whose rest volume is at most ``CRUMB_VOLUME_FRACTION`` of the
model's is removed from the model (its tets leave the live mesh and are
listed in the step's ``removed_tets``); its volume is kept in
``CutMesh.crumb_volume``.  Its nodes are left without tets, like the tip
nodes of a finished split: they are never written (``to_model`` keeps only
used nodes) and carry no mass.  :func:`loose_pieces` reports the larger
pieces the cut has set loose.
"""

from __future__ import annotations

import numpy as np

from cutkit.cutting import _kernels_crumbs as KC
from cutkit.mesh.geometry import tet_volumes6
from cutkit.mesh.topology import node_to_tets

#: A piece cut loose with a rest volume at most this fraction of the model's is a crumb and is
#: removed (the measure of issue 30: a body this small carries no useful physics).
CRUMB_VOLUME_FRACTION = 1e-3
#: A piece a step makes again out of a removed crumb's region (it shares a node with the crumb's dead
#: tets) is removed with the crumb while its rest volume is at most this fraction of the model's:
#: kept, it would be the loose body with the crumb's part missing (a hole whose rim edges are
#: non-manifold).  The main body is far larger, so only loose pieces are removed this way.
CRUMB_REGROWN_FRACTION = 1e-2
#: The crumb search's blocks (:func:`~cutkit.cutting._kernels_crumbs.make_blocks`) are made of about
#: this share of the crumb limit each: where the search meets the uncut tissue, a few clean blocks
#: prove the main body large.
BLOCK_SHARE = 16


def init_crumbs(cm):
    """Crumb bookkeeping of a fresh :class:`~cutkit.cutting.cutmesh.CutMesh` (original tets only)."""
    n0, m0 = cm.n_orig_points, cm.orig_tets.shape[0]
    cm.node_tet_off, cm.node_tet_idx = node_to_tets(cm.orig_tets, n0)
    cm.sub_start = np.zeros(m0, np.int64)
    cm.sub_count = np.zeros(m0, np.int64)
    # a rebase overwrites it with the volume as loaded; one kernel pass (a stacked det took 85 ms on the knee)
    cm.model_volume = float(tet_volumes6(np.ascontiguousarray(cm._X[:n0]), cm.orig_tets).sum() / 6.0)
    cm.crumb_tets = set()  # tet ids of the crumbs of this cut state (dead)
    cm.crumb_volume_before = 0.0  # crumbs removed before the last rebase, mm^3
    cm.crumb_mark = np.zeros(m0, np.int64)  # per-tet marks of the crumb search (see loose_small_pieces)
    cm.crumb_stamp = 0
    # blocks of face-connected original tets, each a share of the crumb limit: a clean one counts whole
    cm.crumb_blocks = KC.make_blocks(np.ascontiguousarray(cm._X[:n0]), cm.orig_tets, cm.neighbors,
                                     CRUMB_VOLUME_FRACTION * cm.model_volume / BLOCK_SHARE)
    cm.crumb_block_dirty = np.zeros(cm.crumb_blocks[1].shape[0], bool)
    cm.crumb_block_mark = np.zeros(cm.crumb_blocks[1].shape[0], np.int64)
    cm.crumb_count = 0  # crumbs removed (a crumb re-made by a later step and removed again counts again)


def crumb_volume(cm) -> float:
    """Rest volume removed as crumbs so far, over every stroke, mm^3.

    The crumbs of this cut state are measured at their nodes' rest positions
    now, not when they were removed: a crumb shares cut nodes (a notch node
    F, a tip node T) with live tets, and those follow the blade in later
    steps, moving volume between the crumb and the live tets around it.
    """
    ids = np.fromiter(cm.crumb_tets, np.int64, len(cm.crumb_tets))
    now = float(_volumes(cm._X, cm._tets[ids]).sum()) if ids.size else 0.0
    return cm.crumb_volume_before + now


def remove_crumbs(cm, seeds) -> int:
    """Remove the crumbs among the pieces of the live tets ``seeds`` (the step's new tets).

    Parameters
    ----------
    cm : CutMesh
    seeds : (s,) int64  tet ids (dead ones are skipped)

    Returns
    -------
    n : int  crumbs removed
    """
    seeds = np.ascontiguousarray(seeds, np.int64)
    if not seeds.size:
        return 0
    total = cm.n_tets_total
    if cm.crumb_mark.shape[0] < total:
        mark = np.zeros(max(total, 2 * cm.crumb_mark.shape[0]), np.int64)
        mark[:cm.crumb_mark.shape[0]] = cm.crumb_mark
        cm.crumb_mark = mark
    cm.crumb_stamp += 4  # marks of earlier calls are below it: no per-step reset
    _blocks_changed(cm, seeds)
    inc = KC.Incidence(cm.node_tet_off, cm.node_tet_idx, cm._def_nodes, cm.n_orig_points, cm.sub_start,
                       cm.sub_count, cm.neighbors, *cm.crumb_blocks, cm.crumb_block_dirty)
    regrown = _touching_crumbs(cm, seeds)  # before this call's crumbs join cm.crumb_tets
    n = _remove_pieces(cm, inc, seeds, CRUMB_VOLUME_FRACTION * cm.model_volume)
    regrown = regrown[cm._alive[regrown]]
    if regrown.size:
        cm.crumb_stamp += 4
        n += _remove_pieces(cm, inc, regrown, CRUMB_REGROWN_FRACTION * cm.model_volume)
    return n


def _remove_pieces(cm, inc, seeds, limit) -> int:
    """Remove the pieces through live tets ``seeds`` whose rest volume is at most ``limit``."""
    dead, n_pieces = KC.loose_small_pieces(cm._X, cm._tets, cm._alive, inc, seeds, limit, cm.crumb_mark,
                                           cm.crumb_block_mark, cm.crumb_stamp)
    if not n_pieces:
        return 0
    cm.remove_tets(dead)
    gone = dead[dead < cm.sub_count.shape[0]]
    cm.crumb_block_dirty[cm.crumb_blocks[0][gone]] = True  # uncut tets of the crumb: their blocks changed
    cm.crumb_tets.update(dead.tolist())
    cm.crumb_count += int(n_pieces)
    return int(n_pieces)


def _blocks_changed(cm, seeds) -> None:
    """Mark dirty the blocks a step changed: those of the seeds' original tets (the seeds are the
    step's new tets and the live tets of the stars of the original vertices it moved, so every
    original tet the step subdivided or reshaped is one or holds one)."""
    cm.crumb_block_dirty[cm.crumb_blocks[0][cm.store.tet_origins[seeds]]] = True  # an original's origin is itself


def _touching_crumbs(cm, seeds):
    """The live tets among ``seeds`` that share a node with a removed crumb's (dead) tets.

    A crumb is a whole piece when it is removed, so afterwards only tets a
    later step makes again in its original tets can share its nodes: the
    crumb's region cut again (:data:`CRUMB_REGROWN_FRACTION`).
    """
    if not cm.crumb_tets:
        return seeds[:0]
    crumb_nodes = np.unique(cm._tets[np.fromiter(cm.crumb_tets, np.int64, len(cm.crumb_tets))])
    live = seeds[cm._alive[seeds]]
    return live[np.isin(cm._tets[live], crumb_nodes).any(axis=1)]


def forget_crumb_tets(cm, ids) -> list:
    """The live ones among tet ids ``ids`` about to be replaced; dead crumb tets among them are forgotten.

    A tet of a crumb re-made by a later re-subdivision of its original tet
    is found again as a crumb in the same step, so its volume is counted once.
    """
    live = [t for t in ids if cm._alive[t]]
    if len(live) != len(ids):
        for t in ids:
            cm.crumb_tets.discard(t)
    return live


def _volumes(X, tets):
    d = X[tets[:, 1:]] - X[tets[:, :1]]
    return np.linalg.det(d) / 6.0


def loose_pieces(cm):
    """Rest volumes of the pieces of the live mesh (shared nodes join tets), largest first.

    Returns
    -------
    volumes : (p,) float64  mm^3, one per piece, in decreasing order
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    tets = cm.tets
    if not len(tets):
        return np.zeros(0)
    k, n = len(tets), cm.n_points
    # the bipartite graph tets -- nodes: tets sharing a node are in one piece
    rows = np.repeat(np.arange(k), 4)
    g = coo_matrix((np.ones(4 * k), (rows, k + tets.ravel())), shape=(k + n, k + n))
    _, comp = connected_components(g, directed=False)
    vols = np.bincount(comp[:k], weights=_volumes(cm._X, tets))
    vols = vols[vols > 0]
    return np.sort(vols)[::-1]
