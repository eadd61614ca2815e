"""Benchmark the mesh core on a ~1M-tet Kuhn box mesh: topology and quality.

Usage: python benchmarks/topology.py [--json] [--n-tets 1000000] [--no-shuffle]

Times (warm, after one compile call on a small mesh) each step: unique
edges, unique faces + neighbours, boundary faces, node -> tet CSR, signed
volumes, dihedral angles.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from cutkit.mesh import (
    boundary_faces,
    dihedral_angles,
    node_to_tets,
    signed_volumes,
    unique_edges,
)
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.topology import _check_tets, _faces
from cutkit.mesh import _topology_kernels as _k


def make_mesh(n_tets: int, shuffle: bool, seed: int = 0):
    side = max(1, round((n_tets / 6) ** (1 / 3)))
    points, tets = box_mesh((side, side, side))
    if shuffle:  # a realistic node numbering: no grid locality
        rng = np.random.default_rng(seed)
        perm = rng.permutation(len(points))
        inv = np.empty_like(perm)
        inv[perm] = np.arange(len(perm))
        points, tets = points[perm], inv[tets][rng.permutation(len(tets))]
    return points, tets


def run(points, tets) -> dict:
    t = {}
    s = time.perf_counter()
    unique_edges(tets)
    t["edges"] = time.perf_counter() - s
    s = time.perf_counter()
    # faces and neighbours share one face pass, as a caller needing both would do
    _, tet_faces, face_tets, _ = _faces(_check_tets(tets))
    _k.neighbors_from_faces(tet_faces, face_tets)
    t["faces_neighbors"] = time.perf_counter() - s
    s = time.perf_counter()
    boundary_faces(tets)
    t["boundary_faces"] = time.perf_counter() - s
    s = time.perf_counter()
    node_to_tets(tets, len(points))
    t["node_to_tets"] = time.perf_counter() - s
    s = time.perf_counter()
    signed_volumes(points, tets)
    t["volumes"] = time.perf_counter() - s
    s = time.perf_counter()
    dihedral_angles(points, tets)
    t["dihedral_angles"] = time.perf_counter() - s
    t["total"] = sum(t.values())
    return t


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print JSON only")
    ap.add_argument("--n-tets", type=int, default=1_000_000)
    ap.add_argument("--no-shuffle", action="store_true", help="keep the grid node numbering")
    args = ap.parse_args()
    run(*make_mesh(1000, True))  # compile / load the numba cache
    points, tets = make_mesh(args.n_tets, not args.no_shuffle)
    times = run(points, tets)
    import numba

    result = {
        "benchmark": "topology",
        "n_points": int(len(points)),
        "n_tets": int(len(tets)),
        "shuffled": not args.no_shuffle,
        "threads": numba.get_num_threads(),
        "seconds": {k: round(v, 4) for k, v in times.items()},
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
