"""The element solvers on a real MRI: nibabel's T1 head image built, cut across the top and held.

    python benchmarks/mri_head.py [--json] [--work DIR] [--solvers hybrid] [--hold S] [--rest-rtol R] [--static]
                                  [--to-residual]

Builds ``pipelines/mri_head.toml`` over the T1 head nibabel ships as test data
(``nibabel/tests/data/anatomical.nii``), writes an incision across the top of
the head (``cutkit trajectory --model``, 5 mm deep), then runs
``relax.py``'s ``knee_solvers`` on it with the blade drawn out before a
``--hold`` (default 1 s): steps not converged, final out of balance over the force scale, the
smallest volume ratio, the opening against a static Newton solve from the
final state (``--static``) and, with ``--to-residual``, the wall time each
solver takes to bring the first solver's cut model to 1e-3 of its force
scale.  ``--work`` keeps the model and the incision (reused when there).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
RECIPE = HERE.parent / "pipelines" / "mri_head.toml"


def mri_volume() -> Path:
    """nibabel's T1 head test image."""
    import nibabel

    return Path(nibabel.__file__).parent / "tests" / "data" / "anatomical.nii"


def build(work: Path) -> tuple[Path, Path]:
    """The head model and its incision in ``work`` (made when missing)."""
    model, incision = work / "head.h5", work / "head_cut.csv"
    cutkit = [sys.executable, "-m", "cutkit.cli.main"]
    if not model.exists():
        subprocess.run(cutkit + ["build-model", str(mri_volume()), "--recipe", str(RECIPE), "-o", str(model)],
                       check=True, stdout=subprocess.DEVNULL)
    if not incision.exists():
        subprocess.run(cutkit + ["trajectory", "-o", str(incision), "--start", "0,-20,40", "--end", "0,20,40",
                                 "--model", str(model), "--depth", "5"], check=True, stdout=subprocess.DEVNULL)
    return model, incision


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--work", default="mri-head", help="folder for the model and the incision")
    ap.add_argument("--solvers", default="hybrid")
    ap.add_argument("--hold", type=float, default=1.0, help="hold after the incision, s")
    ap.add_argument("--rest-rtol", type=float, default=None, help="the resting steps' tolerance (simulate --rest-rtol)")
    ap.add_argument("--static", action="store_true", help="a static Newton solve of each run's final state")
    ap.add_argument("--to-residual", action="store_true", help="bring the first solver's cut model to 1e-3")
    args = ap.parse_args(argv)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    model_path, incision = build(work)
    sys.path.insert(0, str(HERE))
    from relax import knee_solvers

    from cutkit.cutting.trajectory import read_trajectory
    from cutkit.io.model_h5 import read_model

    out = {"model": str(model_path), "incision": str(incision),
           "solvers": knee_solvers(read_model(model_path), tuple(args.solvers.split(",")),
                                   trajectory=read_trajectory(incision), hold_s=args.hold, lift=True,
                                   rest_rtol=args.rest_rtol,
                                   static=args.static,
                                   to_residual=args.to_residual)}
    print(json.dumps(out, indent=1 if args.json else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
