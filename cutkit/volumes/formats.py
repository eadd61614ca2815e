"""Readers and writers of NIfTI, NRRD, MetaImage and NumPy volumes.

Every function works in our LPS convention (``registry`` module): the
direction matrix has the grid axes' unit world directions as columns and
``world = origin + direction @ (spacing * ijk)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cutkit.errors import InputError
from cutkit.volumes.volume import Volume

#: RAS <-> LPS: negate world x and y (the map is its own inverse).
RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0])

#: NRRD "space" values and the sign flips that take them to LPS.
_NRRD_SPACE_TO_LPS = {
    "left-posterior-superior": (1, 1, 1),
    "lps": (1, 1, 1),
    "right-anterior-superior": (-1, -1, 1),
    "ras": (-1, -1, 1),
    "left-anterior-superior": (1, -1, 1),
    "las": (1, -1, 1),
}


def _split_linear(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3, 3) matrix with scaled axis columns -> (spacing (3,), direction (3, 3))."""
    spacing = np.linalg.norm(m, axis=0)
    if np.any(spacing <= 0):
        raise InputError("degenerate voxel axes (zero spacing)")
    return spacing, m / spacing[None, :]


# --------------------------------------------------------------------- NIfTI
def read_nifti(path: Path) -> Volume:
    import nibabel as nib

    img = nib.load(str(path))
    if len(img.shape) < 3:
        raise InputError(f"{path}: expected a 3D volume, got shape {img.shape}")
    raw = img.dataobj
    slope = getattr(raw, "slope", 1.0)
    inter = getattr(raw, "inter", 0.0)
    if (slope not in (None, 1.0)) or (inter not in (None, 0.0)):
        data = np.asarray(img.get_fdata(dtype=np.float32))  # scaled values are physical
    else:
        data = np.asarray(raw)
    if data.dtype.names:  # RGB24 / RGBA32 structured voxels
        data = np.stack([data[n] for n in data.dtype.names[:3]], axis=-1)
    if data.ndim == 5 and data.shape[3] == 1:  # (x, y, z, t=1, c): the NIfTI vector layout
        data = data[:, :, :, 0, :]
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    affine = RAS_TO_LPS @ np.asarray(img.affine, np.float64)[:3, :]
    spacing, direction = _split_linear(affine[:, :3])
    return Volume(data, spacing, affine[:, 3], direction)


def write_nifti(path: Path, vol: Volume) -> None:
    import nibabel as nib

    a = np.eye(4)
    a[:3, :3] = RAS_TO_LPS @ (vol.direction * vol.spacing[None, :])
    a[:3, 3] = RAS_TO_LPS @ vol.origin
    data = np.asarray(vol.data)
    if data.ndim == 4:
        data = data[:, :, :, None, :]  # NIfTI keeps vector components on the 5th axis
    img = nib.Nifti1Image(data, a)
    img.set_qform(a, code=1)
    img.set_sform(a, code=1)
    img.header.set_xyzt_units("mm")
    if data.ndim == 5:
        img.header.set_intent("vector")
    nib.save(img, str(path))


# ---------------------------------------------------------------------- NRRD
def read_nrrd(path: Path) -> Volume:
    import nrrd

    data, header = nrrd.read(str(path))  # index order F: data[i, j, k] as the file's axes
    dirs = header.get("space directions")
    channel_axis = None
    if dirs is not None:
        rows = [None if r is None or np.any(np.isnan(np.asarray(r, float))) else np.asarray(r, float) for r in dirs]
        none_axes = [a for a, r in enumerate(rows) if r is None]
        if len(none_axes) > 1:
            raise InputError(f"{path}: more than one non-spatial axis in 'space directions'")
        if none_axes:
            channel_axis = none_axes[0]
        spatial = np.array([r for r in rows if r is not None], float)
        if spatial.shape != (3, 3):
            raise InputError(f"{path}: expected 3 spatial axes, 'space directions' gives {len(spatial)}")
        m = spatial.T  # rows of 'space directions' are the axis vectors
        space = str(header.get("space", "left-posterior-superior")).lower()
        flip = np.diag(_NRRD_SPACE_TO_LPS.get(space, (1, 1, 1))).astype(float)
        origin = np.asarray(header.get("space origin", np.zeros(3)), float).reshape(3)
        spacing, direction = _split_linear(flip @ m)
        origin = flip @ origin
    else:
        kinds = [str(k).lower() for k in header.get("kinds", [])]
        for a, k in enumerate(kinds):
            if k in ("rgb-color", "vector", "3-vector", "list", "3-color"):
                channel_axis = a
        sp = [float(s) for s in header.get("spacings", [1.0] * data.ndim)]
        sp = [s for a, s in enumerate(sp) if a != channel_axis]
        spacing = np.array([s if np.isfinite(s) and s > 0 else 1.0 for s in sp][:3])
        direction = np.eye(3)
        origin = np.zeros(3)
    if channel_axis is not None:
        data = np.moveaxis(data, channel_axis, -1)
    return Volume(np.ascontiguousarray(data), spacing, origin, direction)


