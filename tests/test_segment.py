"""Segmentation: thresholds, colour channels, Otsu, labels, smoothing, resampling, clean-up."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cutkit.errors import EmptySegmentationError, InputError
from cutkit.segment import (
    clean_mask,
    fill_mask_holes,
    largest_connected_component,
    resample_isotropic,
    segment,
    smooth_mm,
)
from cutkit.volumes import Volume, read_volume

SAMPLES = Path(__file__).resolve().parents[1] / "sample_volumes"


def _ball_image(shape=(24, 24, 24), radius=7.0, spacing=(1.0, 1.0, 1.0)):
    c = (np.array(shape) - 1) / 2.0
    idx = np.indices(shape).astype(float)
    r = np.sqrt(sum(((idx[a] - c[a]) * spacing[a]) ** 2 for a in range(3)))
    return (r <= radius).astype(np.float32) * 100.0, r


def test_threshold_range_selects_exact_voxels():
    data = np.arange(27, dtype=np.float32).reshape(3, 3, 3)
    seg = segment(Volume(data), threshold=(5, 12), clean=False, largest_component=False, fill_holes=False)
    np.testing.assert_array_equal(seg.data, ((data >= 5) & (data <= 12)).astype(np.uint8))
    assert seg.data.dtype == np.uint8


def test_threshold_high_only():
    data = np.arange(27, dtype=np.float32).reshape(3, 3, 3)
    seg = segment(Volume(data), threshold=(None, 3), clean=False, largest_component=False, fill_holes=False)
    assert seg.data.sum() == 4


def test_blue_channel_keeps_the_dark_side_by_otsu():
    img, r = _ball_image()
    rgb = np.empty(img.shape + (3,), np.uint8)
    rgb[...] = (30, 60, 220)  # blue background
    rgb[r <= 7.0] = (140, 40, 40)  # tissue
    seg = segment(Volume(rgb), channel="blue")
    np.testing.assert_array_equal(seg.data, (r <= 7.0).astype(np.uint8))


def test_rgb_without_channel_is_an_input_error():
    with pytest.raises(InputError, match=r"^the volume is RGB: choose a channel"):
        segment(Volume(np.zeros((4, 4, 4, 3), np.uint8)), threshold=(1, None))


def test_bad_channel_name():
    with pytest.raises(InputError, match=r"^channel must be r, g, b \(red, green, blue\) or 0\.\.2 \(got 'purple'\)$"):
        segment(Volume(np.zeros((4, 4, 4, 3), np.uint8)), channel="purple")


def test_otsu_on_ct_phantom_finds_the_leg():
    ct = read_volume(SAMPLES / "knee_ct.nrrd")
    labels = read_volume(SAMPLES / "knee_labels.nrrd")
    seg = segment(ct, otsu=True)
    truth = labels.data > 0
    agree = np.count_nonzero((seg.data > 0) == truth) / truth.size
    assert agree > 0.99


def test_threshold_bone_in_ct_phantom():
    ct = read_volume(SAMPLES / "knee_ct.nrrd")
    labels = read_volume(SAMPLES / "knee_labels.nrrd")
    seg = segment(ct, threshold=(300, None), largest_component=False)
    bone = labels.data == 5
    dice = 2 * np.count_nonzero(bone & (seg.data > 0)) / (bone.sum() + np.count_nonzero(seg.data))
    assert dice > 0.95


def test_blue_channel_segments_rgb_phantom():
    rgb = read_volume(SAMPLES / "knee_rgb.nrrd")
    seg = segment(rgb, channel="b")
    # Compare with the analytic phantom sampled on the colour grid.
    import importlib.util

    spec = importlib.util.spec_from_file_location("mp", SAMPLES / "make_phantoms.py")
    mp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mp)
    truth = mp.knee_labels(1.0)[0] > 0
    assert np.count_nonzero((seg.data > 0) != truth) / truth.size < 0.005


def test_label_map_used_as_is_and_resampled_with_order_0():
    lab = read_volume(SAMPLES / "block_labels.nrrd")
    seg = segment(lab, labels=lab)
    np.testing.assert_array_equal(seg.data, lab.data)
    iso = segment(lab, labels=True, voxel_size_mm=0.5)
    assert set(np.unique(iso.data)) == {0, 1, 2}
    np.testing.assert_allclose(iso.spacing, 0.5)
    np.testing.assert_allclose(iso.origin, lab.origin)
    # A label at a world point survives resampling (nearest neighbour).
    p = lab.index_to_world(np.array([[5.0, 6.0, 4.0], [14.0, 6.0, 4.0]]))
    ijk = np.round(iso.world_to_index(p)).astype(int)
    assert [iso.data[tuple(v)] for v in ijk] == [1, 2]


def test_resample_isotropic_geometry_and_linear_values():
    data = np.arange(6, dtype=np.float32)[:, None, None] * np.ones((6, 3, 5), np.float32)  # value = i
    vol = Volume(data, (2.0, 1.0, 1.5), (10.0, -3.0, 4.0))
    out = resample_isotropic(vol, 1.0, order=1)
    assert out.shape == (11, 3, 7)  # floor((n-1)*s/v)+1
    np.testing.assert_allclose(out.origin, vol.origin)
    np.testing.assert_allclose(out.spacing, 1.0)
    # Linear in i: value at new index i' is i' * 1.0 / 2.0.
    np.testing.assert_allclose(out.data[:, 1, 2], np.arange(11) / 2.0, atol=1e-5)
    # The last voxel centre is the old last voxel centre (same world extent).
    np.testing.assert_allclose(out.index_to_world(np.array([[10, 2, 6]]))[0],
                               vol.index_to_world(np.array([[5, 2, 4]]))[0])


def test_smooth_sigma_is_in_mm_per_axis():
    data = np.zeros((41, 41, 41), np.float32)
    data[20, 20, 20] = 1.0
    out = smooth_mm(data, (1.0, 2.0, 0.5), 2.0)
    # A Gaussian of sigma 2 mm: per-axis sigma in voxels is 2, 1, 4.
    for axis, sig_vox in enumerate((2.0, 1.0, 4.0)):
        profile = out.sum(axis=tuple(a for a in range(3) if a != axis))
        x = np.arange(41) - 20
        var = (profile * x ** 2).sum() / profile.sum()
        assert np.sqrt(var) == pytest.approx(sig_vox, rel=0.02)


def test_clean_removes_specks_and_closes_pinholes():
    img, r = _ball_image()
    mask = r <= 7.0
    noisy = mask.copy()
    noisy[1, 1, 1] = True  # a speck
    noisy[11, 11, 8] = False  # a pinhole
    np.testing.assert_array_equal(clean_mask(noisy), mask)


def test_largest_component_and_fill_holes():
    mask = np.zeros((12, 12, 12), bool)
    mask[1:8, 1:8, 1:8] = True
    mask[10:12, 10:12, 10:12] = True
    mask[4, 4, 4] = False  # enclosed cavity
    big = largest_connected_component(mask)
    assert big.sum() == 7 ** 3 - 1 and not big[10, 10, 10]
    assert fill_mask_holes(big).sum() == 7 ** 3


def test_empty_segmentation_message():
    with pytest.raises(EmptySegmentationError,
                       match=r"^segmentation selects no voxel \(threshold 500:; values range 0\.\.26\)$"):
        segment(Volume(np.arange(27, dtype=np.float32).reshape(3, 3, 3)), threshold=(500, None))


def test_empty_label_map():
    with pytest.raises(EmptySegmentationError, match=r"^label map selects no voxel"):
        segment(Volume(np.zeros((3, 3, 3), np.uint8)), labels=True)


def test_smoothing_then_threshold_gives_a_rounder_ball():
    img, r = _ball_image(spacing=(1.0, 1.0, 1.0))
    seg = segment(Volume(img), threshold=(50, None), smooth_sigma_mm=1.0)
    # Thresholding a smoothed ball at half height keeps its radius (within a voxel).
    radius = r[seg.data > 0].max()
    assert 6.0 <= radius <= 8.0


def test_label_smoothing_keeps_labels_and_removes_a_single_voxel_spur():
    lab = np.zeros((12, 12, 12), np.uint8)
    lab[2:10, 2:10, 2:10] = 1
    lab[2:10, 2:10, 6:10] = 2
    lab[10, 5, 5] = 1  # a one-voxel spur
    seg = segment(Volume(lab), labels=True, smooth_sigma_mm=1.0)
    assert set(np.unique(seg.data)) == {0, 1, 2}
    assert seg.data[10, 5, 5] == 0
    assert seg.data[5, 5, 3] == 1 and seg.data[5, 5, 8] == 2
