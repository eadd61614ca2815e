"""The one table of volume formats, and ``read_volume`` / ``write_volume``.

Each format registers a reader, an optional writer and its file-name
endings (like meshio).  ``read_volume`` picks the format by the longest
matching ending (``.nii.gz`` before ``.gz``) or, for a folder, by its
contents (DICOM slices, else TIFF images), then validates what the reader
returned so that every format gives the same guarantees.

World convention: every ``Volume`` is in LPS millimetres (x towards the
patient's Left, y Posterior, z Superior), as DICOM and ITK use.  Readers of
RAS formats (NIfTI) flip x and y on the way in and out.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from cutkit.errors import InputError
from cutkit.volumes.volume import Volume

#: Direction matrices whose columns deviate from unit length by more than
#: this are rejected (a shear or scale hidden in the direction).
DIRECTION_TOLERANCE = 1e-4


@dataclass(frozen=True)
class VolumeFormat:
    """One entry of the format table."""

    name: str
    extensions: tuple[str, ...]
    reader: Callable[[Path], Volume]
    writer: Callable[[Path, Volume], None] | None = None
    #: True when the file stores no geometry, so spacing/origin come from the caller.
    needs_geometry: bool = False


FORMATS: dict[str, VolumeFormat] = {}


def register_format(fmt: VolumeFormat) -> None:
    """Add ``fmt`` to the table (a later registration of a name replaces it)."""
    FORMATS[fmt.name] = fmt


def _register_builtin() -> None:
    from cutkit.volumes import dicom_tiff as dt
    from cutkit.volumes import formats as f

    register_format(VolumeFormat("nifti", (".nii", ".nii.gz"), f.read_nifti, f.write_nifti))
    register_format(VolumeFormat("nrrd", (".nrrd", ".nhdr"), f.read_nrrd, f.write_nrrd))
    register_format(VolumeFormat("metaimage", (".mha", ".mhd"), f.read_metaimage, f.write_metaimage))
    register_format(VolumeFormat("numpy", (".npy",), f.read_npy, f.write_npy, needs_geometry=True))
    register_format(VolumeFormat("numpy-archive", (".npz",), f.read_npz, f.write_npz, needs_geometry=True))
    register_format(VolumeFormat("tiff", (".tif", ".tiff"), dt.read_tiff, None, needs_geometry=True))
    register_format(VolumeFormat("dicom-series", (), dt.read_dicom_series, None))
    register_format(VolumeFormat("tiff-folder", (), dt.read_tiff_folder, None, needs_geometry=True))


def format_for(path: str | os.PathLike) -> VolumeFormat:
    """The table entry that handles ``path`` (by ending, or by a folder's contents)."""
    if not FORMATS:
        _register_builtin()
    path = Path(path)
    if path.is_dir():
        from cutkit.volumes.dicom_tiff import folder_kind

        return FORMATS[folder_kind(path)]
    name = path.name.lower()
    best = None
    for fmt in FORMATS.values():
        for ext in fmt.extensions:
            if name.endswith(ext) and (best is None or len(ext) > len(best[1])):
                best = (fmt, ext)
    if best is None:
        known = sorted(e for f in FORMATS.values() for e in f.extensions)
        raise InputError(f"{path}: unknown volume format (known endings: {', '.join(known)}, or a DICOM/TIFF folder)")
    return best[0]


def read_volume(path: str | os.PathLike, spacing=None, origin=None) -> Volume:
    """Read a volume file or folder into a :class:`Volume` in LPS mm.

    Parameters
    ----------
    path : path-like
        A file (.nii, .nii.gz, .nrrd, .nhdr, .mha, .mhd, .npy, .npz, .tif,
        .tiff) or a folder of DICOM slices or TIFF images.
    spacing : (3,) float, optional
        Voxel size in mm.  Used by formats that store none (.npy, TIFF); for
        the others it overrides the stored spacing.
    origin : (3,) float, optional
        World position (mm) of voxel (0, 0, 0); same rule as ``spacing``.

    Returns
    -------
    Volume
        ``data`` (nx, ny, nz) scalar/label or (nx, ny, nz, 3) RGB.

    Raises
    ------
    InputError
        Missing, unreadable or corrupt file, unknown ending, wrong
        dimensionality, or no finite value.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    fmt = format_for(path)
    if path.is_file() and path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty (0 bytes), not a {fmt.name} volume")
    try:
        vol = fmt.reader(path)
    except InputError:
        raise
    except Exception as exc:  # the libraries raise many types; the user needs one line
        msg = " ".join(str(exc).split())
        if not msg or isinstance(exc, (StopIteration, EOFError)):
            msg = "the file ends before its header is complete"
        raise InputError(f"{path}: cannot read as {fmt.name}: {msg}") from exc
    if spacing is not None:
        vol.spacing = _positive_vec3(spacing, path, "spacing")
    if origin is not None:
        vol.origin = np.asarray(origin, np.float64).reshape(3)
    return validate_volume(vol, path)


def _positive_vec3(v, path, what) -> np.ndarray:
    a = np.asarray(v, np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"{path}: {what} must be three positive numbers (got {', '.join(f'{v:g}' for v in a)})")
    return a


def validate_volume(vol: Volume, path) -> Volume:
    """Check shape, dtype, values and geometry; squeeze a single channel."""
    data = np.asarray(vol.data)
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    if data.ndim == 2:
        data = data[:, :, None]  # one slice is a valid (thin) volume
    if not (data.ndim == 3 or (data.ndim == 4 and data.shape[3] == 3)):
        raise InputError(
            f"{path}: expected a 3D scalar/label volume or an RGB volume (nx, ny, nz, 3), got shape {data.shape}"
        )
    if min(data.shape[:3]) < 1:
        raise InputError(f"{path}: empty volume of shape {data.shape}")
    if data.dtype == np.bool_:
        data = data.astype(np.uint8)
    if not (np.issubdtype(data.dtype, np.integer) or np.issubdtype(data.dtype, np.floating)):
        raise InputError(f"{path}: unsupported voxel type {data.dtype}")
    if np.issubdtype(data.dtype, np.floating) and not np.any(np.isfinite(data)):
        raise InputError(f"{path}: volume holds no finite value (all NaN/inf)")
    vol.data = np.ascontiguousarray(data)
    vol.spacing = _positive_vec3(vol.spacing, path, "spacing")
    if not np.all(np.isfinite(vol.origin)):
        raise InputError(f"{path}: origin is not finite ({', '.join(f'{v:g}' for v in vol.origin)})")
    d = vol.direction
    if not np.all(np.isfinite(d)) or np.max(np.abs(np.linalg.norm(d, axis=0) - 1.0)) > DIRECTION_TOLERANCE:
        raise InputError(f"{path}: direction columns must be unit vectors")
    if abs(np.linalg.det(d)) < 0.5:
        raise InputError(f"{path}: direction matrix is singular")
    return vol


def write_volume(path: str | os.PathLike, volume: Volume) -> None:
    """Write ``volume`` to ``path`` atomically, in the format its ending names.

    Writers exist for NIfTI, NRRD, MetaImage, .npy (data only) and .npz
    (data, spacing, origin, direction).
    """
    from cutkit.io.atomic import atomic_output

    path = Path(path)
    fmt = format_for(path) if not path.is_dir() else None
    if fmt is None or fmt.writer is None:
        writable = sorted(e for f in FORMATS.values() if f.writer for e in f.extensions)
        raise InputError(f"{path}: cannot write this format (writable endings: {', '.join(writable)})")
    if fmt.name == "nrrd" and path.name.lower().endswith(".nhdr"):
        raise InputError(f"{path}: writing detached .nhdr headers is not supported; use .nrrd")
    # The temporary file keeps the full ending so .nii.gz is gzipped.
    ext = next(e for e in sorted(fmt.extensions, key=len, reverse=True) if path.name.lower().endswith(e))
    with atomic_output(path, suffix=ext) as tmp:
        fmt.writer(tmp, volume)
