"""Quality of the cuts over random blade paths: worst angles, lost edges, tets per cut tet.

For each mesh (jittered block, Delaunay ball) and path kind (see
``tests/_cut_paths.py``), random paths are cut and measured on the mesh as
written (``to_model``):

* the smallest dihedral angle of the tetrahedra the cut made (per path; the
  distribution over paths is reported);
* lost edges: original edges the swept surface crossed strictly inside
  (parameter in [1e-6, 1 - 1e-6]) that are not cut, as a fraction of the
  crossed ones, and by reason (a coincident copy along an earlier stroke's
  cut was cut elsewhere; deferred, see docs/cutting.md; other).  A stroke ends where the
  blade is lifted or has left the tissue, as in ``cutkit cut``, so a stroke's
  losses are counted on its own original edges (a second stroke crossing
  the first cuts the first's sub-tetrahedra);
* new tetrahedra per cut tetrahedron, and the share of cut tetrahedra
  with a forked face (three cut edges: the ``general`` case);
* crumbs: pieces of less than ``CRUMB`` of the mesh's volume at the end
  of a path (a folded sweep or a crossing can cut a sliver of tissue loose).

    python benchmarks/cut_quality.py [--json] [--paths 20]
"""

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))

KINDS = ("straight", "curved", "reversal", "reentry", "crossing", "vertex", "face", "guillotine", "press")
TREMORS = (0.0, 0.1, 0.3, 1.0)
#: A piece below this fraction of the mesh's volume is a crumb.
CRUMB = 1e-3


