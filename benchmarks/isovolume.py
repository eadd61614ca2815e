"""Benchmark: six-tetrahedra marching isovolume vs ``vtk.vtkClipVolume``.

A labelled phantom of ``--size``^3 voxels (a Gaussian-smoothed sphere, label
1, around an inner ellipsoid, label 2) is meshed by
:func:`cutkit.isovolume.isovolume` (warm: the kernels are compiled by a
first call) and by ``vtkClipVolume`` (value 0.5 on the label map as a float
field, tets only) in the same process.  Prints a table, or JSON with
``--json``.

    .venv/bin/python benchmarks/isovolume.py [--json] [--size 128] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def phantom(size: int) -> np.ndarray:
    """(size, size, size) int16 label map: smoothed sphere (1) with an inner ellipsoid (2)."""
    from scipy.ndimage import gaussian_filter

    c = (size - 1) / 2.0
    x = (np.arange(size) - c) / size
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    # a sphere with a bumpy radius, smoothed, so the surface is not a trivial quadric
    r = np.sqrt(X**2 + Y**2 + Z**2)
    bump = 0.03 * np.sin(9 * X) * np.cos(7 * Y) * np.sin(5 * Z + 0.3)
    body = gaussian_filter((r < 0.4 + bump).astype(np.float32), sigma=size / 64.0) >= 0.5
    inner = (X / 0.25) ** 2 + ((Y - 0.03) / 0.15) ** 2 + ((Z + 0.02) / 0.2) ** 2 <= 1.0
    labels = np.zeros(X.shape, np.int16)
    labels[body] = 1
    labels[body & inner] = 2
    return labels


def run_cutkit(labels, spacing, repeat):
    from cutkit.isovolume import dihedral_summary, isovolume
    from cutkit.volumes import Volume

    vol = Volume(labels, spacing=spacing)
    isovolume(Volume(np.pad(np.ones((4, 4, 4), labels.dtype), 2), spacing=spacing))  # compile / load the cache
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        model = isovolume(vol)
        times.append(time.perf_counter() - t0)
    mn, p1 = dihedral_summary(model.points, model.tets)
    return {"seconds": min(times), "tets": model.n_tets, "nodes": model.n_points,
            "min_dihedral_deg": mn, "p1_dihedral_deg": p1}


def run_vtk(labels, spacing, repeat):
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    from cutkit.isovolume import dihedral_summary

    img = vtk.vtkImageData()
    img.SetDimensions(*labels.shape)
    img.SetSpacing(*spacing)
    # vtkImageData is x-fastest: our [i, j, k] array in Fortran order
    arr = numpy_to_vtk(np.asfortranarray(labels.astype(np.float32)).ravel(order="F"), deep=True)
    arr.SetName("labels")
    img.GetPointData().SetScalars(arr)
    times = []
    for _ in range(repeat):
        clip = vtk.vtkClipVolume()
        clip.SetInputData(img)
        clip.SetValue(0.5)
        clip.Mixed3DCellGenerationOff()  # tets only, as ours
        t0 = time.perf_counter()
        clip.Update()
        times.append(time.perf_counter() - t0)
    out = clip.GetOutput()
    points = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    cells = vtk_to_numpy(out.GetCells().GetConnectivityArray()).astype(np.int64).reshape(-1, 4)
    mn, p1 = dihedral_summary(points, cells)
    return {"seconds": min(times), "tets": int(cells.shape[0]), "nodes": int(points.shape[0]),
            "min_dihedral_deg": mn, "p1_dihedral_deg": p1}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    labels = phantom(args.size)
    spacing = (1.0, 1.0, 1.0)
    result = {
        "size": args.size,
        "labelled_voxels": {str(l): int(np.count_nonzero(labels == l)) for l in (1, 2)},
        "cutkit": run_cutkit(labels, spacing, args.repeat),
        "vtkClipVolume": run_vtk(labels, spacing, args.repeat),
    }
    result["speedup"] = result["vtkClipVolume"]["seconds"] / result["cutkit"]["seconds"]
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"isovolume benchmark, {args.size}^3 label map, best of {args.repeat}")
    print(f"{'':16s}{'seconds':>10s}{'tets':>12s}{'nodes':>12s}{'min dih':>10s}{'p1 dih':>10s}")
    for name in ("cutkit", "vtkClipVolume"):
        r = result[name]
        print(f"{name:16s}{r['seconds']:10.3f}{r['tets']:12d}{r['nodes']:12d}"
              f"{r['min_dihedral_deg']:10.2f}{r['p1_dihedral_deg']:10.2f}")
    print(f"speed-up vs vtkClipVolume: {result['speedup']:.2f}x")


if __name__ == "__main__":
    main()
