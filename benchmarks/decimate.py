"""Benchmark: progressive decimation of a 2M-tet two-tissue ellipsoid to 200k tets.

Runs cutkit's decimator and VTK's vtkUnstructuredGridQuadricDecimation on the
same Kuhn-split voxel mesh in the same process and reports time and quality
(smallest dihedral angle, fraction of tets below 10 degrees) of each.

    .venv/bin/python benchmarks/decimate.py [--tets 2000000] [--ratio 0.1] [--json out.json] [--no-vtk] [--optimize]

``--optimize`` also runs gmsh's Netgen optimiser on cutkit's output
(:func:`cutkit.decimate.optimize.optimize`) and reports its decision.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from cutkit.decimate import decimate, quality_summary
from cutkit.mesh.generate import KUHN_TETS
from cutkit.model.tetmodel import TetModel


def voxel_ellipsoid(n: int, radii=(0.45, 0.4, 0.35), inner=0.6):
    """Kuhn-split voxels inside an ellipsoid; label 2 below normalised radius ``inner``."""
    c = (np.arange(n) + 0.5) / n - 0.5
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt((x / radii[0]) ** 2 + (y / radii[1]) ** 2 + (z / radii[2]) ** 2)
    ci, cj, ck = np.nonzero(r <= 1.0)
    vox_label = np.where(r[ci, cj, ck] < inner, 2, 1).astype(np.int32)
    node = lambda i, j, k: (i * (n + 1) + j) * (n + 1) + k  # noqa: E731
    tets = np.empty((6 * ci.size, 4), np.int64)
    for t, corners in enumerate(KUHN_TETS):
        for v, (a, b, cc) in enumerate(corners):
            tets[t::6, v] = node(ci + a, cj + b, ck + cc)
    g = np.arange(n + 1, dtype=np.float64)
    gi, gj, gk = np.meshgrid(g, g, g, indexing="ij")
    points = np.stack([gi.ravel(), gj.ravel(), gk.ravel()], axis=1)
    p = points[tets]
    neg = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    used = np.unique(tets)
    renum = np.full(points.shape[0], -1, np.int64)
    renum[used] = np.arange(used.size)
    return points[used], renum[tets], np.repeat(vox_label, 6)


def grid_size_for(n_tets: int) -> int:
    # The ellipsoid fills 4/3 pi * 0.45 * 0.4 * 0.35 of its n^3 grid, 6 tets a voxel.
    frac = 4.0 / 3.0 * np.pi * 0.45 * 0.4 * 0.35
    return int(round((n_tets / (6.0 * frac)) ** (1.0 / 3.0)))


def run_vtk(points, tets, labels, ratio):
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy

    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(points, deep=True))
    grid.SetPoints(pts)
    cells = vtk.vtkCellArray()
    offsets = numpy_to_vtkIdTypeArray(np.arange(0, 4 * tets.shape[0] + 1, 4, dtype=np.int64), deep=True)
    conn = numpy_to_vtkIdTypeArray(tets.ravel().astype(np.int64), deep=True)
    cells.SetData(offsets, conn)
    grid.SetCells(vtk.VTK_TETRA, cells)
    # The filter decimates in (x, y, z, scalar) space and needs a point scalar:
    # give it the tissue label of each node (the largest of its tets).
    node_label = np.zeros(points.shape[0])
    np.maximum.at(node_label, tets.ravel(), np.repeat(labels.astype(np.float64), 4))
    grid.GetPointData().SetScalars(numpy_to_vtk(node_label, deep=True))
    dec = vtk.vtkUnstructuredGridQuadricDecimation()
    dec.SetInputData(grid)
    dec.SetTargetReduction(1.0 - ratio)
    t0 = time.perf_counter()
    dec.Update()
    seconds = time.perf_counter() - t0
    out = dec.GetOutput()
    out_pts = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    conn = vtk_to_numpy(out.GetCells().GetConnectivityArray()).astype(np.int64).reshape(-1, 4)
    return seconds, out_pts, conn


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tets", type=int, default=2_000_000, help="approximate input size")
    ap.add_argument("--ratio", type=float, default=0.1, help="fraction of tets to keep")
    ap.add_argument("--json", metavar="PATH", help="write the results as JSON")
    ap.add_argument("--no-vtk", action="store_true", help="skip VTK")
    ap.add_argument("--optimize", action="store_true", help="also try gmsh's Netgen optimiser on cutkit's output")
    args = ap.parse_args()

    points, tets, labels = voxel_ellipsoid(grid_size_for(args.tets))
    model = TetModel.from_arrays(points, tets, labels)
    # Compile (or load the cached kernels) outside the timing.
    decimate(TetModel.from_arrays(*voxel_ellipsoid(8)), ratio=0.5)
    results = {"input": quality_summary(points, tets), "target_tets": int(args.ratio * tets.shape[0])}

    t0 = time.perf_counter()
    out = decimate(model, ratio=args.ratio)
    seconds = time.perf_counter() - t0
    results["cutkit"] = {"seconds": seconds, **quality_summary(out.points, out.tets), **{
        k: out.provenance["decimate"][k] for k in ("collapses", "heap_pops", "legality_tests", "precheck_rejects", "rounds")}}
    vols = {}
    for lab in (1, 2):
        v0 = np.sum(_vol(points, tets[labels == lab]))
        v1 = np.sum(_vol(out.points, out.tets[out.labels == lab]))
        vols[str(lab)] = float((v1 - v0) / v0)
    results["cutkit"]["volume_change"] = vols

    if args.optimize:
        from cutkit.decimate.optimize import optimize

        _, results["netgen"] = optimize(out, "netgen")

    if not args.no_vtk:
        vs, vp, vt = run_vtk(points, tets, labels, args.ratio)
        q = quality_summary(vp, vt) if vt.shape[0] else {"tets": 0}
        # VTK may output inverted tets: count them too.
        results["vtk"] = {"seconds": vs, **q, "inverted": int(np.sum(_vol(vp, vt) <= 0))}

    print(f"input: {results['input']['tets']} tets, min dihedral {results['input']['min_dihedral_deg']:.1f} deg")
    for name in ("cutkit", "vtk"):
        if name in results:
            r = results[name]
            print(f"{name:>7}: {r['seconds']:7.2f} s  -> {r['tets']} tets, min dihedral {r['min_dihedral_deg']:.2f} deg, "
                  f"{100 * r['fraction_below']:.2f}% below 10 deg")
    if "netgen" in results:
        r = results["netgen"]
        print(f" netgen: {r['seconds']:7.2f} s  -> {r['tets_after']} tets, min dihedral {r['min_dihedral_before_deg']:.2f} -> "
              f"{r['min_dihedral_after_deg']:.2f} deg: {'accepted' if r['accepted'] else 'rejected'} ({r['reason']})")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


def _vol(points, tets):
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


if __name__ == "__main__":
    main()
