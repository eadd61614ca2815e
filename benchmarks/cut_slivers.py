"""Where the cut-made slivers come from: the worst cut-made tetrahedron of each stroke, by cause.

Cuts the paths of ``tests/test_cut_thousand_paths.py`` (every kind, tremor
0-1 mm, three meshes) and, at the end of each stroke (before the rebase),
takes the stroke's own cut-made tetrahedron with the smallest dihedral
angle and names what made it (the test checks every cut-made tetrahedron
of the model after the rebase and the look at them it opens, where the
blade left: ``benchmarks/cut_fresh_draw.py --seed 7`` gives its figures):

* the case of its original tetrahedron (``corner``, ``quad``, ``partial``,
  ``general``) and whether the tip was inside it (``tip``);
* its nodes' kinds: ``V`` an original vertex, ``E`` an edge node (``E*``:
  the crossing lay within ``EDGE_SNAP`` of a vertex and was clamped),
  ``F`` a face node, ``T`` a tip/centre node;
* ``clamped``: some cut edge of its original tetrahedron was clamped.

Prints the distribution of the worst cut-made angle per path (min, p1,
p10, median) and a histogram of the causes of the strokes below 5 degrees.

    python benchmarks/cut_slivers.py [--every 3] [--json] [--snap] [--no-smoothing]
"""

import argparse
import collections
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))

#: Strokes whose worst cut-made angle is below this are counted by cause.
SLIVER_DEG = 5.0


def _node_kinds(cm):
    """(n_points,) <U2 kind of every node: V, E, E* (clamped edge node), F, T."""
    raw = cm.__dict__.setdefault("raw_edge_t", {})
    kind = np.full(cm.n_points, "V", dtype="<U2")
    cut = np.flatnonzero(np.isfinite(cm.edge_t))
    for e in cut.tolist():
        s = raw.get(e, cm.edge_t[e])
        k = "E*" if min(s, 1 - s) < 0.25 - 1e-12 else "E"
        kind[cm.edge_node[e][cm.edge_node[e] >= 0]] = k
    kind[cm.face_node[cm.face_node >= 0]] = "F"
    kind[cm.tet_T[cm.tet_T >= 0]] = "T"
    return kind


def worst_of_stroke(cm, tip_tets):
    """(angle deg, cause str) of the worst tet made in this stroke, or None."""
    from cutkit.cutting.subdivision import CLASSIFY_TABLE
    from cutkit.mesh.quality import min_dihedral_angles

    ids = [t for v in cm.subtets.values() for t in v if cm._alive[t]]
    if not ids:
        return None
    ids = np.array(ids, np.int64)
    ang = min_dihedral_angles(cm._x, cm._tets[ids])
    w = int(np.argmin(ang))
    t = ids[w]
    o = int(cm._tet_orig[t])
    kind = _node_kinds(cm)
    nodes = "".join(sorted(kind[cm._tets[t]].tolist()))
    case = CLASSIFY_TABLE[cm.tet_mask(o)][0]
    raw = cm.raw_edge_t
    clamped = any(min(raw.get(e, 0.5), 1 - raw.get(e, 0.5)) < 0.25 - 1e-12
                  for e in cm.tet_edges[o].tolist() if np.isfinite(cm.edge_t[e]))
    cause = f"{case}{' tip' if o in tip_tets else ''} {nodes}{' clamped' if clamped else ''}"
    return float(ang[w]), cause


def run(every, snap, smooth=True):
    from test_cut_thousand_paths import ALL_KINDS, MESHES, PATHS_PER_MESH, TREMORS
    from _cut_paths import make_path
    from cutkit.cutting import CutMesh, cut_step
    from cutkit.cutting import cutmesh as CM
    from cutkit.cutting.step import blade_in_tissue, finish_stroke, rebase_if_left

    orig_cut = CM.CutMesh._cut_edge

    def recording_cut(self, e, s):  # keep the crossing before the clamp
        self.__dict__.setdefault("raw_edge_t", {})[int(e)] = float(s)
        return orig_cut(self, e, s)

    CM.CutMesh._cut_edge = recording_cut
    per_path, causes, outcomes = [], collections.Counter(), collections.Counter()
    for name in sorted(MESHES):
        p, t = MESHES[name]
        L = p.max(axis=0)
        for i in range(0, PATHS_PER_MESH, every):
            kind, tremor = ALL_KINDS[i % len(ALL_KINDS)], TREMORS[(i // len(ALL_KINDS)) % len(TREMORS)]
            poses = make_path(kind, np.random.default_rng(1000 * i + 7), L, tremor)
            kw = {"snap_vertices": True} if snap else {}
            kw["smooth_vertices"] = smooth
            cm = CutMesh(p, t, blade_length=2.5 if i % 2 else 10.0, **kw)
            cm.raw_edge_t, tips, worst = {}, set(), []

            def end():  # the stroke ends (as `cutkit cut`: what the blade held looked at once more)
                finish_stroke(cm)
                r = worst_of_stroke(cm, tips)
                if r is not None:
                    worst.append(r)
                cm.raw_edge_t = {}
                tips.clear()

            for pose in poses:
                if pose is None:
                    end()
                    cm.rebase()
                    continue
                res = cut_step(cm, *pose)
                if res.tip_tet >= 0:
                    tips.add(res.tip_tet)
                if not blade_in_tissue(cm) and cm.prev_pose is not None:
                    end()
                    rebase_if_left(cm)
            end()
            outcomes.update(cm.snap_counts)
            if worst:
                a, c = min(worst)
                per_path.append(a)
                for a, c in worst:
                    if a < SLIVER_DEG:
                        causes[c] += 1
    CM.CutMesh._cut_edge = orig_cut
    w = np.array(per_path)
    return {"paths": int(w.size), "worst_angle_min_deg": float(w.min()),
            "worst_angle_p1_deg": float(np.percentile(w, 1)), "worst_angle_p10_deg": float(np.percentile(w, 10)),
            "worst_angle_median_deg": float(np.median(w)), "paths_below_5_deg": int((w < 5).sum()),
            "paths_below_1_deg": int((w < 1).sum()),
            "strokes_below_5_deg_by_cause": dict(causes.most_common()),
            "crossings_near_a_vertex_by_snap_outcome": dict(outcomes.most_common())}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--every", type=int, default=1, help="take every k-th path of each mesh")
    ap.add_argument("--snap", action="store_true", help="cut with snap_vertices=True")
    ap.add_argument("--no-smoothing", action="store_true", help="cut with smooth_vertices=False")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    res = run(args.every, args.snap, not args.no_smoothing)
    print(json.dumps(res, indent=2) if args.json else res)


if __name__ == "__main__":
    main()