def _piece_volumes(points, tets):
    """(k,) float64 volume of each face-connected piece of ``tets`` (m, 4) int64 over ``points`` (n, 3)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from cutkit.mesh.quality import signed_volumes
    from cutkit.mesh.topology import tet_neighbors

    nb = tet_neighbors(tets)
    r, c = np.nonzero(nb >= 0)
    k, lab = connected_components(coo_matrix((np.ones(r.size), (r, nb[r, c])), shape=(len(tets),) * 2),
                                  directed=False)
    return np.bincount(lab, weights=signed_volumes(points, tets), minlength=k)


def _stroke_losses(cm, crossed):
    """Crossed edges of the stroke left uncut, by reason: (refused: a coincident copy cut elsewhere,
    deferred, other); see ``tests/_cut_paths.uncut_reason``."""
    from _cut_paths import uncut_reason

    why = [uncut_reason(cm, e) for e in crossed - set(np.flatnonzero(np.isfinite(cm.edge_t)).tolist())]
    return why.count("refused"), why.count("deferred"), why.count(None)


def measure(p, t, poses, blade_length=10.0):
    """Cut along ``poses``, as ``cutkit cut`` does: a stroke ends (the mesh is rebased) at each ``None``
    (the blade lifted) and wherever the blade has left the tissue after cutting.

    Returns (worst cut-made angle, its ratio to the model tet's, losses by reason (3,), crossed
    edges, cut tets, new tets, general tets, crumbs, crumbs' volume fraction); losses and crossings
    are counted per stroke on its own original edges.
    """
    from _cut_paths import crossed_edges
    from cutkit.cutting import CutMesh, cut_step, to_model
    from cutkit.cutting.step import blade_in_tissue, finish_stroke, rebase_if_left
    from cutkit.cutting.subdivision import CLASSIFY_TABLE
    from cutkit.mesh.quality import min_dihedral_angles, signed_volumes

    cm = CutMesh(p, t, blade_length=blade_length)
    crossed, lost, n_crossed, cut, new, general = set(), np.zeros(3, np.int64), 0, 0, 0, 0

    def end_stroke():
        nonlocal crossed, n_crossed, cut, new, general
        finish_stroke(cm)  # as `cutkit cut`: what the blade held looked at once more
        lost[:] += _stroke_losses(cm, crossed)
        n_crossed += len(crossed)
        cut, new = cut + len(cm.subtets), new + sum(len(v) for v in cm.subtets.values())
        general += sum(CLASSIFY_TABLE[cm.tet_mask(o)][0] == "general" for o in cm.subtets)
        crossed = set()

    for pose in poses:
        if pose is None:
            end_stroke()
            cm.rebase()
            continue
        prev = cm.prev_pose
        cut_step(cm, *pose)
        if prev is not None:
            (P1, Q1), (P0, Q0) = cm.prev_pose, prev
            crossed |= crossed_edges(cm.points[:cm.n_orig_points], cm.edges, [(P0, Q0, Q1), (P0, Q1, P1)])
        if not blade_in_tissue(cm):
            end_stroke()
            rebase_if_left(cm)
    end_stroke()
    m = to_model(cm)
    is_new = m.cell_data["new_tet"] == 1
    worst = rel = None
    if is_new.any():
        ang = min_dihedral_angles(m.points, m.tets[is_new])
        orig = min_dihedral_angles(p, t[cm.model_tet[cm.tet_origin[is_new]]])
        worst, rel = float(ang.min()), float((ang / orig).min())
    vol = _piece_volumes(m.points, m.tets)
    v0 = float(signed_volumes(p, t).sum())
    crumbs = vol < CRUMB * v0
    return worst, rel, lost, n_crossed, cut, new, general, int(crumbs.sum()), float(vol[crumbs].sum() / v0)


def run(n_paths):
    from _cut_paths import delaunay_ball, jittered_block, make_path
    from cutkit.mesh.generate import box_mesh
    from cutkit.cutting import CutMesh, cut_step
    from cutkit.mesh.quality import min_dihedral_angles

    meshes = {"jittered block": jittered_block((5, 3, 3), 0.2, 0), "delaunay ball": delaunay_ball()}
    out = {}
    for name, (p, t) in meshes.items():
        L = p.max(axis=0)
        out[f"{name}: original mesh"] = {"tets": int(len(t)),
                                         "worst_angle_deg": float(min_dihedral_angles(p, t).min())}
        for tremor in TREMORS:
            worst, rels, lost, crossed, cut, new, by_kind = [], [], np.zeros(3, np.int64), 0, 0, 0, {}
            angle_by_kind, general, crumbs, crumb_vol, crumb_paths = {}, 0, 0, 0.0, 0
            for kind in KINDS:
                kl = kc = 0
                kw = []
                for seed in range(n_paths):
                    w, r, lo, cr, c, nw, g, nc, vc = measure(p, t, make_path(kind, np.random.default_rng(seed), L,
                                                                            tremor))
                    general, crumbs, crumb_paths = general + g, crumbs + nc, crumb_paths + (nc > 0)
                    crumb_vol = max(crumb_vol, vc)
                    if w is not None:
                        worst.append(w)
                        rels.append(r)
                        kw.append(w)
                    lost, crossed, cut, new = lost + lo, crossed + cr, cut + c, new + nw
                    kl, kc = kl + int(lo.sum()), kc + cr
                by_kind[kind] = kl / max(kc, 1)
                angle_by_kind[kind] = [float(np.min(kw)), float(np.median(kw))] if kw else None
            w = np.array(worst)
            out[f"{name}, tremor {tremor} mm"] = {
                "paths": len(KINDS) * n_paths, "worst_angle_min_deg": float(w.min()),
                "worst_angle_p10_deg": float(np.percentile(w, 10)), "worst_angle_median_deg": float(np.median(w)),
                "paths_below_5_deg": int((w < 5).sum()), "worst_angle_min_median_by_kind_deg": angle_by_kind,
                "worst_angle_over_original_tet_min": float(np.min(rels)),
                "worst_angle_over_original_tet_median": float(np.median(rels)),
                "lost_edge_fraction": int(lost.sum()) / max(crossed, 1), "lost_edge_fraction_by_kind": by_kind,
                "lost_edges_by_reason": {"copy_cut_elsewhere": int(lost[0]), "deferred": int(lost[1]),
                                         "other": int(lost[2])},
                "new_tets_per_cut_tet": new / max(cut, 1), "general_tet_fraction": general / max(cut, 1),
                "paths_with_crumbs": crumb_paths, "crumbs": crumbs,
                "crumb_volume_fraction_max_per_path": crumb_vol}
    # a long steady incision
    p, t = box_mesh((20, 4, 4))
    cm = CutMesh(p, t, blade_length=10.0)
    for x in np.linspace(-0.5, 20.5, 80):
        cut_step(cm, [x, 1.37, -0.5 + 0.3 * np.sin(x)], [0.1, 0.05, -1.0])
    out["long incision (20 x 4 x 4 bar)"] = {
        "new_tets_per_cut_tet": sum(len(v) for v in cm.subtets.values()) / len(cm.subtets)}
    # ... and a hidden one: the tip stays inside, the tets along its path stay partly cut
    cm = CutMesh(p, t, blade_length=10.0)
    for x in np.linspace(-0.5, 18.5, 80):
        cut_step(cm, [x, 1.37, 1.9 + 0.3 * np.sin(x)], [0.1, 0.05, 1.0])
    out["long hidden incision (20 x 4 x 4 bar, tip inside)"] = {
        "new_tets_per_cut_tet": sum(len(v) for v in cm.subtets.values()) / len(cm.subtets)}
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--paths", type=int, default=20, help="paths per kind and tremor")
    args = ap.parse_args()
    res = run(args.paths)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        for k, r in res.items():
            print(k, ", ".join(f"{a} {b:.3g}" if not isinstance(b, dict) else
                               f"{a} " + " ".join(f"{c}:{d:.3g}" for c, d in b.items()) for a, b in r.items()))


if __name__ == "__main__":
    main()
