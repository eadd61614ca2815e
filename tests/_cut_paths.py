"""Blade paths and meshes for the cutting property tests (plain NumPy).

A path is a list of poses (tip (3,), a (3,) unit, handle to tip) and
``None`` entries where the blade is lifted out (the sweep restarts).
Meshes span [0, L] along each axis with cells about 1 mm wide, so tremor
amplitudes in mm are fractions of an edge.
"""

import numpy as np

from cutkit.cutting.step import finish_stroke
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.quality import signed_volumes

#: An edge counts as crossed strictly inside when the swept surface meets it
#: at a parameter in [ORACLE_EPS, 1 - ORACLE_EPS] (not at or next to a vertex).
ORACLE_EPS = 1e-6

KINDS = ("straight", "curved", "tremor", "reversal", "reentry", "crossing", "vertex", "edge", "face",
         "guillotine", "press")
#: More kinds: entering through a side face below the top, drawn forward, back and forward again
#: along its own cut, a through cut that separates a piece, and three strokes at random angles.
MORE_KINDS = ("side", "retrace", "separate", "strokes")


def jittered_block(shape=(5, 3, 3), jitter=0.2, seed=0):
    """Kuhn-split block with interior nodes moved (no exactly planar contacts inside)."""
    p, t = box_mesh(shape)
    rng = np.random.default_rng(seed)
    inner = np.all((p > 0) & (p < np.array(shape)), axis=1)
    return p + np.where(inner[:, None], rng.uniform(-jitter, jitter, p.shape), 0.0), t


