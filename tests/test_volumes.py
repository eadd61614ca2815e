"""Volume readers: each against a file written by that format's own library."""

from __future__ import annotations

import os

import numpy as np
import pytest

from cutkit.errors import InputError
from cutkit.volumes import Volume, describe_volume, read_volume, write_volume

SPACING = np.array([0.8, 1.25, 2.5])
ORIGIN = np.array([-12.0, 30.5, 7.25])
RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0])
IJK = np.array([[0, 0, 0], [3, 1, 2], [4, 5, 3]])


def _rotation(deg: float) -> np.ndarray:
    """Rotation about the axis (1, 2, 2)/3 by ``deg`` degrees (Rodrigues)."""
    a = np.array([1.0, 2.0, 2.0]) / 3.0
    t = np.radians(deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


ROT = _rotation(30.0)


def _ramp(shape=(5, 6, 4), dtype=np.int16):
    return np.arange(np.prod(shape)).reshape(shape).astype(dtype)


# ------------------------------------------------------------------- NIfTI
@pytest.mark.parametrize("ext", [".nii", ".nii.gz"])
def test_nifti_world_coordinates_are_lps(tmp_path, ext):
    import nibabel as nib

    data = _ramp()
    affine = np.eye(4)
    affine[:3, :3] = ROT * SPACING
    affine[:3, 3] = ORIGIN
    path = tmp_path / f"v{ext}"
    nib.save(nib.Nifti1Image(data, affine), str(path))
    vol = read_volume(path)
    for ijk in IJK:
        ras = affine[:3, :3] @ ijk + affine[:3, 3]
        np.testing.assert_allclose(vol.index_to_world(ijk[None])[0], RAS_TO_LPS @ ras, atol=1e-5)
        assert vol.data[tuple(ijk)] == data[tuple(ijk)]
    np.testing.assert_allclose(vol.spacing, SPACING, rtol=1e-6)


def test_nifti_scaled_values_are_physical(tmp_path):
    import nibabel as nib

    img = nib.Nifti1Image(_ramp(), np.eye(4))
    img.header.set_slope_inter(2.0, -100.0)
    nib.save(img, str(tmp_path / "s.nii"))
    vol = read_volume(tmp_path / "s.nii")
    assert vol.data[1, 2, 3] == pytest.approx(2.0 * _ramp()[1, 2, 3] - 100.0)


# -------------------------------------------------------------------- NRRD
def test_nrrd_space_directions_and_origin(tmp_path):
    import nrrd

    data = _ramp()
    dirs = (ROT * SPACING).T  # rows: the axis vectors
    nrrd.write(str(tmp_path / "v.nrrd"), data, {"space": "left-posterior-superior", "space directions": dirs,
                                                "space origin": ORIGIN})
    vol = read_volume(tmp_path / "v.nrrd")
    for ijk in IJK:
        np.testing.assert_allclose(vol.index_to_world(ijk[None])[0], ORIGIN + ijk @ dirs, atol=1e-9)
        assert vol.data[tuple(ijk)] == data[tuple(ijk)]


def test_detached_nhdr_header(tmp_path):
    import nrrd

    dirs = np.diag(SPACING)
    nrrd.write(str(tmp_path / "v.nhdr"), _ramp(), {"space": "left-posterior-superior", "space directions": dirs,
                                                   "space origin": ORIGIN}, detached_header=True)
    vol = read_volume(tmp_path / "v.nhdr")
    np.testing.assert_array_equal(vol.data, _ramp())
    np.testing.assert_allclose(vol.origin, ORIGIN)


def test_nrrd_ras_space_is_converted_to_lps(tmp_path):
    import nrrd

    dirs = np.diag(SPACING)
    nrrd.write(str(tmp_path / "v.nrrd"), _ramp(), {"space": "right-anterior-superior", "space directions": dirs,
                                                   "space origin": ORIGIN})
    vol = read_volume(tmp_path / "v.nrrd")
    ijk = np.array([2, 3, 1])
    np.testing.assert_allclose(vol.index_to_world(ijk[None])[0], RAS_TO_LPS @ (ORIGIN + ijk @ dirs))


def test_nrrd_rgb_roundtrip_keeps_channels_last(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (4, 5, 6, 3), dtype=np.uint8)
    src = Volume(rgb, SPACING, ORIGIN, ROT)
    write_volume(tmp_path / "c.nrrd", src)
    vol = read_volume(tmp_path / "c.nrrd")
    assert vol.data.shape == (4, 5, 6, 3)
    np.testing.assert_array_equal(vol.data, rgb)
    np.testing.assert_allclose(vol.affine, src.affine, atol=1e-12)


# ---------------------------------------------------------------- MetaImage
@pytest.mark.parametrize("ext", [".mha", ".mhd"])
def test_metaimage_matches_simpleitk_geometry(tmp_path, ext):
    import SimpleITK as sitk

    data = _ramp()
    img = sitk.GetImageFromArray(data.transpose(2, 1, 0).copy())
    img.SetSpacing(SPACING.tolist())
    img.SetOrigin(ORIGIN.tolist())
    img.SetDirection(ROT.reshape(-1).tolist())
    sitk.WriteImage(img, str(tmp_path / f"v{ext}"))
    vol = read_volume(tmp_path / f"v{ext}")
    assert vol.shape == (5, 6, 4)
    for ijk in IJK:
        idx = [int(v) for v in ijk]
        np.testing.assert_allclose(vol.index_to_world(ijk[None])[0], img.TransformIndexToPhysicalPoint(idx),
                                   atol=1e-9)
        assert vol.data[tuple(ijk)] == img.GetPixel(*idx)


# -------------------------------------------------------------------- DICOM
def _write_dicom_series(folder, pixels, pixel_spacing, iop, positions, slope, intercept):
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    series = generate_uid()
    for n, (plane, ipp) in enumerate(zip(pixels, positions)):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.SeriesInstanceUID = series
        ds.Modality = "CT"
        ds.Rows, ds.Columns = plane.shape
        ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 16, 15
        ds.PixelRepresentation = 0
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.PixelSpacing = list(pixel_spacing)
        ds.ImageOrientationPatient = list(iop)
        ds.ImagePositionPatient = list(ipp)
        ds.SliceThickness = 9.0  # deliberately not the spacing
        ds.RescaleSlope = slope
        ds.RescaleIntercept = intercept
        ds.PixelData = plane.astype(np.uint16).tobytes()
        # Names in reverse slice order: the reader must sort by position, not name.
        ds.save_as(str(folder / f"IM{len(pixels) - n:03d}.dcm"), enforce_file_format=True)


def test_dicom_series_sorted_by_position_with_rescale(tmp_path):
    rng = np.random.default_rng(1)
    n_slices, rows, cols = 4, 6, 7
    pixels = rng.integers(0, 3000, (n_slices, rows, cols))
    row_cos, col_cos = ROT[:, 0], ROT[:, 1]
    normal = np.cross(row_cos, col_cos)
    ps = (0.7, 0.9)  # (between rows, between columns)
    positions = [ORIGIN + 2.5 * k * normal for k in range(n_slices)]
    order = [2, 0, 3, 1]  # slices stored out of order
    _write_dicom_series(tmp_path, pixels[order], ps, np.r_[row_cos, col_cos], [positions[o] for o in order],
                        2.0, -1024.0)
    vol = read_volume(tmp_path)
    assert vol.shape == (cols, rows, n_slices)
    np.testing.assert_allclose(vol.spacing, [0.9, 0.7, 2.5], atol=1e-9)
    for i, j, k in [(0, 0, 0), (6, 5, 3), (3, 2, 1)]:
        want = positions[k] + i * ps[1] * row_cos + j * ps[0] * col_cos
        np.testing.assert_allclose(vol.index_to_world(np.array([[i, j, k]]))[0], want, atol=1e-6)
        assert vol.data[i, j, k] == pytest.approx(2.0 * pixels[k, j, i] - 1024.0)


def test_dicom_series_with_gap_is_rejected(tmp_path):
    pixels = np.zeros((3, 4, 4))
    positions = [np.array([0.0, 0.0, z]) for z in (0.0, 1.0, 3.0)]
    _write_dicom_series(tmp_path, pixels, (1.0, 1.0), [1, 0, 0, 0, 1, 0], positions, 1.0, 0.0)
    with pytest.raises(InputError, match=r"irregular slice positions along the normal \(gaps 1\.\.2 mm\)"):
        read_volume(tmp_path)


# --------------------------------------------------------------------- TIFF
def test_tiff_stack_pages_are_k_and_spacing_from_caller(tmp_path):
    import tifffile

    stack = _ramp((4, 6, 5), np.uint16)  # (pages, rows, columns)
    tifffile.imwrite(str(tmp_path / "s.tif"), stack, photometric="minisblack")
    vol = read_volume(tmp_path / "s.tif", spacing=SPACING, origin=ORIGIN)
    assert vol.shape == (5, 6, 4)
    for i, j, k in [(0, 0, 0), (4, 5, 3), (2, 1, 2)]:
        assert vol.data[i, j, k] == stack[k, j, i]
        np.testing.assert_allclose(vol.index_to_world(np.array([[i, j, k]]))[0], ORIGIN + SPACING * [i, j, k])


def test_tiff_folder_and_rgb(tmp_path):
    import tifffile

    rgb = np.random.default_rng(2).integers(0, 256, (3, 6, 5, 3), dtype=np.uint8)
    for k in range(3):
        tifffile.imwrite(str(tmp_path / f"slice{k:02d}.tif"), rgb[k], photometric="rgb")
    vol = read_volume(tmp_path, spacing=(1, 1, 2))
    assert vol.data.shape == (5, 6, 3, 3)
    np.testing.assert_array_equal(vol.data[4, 2, 1], rgb[1, 2, 4])


# -------------------------------------------------------------------- NumPy
def test_npy_takes_geometry_from_arguments(tmp_path):
    data = _ramp().astype(np.float32)
    np.save(tmp_path / "v.npy", data)
    vol = read_volume(tmp_path / "v.npy", spacing=SPACING, origin=ORIGIN)
    np.testing.assert_allclose(vol.index_to_world(np.array([[3, 1, 2]]))[0], ORIGIN + SPACING * [3, 1, 2])
    np.testing.assert_array_equal(vol.data, data)


def test_npz_stores_geometry(tmp_path):
    np.savez(tmp_path / "v.npz", data=_ramp(), spacing=SPACING, origin=ORIGIN, direction=ROT)
    vol = read_volume(tmp_path / "v.npz")
    np.testing.assert_allclose(vol.direction, ROT)
    np.testing.assert_allclose(vol.index_to_world(np.array([[3, 1, 2]]))[0], ORIGIN + ROT @ (SPACING * [3, 1, 2]))


@pytest.mark.parametrize("ext", [".nrrd", ".nii.gz", ".mha", ".npz"])
def test_write_read_roundtrip_keeps_geometry(tmp_path, ext):
    src = Volume(_ramp(), SPACING, ORIGIN, ROT)
    write_volume(tmp_path / f"out{ext}", src)
    vol = read_volume(tmp_path / f"out{ext}")
    np.testing.assert_array_equal(vol.data, src.data)
    np.testing.assert_allclose(vol.affine, src.affine, atol=1e-5)
    assert sorted(os.listdir(tmp_path)) == [f"out{ext}"]  # no temporary left behind


@pytest.mark.parametrize("ext", [".nii.gz", ".mha", ".npz"])
def test_rgb_roundtrip(tmp_path, ext):
    rgb = np.random.default_rng(3).integers(0, 256, (4, 5, 6, 3), dtype=np.uint8)
    src = Volume(rgb, SPACING, ORIGIN, ROT)
    write_volume(tmp_path / f"c{ext}", src)
    vol = read_volume(tmp_path / f"c{ext}")
    np.testing.assert_array_equal(vol.data, rgb)
    np.testing.assert_allclose(vol.affine, src.affine, atol=1e-5)


# ------------------------------------------------------------------- errors
def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"^.*nope\.nrrd: no such file or folder$"):
        read_volume(tmp_path / "nope.nrrd")


