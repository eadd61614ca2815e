"""Optional quality pass after decimation: gmsh's Netgen optimiser, kept only when it helps.

The decimated mesh goes to gmsh as one discrete volume per label, bounded by
one discrete surface per sheet (boundary or tissue interface, a label pair),
and ``gmsh.model.mesh.optimize("Netgen", force=True)`` improves it (moving,
adding and removing interior nodes, swapping faces; the nodes of the bounding
surfaces stay).  The result replaces the mesh only if

* the smallest dihedral angle rises;
* the boundary and the interfaces are unchanged: the same S-faces (same
  nodes at the same positions, same sheets), so no surface point moves;
* the tet count does not grow;
* every node with a boundary condition is kept, and per-node/per-tet data
  can be carried over: gmsh renumbers nodes, so nodes are matched by their
  exact position; a model with texture coordinates or point data may not
  get new or moved nodes, a model with cell data may not change its tets;
* the result passes :func:`cutkit.mesh.check.check_mesh`.

Otherwise the input is returned unchanged.  Either way the report (before and
after minimum dihedral angle, counts, the decision and its reason) is
returned and stored in ``provenance["decimate"]["optimize"]``.  An accepted
mesh is no longer a level of the progressive record, so the record is dropped.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from cutkit.errors import InputError
from cutkit.mesh.geometry import TET_FACES, tet_volumes
from cutkit.model.tetmodel import BoundaryConditions, TetModel

__all__ = ["optimize", "OPTIMIZERS"]

#: Optimisers known to :func:`optimize` (name -> gmsh method).
OPTIMIZERS = {"netgen": "Netgen"}
#: gmsh optimisation passes.
NETGEN_ITERATIONS = 1


def surface_faces_with_sheets(tets: np.ndarray, labels: np.ndarray):
    """Boundary and interface triangles of a labelled tet mesh.

    Parameters
    ----------
    tets : (m, 4) int64
    labels : (m,) int

    Returns
    -------
    faces : (k, 3) int64
        Vertex ids, sorted within each face; faces sorted lexicographically.
    sheets : (k, 2) int64
        The labels on the two sides, sorted; -1 for the outside.
    """
    tets = np.asarray(tets, np.int64)
    labels = np.asarray(labels, np.int64)
    f = np.sort(np.concatenate([tets[:, TET_FACES[i]] for i in range(4)]), axis=1)  # face-major, as lab below
    lab = np.tile(labels, 4)
    order = np.lexsort((lab, f[:, 2], f[:, 1], f[:, 0]))
    f, lab = f[order], lab[order]
    new = np.ones(f.shape[0], bool)
    new[1:] = np.any(f[1:] != f[:-1], axis=1)
    start = np.flatnonzero(new)
    count = np.diff(np.append(start, f.shape[0]))
    lo = lab[start]
    hi = np.where(count == 2, lab[np.minimum(start + 1, f.shape[0] - 1)], -1)
    keep = (count == 1) | (lo != hi)
    s0 = np.where(count == 1, -1, np.minimum(lo, hi))
    s1 = np.where(count == 1, lo, np.maximum(lo, hi))
    return f[start[keep]], np.stack([s0[keep], s1[keep]], axis=1)


def _face_set(faces, sheets) -> set:
    return set(map(tuple, np.concatenate([faces, sheets], axis=1).tolist()))


def _ignore_sigpipe_again() -> None:
    """gmsh's initialisation sets SIGPIPE back to its default (terminate the process); Python
    ignores it so that a write to a closed socket raises BrokenPipeError (the haptics client
    relies on that).  Restore Python's setting; only the main thread may set a signal."""
    import signal
    import threading

    if hasattr(signal, "SIGPIPE") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)


