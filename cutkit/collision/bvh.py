"""Axis-aligned bounding box hierarchy over a deforming surface (paper 4.1).

The hierarchy is built once over the boundary triangles, greedily and
bottom-up (Fig. 5b), and then follows the deformation: every mesh node
has a *tolerance box* of half size ``s_tol`` around the position it had at
its last refit; a leaf box is the union of its three corners' tolerance
boxes (Fig. 5a).  After a position update only nodes that left their
tolerance box cause a refit, of the leaves around them and of those
leaves' ancestors.  Faces created by a cut are added as a small
hierarchy of their own hung under a nearby node; faces removed by a cut
are marked dead.  See ``docs/collision.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from cutkit.collision import _kernels as K
from cutkit.collision.adjacency import boundary_faces, csr_adjacency, edge_adjacency
from cutkit.mesh.geometry import HIT_COPLANAR, HIT_EDGE, HIT_FACE, HIT_VERTEX
from cutkit.errors import InputError, MeshError

__all__ = [
    "DEFAULT_S_TOL",
    "HIT_FACE",
    "HIT_EDGE",
    "HIT_VERTEX",
    "HIT_COPLANAR",
    "SegmentHits",
    "SurfaceBVH",
]

#: Default half size of the tolerance boxes, mm: a node may move this far
#: along each axis before its faces' boxes are refitted.
DEFAULT_S_TOL = 0.05

#: Faces added by cuts are scanned one by one at each update until there
#: are more than max(REINDEX_MIN, REINDEX_FRACTION * indexed faces) of
#: them; then the node-to-faces index is rebuilt (the tree is not).
REINDEX_MIN = 4096
REINDEX_FRACTION = 0.05

_HIT_ROOM = 64  # first guess of the number of hits of one segment


@dataclass
class SegmentHits:
    """Faces met by a segment p0 + t (p1 - p0), sorted by ``t``.

    Attributes
    ----------
    face : (h,) int64
        Face ids (rows of ``SurfaceBVH.faces``).
    kind : (h,) int64
        ``HIT_FACE``, ``HIT_EDGE``, ``HIT_VERTEX`` or ``HIT_COPLANAR``.
    t : (h,) float64
        Segment parameter in [0, 1] (for a coplanar segment: where it
        enters the triangle).
    point : (h, 3) float64
        The hit point, mm.
    """

    face: np.ndarray
    kind: np.ndarray
    t: np.ndarray
    point: np.ndarray

    def __len__(self) -> int:
        return int(self.face.shape[0])


class SurfaceBVH:
    """AABB hierarchy over the boundary triangles of a deforming mesh.

    Build with :meth:`build` (from boundary faces) or :meth:`from_tets`.

    Attributes
    ----------
    faces : (f, 3) int64
        Boundary triangles (including dead ones), outward oriented.
    face_alive : (f,) bool
    face_leaf : (f,) int64
        Leaf node of each face.
    box_min, box_max : (k, 3) float64
        Node boxes (a dead leaf has an empty box, min > max).
    child : (k, 2) int64
        Children of inner nodes, -1 for leaves.
    parent : (k,) int64
        -1 for the root.
    leaf_face : (k,) int64
        Face of a leaf, -1 for inner nodes.
    root : int
    tol_min, tol_max : (n, 3) float64
        Tolerance box of every mesh node.
    s_tol : float
        Half size of the tolerance boxes, mm.
    """

    def __init__(self, n_points: int, s_tol: float):
        self.s_tol = float(s_tol)
        self._n_nodes = 0
        self._n_faces = 0
        self._box_min = np.empty((0, 3))
        self._box_max = np.empty((0, 3))
        self._child = np.empty((0, 2), dtype=np.int64)
        self._parent = np.empty(0, dtype=np.int64)
        self._leaf_face = np.empty(0, dtype=np.int64)
        self._faces = np.empty((0, 3), dtype=np.int64)
        self._face_alive = np.empty(0, dtype=np.bool_)
        self._face_leaf = np.empty(0, dtype=np.int64)
        self.tol_min = np.empty((n_points, 3))
        self.tol_max = np.empty((n_points, 3))
        self.root = -1
        self.counters = np.zeros(3, dtype=np.int64)
        # faces around each node (CSR) over the first _n_indexed faces;
        # faces added later are scanned one by one until the next reindex
        self._node_face_off = np.zeros(1, dtype=np.int64)
        self._node_face_idx = np.empty(0, dtype=np.int64)
        self._n_indexed = 0
        self._hit_buffers = _hit_buffers(_HIT_ROOM)

    # -- views of the used part of the growable arrays -----------------------
    @property
    def n_nodes(self) -> int:
        return self._n_nodes

    @property
    def n_faces(self) -> int:
        return self._n_faces

    box_min = property(lambda self: self._box_min[: self._n_nodes])
    box_max = property(lambda self: self._box_max[: self._n_nodes])
    child = property(lambda self: self._child[: self._n_nodes])
    parent = property(lambda self: self._parent[: self._n_nodes])
    leaf_face = property(lambda self: self._leaf_face[: self._n_nodes])
    faces = property(lambda self: self._faces[: self._n_faces])
    face_alive = property(lambda self: self._face_alive[: self._n_faces])
    face_leaf = property(lambda self: self._face_leaf[: self._n_faces])

    def kernel_tree(self) -> K.Tree:
        """The hierarchy as its kernels read it (the arrays' whole room; the root reaches the nodes in use)."""
        return K.Tree(self._box_min, self._box_max, self._child, self._parent, self._leaf_face, self.root)

    def kernel_surface(self) -> K.Surface:
        """The faces as the queries read them (the arrays' whole room; the leaves name the faces in use)."""
        return K.Surface(self._faces, self._face_alive, self._face_leaf)

    @property
    def refit_counts(self) -> dict[str, int]:
        """Counters since construction or :meth:`reset_counters`.

        ``nodes_left_tolerance``: node updates that left a tolerance box;
        ``leaf_refits``: leaf boxes recomputed; ``node_refits``: inner boxes
        recomputed by the bottom-up refit.
        """
        c = self.counters
        return {"nodes_left_tolerance": int(c[0]), "leaf_refits": int(c[1]), "node_refits": int(c[2])}

    def reset_counters(self) -> None:
        self.counters[:] = 0

    # -- storage -----------------------------------------------------------------
    def _reserve_nodes(self, extra: int) -> None:
        need = self._n_nodes + extra
        cap = self._box_min.shape[0]
        if need <= cap:
            return
        cap = max(need, 2 * cap, 16)

        def grow(a, fill):
            out = np.full((cap,) + a.shape[1:], fill, dtype=a.dtype)
            out[: a.shape[0]] = a
            return out

        self._box_min = grow(self._box_min, np.inf)
        self._box_max = grow(self._box_max, -np.inf)
        self._child = grow(self._child, -1)
        self._parent = grow(self._parent, -1)
        self._leaf_face = grow(self._leaf_face, -1)

    def _reserve_faces(self, extra: int) -> None:
        need = self._n_faces + extra
        cap = self._faces.shape[0]
        if need <= cap:
            return
        cap = max(need, 2 * cap, 16)
        for name, fill in (("_faces", -1), ("_face_alive", False), ("_face_leaf", -1)):
            a = getattr(self, name)
            out = np.full((cap,) + a.shape[1:], fill, dtype=a.dtype)
            out[: a.shape[0]] = a
            setattr(self, name, out)

    def _grow_points(self, points: np.ndarray) -> None:
        """Give new mesh nodes (appended by a cut) their tolerance boxes."""
        n_old = self.tol_min.shape[0]
        n = points.shape[0]
        if n < n_old:
            raise InputError(f"points: {n} rows, but the hierarchy was built for {n_old} nodes")
        if n > n_old:
            new = points[n_old:]
            self.tol_min = np.concatenate([self.tol_min, new - self.s_tol])
            self.tol_max = np.concatenate([self.tol_max, new + self.s_tol])

    def _reindex(self) -> None:
        """Rebuild the node-to-faces index over all current faces."""
        faces = self.faces
        n = self.tol_min.shape[0]
        flat = faces.reshape(-1)
        self._node_face_idx = (np.argsort(flat, kind="stable") // 3).astype(np.int64)
        off = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(flat, minlength=n), out=off[1:])
        self._node_face_off = off
        self._n_indexed = self._n_faces

    # -- construction ------------------------------------------------------------
    @classmethod
    def build(cls, points, faces, s_tol: float = DEFAULT_S_TOL) -> "SurfaceBVH":
        """Build the hierarchy over boundary triangles.

        Parameters
        ----------
        points : (n, 3) float64
            Node positions, mm.
        faces : (f, 3) int64
            Boundary triangles (node ids).
        s_tol : float
            Half size of the tolerance boxes, mm (0 disables them).

        Returns
        -------
        SurfaceBVH
        """
        points = _points(points)
        faces = _faces(faces, points.shape[0])
        if not (np.isfinite(s_tol) and s_tol >= 0):
            raise InputError(f"s_tol must be finite and >= 0, got {s_tol}")
        bvh = cls(points.shape[0], s_tol)
        bvh.tol_min[:] = points - bvh.s_tol
        bvh.tol_max[:] = points + bvh.s_tol
        bvh.root = bvh._add_group(faces)
        bvh._reindex()
        return bvh

    @classmethod
    def from_tets(cls, points, tets, s_tol: float = DEFAULT_S_TOL) -> "SurfaceBVH":
        """Build the hierarchy over the boundary faces of a tetrahedral mesh.

        Parameters
        ----------
        points : (n, 3) float64
        tets : (m, 4) int64
            Positively oriented tetrahedra.
        """
        points = _points(points)
        t = np.asarray(tets)
        if t.ndim != 2 or t.shape[1] != 4 or (t.size and not np.issubdtype(t.dtype, np.integer)):
            raise MeshError(f"tets must be an integer array of shape (m, 4), got {t.dtype} {t.shape}")
        t = np.ascontiguousarray(t, dtype=np.int64)
        if t.size and (t.min() < 0 or t.max() >= points.shape[0]):
            raise MeshError(f"tets refer to nodes outside [0, {points.shape[0]}): {t.min()}..{t.max()}")
        faces, _ = boundary_faces(t)
        return cls.build(points, faces, s_tol)

    def _add_group(self, faces: np.ndarray) -> int:
        """Add leaves for ``faces`` and build the greedy hierarchy over them.

        Returns the group's root node (-1 when ``faces`` is empty).
        """
        m = faces.shape[0]
        if m == 0:
            return -1
        self._reserve_faces(m)
        self._reserve_nodes(2 * m - 1)
        f0 = self._n_faces
        fid = np.arange(f0, f0 + m, dtype=np.int64)
        leaves = np.arange(self._n_nodes, self._n_nodes + m, dtype=np.int64)
        self._faces[fid] = faces
        self._face_alive[fid] = True
        self._face_leaf[fid] = leaves
        self._n_faces += m
        self._leaf_face[leaves] = fid
        self._child[leaves] = -1
        self._parent[leaves] = -1
        # leaf box = union of the corners' tolerance boxes (Fig. 5a)
        self._box_min[leaves] = self.tol_min[faces].min(axis=1)
        self._box_max[leaves] = self.tol_max[faces].max(axis=1)
        self._n_nodes += m
        return self._pair_up(leaves, edge_adjacency(faces))

    def _pair_up(self, nodes: np.ndarray, pairs: np.ndarray) -> int:
        """Greedy bottom-up pairing, level by level, until one root is left (Fig. 5b).

        ``pairs`` (e, 2) are adjacent positions in ``nodes``.  A level's
        adjacency is inherited from the children: two parents are
        neighbours if any of their children are.  Boxes that find no
        unpaired neighbour go up alone.  When a level has no adjacency left
        (separate surface components) its boxes are chained in order along
        the longest axis of their centres so that pairing goes on.
        """
        while nodes.shape[0] > 1:
            L = nodes.shape[0]
            off, idx, pairs = csr_adjacency(pairs, L)
            first, second = K.pair_level(self._box_min, self._box_max, nodes, off, idx)
            is_pair = second >= 0
            n_pairs = int(is_pair.sum())
            if n_pairs == 0:
                centre = self._box_min[nodes] + self._box_max[nodes]
                axis = int(np.argmax(np.ptp(centre, axis=0)))
                order = np.argsort(centre[:, axis], kind="stable")
                pairs = np.stack([order[:-1], order[1:]], axis=1)
                continue
            new = np.arange(self._n_nodes, self._n_nodes + n_pairs, dtype=np.int64)
            self._n_nodes += n_pairs
            a = nodes[first[is_pair]]
            b = nodes[second[is_pair]]
            self._child[new, 0] = a
            self._child[new, 1] = b
            self._parent[new] = -1
            self._leaf_face[new] = -1
            self._parent[a] = new
            self._parent[b] = new
            self._box_min[new] = np.minimum(self._box_min[a], self._box_min[b])
            self._box_max[new] = np.maximum(self._box_max[a], self._box_max[b])
            group_node = nodes[first].copy()
            group_node[is_pair] = new
            group_of = np.empty(L, dtype=np.int64)
            group_of[first] = np.arange(first.shape[0])
            group_of[second[is_pair]] = np.flatnonzero(is_pair)
            gp = group_of[pairs]
            pairs = gp[gp[:, 0] != gp[:, 1]]
            nodes = group_node
        return int(nodes[0])

    # -- deformation -------------------------------------------------------------
    def update(self, points) -> int:
        """Follow a position update: refit where nodes left their tolerance box.

        Parameters
        ----------
        points : (n, 3) float64
            Current node positions; rows beyond those known (nodes created
            by a cut) get new tolerance boxes.

        Returns
        -------
        int
            Number of nodes that left their tolerance box.
        """
        points = _points(points)
        self._grow_points(points)
        before = int(self.counters[0])
        tol = K.Tolerances(self.s_tol, self.tol_min, self.tol_max, self._node_face_off, self._node_face_idx,
                           self._n_indexed)
        K.refit(points, K.Surface(self.faces, self.face_alive, self.face_leaf), tol, self.kernel_tree(),
                self.counters)
        return int(self.counters[0]) - before

    def _grow_up(self, node: int) -> None:
        """Recompute the ancestors of ``node`` from their children."""
        p = int(self._parent[node])
        while p >= 0:
            l, r = self._child[p]
            lo = np.minimum(self._box_min[l], self._box_min[r])
            hi = np.maximum(self._box_max[l], self._box_max[r])
            if np.array_equal(lo, self._box_min[p]) and np.array_equal(hi, self._box_max[p]):
                return
            self._box_min[p] = lo
            self._box_max[p] = hi
            p = int(self._parent[p])

    def add_faces(self, points, faces) -> np.ndarray:
        """Add boundary faces created by a cut, without rebuilding.

        The new faces get leaves and a small greedy hierarchy of their own
        (the "predefined box structure" of 4.1); its root is hung beside
        the leaf reached by descending from the root into the child whose
        box grows least, and the ancestors are grown.

        Parameters
        ----------
        points : (n, 3) float64
            Current positions (may have more rows than before).
        faces : (g, 3) int64

        Returns
        -------
        (g,) int64
            Ids of the new faces.
        """
        points = _points(points)
        faces = _faces(faces, points.shape[0])
        self.update(points)
        start = self._n_faces
        sub = self._add_group(faces)
        if sub >= 0:
            self._reserve_nodes(1)
            self._hang(sub)
        if self._n_faces - self._n_indexed > max(REINDEX_MIN, REINDEX_FRACTION * self._n_indexed):
            self._reindex()
        return np.arange(start, self._n_faces, dtype=np.int64)

    def _hang(self, sub: int) -> None:
        if self.root < 0:
            self.root = sub
            return
        smin, smax = self._box_min[sub], self._box_max[sub]
        node = self.root
        while self._child[node, 0] >= 0:
            best, best_growth = -1, np.inf
            for c in self._child[node]:
                lo = np.minimum(self._box_min[c], smin)
                hi = np.maximum(self._box_max[c], smax)
                old = np.prod(np.maximum(self._box_max[c] - self._box_min[c], 0.0))
                growth = np.prod(hi - lo) - old
                if growth < best_growth:
                    best, best_growth = int(c), growth
            node = best
        new = self._n_nodes
        self._n_nodes += 1
        p = int(self._parent[node])
        self._child[new] = (node, sub)
        self._leaf_face[new] = -1
        self._parent[new] = p
        self._parent[node] = new
        self._parent[sub] = new
        self._box_min[new] = np.minimum(self._box_min[node], smin)
        self._box_max[new] = np.maximum(self._box_max[node], smax)
        if p < 0:
            self.root = new
        else:
            self._child[p, 0 if self._child[p, 0] == node else 1] = new
            self._grow_up(new)

    def remove_faces(self, face_ids) -> None:
        """Mark faces dead (removed by a cut); their leaves get empty boxes.

        Parameters
        ----------
        face_ids : (g,) int
        """
        ids = np.asarray(face_ids, dtype=np.int64).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= self._n_faces):
            raise InputError(f"face ids must lie in [0, {self._n_faces}), got {ids.min()}..{ids.max()}")
        for f in ids:
            if not self._face_alive[f]:
                continue
            self._face_alive[f] = False
            leaf = self._face_leaf[f]
            self._box_min[leaf] = np.inf
            self._box_max[leaf] = -np.inf
            self._grow_up(leaf)

    # -- queries -----------------------------------------------------------------
    def query_segment(self, points, p0, p1, brute_force: bool = False) -> SegmentHits:
        """Live faces met by the segment p0-p1, by top-down traversal.

        ``points`` must be the positions last passed to :meth:`update` (or
        :meth:`build`): the boxes enclose them only then.

        Parameters
        ----------
        points : (n, 3) float64
        p0, p1 : (3,) float64
        brute_force : bool
            Test every face instead of traversing the hierarchy (reference).

        Returns
        -------
        SegmentHits
        """
        # shape only: the O(n) finiteness scan was done by update()
        points = _points(points, check_finite=False)
        if points.shape[0] != self.tol_min.shape[0]:
            raise InputError(
                f"points: {points.shape[0]} rows, expected {self.tol_min.shape[0]} (call update first)"
            )
        p0 = _vec3(p0, "p0")
        p1 = _vec3(p1, "p1")
        while True:
            face, kind, par = self._hit_buffers
            cap = face.shape[0]
            hits = K.HitRoom(face, kind, par)
            if brute_force:
                count = K.brute_segment(points, K.Surface(self.faces, self.face_alive, self.face_leaf), p0, p1, hits)
            else:
                count, _ = K.query_segment(points, self.kernel_surface(), self.kernel_tree(), p0, p1, hits)
            if count <= cap:
                break
            self._hit_buffers = _hit_buffers(count)
        order = np.lexsort((face[:count], par[:count, 0]))
        return SegmentHits(face=face[order], kind=kind[order], t=par[order, 0].copy(),
                           point=par[order, 1:].copy())

    def query_blade(self, points, tip, a, blade_length: float) -> SegmentHits:
        """Faces met by the blade's edge, from ``tip - blade_length * a`` (t = 0) to the tip (t = 1)."""
        tip = _vec3(tip, "tip")
        a = _vec3(a, "a")
        return self.query_segment(points, tip - float(blade_length) * a, tip)

    def query_tip_path(self, points, tip_prev, tip) -> SegmentHits:
        """Faces the tip crossed moving from ``tip_prev`` (t = 0) to ``tip`` (t = 1)."""
        return self.query_segment(points, tip_prev, tip)

    # -- checks ----------------------------------------------------------------
    def check(self, points) -> None:
        """Raise AssertionError unless the tree is consistent with ``points``.

        Every live face's corners lie in its leaf box, every inner box is
        the union of its children's, parent/child links agree and every
        node is reachable from the root exactly once.
        """
        pts = _points(points)
        k = self._n_nodes
        seen = np.zeros(k, dtype=np.int64)
        stack = [self.root] if self.root >= 0 else []
        while stack:
            nd = stack.pop()
            seen[nd] += 1
            l, r = self._child[nd]
            if l >= 0:
                assert self._parent[l] == nd and self._parent[r] == nd
                assert np.array_equal(self._box_min[nd], np.minimum(self._box_min[l], self._box_min[r]))
                assert np.array_equal(self._box_max[nd], np.maximum(self._box_max[l], self._box_max[r]))
                stack += [l, r]
            else:
                f = self._leaf_face[nd]
                assert f >= 0 and self._face_leaf[f] == nd
        assert np.all(seen == 1), "unreachable or shared nodes"
        for f in np.flatnonzero(self.face_alive):
            leaf = self._face_leaf[f]
            c = pts[self._faces[f]]
            assert np.all(c >= self._box_min[leaf]) and np.all(c <= self._box_max[leaf])


