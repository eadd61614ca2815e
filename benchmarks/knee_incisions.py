"""Five incisions through the demo knee that it does not ship: `simulate` with every check a user would make.

Straight incisions (``cutkit.cutting.trajectory.straight_incision``) on the
front, diagonally, on the side, deep at the back and a fast shallow one, in
the demo knee's coordinates (mm; ``cutkit demo`` writes the model).  Each is
simulated as ``cutkit simulate`` does (5 frames/s, no pictures) and read
back: relaxation steps not converged, crossed edges left uncut, tets
inverted in the deformed state, crumbs removed, NaN in ``forces.csv``, the
smallest J of any step, the written mesh through ``cutkit check``, and the
cut-made tetrahedra's smallest dihedral angle (rest configuration) with how
many lie below 5 degrees.

    python benchmarks/knee_incisions.py knee.h5 [--json] [--random N --seed S [--tilt DEG]]

About 1 min on two threads.  ``--random N`` simulates N straight incisions
drawn at random instead (:func:`random_incisions`): on the front, the back
or the side, 10-30 mm long in any direction along the skin, 2-12 mm deep,
cut in 0.6-1.5 s (about 10 s each); with ``--tilt DEG`` the blade leans
sideways (about the direction of the cut) by an angle drawn from -DEG to
DEG, the incisions otherwise the same.
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: name: (skin point where it starts, where it ends, inward normal, depth mm, cut time s)
INCISIONS = {
    "front longitudinal": ([40, 6, 50], [40, 6, 95], [0, 1, 0], 6.0, 1.5),
    "front diagonal": ([25, 6, 60], [55, 6, 95], [0, 1, 0], 8.0, 1.5),
    "side": ([4.5, 25, 60], [4.5, 55, 60], [1, 0, 0], 7.0, 1.5),
    "back deep": ([25, 74, 80], [55, 74, 80], [0, -1, 0], 12.0, 1.5),
    "front shallow fast": ([30, 6, 40], [50, 6, 40], [0, 1, 0], 2.0, 0.6),
}


def random_incisions(n: int, seed: int, tilt_deg: float = 0.0) -> dict:
    """``n`` incisions drawn from ``seed``, as :data:`INCISIONS` gives them; the blade leaning
    sideways by up to ``tilt_deg`` (drawn from a stream of its own: the incisions stay the same)."""
    rng, lean = np.random.default_rng(seed), np.random.default_rng(seed + 1000)
    out = {}
    for i in range(n):
        side = int(rng.integers(3))
        if side == 0:  # front, the skin near y = 6 mm
            a, inward = np.array([rng.uniform(25, 55), 6.0, rng.uniform(40, 95)]), [0, 1, 0]
        elif side == 1:  # back, near y = 74 mm
            a, inward = np.array([rng.uniform(25, 55), 74.0, rng.uniform(50, 95)]), [0, -1, 0]
        else:  # side, near x = 4.5 mm
            a, inward = np.array([4.5, rng.uniform(25, 55), rng.uniform(45, 90)]), [1, 0, 0]
        angle = rng.uniform(0.0, np.pi)
        along = [np.cos(angle), 0.0, np.sin(angle)] if side < 2 else [0.0, np.cos(angle), np.sin(angle)]
        b = a + rng.uniform(10, 30) * np.array(along)
        depth, cut_time = rng.uniform(2, 12), rng.uniform(0.6, 1.5)
        if tilt_deg:
            tilt = np.radians(lean.uniform(-tilt_deg, tilt_deg))
            inward = (np.cos(tilt) * np.array(inward, float) + np.sin(tilt) * np.cross(along, inward)).tolist()
        out[f"random {i}"] = (a.tolist(), b.tolist(), inward, depth, cut_time)
    return out


def one(model, start, end, inward, depth, cut_time) -> dict:
    from cutkit.cutting.trajectory import straight_incision
    from cutkit.io.model_h5 import read_model
    from cutkit.mesh.check import check_mesh
    from cutkit.mesh.quality import min_dihedral_angles
    from cutkit.simulate import SimulateOptions, simulate

    traj = straight_incision(np.array(start, float), np.array(end, float), np.array(inward, float), depth=depth,
                             press_time=0.3, cut_time=cut_time)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        s = simulate(model, traj, Path(d), SimulateOptions(fps=5, frames=False, write_model=True))
        nan_rows = sum("nan" in line.lower() for line in (Path(d) / "forces.csv").read_text().splitlines())
        m = read_model(Path(d) / "model.h5")
    made = m.tets[m.cell_data["new_tet"] == 1]
    angles = min_dihedral_angles(m.points, made) if len(made) else np.full(1, 180.0)
    rs = s["relax_steps"]
    return {"cut_tets": s["cut_tets"], "steps_not_converged": rs["not_converged"], "steps": rs["count"],
            "edges_left_uncut": s["edges_left_uncut"], "inverted_tets_deformed": s["inverted_tets_deformed"],
            "crumbs_removed": s["crumbs_removed"], "nan_rows_in_forces_csv": nan_rows,
            "min_J": rs["min_J_worst"], "check_passed": bool(check_mesh(m.points, m.tets, m.labels).passed),
            "worst_cut_made_dihedral_deg": float(angles.min()), "cut_made_tets_below_5_deg": int((angles < 5).sum()),
            "warnings": len(s["warnings"]), "wall_s": time.perf_counter() - t0}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="the demo knee (cutkit demo writes cutkit-demo/knee.h5)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--random", type=int, default=0, metavar="N", help="N random incisions instead of the five")
    ap.add_argument("--seed", type=int, default=1, help="seed of the random incisions")
    ap.add_argument("--tilt", type=float, default=0.0, metavar="DEG",
                    help="the random incisions' blade leaning sideways by up to DEG degrees")
    args = ap.parse_args()
    from cutkit.errors import InputError
    from cutkit.io.model_h5 import read_model

    try:
        model = read_model(args.model)
    except (InputError, OSError) as e:
        sys.exit(f"knee_incisions: {e}")
    cases = random_incisions(args.random, args.seed, args.tilt) if args.random else INCISIONS
    res = {name: one(model, *case) for name, case in cases.items()}
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        for name, r in res.items():
            print(f"{name:20s} " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                             for k, v in r.items()))


if __name__ == "__main__":
    main()
