"""Slow, obviously correct twins of the isovolume kernels (pure Python, per tet).

Nodes are named, not numbered: ``("v", g)`` a grid vertex, ``("e", lo, hi)``
the crossing on grid edge (lo, hi), ``("c", cube, t)`` the centre of Kuhn
tet t of a cube.  Clipped polytopes are split by a generic *pulling*
triangulation from their node of smallest key (every face not containing
that node, triangulated by the quad rule, is coned to it) - for prisms and
pyramids this is the rule the kernels hard-code, reached another way.
"""

from __future__ import annotations

from itertools import permutations

import numpy as np

N_DIRS = 7
#: The centre of a coned tet is moved when its cone has a smaller dihedral angle (degrees).
CENTRE_MIN_DIHEDRAL_DEG = 15.0


def min_dihedral_twin(p):
    """Smallest dihedral angle (degrees) of a tet given as four (3,) points, from face normals."""
    p = [np.asarray(x, float) for x in p]
    angles = []
    for i in range(4):
        for j in range(i + 1, 4):
            # faces i and j are opposite vertices i and j; they share edge (k, l)
            k, l = [x for x in range(4) if x not in (i, j)]
            e = p[l] - p[k]
            # components perpendicular to the shared edge of the vectors to the opposite vertices
            a = p[j] - p[k] - np.dot(p[j] - p[k], e) / np.dot(e, e) * e
            b = p[i] - p[k] - np.dot(p[i] - p[k], e) / np.dot(e, e) * e
            angles.append(np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))
    return min(angles)


def _kuhn_tets():
    out = []
    for perm in permutations(range(3)):
        c = [0, 0, 0]
        path = [tuple(c)]
        for axis in perm:
            c = list(c)
            c[axis] = 1
            path.append(tuple(c))
        out.append(path)
    return out


def _neighbour_offsets():
    offs = []
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                if dx or dy or dz:
                    offs.append((dx, dy, dz))
    return offs


def classify_twin(f, level, snap):
    """Per vertex: ON flag by the snapping rule, and 'inside' (f > level or ON)."""
    nx, ny, nz = f.shape
    on = np.zeros(f.shape, bool)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                fu = f[i, j, k]
                if fu == level:
                    on[i, j, k] = True
                    continue
                for d in _neighbour_offsets():
                    for s in (1, -1):
                        a, b, c = i + s * d[0], j + s * d[1], k + s * d[2]
                        if not (0 <= a < nx and 0 <= b < ny and 0 <= c < nz):
                            continue
                        fv = f[a, b, c]
                        if (fu - level) * (fv - level) < 0 and (level - fu) / (fv - fu) < snap:
                            on[i, j, k] = True
    return on