def _run_gmsh(method, points, tets, labels, faces, sheets):
    """Optimise with gmsh; returns ``(points, tets, labels)`` of the result (nodes renumbered by gmsh)."""
    import gmsh

    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(interruptible=False)
        _ignore_sigpipe_again()
    previous = None if own else gmsh.model.getCurrent()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cutkit-optimize")
        sheet_ids, sheet_of_face = np.unique(sheets, axis=0, return_inverse=True)
        sheet_of_face = sheet_of_face.ravel()
        for s in range(sheet_ids.shape[0]):
            gmsh.model.addDiscreteEntity(2, s + 1)
        label_ids = np.unique(labels)
        for i, lab in enumerate(label_ids):
            bounding = [s + 1 for s in range(sheet_ids.shape[0]) if lab in sheet_ids[s]]
            gmsh.model.addDiscreteEntity(3, i + 1, bounding)
        # Each node once: surface nodes on a sheet, the others in their volume.
        owner = np.zeros(points.shape[0], np.int64)
        owner[faces.ravel()] = np.repeat(sheet_of_face + 1, 3)
        for s in range(sheet_ids.shape[0]):
            nodes = np.flatnonzero(owner == s + 1)
            gmsh.model.mesh.addNodes(2, s + 1, (nodes + 1).tolist(), points[nodes].ravel().tolist())
        for i, lab in enumerate(label_ids):
            nodes = np.unique(tets[labels == lab])
            nodes = nodes[owner[nodes] == 0]
            owner[nodes] = -1
            gmsh.model.mesh.addNodes(3, i + 1, (nodes + 1).tolist(), points[nodes].ravel().tolist())
        for s in range(sheet_ids.shape[0]):
            gmsh.model.mesh.addElementsByType(s + 1, 2, [], (faces[sheet_of_face == s] + 1).ravel().tolist())
        for i, lab in enumerate(label_ids):
            gmsh.model.mesh.addElementsByType(i + 1, 4, [], (tets[labels == lab] + 1).ravel().tolist())
        gmsh.model.mesh.optimize(method, force=True, niter=NETGEN_ITERATIONS)
        tags, xyz, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(tags.max()) + 1 if tags.size else 1, -1, np.int64)
        index[tags.astype(np.int64)] = np.arange(tags.size)
        out_tets, out_labels = [], []
        for i, lab in enumerate(label_ids):
            _, nodes = gmsh.model.mesh.getElementsByType(4, i + 1)
            t = index[np.asarray(nodes, np.int64).reshape(-1, 4)]
            out_tets.append(t)
            out_labels.append(np.full(t.shape[0], lab, labels.dtype))
    finally:
        if own:
            gmsh.finalize()
        else:  # leave the caller's gmsh session as it was
            if "cutkit-optimize" in gmsh.model.list():
                gmsh.model.setCurrent("cutkit-optimize")
                gmsh.model.remove()
            gmsh.model.setCurrent(previous)
    return np.asarray(xyz, np.float64).reshape(-1, 3), np.concatenate(out_tets), np.concatenate(out_labels)


