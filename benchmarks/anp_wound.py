"""Wound opening of a cut prestrained slab with each element choice (P1 ``nh`` and ANP ``anp``).

Usage: python benchmarks/anp_wound.py [--nus 0.45,0.49] [--smoothing 0.7]

The slab of tests/test_anp.py (6 x 3 x 3 mm, Kuhn split 6 x 3 x 3 cells, E 30 kPa, 10 %
prestrain along y, bottom held) is cut along y = 1.37 by eight blade steps (blade 1.6 mm,
tip 0.5 mm above the top) and relaxed by Newton steps of 20 ms, then 0.2 s more, then to static
equilibrium (``static_solve``, relative residual 1e-8).  Prints one JSON object: per nu and
element the mean and largest distance between the two copies of the cut nodes
(``cutkit.simulate.session.cut_opening``) after the steps and at equilibrium, the smallest
signed tet volume at equilibrium and the Newton iterations of the steps.  ``--smoothing alpha``
adds ANP with that deviatoric smoothing.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_anp import cut_slab  # noqa: E402

from cutkit.mesh.quality import signed_volumes  # noqa: E402
from cutkit.relax.equilibrium import static_solve  # noqa: E402
from cutkit.simulate.session import cut_opening  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nus", default="0.45,0.49")
    ap.add_argument("--smoothing", type=float, default=None, help="add ANP with this deviatoric smoothing")
    a = ap.parse_args(argv)
    elements = [("nh", 0.0), ("anp", 0.0)] + ([("anp", a.smoothing)] if a.smoothing else [])
    out = []
    for nu in (float(v) for v in a.nus.split(",")):
        for element, alpha in elements:
            tis = cut_slab(element, nu, alpha)
            x = tis.state.positions
            steps = cut_opening(tis.cm, x)
            info = static_solve(tis.em, x, rtol=1e-8, atol=1e-14, max_iterations=200)
            d = cut_opening(tis.cm, x)
            out.append({"nu": nu, "element": element, "deviatoric_smoothing": tis.em.deviatoric_smoothing,
                        "steps_opening_mean_mm": round(float(steps.mean()), 4),
                        "opening_mean_mm": round(float(d.mean()), 4), "opening_max_mm": round(float(d.max()), 4),
                        "cut_pairs": int(d.size), "equilibrium_converged": bool(info.converged),
                        "min_signed_volume_mm3": float(signed_volumes(x, tis.cm.tets).min()),
                        "step_newton_iterations": int(tis.counts["newton_iterations"])})
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
