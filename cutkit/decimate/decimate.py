"""Progressive tetrahedral decimation by half-edge collapses (paper section 7.1, ref. [25]).

The isovolume mesh has millions of small tets; a cuttable model needs tens to
hundreds of thousands.  Following Staadt and Gross, edges are collapsed in the
order of a weighting function "tuned to collapse all the small edges of the
interior mesh while preserving the details on the mesh surface": interior
edges first by length, edges onto the surface next, moves of surface
(boundary or tissue-interface) vertices last and only within a tolerance.
See docs/decimation.md for the rules and what they guarantee.
"""

from __future__ import annotations

import copy
import math
from typing import Callable

import numpy as np

from cutkit.errors import InputError, MeshError
from cutkit.model.tetmodel import BoundaryConditions, TetModel
from cutkit.decimate.progressive import RECORD

__all__ = ["decimate", "min_dihedral_deg", "quality_summary", "reference_length", "DEFAULT_MIN_DIHEDRAL_DEG", "W_SURFACE", "W_TOUCH", "NORMAL_MAX_DEG"]

#: Default smallest dihedral angle a collapse may create, degrees.
DEFAULT_MIN_DIHEDRAL_DEG = 10.0
#: Cost factor of moving a surface (boundary/interface) vertex: surface
#: edges are collapsed once interior edges are about this much longer.
W_SURFACE = 3.0
#: Extra cost of collapsing an interior vertex onto a surface vertex.
W_TOUCH = 0.5
#: Largest turn of a surface triangle's normal in one collapse, degrees (fold test).
NORMAL_MAX_DEG = 60.0
#: Smallest 6 * volume of a tet after a collapse, relative to h^3.
VOL_EPS_REL = 1e-9
#: Drift of each tissue's volume that surface collapses may build up, as a
#: fraction of that tissue's volume (collapses that reduce the drift are always allowed).
VOLUME_BUDGET_REL = 0.02
#: Fraction of the surface tolerance one collapse may use: a collapse checks
#: the original points of u and v, not those of its other neighbours.
SURFACE_SAFETY = 0.9
#: Heap entries popped per kernel call between two progress reports.
POPS_PER_CALL = 20_000
#: Rounds of re-costing every vertex once the heap runs dry.
MAX_ROUNDS = 8
#: A collapse may not put a boundary node within this fraction of a new boundary face's size of
#: that face (rule 4, docs/decimation.md): ten times ``cutkit check``'s hanging-node tolerance, so
#: that a decimated mesh passes the check with room to spare.
HANGING_MARGIN = 10.0


