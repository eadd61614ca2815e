"""Benchmark: the knee phantom at full resolution, isovolume then decimation to a tenth.

The native 1.5 mm label map (``sample_volumes/knee_labels.nrrd``, no
resampling) goes through the six-tetrahedra isovolume and the progressive
decimation; the script reports the tet counts, the decimation time, the
smallest dihedral angle before and after, the boundary Hausdorff distance
between the two meshes (point-to-surface distances of surface samples, both
ways), each tissue's volume change and whether ``cutkit check`` passes.

    .venv/bin/python benchmarks/decimate_knee.py [--ratio 0.1] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from cutkit.decimate import decimate, quality_summary
from cutkit.isovolume import isovolume
from cutkit.mesh.check import check_mesh
from cutkit.mesh.quality import signed_volumes
from cutkit.volumes import read_volume

KNEE = Path(__file__).resolve().parent.parent / "sample_volumes" / "knee_labels.nrrd"


def _surface(points, tets):
    import pyvista as pv

    cells = np.hstack([np.full((tets.shape[0], 1), 4), tets]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(tets.shape[0], pv.CellType.TETRA, np.uint8), points)
    try:
        return grid.extract_surface(algorithm="dataset_surface").triangulate()
    except TypeError:  # pyvista before the keyword existed
        return grid.extract_surface().triangulate()


def _samples(surf):
    return np.vstack([surf.points, surf.cell_centers().points])


def boundary_hausdorff(points_a, tets_a, points_b, tets_b) -> float:
    """Largest distance of a boundary sample (vertices and face centroids) of either mesh to the other's boundary, mm."""
    import pyvista as pv

    sa, sb = _surface(points_a, tets_a), _surface(points_b, tets_b)
    worst = 0.0
    for src, dst in ((sa, sb), (sb, sa)):
        d = pv.PolyData(_samples(src)).compute_implicit_distance(dst)["implicit_distance"]
        worst = max(worst, float(np.abs(d).max()))
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ratio", type=float, default=0.1, help="fraction of tets to keep")
    ap.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = ap.parse_args()

    volume = read_volume(KNEE)
    t0 = time.perf_counter()
    fine = isovolume(volume, level=0.5)
    iso_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    coarse = decimate(fine, ratio=args.ratio)
    dec_s = time.perf_counter() - t0

    q_in = quality_summary(fine.points, fine.tets)
    q_out = quality_summary(coarse.points, coarse.tets)
    v_in, v_out = signed_volumes(fine.points, fine.tets), signed_volumes(coarse.points, coarse.tets)
    volume_change = {}
    for lab in np.unique(fine.labels):
        a, b = v_in[fine.labels == lab].sum(), v_out[coarse.labels == lab].sum()
        volume_change[str(int(lab))] = float((b - a) / a)
    report = check_mesh(coarse.points, coarse.tets, coarse.labels)
    results = {
        "input_tets": int(fine.n_tets),
        "output_tets": int(coarse.n_tets),
        "reduction": fine.n_tets / coarse.n_tets,
        "isovolume_seconds": iso_s,
        "decimate_seconds": dec_s,
        "input_min_dihedral_deg": q_in["min_dihedral_deg"],
        "output_min_dihedral_deg": q_out["min_dihedral_deg"],
        "output_fraction_below_10_deg": q_out["fraction_below"],
        "boundary_hausdorff_mm": boundary_hausdorff(fine.points, fine.tets, coarse.points, coarse.tets),
        "voxel_mm": float(min(volume.spacing)),
        "volume_change": volume_change,
        "check_passed": bool(report.passed),
        "check_failed": report.failed,
    }
    print(f"isovolume {results['input_tets']} tets in {iso_s:.1f} s (min dihedral {q_in['min_dihedral_deg']:.2f} deg)")
    print(f"decimate  {results['output_tets']} tets ({results['reduction']:.1f}x fewer) in {dec_s:.1f} s, "
          f"min dihedral {q_out['min_dihedral_deg']:.2f} deg, boundary Hausdorff {results['boundary_hausdorff_mm']:.2f} mm")
    print("volume change " + ", ".join(f"{k}: {100 * v:+.2f}%" for k, v in volume_change.items())
          + f"; check {'passed' if report.passed else 'FAILED: ' + ', '.join(report.failed)}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()
