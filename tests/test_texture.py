"""Texture registration: ICP recovers a known drift; coordinates sample the right voxels."""

import numpy as np
import pytest

from cutkit.errors import InputError
from cutkit.isovolume import isovolume
from cutkit.mesh.generate import voxel_mesh
from cutkit.model import TetModel
from cutkit.texture import downsample_texture, fit_transform, register_texture
from cutkit.volumes import Volume


def _sphere(shape=(28, 28, 28), radius=10.0):
    idx = np.indices(shape).transpose(1, 2, 3, 0) - (np.array(shape) - 1) / 2.0
    return (np.linalg.norm(idx, axis=-1) <= radius).astype(np.uint8)


def test_fit_transform_recovers_rigid_and_affine_maps():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(50, 3))
    angle = 0.3
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    dst = src @ rot.T + [1.0, -2.0, 0.5]
    t = fit_transform(src, dst, "rigid")
    np.testing.assert_allclose(t[:3, :3], rot, atol=1e-12)
    np.testing.assert_allclose(t[:3, 3], [1.0, -2.0, 0.5], atol=1e-12)
    a = np.array([[1.1, 0.1, 0], [0, 0.9, 0.2], [0, 0, 1.3]])
    t = fit_transform(src, src @ a.T + 3.0, "affine")
    np.testing.assert_allclose(t[:3, :3], a, atol=1e-12)


def test_rigid_registration_undoes_a_drift():
    mask = _sphere()
    spacing = np.array([1.0, 1.0, 1.0])
    origin = np.array([5.0, -3.0, 2.0])
    seg = Volume(mask, spacing=spacing, origin=origin)
    # The isovolume's boundary follows the isosurface ICP aligns to; a voxel
    # staircase would leave a bias of a few tenths of a millimetre.
    iso = isovolume(seg)
    points, tets, labels = iso.points, iso.tets, iso.labels
    drift = np.array([1.2, -0.8, 0.6])
    model = TetModel.from_arrays(points + drift, tets, labels)
    rgb = np.zeros(mask.shape + (3,), np.uint8)
    rgb[..., 0] = np.arange(mask.shape[0])[:, None, None] * 9  # red encodes i
    tex = Volume(rgb, spacing=spacing, origin=origin)
    out, rep = register_texture(model, tex, segmentation=seg, method="rigid")
    assert rep.residual_after_mm < 0.5 * rep.residual_before_mm
    np.testing.assert_allclose(rep.transform[:3, 3], -drift, atol=0.2)
    np.testing.assert_allclose(rep.transform[:3, :3], np.eye(3), atol=0.02)
    # The node that drifted from voxel-centre position p is coloured by voxel p.
    node = np.argmin(np.linalg.norm(out.points - (origin + [14, 14, 14] + drift), axis=1))
    i_expected = (out.points[node, 0] - drift[0] - origin[0])
    assert abs(out.texture.sample_rgb(out.texcoords[node : node + 1])[0, 0] - 9 * i_expected) <= 9 * 0.35


def test_without_registration_texcoords_are_canonical():
    mask = _sphere((10, 10, 10), 4)
    points, tets, labels = voxel_mesh(mask)
    model = TetModel.from_arrays(points, tets, labels)
    tex = Volume(np.zeros((10, 10, 10), np.uint8), spacing=(1, 1, 1), origin=(0, 0, 0))
    out, rep = register_texture(model, tex, method="none")
    np.testing.assert_allclose(out.texcoords, (points + 0.5) / 10.0)
    assert rep.method == "none"


def test_registration_needs_a_segmentation():
    mask = _sphere((10, 10, 10), 4)
    points, tets, labels = voxel_mesh(mask)
    model = TetModel.from_arrays(points, tets, labels)
    with pytest.raises(InputError, match="needs the segmentation"):
        register_texture(model, Volume(mask), method="rigid")


def test_downsample_keeps_voxel_centres_in_place():
    data = np.arange(8 * 6 * 4, dtype=np.float64).reshape(8, 6, 4) % 200
    vol = Volume(data.astype(np.uint8), spacing=(0.5, 1.0, 2.0), origin=(1.0, 2.0, 3.0))
    small, factor = downsample_texture(vol, max_voxels=8 * 6 * 4 // 8)
    assert factor == 2
    assert small.shape == (4, 3, 2)
    # centre of block (0,0,0) = mean of voxel centres 0 and 1 along each axis
    np.testing.assert_allclose(small.index_to_world([[0, 0, 0]]), vol.index_to_world([[0.5, 0.5, 0.5]]))
    assert small.data[0, 0, 0, 0] == int(np.rint(data[:2, :2, :2].mean()))


def test_background_takes_the_nearest_tissue_colour():
    from cutkit.texture.register import pad_background

    labels = np.zeros((6, 4, 4), np.uint8)
    labels[:3] = 1  # tissue in the first three slabs
    rgb = np.zeros((6, 4, 4, 3), np.uint8)
    rgb[..., 2] = 230  # blue gel everywhere ...
    rgb[:3, ..., 0] = np.arange(3)[:, None, None] * 50 + 10  # ... tissue red varies along x
    rgb[:3, ..., 2] = 0
    seg = Volume(labels, spacing=(2.0, 2.0, 2.0), origin=(1.0, 0.0, 0.0))
    tex = Volume(rgb, spacing=(2.0, 2.0, 2.0), origin=(1.0, 0.0, 0.0))
    out = pad_background(tex, seg)
    np.testing.assert_array_equal(out.data[:3], rgb[:3])  # tissue unchanged
    # every background voxel now carries the colour of the last tissue slab
    np.testing.assert_array_equal(out.data[3:, ..., 0], 110)
    np.testing.assert_array_equal(out.data[3:, ..., 2], 0)