def test_unknown_extension(tmp_path):
    (tmp_path / "v.xyz").write_bytes(b"0")
    with pytest.raises(InputError, match=r"v\.xyz: unknown volume format \(known endings: .*\.nii\.gz"):
        read_volume(tmp_path / "v.xyz")


@pytest.mark.parametrize("ext", [".nrrd", ".nii", ".mha", ".npy", ".tif"])
def test_corrupt_file_gives_one_line(tmp_path, ext):
    path = tmp_path / f"bad{ext}"
    path.write_bytes(b"this is not a volume\n\x00\x01garbage\n" * 3)
    with pytest.raises(InputError, match=rf"bad{ext}: cannot read as ") as err:
        read_volume(path)
    assert "\n" not in str(err.value)


def test_nan_only_volume(tmp_path):
    np.save(tmp_path / "n.npy", np.full((3, 3, 3), np.nan))
    with pytest.raises(InputError, match=r"n\.npy: volume holds no finite value \(all NaN/inf\)$"):
        read_volume(tmp_path / "n.npy")


@pytest.mark.parametrize("shape", [(5,), (3, 3, 3, 4), (2, 2, 2, 2, 2)])
def test_wrong_dimensionality(tmp_path, shape):
    np.save(tmp_path / "d.npy", np.zeros(shape))
    with pytest.raises(InputError, match=r"d\.npy: expected a 3D scalar/label volume or an RGB volume"):
        read_volume(tmp_path / "d.npy")


def test_write_unsupported_format_leaves_nothing(tmp_path):
    with pytest.raises(InputError, match=r"out\.tif: cannot write this format"):
        write_volume(tmp_path / "out.tif", Volume(_ramp()))
    assert os.listdir(tmp_path) == []


# ----------------------------------------------------------------- describe
def test_describe_label_volume():
    data = np.zeros((4, 4, 4), np.uint8)
    data[:2] = 3
    d = describe_volume(Volume(data, (1.0, 2.0, 0.5)))
    assert d["dims"] == [4, 4, 4] and d["channels"] == 1 and d["dtype"] == "uint8"
    assert d["labels"] == [{"label": 0, "voxels": 32, "mm3": 32.0}, {"label": 3, "voxels": 32, "mm3": 32.0}]
    assert d["value_range"] == [0.0, 3.0]


def test_describe_rgb_has_no_labels():
    d = describe_volume(Volume(np.zeros((2, 3, 4, 3), np.uint8)))
    assert d["channels"] == 3 and d["labels"] is None and d["dims"] == [2, 3, 4]
