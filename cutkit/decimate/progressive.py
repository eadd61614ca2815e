"""The progressive record of a decimation and the extraction of its levels.

A decimation is a sequence of half-edge collapses ``u_j -> v_j`` (Staadt and
Gross's progressive tetrahedralizations, the paper's section 7.1 / ref. [25]).
The record keeps the finest mesh and the ordered collapses; level ``k`` is the
mesh after the first ``k`` collapses.  Extracting it replays the collapses on
vertex ids with a union-find (``u_j`` joins ``v_j``), drops the tets that lost a
vertex (two equal ids) and renumbers the nodes that are still used, in
increasing original id.  That is exactly how :func:`cutkit.decimate.decimate`
numbers its output, so the record reproduces it bit for bit.

Layout of ``model.extra["progressive"]`` (``n0``/``m0``: nodes/tets of the
finest mesh, ``K``: collapses, ``n``/``m``: nodes/tets of the model)::

    points0      (n0, 3) float64   finest node positions, mm
    tets0        (m0, 4) int64     finest tets, positively oriented
    labels0      (m0,)   int32     finest tissue labels
    texcoords0   (n0, 3) float64   finest texture coordinates (only if textured)
    collapse_u   (K,)    int64     removed vertex of collapse j (finest ids)
    collapse_v   (K,)    int64     vertex it was collapsed onto (finest ids)
    tet_counts   (K + 1,) int64    tets after the first j collapses (tet_counts[0] = m0)
    level        (1,)    int64     level of the model's own mesh
    node_ids     (n,)    int64     finest id of each node of the model
    tet_ids      (m,)    int64     finest index of each tet of the model

The tets removed by collapse ``j`` are those that hold both ``u_j`` and
``v_j`` after the first ``j - 1`` collapses; the tets it changes are the other
tets of ``u_j`` (``u_j`` becomes ``v_j``): the vertex split that undoes it.
"""

from __future__ import annotations

import copy

import numpy as np

from cutkit.errors import InputError, ModelFormatError
from cutkit.model.tetmodel import BoundaryConditions, TetModel

#: Name of the group in ``TetModel.extra``.
RECORD = "progressive"

__all__ = ["RECORD", "extract_level", "replay", "n_levels"]


def replay(tets0, collapse_u, collapse_v, n_points0, level):
    """Mesh after the first ``level`` collapses, in the finest ids.

    Parameters
    ----------
    tets0 : (m0, 4) int64
    collapse_u, collapse_v : (K,) int64
    n_points0 : int
    level : int
        0 <= level <= K.

    Returns
    -------
    tets : (m, 4) int64
        Surviving tets (finest order), vertices replaced by their representative.
    tet_ids : (m,) int64
        Finest index of each surviving tet.
    root : (n_points0,) int64
        Representative (surviving vertex) of every finest vertex.
    """
    parent = np.arange(n_points0, dtype=np.int64)
    parent[collapse_u[:level]] = collapse_v[:level]
    # Pointer jumping: each pass halves every chain, so O(log depth) passes.
    while True:
        nxt = parent[parent]
        if np.array_equal(nxt, parent):
            break
        parent = nxt
    t = parent[tets0]
    keep = (
        (t[:, 0] != t[:, 1]) & (t[:, 0] != t[:, 2]) & (t[:, 0] != t[:, 3])
        & (t[:, 1] != t[:, 2]) & (t[:, 1] != t[:, 3]) & (t[:, 2] != t[:, 3])
    )
    tet_ids = np.flatnonzero(keep).astype(np.int64)
    return np.ascontiguousarray(t[keep]), tet_ids, parent


def n_levels(model: TetModel) -> int:
    """Number of recorded collapses ``K`` (levels are 0..K)."""
    return int(_record(model)["collapse_u"].shape[0])


def _record(model: TetModel) -> dict:
    rec = model.extra.get(RECORD)
    if rec is None:
        raise InputError("the model has no progressive record (extra/progressive): decimate it with "
                         "`cutkit decimate`, or build it with `cutkit build-model --keep-record`")
    for name in ("points0", "tets0", "labels0", "collapse_u", "collapse_v", "tet_counts", "level", "node_ids", "tet_ids"):
        if name not in rec:
            raise ModelFormatError(f"progressive record is missing extra/progressive/{name}")
    return rec


