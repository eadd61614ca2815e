"""The cut mesh as a model, and its cut surface."""

from __future__ import annotations

import numpy as np

from cutkit.cutting.cutmesh import CutMesh


def compact_nodes(tets, n_points):
    """Keep only the nodes some tet uses, in their order.

    Parameters
    ----------
    tets : (m, 4) int64
    n_points : int

    Returns
    -------
    kept : (k,) int64
        Old ids of the kept nodes, ascending (so when every original node
        is used the originals keep their numbers).
    new_index : (n_points,) int64
        New id of each old node, -1 for a dropped one.
    """
    used = np.zeros(int(n_points), bool)
    used[np.asarray(tets, np.int64).ravel()] = True
    kept = np.flatnonzero(used)
    new_index = np.full(int(n_points), -1, np.int64)
    new_index[kept] = np.arange(kept.size)
    return kept, new_index


def _remap_boundary(boundary, new_index):
    """Boundary conditions on the compacted numbering (conditions on dropped nodes go)."""
    from dataclasses import replace
    n = new_index.shape[0]

    def remap(ids):
        ids = np.asarray(ids, np.int64)
        ok = (ids >= 0) & (ids < n)
        ok[ok] &= new_index[ids[ok]] >= 0
        return new_index[ids[ok]], ok

    fixed, _ = remap(boundary.fixed_nodes)
    pres, ok = remap(boundary.prescribed_nodes)
    disp = np.asarray(boundary.prescribed_displacement, np.float64).reshape(-1, 3)[ok]
    return replace(boundary, fixed_nodes=fixed, prescribed_nodes=pres, prescribed_displacement=disp)


def to_model(cm: CutMesh, model=None, points=None, point_data=None):
    """The cut mesh as a :class:`~cutkit.model.tetmodel.TetModel`, without orphan nodes.

    Only the nodes a live tetrahedron uses are written (see
    :func:`compact_nodes`); boundary conditions are carried over to the new
    numbering.  Adds ``cell_data['new_tet']`` (uint8, 1 for sub-tets of cut
    tets) and ``point_data['new_node']`` (uint8).  Materials, boundary
    conditions, prestress and texture are taken from ``model`` when given.

    Parameters
    ----------
    cm : CutMesh
    model : TetModel, optional
    points : (cm.n_points, 3) float64, optional
        Positions to write (default: the CutMesh's current positions).
    point_data : dict of str to (cm.n_points, ...) arrays, optional
        Further per-node arrays on the CutMesh numbering, compacted alike.
    """
    from dataclasses import replace
    from cutkit.model.tetmodel import TetModel
    n = cm.n_points
    ids = np.flatnonzero(cm._alive[:cm.n_tets_total])
    kept, new_index = compact_nodes(cm._tets[ids], n)
    tets = new_index[cm._tets[ids]]
    origin = cm._tet_orig[ids]
    pts = (cm.points if points is None else np.asarray(points, np.float64)[:n])[kept]
    # cut-made nodes and tets of every stroke, also those before a rebase
    pd = {"new_node": (kept >= cm.n_model_points).astype(np.uint8)}
    cd = {"new_tet": cm.store.made_by_cut(ids).astype(np.uint8)}
    labels = cm.labels[origin]
    texcoords = None if cm.texcoords is None else cm.texcoords[kept].copy()
    if model is not None:
        # new nodes take their first defining node's value (traced back to the model's nodes)
        src = cm.store.node_model_source(kept)
        mtet = cm.model_tet[origin]
        for k, v in model.point_data.items():
            if v.shape[0] == cm.n_model_points and k != "new_node":
                pd[k] = v[src]
        for k, v in model.cell_data.items():
            if v.shape[0] == cm.n_model_tets and k != "new_tet":
                cd[k] = v[mtet]
    for k, v in (point_data or {}).items():
        pd[k] = np.asarray(v)[:n][kept]
    if model is not None:
        return replace(model, points=pts, tets=tets, labels=labels, texcoords=texcoords, point_data=pd,
                       cell_data=cd, boundary=_remap_boundary(model.boundary, new_index))
    return TetModel(points=pts, tets=tets, labels=labels, texcoords=texcoords, point_data=pd, cell_data=cd)