def write_nrrd(path: Path, vol: Volume) -> None:
    import nrrd

    data = np.asarray(vol.data)
    m = vol.direction * vol.spacing[None, :]
    dirs = m.T.copy()
    kinds = ["domain"] * 3
    if data.ndim == 4:
        data = np.moveaxis(data, -1, 0)  # colour fastest, as NRRD tools expect
        dirs = np.vstack([np.full((1, 3), np.nan), dirs])
        kinds = ["RGB-color" if data.shape[0] == 3 else "vector"] + kinds
    header = {
        "space": "left-posterior-superior",
        "space directions": dirs,
        "space origin": vol.origin.copy(),
        "kinds": kinds,
        "encoding": "gzip",
    }
    nrrd.write(str(path), data, header, compression_level=9)


# ----------------------------------------------------------------- MetaImage
def read_metaimage(path: Path) -> Volume:
    import SimpleITK as sitk

    img = sitk.ReadImage(str(path))
    if img.GetDimension() != 3:
        raise InputError(f"{path}: expected a 3D image, got {img.GetDimension()}D")
    arr = sitk.GetArrayFromImage(img)  # [k, j, i] (+ components)
    data = arr.transpose(2, 1, 0, 3) if arr.ndim == 4 else arr.transpose(2, 1, 0)
    direction = np.asarray(img.GetDirection(), float).reshape(3, 3)  # ITK is LPS already
    return Volume(np.ascontiguousarray(data), img.GetSpacing(), img.GetOrigin(), direction)


def write_metaimage(path: Path, vol: Volume) -> None:
    import SimpleITK as sitk

    data = np.asarray(vol.data)
    rgb = data.ndim == 4
    arr = data.transpose(2, 1, 0, 3) if rgb else data.transpose(2, 1, 0)
    img = sitk.GetImageFromArray(np.ascontiguousarray(arr), isVector=rgb)
    img.SetSpacing([float(s) for s in vol.spacing])
    img.SetOrigin([float(o) for o in vol.origin])
    img.SetDirection([float(d) for d in vol.direction.reshape(-1)])
    sitk.WriteImage(img, str(path), useCompression=str(path).lower().endswith(".mha"))


# --------------------------------------------------------------------- NumPy
def read_npy(path: Path) -> Volume:
    data = np.load(str(path), allow_pickle=False)
    return Volume(data)


def write_npy(path: Path, vol: Volume) -> None:
    with open(path, "wb") as f:  # np.save(path) would append ".npy" to a temporary name
        np.save(f, np.asarray(vol.data), allow_pickle=False)


def read_npz(path: Path) -> Volume:
    with np.load(str(path), allow_pickle=False) as z:
        keys = list(z.keys())
        if "data" in z:
            data = z["data"]
        elif len(keys) == 1:
            data = z[keys[0]]
        else:
            raise InputError(f"{path}: .npz holds several arrays ({', '.join(keys)}) and none named 'data'")
        vol = Volume(data)
        if "spacing" in z:
            vol.spacing = np.asarray(z["spacing"], float).reshape(3)
        if "origin" in z:
            vol.origin = np.asarray(z["origin"], float).reshape(3)
        if "direction" in z:
            vol.direction = np.asarray(z["direction"], float).reshape(3, 3)
    return vol


def write_npz(path: Path, vol: Volume) -> None:
    with open(path, "wb") as f:
        np.savez_compressed(f, data=np.asarray(vol.data), spacing=vol.spacing, origin=vol.origin,
                            direction=vol.direction)
