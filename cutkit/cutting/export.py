"""The cut mesh as a model, and its cut surface."""

from __future__ import annotations

import numpy as np

from cutkit.cutting.cutmesh import CutMesh


def cut_surface_faces(cm: CutMesh) -> np.ndarray:
    """(k, 3) int64 boundary triangles of the cut surface (both sides of each cut).

    Every triangle of the Fig. 2 face patterns contains an original
    vertex, and every cut-surface triangle is made of cut nodes only.  Only
    sub-tets of cut tets hold cut nodes, so the faces are looked for among
    them alone: the work follows the size of the cut, not of the mesh.
    """
    from cutkit.mesh.topology import boundary_faces

    m0, total = cm.orig_tets.shape[0], cm.n_tets_total
    sub_tets = cm._tets[m0:total][cm._alive[m0:total]]
    if sub_tets.shape[0] == 0:
        return np.zeros((0, 3), np.int64)
    faces, _ = boundary_faces(sub_tets)
    # A face made only of cut nodes belongs to sub-tets only, so appearing
    # once among them it appears once in the whole mesh: it is on the boundary.
    return faces[(faces >= cm.n_orig_points).all(axis=1)]


def to_model(cm: CutMesh, model=None):
    """The cut mesh as a :class:`~cutkit.model.tetmodel.TetModel`.

    Adds ``cell_data['new_tet']`` (uint8, 1 for sub-tets of cut tets) and
    ``point_data['new_node']`` (uint8).  Materials, boundary conditions,
    prestress and texture are taken from ``model`` when given.
    """
    from dataclasses import replace
    from cutkit.model.tetmodel import TetModel
    tets = cm.tets
    origin = cm.tet_origin
    new_tet = (np.arange(cm.n_tets_total)[cm._alive[:cm.n_tets_total]] >= cm.orig_tets.shape[0]).astype(np.uint8)
    new_node = np.zeros(cm.n_points, np.uint8)
    new_node[cm.n_orig_points:] = 1
    labels = cm.labels[origin]
    pd = {"new_node": new_node}
    cd = {"new_tet": new_tet}
    if model is not None:
        for k, v in model.point_data.items():
            if v.shape[0] == cm.n_orig_points and k != "new_node":
                # new nodes take their first defining node's value
                src = np.where(np.arange(cm.n_points) < cm.n_orig_points, np.arange(cm.n_points),
                               cm._def_nodes[:cm.n_points, 0])
                pd[k] = v[src]
        for k, v in model.cell_data.items():
            if v.shape[0] == cm.orig_tets.shape[0] and k != "new_tet":
                cd[k] = v[origin]
        return replace(model, points=cm.points.copy(), tets=tets, labels=labels,
                       texcoords=None if cm.texcoords is None else cm.texcoords.copy(),
                       point_data=pd, cell_data=cd)
    return TetModel(points=cm.points.copy(), tets=tets, labels=labels,
                    texcoords=None if cm.texcoords is None else cm.texcoords.copy(),
                    point_data=pd, cell_data=cd)