def extract_level(model: TetModel, level: int) -> TetModel:
    """The model at level ``level`` of its progressive record (0 = finest).

    Parameters
    ----------
    model : TetModel
        A model with ``extra["progressive"]`` (any level of the same record).
    level : int
        Number of collapses to apply, ``0 <= level <= K``.

    Returns
    -------
    TetModel
        Points, tets, labels and texture coordinates of that level; boundary
        conditions follow their nodes (a node removed at a coarser level
        hands its condition to the node it was collapsed onto; the decimator
        never removes them).  Point and cell data are kept for levels at
        least as coarse as the model's own and dropped for finer ones (the
        record does not store them for the removed nodes).  The record is
        carried over with its ``level``, ``node_ids`` and ``tet_ids`` updated.
    """
    rec = _record(model)
    cu = np.asarray(rec["collapse_u"], np.int64)
    cv = np.asarray(rec["collapse_v"], np.int64)
    k_max = cu.shape[0]
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= int(level) <= k_max:
        raise InputError(f"level {level} is out of range: the progressive record has levels 0..{k_max}")
    level = int(level)
    points0 = np.asarray(rec["points0"], np.float64)
    tets0 = np.asarray(rec["tets0"], np.int64)
    labels0 = np.asarray(rec["labels0"], np.int32)
    cur_level = int(np.asarray(rec["level"]).ravel()[0])
    cur_nodes = np.asarray(rec["node_ids"], np.int64)
    cur_tets = np.asarray(rec["tet_ids"], np.int64)
    if cur_nodes.shape[0] != model.n_points or cur_tets.shape[0] != model.n_tets:
        raise ModelFormatError("progressive record does not match the model (node_ids/tet_ids lengths)")

    tets, tet_ids, root = replay(tets0, cu, cv, points0.shape[0], level)
    used = np.unique(tets)
    renum = np.full(points0.shape[0], -1, np.int64)
    renum[used] = np.arange(used.shape[0])
    out_tets = renum[tets]

    def follow(local_nodes):
        return renum[root[cur_nodes[np.asarray(local_nodes, np.int64)]]]

    bc = model.boundary
    boundary = BoundaryConditions(
        fixed_nodes=np.unique(follow(bc.fixed_nodes)).astype(np.int64),
        prescribed_nodes=follow(bc.prescribed_nodes).astype(np.int64),
        prescribed_displacement=np.asarray(bc.prescribed_displacement, np.float64).reshape(-1, 3).copy(),
    )
    texcoords = None
    if model.texcoords is not None and "texcoords0" in rec:
        texcoords = np.ascontiguousarray(np.asarray(rec["texcoords0"], np.float64)[used])

    point_data, cell_data = {}, {}
    if level >= cur_level:
        local_node = np.full(points0.shape[0], -1, np.int64)
        local_node[cur_nodes] = np.arange(cur_nodes.shape[0])
        local_tet = np.full(tets0.shape[0], -1, np.int64)
        local_tet[cur_tets] = np.arange(cur_tets.shape[0])
        point_data = {k: np.asarray(a)[local_node[used]] for k, a in model.point_data.items()}
        cell_data = {k: np.asarray(a)[local_tet[tet_ids]] for k, a in model.cell_data.items()}

    new_rec = dict(rec)
    new_rec["level"] = np.array([level], np.int64)
    new_rec["node_ids"] = used.astype(np.int64)
    new_rec["tet_ids"] = tet_ids
    extra = dict(model.extra)
    extra[RECORD] = new_rec
    provenance = copy.deepcopy(model.provenance)
    provenance.setdefault("decimate", {})
    if isinstance(provenance["decimate"], dict):
        provenance["decimate"]["level"] = level
    return TetModel(
        points=np.ascontiguousarray(points0[used]),
        tets=np.ascontiguousarray(out_tets),
        labels=np.ascontiguousarray(labels0[tet_ids]),
        materials=model.materials,
        boundary=boundary,
        prestress=model.prestress,
        texture=model.texture,
        texcoords=texcoords,
        point_data=point_data,
        cell_data=cell_data,
        provenance=provenance,
        extra=extra,
    )
