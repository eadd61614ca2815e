"""The committed sample volumes match their generator and their README."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from cutkit.volumes import read_volume

SAMPLES = Path(__file__).resolve().parents[1] / "sample_volumes"


@pytest.fixture(scope="module")
def phantoms():
    spec = importlib.util.spec_from_file_location("make_phantoms", SAMPLES / "make_phantoms.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_block_phantom_regenerates_identically(phantoms):
    lab, origin, spacing = phantoms.block_labels()
    vol = read_volume(SAMPLES / "block_labels.nrrd")
    assert vol.data.dtype == np.uint8
    np.testing.assert_array_equal(vol.data, lab)
    np.testing.assert_allclose(vol.origin, origin)
    np.testing.assert_allclose(vol.spacing, spacing)
    np.testing.assert_allclose(vol.direction, np.eye(3))


def test_knee_labels_match_generator_and_anatomy(phantoms):
    vol = read_volume(SAMPLES / "knee_labels.nrrd")
    lab, origin, spacing = phantoms.knee_labels()
    np.testing.assert_array_equal(vol.data, lab)
    np.testing.assert_allclose(vol.origin, origin)
    assert set(np.unique(vol.data)) == {0, 1, 2, 3, 4, 5}
    # The voxel grid spans the documented 81 x 81 x 120 mm box.
    np.testing.assert_allclose(np.array(vol.shape) * vol.spacing, [81.0, 81.0, 120.0])
    # Anatomy at known world points (LPS; the front of the knee is -y).
    def label_at(xyz):
        ijk = np.round(vol.world_to_index(np.array([xyz]))[0]).astype(int)
        return vol.data[tuple(ijk)]

    assert label_at([40.0, 40.0, 30.0]) == 5  # tibia shaft on the axis
    assert label_at([40.0, 40.0, 100.0]) == 5  # femur shaft
    assert label_at([40.0, 16.0, 55.0]) == 4  # patellar tendon in front
    assert label_at([55.0, 52.0, 20.0]) == 3  # muscle
    assert label_at([79.5, 79.5, 60.0]) == 0  # corner outside the leg
    # Skin is the outermost tissue along a ray from the axis to the left.
    ray = [label_at([x, 40.0, 20.0]) for x in np.arange(40.0, 80.0, 0.75)]
    outer = [v for v in ray if v != 0][-1]
    assert outer == 1
    # The front skin lies near y = 5 mm at mid-length (where the shipped incision.csv starts its cut).
    front = [y for y in np.arange(0.0, 20.0, 0.5) if label_at([40.0, y, 60.0]) != 0][0]
    assert 4.0 <= front <= 7.0


def test_rgb_and_ct_are_consistent_with_labels(phantoms):
    labels = read_volume(SAMPLES / "knee_labels.nrrd")
    rgb = read_volume(SAMPLES / "knee_rgb.nrrd")
    ct = read_volume(SAMPLES / "knee_ct.nrrd")
    assert rgb.data.shape[3] == 3 and rgb.data.dtype == np.uint8
    assert ct.data.dtype == np.int16
    np.testing.assert_allclose(ct.affine, labels.affine)
    # Background is blue: blue exceeds red and green well outside the leg.
    b = rgb.data[0, 0, :, :].astype(float)
    assert np.all(b[:, 2] > b[:, 0] + 100) and np.all(b[:, 2] > b[:, 1] + 100)
    # Bone in the CT-like volume is bright, air dark.
    assert ct.data[labels.data == 5].mean() > 500 and ct.data[labels.data == 0].mean() < -900
