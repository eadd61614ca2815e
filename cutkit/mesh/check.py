"""Validity checks of a tetrahedral mesh (what ``cutkit check`` reports).

Each check is one row of a :class:`CheckReport`.  Tolerances are the module
constants below; see docs/mesh-core.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cutkit.errors import MeshError
from cutkit.mesh import _check_kernels as _ck
from cutkit.mesh import _topology_kernels as _tk
from cutkit.mesh import quality
from cutkit.mesh.topology import TET_EDGES, TET_FACES

__all__ = ["CheckRow", "CheckReport", "check_mesh", "ORIENTATION_REL_TOL", "HANGING_NODE_REL_TOL"]

#: A tet fails the orientation check when 6 * volume <= ORIENTATION_REL_TOL * (longest edge)**3,
#: i.e. when it is inverted or flat to within rounding of its own size.
ORIENTATION_REL_TOL = 1e-12
#: A boundary node hangs on a boundary triangle when it is within this fraction of the
#: triangle's longest edge from the triangle (plane distance and barycentric slack),
#: and not within it from one of the triangle's corners.
HANGING_NODE_REL_TOL = 1e-6
#: At most this many offenders are named in a row's detail.
MAX_NAMED = 5


@dataclass
class CheckRow:
    """One check: its name, whether it passed, and a one-line detail."""

    name: str
    passed: bool
    detail: str


@dataclass
class CheckReport:
    """The result of :func:`check_mesh`.

    Attributes
    ----------
    rows : list of CheckRow
    min_dihedral_angle : float
        Worst (smallest) dihedral angle of the mesh in degrees (nan if not computed).
    hanging_nodes : (h,) int64
        Node ids found hanging on a boundary face or edge.
    """

    rows: list[CheckRow] = field(default_factory=list)
    min_dihedral_angle: float = float("nan")
    hanging_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.rows)

    @property
    def failed(self) -> list[str]:
        return [r.name for r in self.rows if not r.passed]

    def add(self, name: str, passed: bool, detail: str) -> None:
        self.rows.append(CheckRow(name, bool(passed), detail))


def _name(ids, what: str) -> str:
    ids = np.asarray(ids).ravel()
    shown = ", ".join(str(int(i)) for i in ids[:MAX_NAMED])
    more = f" (+{ids.size - MAX_NAMED} more)" if ids.size > MAX_NAMED else ""
    return f"{ids.size} {what}: {shown}{more}"


def check_mesh(points, tets, labels=None, min_dihedral: float = 0.0, quick: bool = False) -> CheckReport:
    """Check that a tet mesh is a valid, conforming, positively oriented mesh.

    Parameters
    ----------
    points : (n, 3) float
    tets : (m, 4) int
    labels : (m,) int, optional
        Checked for shape and integer type when given.
    min_dihedral : float
        The dihedral-angle row fails when the worst angle (degrees) is below this.
    quick : bool
        Only the cheap checks (a few passes over the tets): finite coordinates,
        indices, labels, positive orientation, faces shared by at most two tets.

    Returns
    -------
    CheckReport
        Checks, in order: finite coordinates, indices in range, labels,
        positive orientation, faces shared by at most two tets, closed
        2-manifold boundary (edges, then vertices), no hanging node on the
        boundary, no unused node, worst dihedral angle.  Checks that need a
        valid index array are skipped (not listed) when indices are bad.

    Raises
    ------
    MeshError
        When ``points`` or ``tets`` do not even have the right shapes.
    """
    rep = CheckReport()
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.issubdtype(pts.dtype, np.number):
        raise MeshError(f"points must be a numeric (n, 3) array, got shape {pts.shape}")
    tt = np.asarray(tets)
    if tt.ndim != 2 or tt.shape[1] != 4 or (tt.size and not np.issubdtype(tt.dtype, np.integer)):
        raise MeshError(f"tets must be an integer (m, 4) array, got shape {tt.shape}")
    pts = np.ascontiguousarray(pts, np.float64)
    tt = np.ascontiguousarray(tt, np.int64)
    n, m = pts.shape[0], tt.shape[0]

    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    rep.add("finite coordinates", bad.size == 0, "all finite" if bad.size == 0 else _name(bad, "nodes with NaN/inf"))

    out = np.flatnonzero(((tt < 0) | (tt >= n)).any(axis=1))
    rep.add("indices in range", out.size == 0,
            f"{m} tets on {n} nodes" if out.size == 0 else _name(out, f"tets with a node index outside [0, {n})"))
    if labels is not None:
        lab = np.asarray(labels)
        ok = lab.shape == (m,) and (m == 0 or np.issubdtype(lab.dtype, np.integer))
        rep.add("labels", ok, f"{np.unique(lab).size} labels" if ok else f"labels must be (m,) integers, got {lab.shape} {lab.dtype}")
    if out.size or bad.size or m == 0:
        if m == 0:
            rep.add("non-empty", False, "the mesh has no tetrahedra")
        return rep

    # orientation: 6V against the tet's own size cubed
    vol6 = quality.signed_volumes(pts, tt) * 6.0
    e = pts[tt[:, TET_EDGES[:, 1]]] - pts[tt[:, TET_EDGES[:, 0]]]
    longest = np.sqrt((e * e).sum(axis=2).max(axis=1))
    inv = np.flatnonzero(vol6 <= ORIENTATION_REL_TOL * longest**3)
    rep.add("positive orientation", inv.size == 0,
            "all tets positive" if inv.size == 0 else _name(inv, "inverted or flat tets"))

    triples = _tk.sorted_tuples(tt, np.ascontiguousarray(TET_FACES))
    faces, finv = _tk.unique_rows(triples, np.int64(n))
    face_tets, count = _tk.face_tets_from_inverse(finv, faces.shape[0])
    over = np.flatnonzero(count > 2)
    rep.add("faces shared by <= 2 tets", over.size == 0,
            f"{faces.shape[0]} faces" if over.size == 0
            else f"{over.size} faces in 3+ tets, e.g. nodes {faces[over[0]].tolist()}")
    if quick:
        return rep

    # boundary: faces used once, outward-oriented
    local = np.flatnonzero(count[finv] == 1)
    bt = local // 4
    bfaces = np.ascontiguousarray(tt[bt[:, None], TET_FACES[local % 4]])
    nb = bfaces.shape[0]
    be_rows = np.sort(bfaces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    bedges, einv = _tk.unique_rows(np.ascontiguousarray(be_rows), np.int64(n)) if nb else (np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    ecount = np.bincount(einv, minlength=bedges.shape[0])
    badedge = np.flatnonzero(ecount != 2)
    if badedge.size:
        ex = bedges[badedge[0]].tolist()
        detail = f"{badedge.size} boundary edges not in exactly two boundary faces, e.g. nodes {ex} in {int(ecount[badedge[0]])}"
    else:
        detail = f"{nb} boundary faces, {bedges.shape[0]} edges"
    rep.add("closed manifold boundary (edges)", badedge.size == 0, detail)
    if badedge.size == 0 and nb:
        nm = _nonmanifold_vertices(bfaces, einv, n)
        rep.add("manifold boundary vertices", nm.size == 0,
                "every boundary vertex has one disc of faces" if nm.size == 0 else _name(nm, "non-manifold vertices"))

    hanging, tri = _hanging_nodes(pts, bfaces)
    rep.hanging_nodes = hanging
    rep.add("no hanging node (conforming)", hanging.size == 0,
            "no node on a boundary face or edge it does not belong to" if hanging.size == 0
            else _name(hanging, "hanging nodes") + f" (node {int(hanging[0])} lies on boundary face {tri.tolist()})")

    used = np.zeros(n, bool)
    used[tt.ravel()] = True
    unused = np.flatnonzero(~used)
    rep.add("no unused node", unused.size == 0, "all nodes used" if unused.size == 0 else _name(unused, "unused nodes"))

    ang = quality.dihedral_angles(pts, tt).min(axis=1)
    worst = int(np.argmin(ang))
    rep.min_dihedral_angle = float(ang[worst])
    rep.add("min dihedral angle", rep.min_dihedral_angle > min_dihedral,
            f"{rep.min_dihedral_angle:.3f} deg at tet {worst} (limit {min_dihedral:g})")
    return rep


def _nonmanifold_vertices(bfaces: np.ndarray, einv: np.ndarray, n: int) -> np.ndarray:
    """Vertices whose boundary faces form more than one edge-connected fan.

    Corners (face, vertex) are graph nodes; two faces sharing a boundary
    edge link their corners at both ends of it.  A manifold vertex has all
    its corners in one component.  Assumes every edge is in two faces.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nb = bfaces.shape[0]
    # half-edge k of face f runs from local vertex k to k+1; einv row 3f+k
    order = np.argsort(einv, kind="stable")
    h0, h1 = order[0::2], order[1::2]  # the two half-edges of each edge
    f0, k0 = h0 // 3, h0 % 3
    f1, k1 = h1 // 3, h1 % 3
    va0 = bfaces[f0, k0]
    # corner of face f at local vertex k has id 3f+k; match the same vertex in the other face
    loc_a1 = np.where(bfaces[f1, k1] == va0, k1, (k1 + 1) % 3)
    loc_b1 = np.where(bfaces[f1, k1] == va0, (k1 + 1) % 3, k1)
    src = np.concatenate([3 * f0 + k0, 3 * f0 + (k0 + 1) % 3])
    dst = np.concatenate([3 * f1 + loc_a1, 3 * f1 + loc_b1])
    g = coo_matrix((np.ones(src.size), (src, dst)), shape=(3 * nb, 3 * nb))
    n_comp, comp = connected_components(g, directed=False)
    # each (vertex, fan) pair once, as one integer (np.unique over rows is several times slower)
    pairs = np.unique(bfaces.ravel().astype(np.int64) * np.int64(n_comp) + comp)
    per_vertex = np.bincount(pairs // n_comp, minlength=n)
    return np.flatnonzero(per_vertex > 1)


def _hanging_nodes(pts: np.ndarray, bfaces: np.ndarray):
    """Boundary nodes lying on a boundary triangle or edge they are not a corner of.

    Spatial hash: boundary nodes binned in a uniform grid of cell size
    ~ the mean boundary edge length, each triangle tests only the cells
    its (tolerance-grown) bounding box covers.
    """
    if bfaces.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(3, np.int64)
    cand = np.unique(bfaces)
    cp = pts[cand]
    lo = cp.min(axis=0)
    ext = cp.max(axis=0) - lo
    edge = np.linalg.norm(pts[bfaces[:, 1]] - pts[bfaces[:, 0]], axis=1).mean()
    h = max(edge, ext.max() / 1024.0, 1e-300)
    dims = np.minimum(np.floor(ext / h).astype(np.int64) + 1, 1 << 20)
    h = max(h, float((ext / dims).max()))
    ijk = np.minimum(np.floor((cp - lo) / h).astype(np.int64), dims - 1)
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    order = np.argsort(keys, kind="stable")
    hit = _ck.hanging_nodes(pts, bfaces, cand, np.ascontiguousarray(keys[order]), order.astype(np.int64),
                            lo, float(h), dims, HANGING_NODE_REL_TOL)
    nodes = np.flatnonzero(hit >= 0)
    return nodes, (bfaces[hit[nodes[0]]] if nodes.size else np.zeros(3, np.int64))