def _points(points, check_finite: bool = True) -> np.ndarray:
    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (n, 3), got {p.shape}")
    if check_finite and not np.all(np.isfinite(p)):
        raise InputError("points contain NaN or infinite values")
    return p


def _faces(faces, n_points: int) -> np.ndarray:
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise MeshError(f"faces must have shape (f, 3), got {f.shape}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise MeshError(f"faces must be integers, got {f.dtype}")
    f = np.ascontiguousarray(f, dtype=np.int64)
    if f.size and (f.min() < 0 or f.max() >= n_points):
        raise MeshError(f"faces refer to nodes outside [0, {n_points}): {f.min()}..{f.max()}")
    return f


def _hit_buffers(cap: int):
    face = np.empty(cap, dtype=np.int64)
    kind = np.empty(cap, dtype=np.int64)
    param = np.empty((cap, 4), dtype=np.float64)
    return face, kind, param


def _vec3(v, name: str) -> np.ndarray:
    a = np.ascontiguousarray(v, dtype=np.float64).reshape(-1)
    # math.isfinite over three floats: np.isfinite's ufunc call cost more than a whole query
    if a.shape != (3,) or not all(map(math.isfinite, a.tolist())):
        raise InputError(f"{name} must be 3 finite numbers, got {v!r}")
    return a