class _Grid:
    def __init__(self, shape, lab, on, f, level, scalar):
        self.shape = shape
        self.lab = lab
        self.on = on
        self.f = f
        self.level = level
        self.scalar = scalar
        self.n = shape[0] * shape[1] * shape[2]
        self._positions = {}  # node -> its position: a centre's search reads its cone's nodes many times

    def gid(self, p):
        return (p[0] * self.shape[1] + p[1]) * self.shape[2] + p[2]

    def key(self, node):
        if node[0] == "v":
            return self.gid(node[1])
        lo, hi = node[1], node[2]
        d = tuple(h - l for h, l in zip(hi, lo))
        return self.n + N_DIRS * self.gid(lo) + (4 * d[0] + 2 * d[1] + d[2] - 1)

    def pos(self, node):
        if node not in self._positions:
            self._positions[node] = self._place(node)
        return self._positions[node].copy()

    def _place(self, node):
        if node[0] == "v":
            return np.array(node[1], float)
        if node[0] == "c":
            return self.centre(node)
        lo, hi = np.array(node[1], float), np.array(node[2], float)
        if self.scalar:
            flo, fhi = self.f[node[1]], self.f[node[2]]
            s = (self.level - flo) / (fhi - flo)
        else:
            s = self.label_crossing(node[1], node[2])
        return lo + s * (hi - lo)

    def centre(self, node):
        """Centre of a coned tet: the crossing mean, moved off a sliver (docs/isovolume.md section 4)."""
        cube, t, corners = node[1], node[2], node[3]
        has_bg = any(self.lab[c] == 0 for c in corners)

        def crossing_mean(background_only):
            pts = []
            for a in range(4):
                for b in range(a + 1, 4):
                    la, lb = self.lab[corners[a]], self.lab[corners[b]]
                    if la != lb and (not background_only or la == 0 or lb == 0):
                        pts.append(self.pos(_crossing(corners[a], corners[b])))
            return np.mean(pts, axis=0)

        cone = [tet for tet, _ in _cone_twin(self, cube, t, corners)]

        def smallest_angle(c):
            return min(min_dihedral_twin([c if n == node else self.pos(n) for n in tet]) for tet in cone)

        c0 = crossing_mean(has_bg)
        if has_bg or smallest_angle(c0) >= CENTRE_MIN_DIHEDRAL_DEG:
            return c0
        best, best_angle = c0, smallest_angle(c0)
        centroid = np.mean(np.array(corners, float), axis=0)
        for f in (0.25, 0.5, 0.75, 1.0):
            c = c0 + f * (centroid - c0)
            a = smallest_angle(c)
            if a > best_angle + 1e-6:
                best, best_angle = c, a
        return best

    def label_crossing(self, lo, hi):
        """Zero of the multilinear interpolant of h = [label a] - [label b] on the diagonal lo -> hi."""
        from scipy.optimize import brentq

        a, b = self.lab[lo], self.lab[hi]
        d = [h - l for h, l in zip(hi, lo)]
        corners = []
        for ox in range(d[0] + 1):
            for oy in range(d[1] + 1):
                for oz in range(d[2] + 1):
                    c = (lo[0] + ox, lo[1] + oy, lo[2] + oz)
                    h = 1.0 if self.lab[c] == a else (-1.0 if self.lab[c] == b else 0.0)
                    corners.append(((ox, oy, oz), h))

        def interp(s):
            total = 0.0
            for (ox, oy, oz), h in corners:
                w = 1.0
                for o, dd in zip((ox, oy, oz), d):
                    if dd:
                        w *= s if o else 1.0 - s
                total += w * h
            return total

        return brentq(interp, 0.0, 1.0, xtol=1e-15)


def _crossing(a, b):
    lo, hi = (a, b) if sum(a) < sum(b) else (b, a)
    return ("e", lo, hi)


def _face_polygon(grid, tri, inside):
    """Part of triangle ``tri`` (grid points) where ``inside`` holds, in cyclic order."""
    poly = []
    for idx in range(3):
        a, b = tri[idx], tri[(idx + 1) % 3]
        if inside(a):
            poly.append(("v", a))
        if _cut(grid, a, b, inside):
            poly.append(_crossing(a, b))
    return poly


def _cut(grid, a, b, inside):
    """Does edge (a, b) carry a crossing between the inside and the outside?"""
    if grid.on[a] or grid.on[b]:
        return False
    return inside(a) != inside(b)


def _triangulate(grid, poly):
    """Triangles of a planar convex polygon of 3 or 4 nodes (quad rule: smallest-key diagonal)."""
    if len(poly) == 3:
        return [tuple(poly)]
    assert len(poly) == 4, poly
    keys = [grid.key(n) for n in poly]
    m = int(np.argmin(keys))
    q = poly[m:] + poly[:m]
    return [(q[0], q[1], q[2]), (q[0], q[2], q[3])]


def _order_planar(grid, nodes):
    pts = np.array([grid.pos(n) for n in nodes])
    c = pts.mean(axis=0)
    normal = np.cross(pts[1] - pts[0], pts[2] - pts[0])
    u = pts[0] - c
    u /= np.linalg.norm(u)
    v = np.cross(normal / np.linalg.norm(normal), u)
    ang = [np.arctan2((p - c) @ v, (p - c) @ u) for p in pts]
    return [nodes[i] for i in np.argsort(ang)]


def _clip_tet_twin(grid, corners, inside):
    """Tets (node tuples) of the part of a tet where ``inside`` holds (ON corners included)."""
    ins = [c for c in corners if inside(c) and not grid.on[c]]
    outs = [c for c in corners if not inside(c) and not grid.on[c]]
    if not outs:  # every corner in or ON: {interpolant >= level} is the whole tet
        return [tuple(("v", c) for c in corners)]
    if not ins:
        return []
    side = lambda c: grid.on[c] or inside(c)  # noqa: E731
    faces = []
    for o in range(4):
        tri = [corners[(o + s) % 4] for s in (1, 2, 3)]
        poly = _face_polygon(grid, tri, side)
        if len(poly) >= 3:
            faces.append(poly)
    cut = [("v", c) for c in corners if grid.on[c]]
    cut += [_crossing(a, b) for a in ins for b in outs]
    if len(cut) >= 3:
        faces.append(_order_planar(grid, cut))
    nodes = {n for poly in faces for n in poly}
    apex = min(nodes, key=grid.key)
    tets = []
    for poly in faces:
        if apex in poly:
            continue
        for tri in _triangulate(grid, poly):
            tets.append((apex,) + tri)
    return tets


