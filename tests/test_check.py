import numpy as np
import pytest

import _twins_topology as twin
from _meshes_check import conforming_mesh, hanging_mesh
from cutkit.errors import MeshError
from cutkit.mesh.check import HANGING_NODE_REL_TOL, _hanging_nodes, check_mesh
from cutkit.mesh.generate import box_mesh
from cutkit.mesh.topology import boundary_faces


def rows(rep):
    return {r.name: r for r in rep.rows}


def test_conforming_box_passes():
    p, t = conforming_mesh()
    rep = check_mesh(p, t, np.ones(len(t), np.int32))
    assert rep.passed, [(r.name, r.detail) for r in rep.rows if not r.passed]
    assert rep.min_dihedral_angle == pytest.approx(45.0)
    assert "manifold boundary vertices" in rows(rep)


def test_hanging_nodes_named():
    p, t = hanging_mesh()
    rep = check_mesh(p, t)
    row = rows(rep)["no hanging node (conforming)"]
    assert not row.passed
    on_face = np.flatnonzero(np.isclose(p[:, 0], 1.0))
    corner = np.all(np.isclose(p[on_face, 1:] % 1.0, 0.0), axis=1)
    expected = np.sort(on_face[~corner])  # 5 nodes: 4 edge midpoints and the face centre
    np.testing.assert_array_equal(rep.hanging_nodes, expected)
    assert row.detail.startswith(f"5 hanging nodes: {expected[0]}, ")
    assert "no hanging node (conforming)" in rep.failed
    bf, _ = boundary_faces(t)
    np.testing.assert_array_equal(_hanging_nodes(p, bf)[0], twin.hanging_nodes(p, bf, HANGING_NODE_REL_TOL))


def test_hanging_node_twin_random_perturbed():
    rng = np.random.default_rng(2)
    p, t = box_mesh((3, 3, 3))
    p = p + rng.normal(scale=0.05, size=p.shape)
    bf, _ = boundary_faces(t)
    assert _hanging_nodes(p, bf)[0].size == 0
    # move one boundary node exactly onto the middle of a boundary triangle it does not belong to
    tri = bf[7]
    node = next(int(v) for v in np.unique(bf) if v not in tri and v not in t[np.any(np.isin(t, tri), axis=1)])
    p[node] = p[tri].mean(axis=0)
    got = _hanging_nodes(p, bf)[0]
    assert node in got
    np.testing.assert_array_equal(got, twin.hanging_nodes(p, bf, HANGING_NODE_REL_TOL))


def test_inverted_flat_unused_nan():
    p, t = box_mesh((1, 1, 1))
    t = t.copy()
    t[2] = t[2, [1, 0, 2, 3]]
    p = np.vstack([p, [[5, 5, 5]]])
    rep = check_mesh(p, t)
    r = rows(rep)
    assert not r["positive orientation"].passed and r["positive orientation"].detail == "1 inverted or flat tets: 2"
    assert not r["no unused node"].passed and r["no unused node"].detail == "1 unused nodes: 8"
    p[8] = np.nan
    rep = check_mesh(p, t)
    assert rows(rep)["finite coordinates"].detail == "1 nodes with NaN/inf: 8"
    assert not rep.passed


def test_indices_out_of_range_and_nonmanifold():
    p, t = box_mesh((1, 1, 1))
    bad = t.copy()
    bad[0, 0] = 99
    r = rows(check_mesh(p, bad))
    assert r["indices in range"].detail == "1 tets with a node index outside [0, 8): 0"
    assert "positive orientation" not in r
    # two cubes touching at one corner only: a non-manifold boundary vertex
    p2, t2 = box_mesh((1, 1, 1), origin=(1.0, 1.0, 1.0))
    from _meshes_check import merge

    pp, tt = merge(np.vstack([p, p2]), np.vstack([t, t2 + 8]))
    r = rows(check_mesh(pp, tt))
    assert r["closed manifold boundary (edges)"].passed
    nm = r["manifold boundary vertices"]
    assert not nm.passed
    shared = int(np.flatnonzero(np.all(pp == 1.0, axis=1))[0])
    assert nm.detail == f"1 non-manifold vertices: {shared}"


def test_face_in_three_tets_and_open_boundary():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1], [0.3, 0.3, 1]], float)
    t = np.array([[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]])
    r = rows(check_mesh(p, t))
    assert not r["faces shared by <= 2 tets"].passed
    assert "nodes [0, 1, 2]" in r["faces shared by <= 2 tets"].detail
    with pytest.raises(MeshError, match=r"tets must be an integer \(m, 4\) array, got shape \(3,\)"):
        check_mesh(p, np.arange(3))