def reference_length(points: np.ndarray, tets: np.ndarray) -> float:
    """Median over tets of the shortest edge (one voxel on an isovolume mesh).

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64
        At most about 400 000 evenly spaced tets are looked at.
    """
    from cutkit.decimate._kernels import shortest_edges

    stride = max(1, tets.shape[0] // 400_000)
    return float(np.median(shortest_edges(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(tets, np.int64), stride)))


def _check_model(model: TetModel):
    points = np.ascontiguousarray(model.points, np.float64)
    tets = np.ascontiguousarray(model.tets, np.int64)
    labels = np.ascontiguousarray(model.labels, np.int32)
    if points.ndim != 2 or points.shape[1] != 3:
        raise MeshError(f"points must have shape (n, 3), got {points.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise MeshError(f"tets must have shape (m, 4), got {tets.shape}")
    if labels.shape != (tets.shape[0],):
        raise MeshError(f"labels must have shape ({tets.shape[0]},), got {labels.shape}")
    if tets.shape[0] == 0:
        raise MeshError("the model has no tets")
    if not np.all(np.isfinite(points)):
        raise MeshError("points contain NaN or infinite coordinates")
    if tets.min() < 0 or tets.max() >= points.shape[0]:
        raise MeshError(f"tets reference nodes outside 0..{points.shape[0] - 1}")
    from cutkit.mesh.geometry import tet_volumes6

    vol6 = tet_volumes6(points, tets)
    bad = np.flatnonzero(vol6 <= 0.0)
    if bad.size:
        raise MeshError(f"{bad.size} tets are inverted or flat (first: tet {bad[0]}); decimation needs positively oriented tets")
    return points, tets, labels, vol6


def _target_count(m: int, target_tets, ratio) -> int:
    if (target_tets is None) == (ratio is None):
        raise InputError("give exactly one of target_tets or ratio")
    if target_tets is not None:
        if isinstance(target_tets, bool) or int(target_tets) != target_tets or target_tets < 1:
            raise InputError(f"target_tets must be a positive integer, got {target_tets}")
        return int(target_tets)
    if not (isinstance(ratio, (int, float)) and 0.0 < ratio <= 1.0):
        raise InputError(f"ratio must be the fraction of tets to keep, in (0, 1], got {ratio}")
    return max(1, int(math.floor(ratio * m)))


def _boundary_grid(points: np.ndarray, tets: np.ndarray, h: float):
    """The outer boundary's nodes binned in a uniform grid of cell size about ``h`` (rule 4 of
    :mod:`cutkit.decimate._legality`): sorted linear cell keys, their nodes, and
    ``(lo x, y, z, cell size, cells along x, y, z, relative tolerance)``."""
    from cutkit.mesh.check import HANGING_NODE_REL_TOL
    from cutkit.mesh.topology import boundary_faces

    faces, _ = boundary_faces(tets)
    nodes = np.unique(faces).astype(np.int64)
    if nodes.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(8)
    cp = points[nodes]
    lo = cp.min(axis=0)
    ext = cp.max(axis=0) - lo
    cell = max(float(h), float(ext.max()) / 1024.0, 1e-300)
    dims = np.minimum(np.floor(ext / cell).astype(np.int64) + 1, 1 << 20)
    cell = max(cell, float((ext / dims).max()))
    ijk = np.minimum(np.floor((cp - lo) / cell).astype(np.int64), dims - 1)
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(keys, kind="stable")
    grid = np.array([*lo, cell, *dims.astype(np.float64), HANGING_MARGIN * HANGING_NODE_REL_TOL])
    return np.ascontiguousarray(keys[order]), np.ascontiguousarray(nodes[order]), grid


def _adjacency(tets: np.ndarray, n: int):
    """Per-vertex tet lists in one pool: (start, len, cap, pool, pool_end); see :mod:`._pool`."""
    from cutkit.decimate._kernels import build_adjacency

    # As much slack as incidences: lists move to the end as they grow and
    # are packed to the front when the end is reached.
    return build_adjacency(tets, n, tets.size + 64)


def _distinct(labels: np.ndarray) -> np.ndarray:
    """Sorted distinct labels (bincount when they are small non-negative ints: no sort of m values)."""
    lo, hi = int(labels.min()), int(labels.max())
    if lo >= 0 and hi < 1 << 16:
        return np.flatnonzero(np.bincount(labels, minlength=hi + 1)).astype(labels.dtype)
    return np.unique(labels)


def legality_params(h, tol, min_dihedral_deg):
    """(N_PARAMS,) float64: the legality rules' parameters (``_legality.P_*``) for reference length
    ``h`` and surface tolerance ``tol`` (mm) and the smallest dihedral angle allowed (degrees)."""
    from cutkit.decimate import _legality as L

    params = np.zeros(L.N_PARAMS)
    params[L.P_H] = h
    params[L.P_COS_MIN] = math.cos(math.radians(min_dihedral_deg))
    params[L.P_TOL] = tol
    params[L.P_NORMAL_COS] = math.cos(math.radians(NORMAL_MAX_DEG))
    params[L.P_W_SURFACE] = W_SURFACE
    params[L.P_W_TOUCH] = W_TOUCH
    params[L.P_VOL_EPS] = VOL_EPS_REL * h**3
    params[L.P_SURF_SAFETY] = SURFACE_SAFETY
    return params


def decimation_state(points, tets0, labels, vol6, locked, h):
    """The kernels' state of a decimation before its first collapse, and the pool's end.

    Parameters
    ----------
    points : (n, 3) float64
    tets0 : (m, 4) int64
        Positively oriented; copied (the collapses rewrite the copy).
    labels : (m,) int32
    vol6 : (m,) float64
        Six times each tet's volume.
    locked : (n,) uint8
        1 where a vertex never moves (a boundary condition holds it).
    h : float
        The reference length, mm.

    Returns
    -------
    (state, pool_end) : (``_state.Decimation``, int)
    """
    from cutkit.decimate import _kernels as K
    from cutkit.decimate import _state as S

    n, m = points.shape[0], tets0.shape[0]
    tets = tets0.copy()
    adj_start, adj_len, adj_cap, pool, pool_end = _adjacency(tets, n)
    label_values = _distinct(labels)
    tet_lab = np.searchsorted(label_values, labels).astype(np.int64)
    budget = S.Budget(np.zeros(label_values.size),
                      VOLUME_BUDGET_REL * np.bincount(tet_lab, weights=vol6 / 6.0, minlength=label_values.size))
    vclass = K.classify_vertices(tets, labels, adj_start, adj_len, pool)
    mesh = S.Mesh(points, labels, tet_lab, np.ones(m, np.uint8), K.all_tet_max_cos(points, tets),
                  (adj_len > 0).astype(np.uint8), vclass, locked)
    # Original surface points each vertex stands for: itself, the centroids of
    # the S-faces it is the smallest vertex of, and what it absorbs.
    face_owner, face_centroids = K.surface_face_points(points, tets, labels, adj_start, adj_len, pool, vclass)
    own_pts = np.ascontiguousarray(np.concatenate([points, face_centroids]))
    owners = S.Owners(own_pts, np.arange(n, dtype=np.int64), np.full(own_pts.shape[0], -1, np.int64))
    K.link_owned_points(face_owner, n, owners.own_tail, owners.own_next)
    cap = 4 * n + 64
    queue = S.Queue(np.zeros(n, np.int64), np.full(n, np.inf), np.full(n, np.inf), np.empty(cap),
                    np.empty(cap, np.int64), np.empty(cap, np.int64))
    tet_counts = np.empty(n + 1, np.int64)
    tet_counts[0] = m
    log = S.Log(np.empty(n, np.int64), np.empty(n, np.int64), tet_counts)
    state = S.Decimation(mesh, S.Stars(tets, adj_start, adj_len, pool), adj_cap, queue, owners,
                         (np.zeros(n, np.int64), np.zeros(n, np.int64)), budget, log,
                         S.Boundary(*_boundary_grid(points, tets0, h)))
    return state, pool_end


def decimate(
    model: TetModel,
    target_tets: int | None = None,
    ratio: float | None = None,
    surface_tolerance_mm: float | None = None,
    min_dihedral_deg: float = DEFAULT_MIN_DIHEDRAL_DEG,
    progress: Callable[[int, int], None] | None = None,
) -> TetModel:
    """Decimate a tet model by half-edge collapses, recording them progressively.

    Parameters
    ----------
    model : TetModel
        Positively oriented tets.  An existing ``extra["progressive"]`` record
        is continued from the model's level.
    target_tets : int, optional
        Stop once the model has at most this many tets.
    ratio : float, optional
        Fraction of the tets to keep, in (0, 1] (0.1 = ten times fewer).
        Exactly one of ``target_tets`` and ``ratio`` is given.
    surface_tolerance_mm : float, optional
        How far the boundary and the tissue interfaces may move, mm.
        Defaults to the median over tets of the shortest edge (one voxel on
        an isovolume mesh).
    min_dihedral_deg : float
        No collapse creates a tet with a smaller dihedral angle, nor makes
        the smallest angle around the removed vertex worse.
    progress : callable, optional
        Called as ``progress(removed_tets, tets_to_remove)``.

    Returns
    -------
    TetModel
        The decimated model (nodes renumbered in increasing input id, tets in
        input order) with ``extra["progressive"]`` (see
        :mod:`cutkit.decimate.progressive`).  The target may not be reached
        when no legal collapse is left; compare ``n_tets``.
    """
    from cutkit.decimate import _kernels as K
    from cutkit.decimate import _pool as P

    points, tets0, labels, vol6 = _check_model(model)
    n, m = points.shape[0], tets0.shape[0]
    target = _target_count(m, target_tets, ratio)
    if not (isinstance(min_dihedral_deg, (int, float)) and 0.0 <= min_dihedral_deg < 70.0):
        raise InputError(f"min_dihedral_deg must be in [0, 70), got {min_dihedral_deg}")
    h = reference_length(points, tets0)
    if surface_tolerance_mm is None:
        tol = h
    else:
        if not (isinstance(surface_tolerance_mm, (int, float)) and surface_tolerance_mm >= 0.0 and math.isfinite(surface_tolerance_mm)):
            raise InputError(f"surface_tolerance_mm must be a finite number >= 0, got {surface_tolerance_mm}")
        tol = float(surface_tolerance_mm)

    locked = np.zeros(n, np.uint8)
    for name, nodes in (("fixed_nodes", model.boundary.fixed_nodes), ("prescribed_nodes", model.boundary.prescribed_nodes)):
        nodes = np.asarray(nodes, np.int64).ravel()
        if nodes.size and (nodes.min() < 0 or nodes.max() >= n):
            raise MeshError(f"boundary.{name} references nodes outside 0..{n - 1}")
        locked[nodes] = 1

    state, pool_end = decimation_state(points, tets0, labels, vol6, locked, h)
    counters = np.zeros(P.N_COUNTERS, np.int64)
    counters[P.C_POOL_END] = pool_end
    counters[P.C_ALIVE_TETS] = m
    counters[P.C_TARGET] = target
    params = legality_params(h, tol, min_dihedral_deg)

    to_remove = max(m - target, 0)
    rounds = 0
    done_at_round = -1
    status = K.STATUS_EMPTY
    while counters[P.C_ALIVE_TETS] > target:
        if status == K.STATUS_EMPTY:
            if counters[P.C_COLLAPSES] == done_at_round or rounds >= MAX_ROUNDS:
                break  # a full round without a collapse: nothing legal is left
            done_at_round = int(counters[P.C_COLLAPSES])
            rounds += 1
            K.push_all(state, counters, params)
        status = K.run_collapses(state, counters, params, POPS_PER_CALL)
        if progress is not None:
            progress(int(min(m - counters[P.C_ALIVE_TETS], to_remove)), to_remove)

    k = int(counters[P.C_COLLAPSES])
    alive_idx = np.flatnonzero(state.mesh.tet_alive).astype(np.int64)
    out_tets_local = state.stars.tets[alive_idx]
    used = np.unique(out_tets_local)
    renum = np.full(n, -1, np.int64)
    renum[used] = np.arange(used.shape[0])

    result = _assemble(model, points, labels, out_tets_local, alive_idx, used, renum)
    log = state.log
    result.extra[RECORD] = _record(model, points, tets0, labels, log.collapse_u[:k], log.collapse_v[:k],
                                   log.tet_counts[: k + 1], alive_idx, used)
    result.provenance = copy.deepcopy(model.provenance)
    result.provenance["decimate"] = {
        "input_tets": m,
        "target_tets": target,
        "output_tets": int(alive_idx.shape[0]),
        "collapses": k,
        "surface_tolerance_mm": tol,
        "min_dihedral_deg": float(min_dihedral_deg),
        "reference_length_mm": h,
        "level": int(result.extra[RECORD]["level"][0]),
        "heap_pops": int(counters[P.C_POPS]),
        "legality_tests": int(counters[P.C_CHECKS]),
        "precheck_rejects": int(counters[P.C_PRECHECK_REJECTS]),
        "rounds": rounds,
    }
    return result


def _assemble(model, points, labels, out_tets_local, alive_idx, used, renum) -> TetModel:
    bc = model.boundary
    boundary = BoundaryConditions(
        fixed_nodes=renum[np.asarray(bc.fixed_nodes, np.int64)],
        prescribed_nodes=renum[np.asarray(bc.prescribed_nodes, np.int64)],
        prescribed_displacement=np.asarray(bc.prescribed_displacement, np.float64).reshape(-1, 3).copy(),
    )
    texcoords = None if model.texcoords is None else np.ascontiguousarray(np.asarray(model.texcoords, np.float64)[used])
    return TetModel(
        points=np.ascontiguousarray(points[used]),
        tets=np.ascontiguousarray(renum[out_tets_local]),
        labels=np.ascontiguousarray(labels[alive_idx]),
        materials=model.materials,
        boundary=boundary,
        prestress=model.prestress,
        texture=model.texture,
        texcoords=texcoords,
        point_data={k: np.asarray(a)[used] for k, a in model.point_data.items()},
        cell_data={k: np.asarray(a)[alive_idx] for k, a in model.cell_data.items()},
        provenance={},
        extra={k: v for k, v in model.extra.items() if k != RECORD},
    )


def _record(model, points, tets, labels, cu, cv, counts, alive_idx, used) -> dict:
    """The progressive record, continuing the model's own record if it has one."""
    old = model.extra.get(RECORD)
    if old is None:
        rec = {"points0": points, "tets0": tets, "labels0": labels}
        if model.texcoords is not None:
            rec["texcoords0"] = np.ascontiguousarray(np.asarray(model.texcoords, np.float64))
        node_ids = np.arange(points.shape[0], dtype=np.int64)
        tet_ids = np.arange(tets.shape[0], dtype=np.int64)
        prev_u = np.zeros(0, np.int64)
        prev_v = np.zeros(0, np.int64)
        prev_counts = np.zeros(0, np.int64)
    else:
        level = int(np.asarray(old["level"]).ravel()[0])
        rec = {k: old[k] for k in ("points0", "tets0", "labels0", "texcoords0") if k in old}
        node_ids = np.asarray(old["node_ids"], np.int64)
        tet_ids = np.asarray(old["tet_ids"], np.int64)
        prev_u = np.asarray(old["collapse_u"], np.int64)[:level]
        prev_v = np.asarray(old["collapse_v"], np.int64)[:level]
        prev_counts = np.asarray(old["tet_counts"], np.int64)[:level]
    rec["collapse_u"] = np.concatenate([prev_u, node_ids[cu]])
    rec["collapse_v"] = np.concatenate([prev_v, node_ids[cv]])
    rec["tet_counts"] = np.concatenate([prev_counts, counts]).astype(np.int64)
    rec["level"] = np.array([rec["collapse_u"].shape[0]], np.int64)
    rec["node_ids"] = node_ids[used]
    rec["tet_ids"] = tet_ids[alive_idx]
    return rec


def min_dihedral_deg(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Smallest dihedral angle of each tet, degrees.

    A stand-in for :func:`cutkit.mesh.quality.min_dihedral_angles` computed
    with the decimator's own kernel.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64

    Returns
    -------
    (m,) float64
    """
    from cutkit.decimate._kernels import all_tet_max_cos

    points = np.ascontiguousarray(points, np.float64)
    tets = np.ascontiguousarray(tets, np.int64)
    return np.degrees(np.arccos(np.clip(all_tet_max_cos(points, tets), -1.0, 1.0)))


def quality_summary(points: np.ndarray, tets: np.ndarray, threshold_deg: float = DEFAULT_MIN_DIHEDRAL_DEG) -> dict:
    """``{"tets", "min_dihedral_deg", "fraction_below"}`` of a mesh (fraction of tets under ``threshold_deg``)."""
    md = min_dihedral_deg(points, tets)
    return {
        "tets": int(tets.shape[0]),
        "min_dihedral_deg": float(md.min()) if md.size else float("nan"),
        "fraction_below": float(np.mean(md < threshold_deg)) if md.size else 0.0,
    }