def _cone_twin(grid, cube, t, corners):
    """Tets of a tet with three or four labels: per-face label partition coned to the centre."""
    centre = ("c", cube, t, tuple(corners))
    out = []
    lab = {c: int(grid.lab[c]) for c in corners}
    for o in range(4):
        tri = [corners[(o + s) % 4] for s in (1, 2, 3)]
        labels_here = {lab[c] for c in tri}
        if len(labels_here) == 3:
            for idx in range(3):
                a, b, c = tri[idx], tri[(idx + 1) % 3], tri[(idx + 2) % 3]
                if lab[a]:
                    out.append(((centre, ("v", a), _crossing(a, b), _crossing(a, c)), lab[a]))
            tissue = [c for c in tri if lab[c] != 0]
            winner = min(tissue, key=lambda c: grid.gid(c))
            mid = (_crossing(tri[0], tri[1]), _crossing(tri[1], tri[2]), _crossing(tri[2], tri[0]))
            out.append(((centre,) + mid, lab[winner]))
            continue
        for x in labels_here:
            if x == 0:
                continue
            poly = _face_polygon(grid, tri, lambda c, x=x: lab[c] == x)
            for tri2 in _triangulate(grid, poly):
                out.append(((centre,) + tri2, x))
    return out


def isovolume_twin(data, level=0.5, snap=0.15, label=1):
    """Tets of the marching isovolume, by brute force.

    Parameters
    ----------
    data : (nx, ny, nz) float (scalar field, keep >= level) or int (label map).

    Returns
    -------
    tets : list of ((4,) tuple of (3,) float64 index-space positions, label)
        In no particular order or orientation.
    """
    scalar = data.dtype.kind == "f"
    if scalar:
        on = classify_twin(data, level, snap)
        lab = np.where((data > level) | on, label, 0)
    else:
        on = np.zeros(data.shape, bool)
        lab = data.astype(np.int64)
    grid = _Grid(data.shape, lab, on, data, level, scalar)
    nx, ny, nz = data.shape
    result = []
    for i in range(nx - 1):
        for j in range(ny - 1):
            for k in range(nz - 1):
                for t, path in enumerate(_kuhn_tets()):
                    corners = [(i + a, j + b, k + c) for a, b, c in path]
                    labels_here = sorted({int(lab[c]) for c in corners})
                    counts = sorted(int(np.sum([lab[c] == x for c in corners])) for x in labels_here)
                    if len(labels_here) == 1 or (len(labels_here) == 2 and (scalar or counts != [2, 2])):
                        for x in labels_here:
                            if x == 0:
                                continue
                            for tet in _clip_tet_twin(grid, corners, lambda c, x=x: lab[c] == x):
                                result.append((tet, x))
                    else:
                        result.extend(_cone_twin(grid, (i, j, k), t, corners))
    return [(tuple(grid.pos(n) for n in tet), x) for tet, x in result]


def clipped_volume_twin(data, level, snap):
    """Volume (index units) of {linear interpolant >= level} over all Kuhn tets, by convex hulls.

    Independent of any splitting rule: each tet's part is the convex hull of
    its inside/ON corners and its crossing points.
    """
    from scipy.spatial import ConvexHull

    on = classify_twin(data, level, snap)
    inside = (data > level) | on
    grid = _Grid(data.shape, inside.astype(int), on, data, level, True)
    nx, ny, nz = data.shape
    total = 0.0
    for i in range(nx - 1):
        for j in range(ny - 1):
            for k in range(nz - 1):
                for path in _kuhn_tets():
                    corners = [(i + a, j + b, k + c) for a, b, c in path]
                    if all(on[c] for c in corners):
                        total += 1.0 / 6.0
                        continue
                    pts = [grid.pos(("v", c)) for c in corners if inside[c]]
                    pts += [grid.pos(_crossing(a, b)) for a in corners for b in corners
                            if sum(a) < sum(b) and _cut(grid, a, b, lambda c: inside[c])]
                    if len(pts) >= 4:
                        try:
                            total += ConvexHull(np.array(pts)).volume
                        except Exception:  # flat: zero volume
                            pass
    return total