def delaunay_ball(n=260, radius=3.0, seed=1):
    """Delaunay tetrahedralisation of random points in a ball (as an imported TetGen/gmsh mesh would be)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = radius * np.concatenate([np.ones(n // 3), rng.uniform(0, 1, n - n // 3) ** (1 / 3)])
    p = d * r[:, None] + radius
    t = Delaunay(p).simplices.astype(np.int64)
    v = signed_volumes(p, t)
    t[v < 0] = t[v < 0][:, [0, 2, 1, 3]]
    keep = np.abs(v) > 1e-6 * radius ** 3
    used = np.unique(t[keep])
    remap = -np.ones(n, np.int64)
    remap[used] = np.arange(used.size)
    return p[used], remap[t[keep]]


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def make_path(kind, rng, L, tremor=0.0):
    """Poses of one blade path of ``kind`` over a mesh spanning [0, L] (3,)."""
    L = np.asarray(L, float)
    n = int(rng.integers(4, 16))
    y0, z0 = rng.uniform(0.3, L[1] - 0.3), rng.uniform(0.2 * L[2], L[2] + 0.5)
    a = _unit([rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), 1.0])
    xs = np.linspace(-0.5, L[0] + 0.5, n)

    def line(xs, y, z, a, wobble=0.0):
        return [(np.array([x, y + wobble * np.sin(1.3 * x), z]), a) for x in xs]

    if kind == "straight":
        poses = line(xs, y0, z0, a)
    elif kind == "curved":
        poses = line(xs, y0, z0, a, wobble=rng.uniform(0.2, 0.8))
    elif kind == "tremor":
        poses = line(xs, y0, z0, a)
    elif kind == "reversal":
        xm = rng.uniform(0.3, 0.8) * L[0]
        poses = line(np.concatenate([np.linspace(-0.5, xm, n), np.linspace(xm, 0.2 * xm, n // 2)]), y0, z0, a)
    elif kind == "reentry":
        out = np.array([0.0, 0.0, L[2] + 3.0])
        first = line(xs[: n // 2], y0, z0, a)
        poses = first + [(first[-1][0] + out, a)] + line(xs[n // 2:], y0, z0, a)
    elif kind == "crossing":
        ys = np.linspace(-0.5, L[1] + 0.5, n)
        x0 = rng.uniform(0.3, L[0] - 0.3)
        poses = line(xs, y0, z0, a) + [None] + [(np.array([x0, y, z0]), a) for y in ys]
    elif kind == "vertex":  # the tip's path runs through grid nodes
        y, z = float(rng.integers(1, int(L[1]))), float(rng.integers(1, int(L[2])))
        poses = line(np.arange(-1.0, L[0] + 1.5), y, z, _unit([0, 0, 1.0]))
    elif kind == "edge":  # the blade lies along grid edges, moving along y
        x = float(rng.integers(1, int(L[0])))
        ys = np.linspace(-0.5, L[1] + 0.5, n)
        poses = [(np.array([x, y, -0.5]), _unit([0, 0, -1.0])) for y in ys]
    elif kind == "face":  # the blade in a grid plane
        y = float(rng.integers(1, int(L[1])))
        poses = line(xs, y, -0.5, _unit([0, 0, -1.0]))
    elif kind == "press":  # pushed in along its own axis (flat swept quads), drawn sideways, pulled out
        a = _unit([rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), -1.0])
        start = np.array([rng.uniform(0.5, 0.4 * L[0]), y0, L[2] + 1.0])
        depth = rng.uniform(0.5, L[2] + 0.5)
        down = [(start + s * a, a) for s in np.linspace(0.0, depth + 1.0, n // 2 + 2)]
        tip = down[-1][0]
        side = [(tip + [dx, 0.0, 0.0], a) for dx in np.linspace(0.0, rng.uniform(0.5, 0.5 * L[0]), n // 2 + 2)[1:]]
        tip = side[-1][0]
        poses = down + side + [(tip - s * a, a) for s in np.linspace(0.0, depth + 1.0, 4)[1:]]
    elif kind == "side":  # the tip below the top: the blade enters edge-first through the side face x = 0
        poses = line(xs, y0, rng.uniform(0.3, 0.7) * L[2], a)
    elif kind == "retrace":  # forward, back over its own cut, forward again
        xm = rng.uniform(0.4, 0.9) * L[0]
        go = np.linspace(-0.5, xm, n)
        poses = line(np.concatenate([go, go[::-1][1:], go[1:]]), y0, z0, a)
    elif kind == "separate":  # the tip below the mesh: cuts it in two
        poses = line(xs, y0, -0.5, _unit([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), -1.0]))
    elif kind == "strokes":  # three straight strokes at random angles, lifted between
        poses = []
        for k in range(3):
            ang, c = rng.uniform(0.0, np.pi), rng.uniform(0.2, 0.8, 3) * L
            d = np.array([np.cos(ang), np.sin(ang), 0.0])
            reach = np.linalg.norm(L[:2]) / 2 + 1.0
            poses += [None] if k else []
            poses += [(c + s * d, a) for s in np.linspace(-reach, reach, int(rng.integers(4, 10)))]
    else:  # guillotine: one step from above to below, the blade longer than the mesh
        x = rng.uniform(0.3, L[0] - 0.3)
        a = _unit([0, -1.0, rng.uniform(-0.3, 0.3)])
        poses = [(np.array([x, -1.0, L[2] + 2.0]), a), (np.array([x, -1.0, -2.0]), a)]
    if tremor > 0:
        poses = [None if q is None else (q[0] + rng.normal(0, tremor / 3, 3), q[1]) for q in poses]
    return poses


def crossing_strokes(rng, L, through=True, tremor=0.0):
    """Two straight strokes crossing near the middle of a mesh spanning [0, L] (3,), ``None`` between.

    Each stroke runs along a random direction in the x-y plane, its tip over
    one point near the middle (the second at 45-135 degrees to the first), the
    blade tilted at random; ``through``: the tip below the mesh (each stroke
    cuts it in two), else at a random depth.
    """
    L = np.asarray(L, float)
    phi = rng.uniform(0.0, np.pi)
    c = L / 2 + np.array([*rng.uniform(-0.15, 0.15, 2) * L[:2], 0.0])  # both strokes' tips pass over it
    poses = []
    for k, ang in enumerate((phi, phi + rng.uniform(0.25 * np.pi, 0.75 * np.pi))):
        d = np.array([np.cos(ang), np.sin(ang), 0.0])
        c[2] = -0.5 if through else rng.uniform(0.3, 0.8) * L[2]
        a = _unit([*rng.uniform(-0.2, 0.2, 2), -1.0])
        reach = np.linalg.norm(L) + 1.0  # past the mesh at every height of the tilted blade
        n = int(rng.integers(6, 14))
        poses += [None] if k else []
        poses += [(c + s * d + rng.normal(0, tremor / 3, 3), a) for s in np.linspace(-reach, reach, n)]
    return poses


def lift(cm):
    """The blade leaves the tissue: the next pose starts a new sweep, which may cross this one (rebase),
    and every cut-made tet is looked at once more in the fresh cut state (as ``rebase_if_left``)."""
    cm.rebase()
    finish_stroke(cm)


def uncut_reason(cm, e):
    """Why original edge ``e`` of the current stroke is not cut: "followed", "refused", "deferred" or None.

    An edge and its coincident copies along an earlier stroke's cut
    (``edge_twins``) are cut together or not at all (docs/cutting.md):
    followed when the blade crossed it inside an earlier stroke's wound and
    ran along its walls (``cutkit.cutting.following``; checked by
    :func:`check_followed` at its step), refused when one of
    the copies is cut already (met first, at another point, from the other
    side), deferred when the cut is waiting (two opposite cut edges alone in
    a tet).
    """
    group = [int(e)] + list(cm.edge_twins.get(int(e), ()))
    if any(g in vars(cm).get("followed_checked", ()) for g in group):
        return "followed"
    if any(np.isfinite(cm.edge_t[g]) for g in group):
        return "refused"
    if any(g in cm.pending_edges for g in group):
        return "deferred"
    return None


#: How far past ``FOLLOW_BAND`` of the mesh size a followed edge's crossing may lie from an earlier cut's
#: wall (rounding of the test's own crossing and distances).
FOLLOW_SLACK = 1e-6


def point_triangle_distances(p, a, b, c):
    """(k,) distance from point p (3,) to the triangles a, b, c (k, 3) each: the least of the distances to
    the plane's foot (where it lies inside) and to the three sides, in NumPy (the slow reference)."""
    n = np.cross(b - a, c - a)
    nn = np.maximum((n * n).sum(1), 1e-300)
    foot = p - (((p - a) * n).sum(1) / nn)[:, None] * n
    inside = (n * n).sum(1) > 0.0  # a degenerate triangle is its sides
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(v - u, foot - u) * n).sum(1) >= 0.0
    d = np.where(inside, np.linalg.norm(p - foot, axis=1), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        t = np.clip(((p - u) * e).sum(1) / np.maximum((e * e).sum(1), 1e-300), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(p - (u + t[:, None] * e), axis=1))
    return d


def model_sizes(cm):
    """(m0,) the model's mesh size at each original tet: the edge of the regular tetrahedron of its
    model tet's volume (the live pieces' rest volumes summed)."""
    X = cm.rest_points
    t = cm.orig_tets
    vol = np.abs(np.linalg.det(X[t[:, 1:]] - X[t[:, :1]])) / 6.0
    model = np.bincount(cm.model_tet, weights=vol, minlength=cm.n_model_tets)
    return np.cbrt(6.0 * np.sqrt(2.0) * model[cm.model_tet])


def followed_near_wound(cm, e, swept, x, sizes=None):
    """Whether original edge ``e`` is crossed by one of a step's ``swept`` triangles within
    ``FOLLOW_BAND`` of the model's mesh size there (:func:`model_sizes`, the largest of the tets
    around the edge) of an earlier stroke's wall (``cm.cut_faces_before``), with the
    nodes at ``x`` (n, 3), where the step began: the test's own crossings and distances.  None where
    the test finds no crossing (an edge in the blade's plane: the cut's symbolic perturbation crosses
    it, the test's crossing does not, and it need not be cut)."""
    from _twins_cut import segment_triangle_many

    from cutkit.cutting.following import FOLLOW_BAND

    i, j = cm.edges[e]
    sizes = model_sizes(cm) if sizes is None else sizes
    length = float(sizes[np.flatnonzero((cm.tet_edges == e).any(axis=1))].max())  # the largest around it
    walls = x[np.array(sorted(cm.cut_faces_before))] if cm.cut_faces_before else None
    crossed = False
    for tri in swept:
        s = segment_triangle_many(x[i][None], x[j][None], *[np.asarray(q, float) for q in tri])[0]
        if s < 0.0:
            continue
        crossed = True
        d = point_triangle_distances(x[i] + s * (x[j] - x[i]), walls[:, 0], walls[:, 1], walls[:, 2]).min() \
            if walls is not None else np.inf
        if d <= (FOLLOW_BAND + FOLLOW_SLACK) * length:
            return True
    return False if crossed else None


def check_followed(cm, x, swept, before):
    """After a step (nodes at ``x`` (n, 3) where it began, its ``swept`` triangles, ``before`` the set
    of edges followed before it): each edge the cut followed first in this step that the test finds
    crossed in the wound's band (:func:`followed_near_wound`) joins ``cm.followed_checked`` (a set the
    test keeps on the cut state; a rebase drops both); returns those the test finds crossed outside it."""
    checked = vars(cm).setdefault("followed_checked", set())
    bad = []
    new = sorted(cm.followed_edges - before)
    sizes = model_sizes(cm) if new else None
    for e in new:
        near = followed_near_wound(cm, e, swept, x, sizes)
        if near:
            checked.add(e)
        elif near is not None:
            bad.append(e)
    return bad


def crossed_edges(p, edges, swept):
    """Original edges (set of ids into ``edges`` (m, 2)) over positions ``p`` (n, 3) met strictly inside by
    one of the ``swept`` triangles (each three (3,) points): the slow reference."""
    from _twins_cut import segment_triangle_many

    out = set()
    a, b = p[edges[:, 0]], p[edges[:, 1]]
    lo_e, hi_e = np.minimum(a, b), np.maximum(a, b)
    for tri in swept:
        tri = [np.asarray(q, float) for q in tri]
        lo, hi = np.min(tri, axis=0), np.max(tri, axis=0)
        near = np.flatnonzero(np.all((lo_e <= hi) & (hi_e >= lo), axis=1))
        s = segment_triangle_many(a[near], b[near], *tri)
        out.update(near[(ORACLE_EPS <= s) & (s <= 1 - ORACLE_EPS)].tolist())
    return out
