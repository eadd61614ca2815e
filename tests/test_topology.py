import numpy as np
import pytest

import _twins_topology as twin
from cutkit.errors import MeshError
from cutkit.mesh import (
    TET_EDGES,
    TET_FACES,
    boundary_faces,
    node_to_tets,
    signed_volumes,
    tet_neighbors,
    unique_edges,
    unique_faces,
)
from cutkit.mesh.generate import box_mesh


def shuffled_box(shape, seed):
    """A Kuhn box mesh with randomly renumbered nodes and tets and rotated tet vertex order
    (even permutations keep the orientation)."""
    rng = np.random.default_rng(seed)
    points, tets = box_mesh(shape)
    perm = rng.permutation(len(points))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    points = points[perm]
    tets = inv[tets][rng.permutation(len(tets))]
    even = np.array([[0, 1, 2, 3], [1, 2, 0, 3], [2, 0, 1, 3], [1, 0, 3, 2]])  # even permutations
    tets = np.take_along_axis(tets, even[rng.integers(0, 4, len(tets))], axis=1)
    return points, tets


@pytest.mark.parametrize("seed", [0, 1])
def test_kernels_match_twins(seed):
    points, tets = shuffled_box((3, 2, 4), seed)
    assert np.all(signed_volumes(points, tets) > 0)
    e, te = unique_edges(tets)
    e2, te2 = twin.unique_edges(tets)
    np.testing.assert_array_equal(e, e2)
    np.testing.assert_array_equal(te, te2)
    f, tf, ft = unique_faces(tets)
    f2, tf2, ft2 = twin.unique_faces(tets)
    np.testing.assert_array_equal(f, f2)
    np.testing.assert_array_equal(tf, tf2)
    np.testing.assert_array_equal(np.sort(ft, axis=1), np.sort(ft2, axis=1))
    np.testing.assert_array_equal(tet_neighbors(tets), twin.tet_neighbors(tets))
    off, idx = node_to_tets(tets, len(points))
    off2, idx2 = twin.node_to_tets(tets, len(points))
    np.testing.assert_array_equal(off, off2)
    np.testing.assert_array_equal(idx, idx2)


def test_box_counts_and_euler():
    nx, ny, nz = 3, 2, 4
    points, tets = shuffled_box((nx, ny, nz), 3)
    edges, _ = unique_edges(tets)
    faces, _, _ = unique_faces(tets)
    # Euler characteristic of a ball: V - E + F - T = 1
    assert len(points) - len(edges) + len(faces) - len(tets) == 1
    bf, bt = boundary_faces(tets)
    assert len(bf) == 4 * (nx * ny + ny * nz + nx * nz)  # two triangles per boundary square


def test_boundary_faces_outward_and_match_twin():
    points, tets = shuffled_box((2, 3, 2), 4)
    bf, bt = boundary_faces(tets)
    twin_set = {(tuple(f), t) for f, t in twin.boundary_faces(tets)}
    assert {(tuple(f), t) for f, t in zip(bf.tolist(), bt.tolist())} == twin_set
    # Outward: normal points away from the box centre, and the surface encloses +volume.
    p = points[bf]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    centroid = p.mean(axis=1) - points.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", n, centroid) > 0)
    enclosed = np.einsum("ij,ij->i", p[:, 0], n).sum() / 6
    assert enclosed == pytest.approx(signed_volumes(points, tets).sum())


def test_face_topology_is_the_three_functions_in_one_pass():
    from cutkit.mesh.topology import face_topology

    _, tets = shuffled_box((3, 2, 2), 7)
    topo = face_topology(tets)
    faces, tet_faces, face_tets = unique_faces(tets)
    bf, bt = boundary_faces(tets)
    for got, want in ((topo.faces, faces), (topo.tet_faces, tet_faces), (topo.face_tets, face_tets),
                      (topo.neighbors, tet_neighbors(tets)), (topo.boundary_faces, bf), (topo.boundary_face_tet, bt)):
        assert got.dtype == want.dtype and np.array_equal(got, want)


def test_edge_and_node_incidence_list_each_tet_once_in_order():
    from cutkit.mesh.topology import edge_to_tets

    _, tets = shuffled_box((3, 2, 3), 9)
    edges, tet_edges = unique_edges(tets)
    for table, n, (off, idx) in ((tet_edges, len(edges), edge_to_tets(tet_edges, len(edges))),
                                 (tets, int(tets.max()) + 1, node_to_tets(tets, int(tets.max()) + 1))):
        for v in range(n):
            assert idx[off[v]:off[v + 1]].tolist() == np.flatnonzero((table == v).any(axis=1)).tolist()


def test_face_convention_outward_single_tet():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    tet = np.arange(4)
    for i in range(4):
        a, b, c = points[tet[TET_FACES[i]]]
        n = np.cross(b - a, c - a)
        assert np.dot(n, a - points[i]) > 0  # away from the opposite vertex
        assert i not in TET_FACES[i]
    assert sorted(map(tuple, TET_EDGES.tolist())) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def test_nonmanifold_face_and_empty():
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 2, 1, 5]])
    f, tf, ft = unique_faces(tets)
    shared = tf[0, 3]
    assert tf[1, 3] == shared and tf[2, 3] == shared
    bf, _ = boundary_faces(tets)
    assert not any(sorted(x) == [0, 1, 2] for x in bf.tolist())
    e, te = unique_edges(np.zeros((0, 4), int))
    assert e.shape == (0, 2) and te.shape == (0, 6)
    off, idx = node_to_tets(np.zeros((0, 4), int), 3)
    np.testing.assert_array_equal(off, [0, 0, 0, 0])


def test_bad_input_messages():
    with pytest.raises(MeshError, match=r"tets must have shape \(m, 4\), got \(2, 3\)"):
        unique_edges(np.zeros((2, 3), int))
    with pytest.raises(MeshError, match="tets must be integer node indices, got dtype float64"):
        unique_faces(np.zeros((1, 4)))
    with pytest.raises(MeshError, match=r"tets reference node 7 but there are only 4 points"):
        node_to_tets(np.array([[0, 1, 2, 7]]), 4)
    with pytest.raises(MeshError, match=r"negative node index \(-1\)"):
        tet_neighbors(np.array([[0, 1, 2, -1]]))