def optimize(model: TetModel, method: str = "netgen") -> tuple[TetModel, dict]:
    """Improve the tet shapes with gmsh's optimiser; keep the result only if it is better and compatible.

    Parameters
    ----------
    model : TetModel
        Positively oriented tets (e.g. the output of :func:`cutkit.decimate.decimate`).
    method : str
        A key of :data:`OPTIMIZERS`.

    Returns
    -------
    model : TetModel
        The optimised model, or a shallow copy of ``model`` (same arrays) when
        the result was rejected; ``provenance["decimate"]["optimize"]`` holds the report.
    report : dict
        ``method``, ``accepted`` (bool), ``reason``, ``min_dihedral_before_deg``,
        ``min_dihedral_after_deg`` (nan if gmsh failed), ``tets_before``,
        ``tets_after``, ``nodes_before``, ``nodes_after``, ``nodes_new``
        (output nodes not at an input node's position), ``max_boundary_shift_mm``
        (0 when the boundary is unchanged), ``seconds``.
    """
    from scipy.spatial import cKDTree

    from cutkit.decimate.decimate import min_dihedral_deg
    from cutkit.decimate.progressive import RECORD
    from cutkit.mesh.check import check_mesh

    if method not in OPTIMIZERS:
        raise InputError(f"unknown optimiser {method!r}; known: {', '.join(OPTIMIZERS)}")
    try:
        import gmsh  # noqa: F401
    except ImportError:
        raise InputError("the optimiser needs the gmsh Python package (pip install gmsh)") from None
    t0 = time.perf_counter()
    points = np.ascontiguousarray(model.points, np.float64)
    tets = np.ascontiguousarray(model.tets, np.int64)
    labels = np.asarray(model.labels)
    before = float(min_dihedral_deg(points, tets).min())
    report = {"method": method, "accepted": False, "reason": "", "min_dihedral_before_deg": before,
              "min_dihedral_after_deg": float("nan"), "tets_before": int(tets.shape[0]), "tets_after": int(tets.shape[0]),
              "nodes_before": int(points.shape[0]), "nodes_after": int(points.shape[0]), "nodes_new": 0,
              "max_boundary_shift_mm": 0.0, "seconds": 0.0}

    def done(result, reason, accepted=False):
        report["accepted"] = accepted
        report["reason"] = reason
        report["seconds"] = time.perf_counter() - t0
        if result is model:
            result = copy.copy(model)  # same arrays, its own provenance
            result.provenance = copy.deepcopy(model.provenance)
        result.provenance.setdefault("decimate", {})["optimize"] = dict(report)
        return result, report

    faces, sheets = surface_faces_with_sheets(tets, labels)
    try:
        p2, t2, l2 = _run_gmsh(OPTIMIZERS[method], points, tets, labels, faces, sheets)
    except Exception as err:  # gmsh raises plain Exceptions
        return done(model, f"gmsh failed: {' '.join(str(err).split())}")
    report.update(tets_after=int(t2.shape[0]), nodes_after=int(p2.shape[0]))
    if t2.shape[0] == 0 or np.any(t2 < 0):
        return done(model, "gmsh returned no tets or tets with unknown nodes")
    # Orientation is a convention: turn gmsh's tets positive before judging them.
    neg = tet_volumes(p2, t2) < 0
    t2[neg, 2], t2[neg, 3] = t2[neg, 3].copy(), t2[neg, 2].copy()
    after = float(min_dihedral_deg(p2, t2).min())
    report["min_dihedral_after_deg"] = after

    # Identity of the nodes: gmsh renumbers, so match exact positions.
    dist, near = cKDTree(points).query(p2)
    matched = dist == 0.0
    orig_of = np.where(matched, near, -1)
    report["nodes_new"] = int(np.sum(~matched))
    snodes = np.unique(faces)
    sdist, _ = cKDTree(p2).query(points[snodes])
    report["max_boundary_shift_mm"] = float(sdist.max()) if sdist.size else 0.0
    if after <= before:
        return done(model, f"minimum dihedral angle not raised ({before:.2f} -> {after:.2f} deg)")
    if t2.shape[0] > tets.shape[0]:
        return done(model, f"tet count grew ({tets.shape[0]} -> {t2.shape[0]})")
    st2 = np.sort(t2, axis=1)
    if np.any(st2[:, 1:] == st2[:, :-1]) or np.unique(orig_of[matched]).size != int(matched.sum()):
        return done(model, "gmsh returned degenerate tets or duplicate nodes")
    f2, s2 = surface_faces_with_sheets(np.where(matched[t2], orig_of[t2], -1 - t2), l2)
    if report["max_boundary_shift_mm"] > 0.0 or _face_set(faces, sheets) != _face_set(f2, s2):
        return done(model, "boundary or tissue interfaces changed")
    bc = model.boundary
    bc_nodes = np.concatenate([np.asarray(bc.fixed_nodes, np.int64).ravel(), np.asarray(bc.prescribed_nodes, np.int64).ravel()])
    kept = np.zeros(points.shape[0], bool)
    kept[orig_of[matched]] = True
    if bc_nodes.size and not kept[bc_nodes].all():
        return done(model, "nodes with boundary conditions were moved or removed")
    if report["nodes_new"] and (model.texcoords is not None or model.point_data):
        return done(model, f"{report['nodes_new']} new or moved nodes cannot carry texture coordinates / point data")
    if model.cell_data:
        return done(model, "the tets changed and cell data cannot be carried over")
    if not check_mesh(p2, t2, l2).passed:
        return done(model, "the optimised mesh fails the mesh check")

    # Node order: kept input nodes in input order, then the new ones.
    new_nodes = np.flatnonzero(~matched)
    order = np.concatenate([np.flatnonzero(matched)[np.argsort(orig_of[matched], kind="stable")], new_nodes])
    renum = np.empty(p2.shape[0], np.int64)
    renum[order] = np.arange(order.size)
    renum_in = np.full(points.shape[0], -1, np.int64)
    renum_in[orig_of[matched]] = renum[np.flatnonzero(matched)]
    kept_ids = np.sort(orig_of[matched])
    tt = renum[t2]
    tet_order = np.lexsort((tt[:, 3], tt[:, 2], tt[:, 1], tt[:, 0], l2))
    result = TetModel(
        points=np.ascontiguousarray(p2[order]),
        tets=np.ascontiguousarray(tt[tet_order]),
        labels=np.ascontiguousarray(l2[tet_order]),
        materials=model.materials,
        boundary=BoundaryConditions(
            fixed_nodes=renum_in[np.asarray(bc.fixed_nodes, np.int64)],
            prescribed_nodes=renum_in[np.asarray(bc.prescribed_nodes, np.int64)],
            prescribed_displacement=np.asarray(bc.prescribed_displacement, np.float64).reshape(-1, 3).copy(),
        ),
        prestress=model.prestress,
        texture=model.texture,
        texcoords=None if model.texcoords is None else np.ascontiguousarray(np.asarray(model.texcoords, np.float64)[kept_ids]),
        point_data={k: np.asarray(a)[kept_ids] for k, a in model.point_data.items()},
        cell_data={},
        provenance=copy.deepcopy(model.provenance),
        extra={k: v for k, v in model.extra.items() if k != RECORD},
    )
    return done(result, f"minimum dihedral angle raised ({before:.2f} -> {after:.2f} deg), boundary unchanged", accepted=True)
