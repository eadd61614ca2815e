import numpy as np
import pytest

import _twins_topology as twin
from cutkit.errors import MeshError
from cutkit.mesh import dihedral_angles, min_dihedral_angles, signed_volumes
from cutkit.mesh.generate import box_mesh

REGULAR = np.degrees(np.arccos(1 / 3))  # 70.5288 degrees


def regular_tet():
    p = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    t = np.array([[0, 1, 2, 3]])
    if twin.signed_volumes(p, t)[0] < 0:
        t = t[:, [0, 1, 3, 2]]
    return p, t


def test_regular_tet():
    p, t = regular_tet()
    np.testing.assert_allclose(dihedral_angles(p, t), REGULAR, atol=1e-12)
    assert REGULAR == pytest.approx(70.5288, abs=1e-4)
    assert signed_volumes(p, t)[0] == pytest.approx(8 / 3)


def test_random_tets_match_twin():
    rng = np.random.default_rng(5)
    p = rng.normal(size=(60, 3))
    t = np.array([rng.choice(60, 4, replace=False) for _ in range(200)])
    np.testing.assert_allclose(signed_volumes(p, t), twin.signed_volumes(p, t), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(dihedral_angles(p, t), twin.dihedral_angles(p, t), atol=1e-6)
    np.testing.assert_allclose(min_dihedral_angles(p, t), twin.dihedral_angles(p, t).min(axis=1), atol=1e-6)


@pytest.mark.parametrize("extra", [-1, 0, 1000])
def test_small_and_large_sets_give_the_same_bits_on_either_side_of_the_serial_bound(extra):
    """Below SERIAL_MAX_TETS the measures run on the calling thread, from it on in the parallel
    kernels: both give the same bits (the same per-tet primitive), and both match the twin."""
    from cutkit.mesh import _quality_kernels as Q
    from cutkit.mesh.quality import SERIAL_MAX_TETS

    rng = np.random.default_rng(11)
    p = rng.normal(size=(300, 3))
    m = SERIAL_MAX_TETS + extra
    t = np.argsort(rng.random((m, 300)), axis=1)[:, :4].astype(np.int64)
    np.testing.assert_array_equal(signed_volumes(p, t), Q.signed_volumes(p, t))
    np.testing.assert_array_equal(dihedral_angles(p, t), Q.dihedral_angles(p, t))
    head = slice(0, 300)
    np.testing.assert_array_equal(signed_volumes(p, t[head]), Q.signed_volumes(p, t[head]))
    np.testing.assert_array_equal(dihedral_angles(p, t[head]), Q.dihedral_angles(p, t[head]))
    np.testing.assert_allclose(signed_volumes(p, t), twin.signed_volumes(p, t), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(dihedral_angles(p, t), twin.dihedral_angles(p, t), atol=1e-6)


def test_box_angles_and_sum_of_volumes():
    p, t = box_mesh((2, 2, 2), spacing=(1.0, 2.0, 0.5))
    assert signed_volumes(p, t).sum() == pytest.approx(2 * 4 * 1)
    np.testing.assert_allclose(dihedral_angles(p, t), twin.dihedral_angles(p, t), atol=1e-9)
    # Kuhn cube tets (unit spacing) have dihedral angles 45, 60 and 90 degrees only.
    p, t = box_mesh((1, 1, 1))
    a = np.round(dihedral_angles(p, t), 9)
    assert set(np.unique(a)) <= {45.0, 60.0, 90.0}


def test_flat_tet_gives_0_and_180():
    # a planar quad split as a tet: the two diagonals cross -> angles 0 at four edges, 180 at two
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    a = dihedral_angles(p, np.array([[0, 1, 2, 3]]))[0]
    assert signed_volumes(p, np.array([[0, 1, 2, 3]]))[0] == 0
    assert sorted(np.round(a, 12).tolist()) == [0, 0, 0, 0, 180, 180]


def test_sliver_precision():
    # four nearly coplanar points (height 1e-9): the smallest angle is tiny but exact-ish.
    h = 1e-9
    p = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 0.3, h]], float)
    t = np.array([[0, 1, 2, 3]])
    a = dihedral_angles(p, t)[0]
    # edge (0,1) lies on the x axis; apex seen across it at (y, z) = (0.3, h), base at (1, 0)
    assert a[0] == pytest.approx(np.degrees(np.arctan2(h, 0.3)), rel=1e-9)
    # an arccos formula would round this to exactly 0
    assert 0 < a.min() < 1e-6


def test_orientation_independent_and_bad_points():
    p, t = regular_tet()
    np.testing.assert_allclose(dihedral_angles(p, t[:, [1, 0, 2, 3]]), REGULAR)
    assert signed_volumes(p, t[:, [1, 0, 2, 3]])[0] < 0
    with pytest.raises(MeshError, match=r"points must have shape \(n, 3\), got \(4, 2\)"):
        signed_volumes(p[:, :2], t)
    with pytest.raises(MeshError, match="tets reference node 4 but there are only 4 points"):
        dihedral_angles(p, np.array([[0, 1, 2, 4]]))
