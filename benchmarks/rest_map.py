"""How steadily the blade's rest pose follows a steady hand in ``simulate`` (the cut is made there).

The cut is made in the rest configuration: every geometry update carries
the blade there by the displacement of the tissue around it
(``cutkit.relax.rest_map``).  A rest pose that jumps from step to step
folds the swept surface, and the cut leaves edges uncut.  For each run this
records the blade's rest tip at every cut step and reports, over the steady
part (the hand moving along the incision, three steps trimmed at each end):

* ``sideways_wobble_mm``: rms second difference of the rest tip across the
  incision's direction (0 for a straight path);
* ``advance_min_mm``, ``advance_std_mm``: the rest tip's advance per step
  along the incision (negative: it stepped back), and
  ``advance_minus_hand_std_mm``: the spread of its difference to the hand's
  (the hand's own speed changes taken out);
* ``edges_left_uncut``, ``cut_tets``, ``opening_mm`` from the summary.

Runs: the shipped incision on a model (``--model``, e.g. the demo's
knee.h5), element model and springs; and the slab of
``tests/test_simulate_strokes.py`` cut by two steady crossing
through-strokes (its steady parts per stroke).

    python benchmarks/rest_map.py [--json] [--model knee.h5]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))


def _record(run):
    """Run ``run()`` (a simulate call) while recording (rest tip, proxy, stroke) at every cut step."""
    import cutkit.simulate.tasks as tasks

    rec = []
    cut = tasks.CutTask._cut

    def recording(self, blade_tip, axis, proxy):
        rec.append((np.array(blade_tip), np.array(proxy), self.cm.n_rebases, np.array(axis)))
        return cut(self, blade_tip, axis, proxy)

    tasks.CutTask._cut = recording
    try:
        summary = run()
    finally:
        tasks.CutTask._cut = cut
    return summary, rec


def _steadiness(rest, proxy, axis):
    """The figures above for one stroke: rest tips (k, 3), proxies (k, 3), blade axes (k, 3); None for a
    stroke of a few steps (a graze of the wound's lip on the way out)."""
    if len(rest) < 10:
        return None
    d = np.diff(proxy, axis=0)
    across = d - np.sum(d * axis[1:], axis=1)[:, None] * axis[1:]  # pressing in and lifting out go along the blade
    along = np.linalg.svd(across)[2][0]
    along *= np.sign(np.median(across @ along))
    step = np.linalg.norm(d, axis=1)
    moving = (d @ along > 0.9 * step) & (step > 0.0)  # drawn along the incision, not pressed or lifted
    steady = np.flatnonzero(moving)[3:-3]
    if steady.size < 5:
        return None
    r = rest[steady]
    advance = np.diff(r @ along)
    lag = advance - np.diff(proxy[steady] @ along)  # the rest tip's advance beyond the hand's
    across = r - np.outer(r @ along, along)
    wobble = np.diff(across, 2, axis=0)
    return {"steps": int(steady.size), "sideways_wobble_mm": float(np.sqrt((wobble ** 2).sum(axis=1).mean())),
            "advance_min_mm": float(advance.min()), "advance_median_mm": float(np.median(advance)),
            "advance_std_mm": float(advance.std()), "advance_minus_hand_std_mm": float(lag.std())}


def _figures(summary, rec):
    rest = np.array([q[0] for q in rec])
    proxy = np.array([q[1] for q in rec])
    stroke = np.array([q[2] for q in rec])
    axis = np.array([q[3] for q in rec])
    steady = [_steadiness(rest[stroke == k], proxy[stroke == k], axis[stroke == k]) for k in np.unique(stroke)]
    return {"strokes": [s for s in steady if s is not None],
            "edges_left_uncut": summary.get("edges_left_uncut"), "cut_tets": summary["cut_tets"],
            "opening_mm": summary["cut_opening_mm"]["final_mean"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--model", help="a model file cut along sample_volumes/incision.csv (e.g. the demo's knee.h5)")
    args = ap.parse_args()

    import test_simulate_strokes as strokes
    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model
    from cutkit.simulate import SimulateOptions, simulate

    out = {}
    for material in ("neohookean", "springs"):
        with tempfile.TemporaryDirectory() as d:
            def run():
                return strokes._run(Path(d), material)
            out[f"slab, two crossing strokes, {material}"] = _figures(*_record(run))
    if args.model:
        model = read_model(args.model)
        incision = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sample_volumes", "incision.csv")
        traj = read_trajectory(incision)
        for material in ("neohookean", "springs"):
            with tempfile.TemporaryDirectory() as d:
                def run():
                    return simulate(model, traj, Path(d), SimulateOptions(fps=10, frames=False, write_model=False,
                                                                          material_model=material))
                out[f"{Path(args.model).name}, shipped incision, {material}"] = _figures(*_record(run))
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for name, r in out.items():
            strokes_line = "; ".join(f"wobble {s['sideways_wobble_mm']:.3f} mm, advance min {s['advance_min_mm']:.3f} "
                                     f"mm, beyond the hand's std {s['advance_minus_hand_std_mm']:.3f} mm"
                                     for s in r["strokes"])
            print(f"{name}: {strokes_line}; {r['edges_left_uncut']} edges left uncut, {r['cut_tets']} tets cut, "
                  f"opening {r['opening_mm']:.2f} mm")


if __name__ == "__main__":
    main()
